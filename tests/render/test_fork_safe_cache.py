"""ForkSafeKernel (spacedg.render.threads) passes a kernel's defaults explicitly, so its disk cache hits.

numba types an omitted argument as ``Omitted(default)``, keyed by the default's value, an array's
by its ``id()``: a kernel called without its array default (``defocus_cpu.measure_sharp``'s
``lut``) got a new signature in every process, never found its on-disk cache and compiled afresh
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


def test_the_defocus_measurement_kernel_has_no_omitted_argument() -> None:
    from spacedg.render import defocus_cpu

    kernel = defocus_cpu.measure_sharp
    assert kernel._arity == kernel.parallel.py_func.__code__.co_argcount and len(kernel._defaults) == len(kernel.parallel.py_func.__defaults__ or ())
