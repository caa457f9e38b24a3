"""numba's CPU target for spacedg's kernels: full-width (512-bit) vectors on AVX-512 hosts.

Why: LLVM tunes Intel's AVX-512 server cores (Skylake-SP to Emerald Rapids) to prefer 256-bit
vectors (its ``prefer-256-bit`` tuning: the early ones lowered their clock on 512-bit work), so
numba, which compiles for the host, never uses the full registers. spacedg's compositor works on
rows of 16 float32 pixels, one 512-bit vector and two 256-bit ones. Measured on an Emerald Rapids
host, one thread (``benchmarks/render_speed.py``; ``/work/notes/s46`` in the session notes): the
composite of 100k random Gaussians at 640 × 480 went from 40–58 to 29–32 ms, with the same bits in
every output (no kernel's arithmetic depends on the vector width: their sums keep the source
order, the compositor's are per pixel).

What: :func:`prefer_full_width_vectors`, called when this module is imported (every spacedg module
with kernels imports :mod:`spacedg.render.kernel_cache`, which imports this one first), sets
``numba.config.CPU_FEATURES`` to numba's own host feature string plus ``-prefer-256-bit``, when

- the host is x86-64 with ``avx512f`` (elsewhere the tuning does not exist);
- the user set neither ``NUMBA_CPU_NAME`` nor ``NUMBA_CPU_FEATURES`` (theirs wins; setting
  ``NUMBA_CPU_FEATURES`` to numba's host string is how to keep numba's default);
- numba has not compiled anything yet in this process (its CPU target reads the features once).

numba keys its on-disk caches by the feature string, so these entries never mix with entries
compiled with numba's default. The setting is numba's, for the process: numba code compiled
after spacedg's import gets full-width vectors too.
"""

from __future__ import annotations

import platform

from numba.core import config, registry

__all__ = ["FULL_WIDTH_FEATURE", "prefer_full_width_vectors", "full_width_vectors"]

#: Appended to numba's host feature string: turns off LLVM's 256-bit preference.
FULL_WIDTH_FEATURE = "-prefer-256-bit"


def _target_initialised() -> bool:
    """Whether numba's CPU target has been set up (after which its features are fixed)."""
    return "_toplevel_target_context" in vars(registry.cpu_target)


def prefer_full_width_vectors() -> bool:
    """Ask numba for 512-bit vectors on an AVX-512 x86-64 host (module docstring); ``True`` when
    numba's CPU features are (now) spacedg's, ``False`` when they were left as they are."""
    if config.CPU_FEATURES is not None:
        return config.CPU_FEATURES.endswith("," + FULL_WIDTH_FEATURE)
    if config.CPU_NAME is not None or _target_initialised():
        return False
    if platform.machine().lower() not in ("x86_64", "amd64"):
        return False
    from numba.core.codegen import get_host_cpu_features

    features = get_host_cpu_features()
    if "+avx512f" not in features.split(","):
        return False
    config.CPU_FEATURES = f"{features},{FULL_WIDTH_FEATURE}"
    return True


def full_width_vectors() -> bool:
    """Whether numba compiles with spacedg's full-width setting in this process."""
    return config.CPU_FEATURES is not None and config.CPU_FEATURES.endswith("," + FULL_WIDTH_FEATURE)


prefer_full_width_vectors()
