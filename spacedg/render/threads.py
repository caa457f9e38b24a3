"""Fork-safe parallel kernels: a process forked after numba's OpenMP threads started runs them serially.

numba runs ``parallel=True`` kernels on a threading layer; on Linux that is GNU OpenMP
(``omp``) unless TBB is installed. GNU OpenMP is **not fork-safe**: once a process has
rendered, a child forked from it (a PyTorch DataLoader worker after ``dataset[0]``) would abort
on its first parallel kernel. Every parallel kernel of spacedg is therefore wrapped in a
:class:`ForkSafeKernel`: in such a child it runs a serial twin — the same Python function
compiled without ``parallel`` (prange is range) — which gives the same bytes (every kernel
writes each output element from one iteration, in one order) and never touches OpenMP.

Alternatives measured on the built-in room at 640×480 (165k Gaussians), median of 30 renders:

- numba's fork-safe ``workqueue`` layer: 20.6 → 16.3 ms on 1 → 2 threads against OpenMP's
  19.4 → 12.7 ms (+6 % / +28 %), and 300 small 64×48 renders took 0.25 s instead of 0.11 s on
  1 thread (its idle threads nap-poll, so each launch waits ~60 µs);
- TBB: fork-safe and fast, but not installable everywhere (``libtbb``).

With serial twins the main process keeps OpenMP at full speed (no cost); only workers forked
after the main process rendered run single-threaded: a render there takes the 1-thread time
(serial twins and the parallel kernels on 1 thread measured 20.6 vs 20.0 ms and 20.8 vs
20.9 ms, alternating), i.e. ~20 ms instead of ~13 ms where 2 cores are free — DataLoader
workers usually share the cores between them anyway, and this is the case that used to abort. Workers forked before any render, and processes on the ``tbb`` or
``workqueue`` layers, use the parallel kernels. ``OMP_WAIT_POLICY=PASSIVE`` (set by
``import spacedg``) is unchanged.
"""

from __future__ import annotations

import contextlib
import functools
import os
import types
from collections.abc import Iterator
from typing import Any

__all__ = ["ForkSafeKernel", "fork_safe", "limit_blas_threads", "serial_kernels", "serial_mode", "set_render_threads"]

_serial = False


def serial_mode() -> bool:
    """Whether this process was forked after its parent's OpenMP threads started (kernels run serially)."""
    return _serial


@contextlib.contextmanager
def serial_kernels() -> Iterator[None]:
    """Within the block every :class:`ForkSafeKernel` runs its serial twin in this process, as a forked
    worker would: the warm-up (``spacedg kernels``' ``serial`` group) compiles the twins into numba's cache
    this way, so the workers load them. Safe anywhere (a twin never touches OpenMP); same bytes."""
    global _serial
    before = _serial
    _serial = True
    try:
        yield
    finally:
        _serial = before


def _omp_pool_started() -> bool:
    import sys

    if "numba" not in sys.modules:
        return False
    try:
        import numba
        from numba.np.ufunc import parallel
    except Exception:  # noqa: BLE001 - a fork hook must never fail
        return False
    if not getattr(parallel, "_is_initialized", False):
        return False
    try:
        return numba.threading_layer() == "omp"
    except ValueError:
        return False


def _after_fork_in_child() -> None:
    global _serial
    if _serial or _omp_pool_started():
        _serial = True


os.register_at_fork(after_in_child=_after_fork_in_child)


class ForkSafeKernel:
    """A ``numba.njit(parallel=True)`` dispatcher that runs its serial twin in a process forked
    after OpenMP started (see the module docstring). Other attributes are the dispatcher's."""

    def __init__(self, dispatcher: Any) -> None:
        self.parallel = dispatcher
        self._serial: Any = None
        functools.update_wrapper(self, dispatcher.py_func)
        code = dispatcher.py_func.__code__
        self._arity = code.co_argcount
        self._defaults: tuple[Any, ...] = dispatcher.py_func.__defaults__ or ()

    @property
    def serial(self) -> Any:
        """The serial twin (compiled on first use; cached on disk under its own name where the kernel is)."""
        if self._serial is None:
            import numba

            func = self.parallel.py_func
            twin = types.FunctionType(func.__code__, func.__globals__, func.__name__ + "_serial", func.__defaults__, func.__closure__)
            twin.__qualname__ = func.__qualname__ + "_serial"
            options = {k: v for k, v in self.parallel.targetoptions.items() if k not in ("parallel", "nopython", "cache")}
            # ``cache`` is not among the target options: without it the twins were compiled afresh in every
            # forked worker (a clean view's: ~10 s a worker, the workers at once). A dispatcher with a disk
            # cache holds a FunctionCache, one without a NullCache; read defensively (numba's private attribute:
            # an error here would surface as a missing ``serial`` through __getattr__)
            cached = type(getattr(self.parallel, "_cache", None)).__name__ not in ("NullCache", "NoneType")
            self._serial = numba.njit(cache=cached, **options)(twin)
        return self._serial

    def __call__(self, *args: Any) -> Any:
        missing = self._arity - len(args)
        if 0 < missing <= len(self._defaults):
            # defaults passed explicitly: numba keys an omitted argument by its value, an array's by
            # its id(), so a kernel called without its array default never hit its disk cache and
            # compiled afresh in every process (seconds each)
            args = (*args, *self._defaults[len(self._defaults) - missing:])
        return (self.serial if _serial else self.parallel)(*args)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.parallel, name)


def fork_safe(dispatcher: Any) -> ForkSafeKernel:
    """Decorator form: ``@fork_safe`` above ``@numba.njit(parallel=True, ...)``."""
    return ForkSafeKernel(dispatcher)


def set_render_threads(count: int) -> int:
    """Use ``count`` numba threads for this process's parallel kernels (clamped to
    ``[1, NUMBA_NUM_THREADS]``), and at most as many for numpy's BLAS (:func:`limit_blas_threads`);
    returns the count set. Imports numba (the compiled path's runtime); call it in the process
    that renders, e.g. a DataLoader worker."""
    import numba

    count = max(1, min(int(count), int(numba.config.NUMBA_NUM_THREADS)))
    numba.set_num_threads(count)
    limit_blas_threads(count)
    return count


def limit_blas_threads(count: int) -> None:
    """numpy's BLAS (OpenBLAS, MKL, …) on at most ``count`` threads in this process (threadpoolctl):
    each BLAS pool keeps its own count when that is lower already (``OPENBLAS_NUM_THREADS=1``).

    Why: a worker process's BLAS pool starts with every core's thread, so the workers of one
    machine oversubscribe it: the camera projection of the scene depth (``spacedg.data.pipeline.view_depth``,
    one 167k × 3 by 3 × 3 product) took 31–36 ms a view in two processes at once against 9–11 ms
    with one BLAS thread each, on 2 cores. The products spacedg computes (a few columns) come out
    the same bytes on any thread count (BLAS splits the rows and columns of the result; a long sum,
    as in a threaded ``dot``, could split differently). Nothing happens without threadpoolctl or a
    BLAS it knows."""
    try:
        from threadpoolctl import threadpool_info, threadpool_limits
    except ImportError:  # pragma: no cover - a dependency; a stripped environment keeps the defaults
        return
    limits = {
        pool["prefix"]: min(max(1, int(count)), int(pool["num_threads"]))
        for pool in threadpool_info() if pool.get("user_api") == "blas" and pool.get("num_threads")
    }
    if limits:
        threadpool_limits(limits=limits)
