"""ForkSafeKernel (spacedg.render.threads) passes a kernel's defaults explicitly, so its disk cache hits.

numba types an omitted argument as ``Omitted(default)``, keyed by the default's value, an array's
by its ``id()``: a kernel called without its array default (the former
``defocus_cpu.measure_sharp``'s ``lut``) got a new signature in every process, never found its on-disk cache and compiled afresh
each time (~6 s of CPU per process that rendered defocus).
"""

from __future__ import annotations

import numba
import numpy as np

from spacedg.render.threads import fork_safe

_TABLE = np.arange(4, dtype=np.float64)


@fork_safe
@numba.njit(parallel=True)
def _lookup(n, scale=2.0, table=_TABLE):  # pragma: no cover - compiled
    total = 0.0
    for i in numba.prange(n):
        total += table[i] * scale
    return total


def test_defaults_are_passed_explicitly_and_keep_a_stable_signature() -> None:
    assert _lookup(4) == 12.0 and _lookup(4, 1.0) == 6.0 and _lookup(2, 1.0, np.ones(4)) == 2.0
    signatures = _lookup.parallel.signatures
    assert not any(isinstance(t, numba.types.Omitted) for sig in signatures for t in sig), signatures
    assert len(signatures) == 1, signatures  # (int64, float64, array): one compile whatever was omitted


def test_every_fork_safe_render_kernel_knows_all_its_defaults() -> None:
    import importlib
    import pkgutil

    import spacedg.render as render_pkg
    from spacedg.render.threads import ForkSafeKernel

    kernels = []
    for info in pkgutil.iter_modules(render_pkg.__path__):
        if info.name == "gsplat_backend":
            continue  # needs CUDA's gsplat; holds no numba kernel
        module = importlib.import_module(f"spacedg.render.{info.name}")
        kernels += [k for k in vars(module).values() if isinstance(k, ForkSafeKernel)]
    assert kernels, "no fork-safe kernel found under spacedg.render"
    for kernel in kernels:
        code = kernel.parallel.py_func.__code__
        assert kernel._arity == code.co_argcount, kernel
        assert len(kernel._defaults) == len(kernel.parallel.py_func.__defaults__ or ()), kernel
