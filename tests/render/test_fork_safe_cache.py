"""ForkSafeKernel (spacedg.render.threads) passes a kernel's defaults explicitly, so its disk cache hits.

numba types an omitted argument as ``Omitted(default)``, keyed by the default's value, an array's
by its ``id()``: a kernel called without its array default (the former
``defocus_cpu.measure_sharp``'s ``lut``) got a new signature in every process, never found its on-disk cache and compiled afresh
each time (~6 s of CPU per process that rendered defocus).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numba
import numpy as np
import pytest

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


_TWIN_CHILD = r"""
import numpy as np
from spacedg.render.motion_warp import finish_average
from spacedg.render.threads import serial_kernels
acc = np.full((2, 3, 4), 2.0, np.float32)
rgb, alpha = np.empty((2, 3, 3), np.float32), np.empty((2, 3), np.float32)
with serial_kernels():
    finish_average(acc, 2, rgb, alpha)
print(finish_average.serial.stats.cache_hits.total(), float(rgb.sum()), float(alpha.sum()))
"""


def test_a_cached_kernels_serial_twin_is_cached_on_disk_under_its_own_name(tmp_path: Path) -> None:
    """A forked worker's twins load from numba's cache like the parallel kernels (``spacedg kernels``'
    ``serial`` group writes them): the second process loads what the first compiled, the same bytes.
    An uncached kernel's twin stays uncached."""
    from spacedg.render.threads import serial_kernels, serial_mode

    assert _lookup.serial._cache.__class__.__name__ == "NullCache"  # _lookup has no cache=True
    assert not serial_mode()
    with serial_kernels():
        assert serial_mode() and _lookup(4) == 12.0 and _lookup.serial.signatures
    assert not serial_mode()
    with pytest.raises(RuntimeError, match="inside"), serial_kernels():
        raise RuntimeError("inside")
    assert not serial_mode()  # restored after an error too
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"), SPACEDG_DISABLE_PLUGIN_AUTOLOAD="1")
    runs = [subprocess.run([sys.executable, "-c", _TWIN_CHILD], env=env, capture_output=True, text=True, check=True).stdout.split()
            for _ in range(2)]
    assert runs[0] == ["0", "18.0", "6.0"] and runs[1] == ["1", "18.0", "6.0"]  # compiled, then loaded from the cache
    assert [p.name.split("-")[0] for p in (tmp_path / "cache").rglob("*.nbi")] == ["motion_warp.finish_average_serial"]
