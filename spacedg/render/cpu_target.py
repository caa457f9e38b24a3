"""numba's CPU target for spacedg's kernels: full-width (512-bit) vectors on AVX-512 hosts.

Why: LLVM tunes Intel's AVX-512 server cores to prefer 256-bit vectors (its ``prefer-256-bit``
tuning: Skylake-SP and Cascade Lake lowered their clock on 512-bit work), so numba, which
compiles for the host, never uses the full registers. spacedg's compositor works on rows of 16
float32 pixels, one 512-bit vector and two 256-bit ones. Measured on an Emerald Rapids host, one
thread (``benchmarks/render_speed.py --old HEAD --old-vectors default``): the composite of 100k
random Gaussians at 640 × 480 41.6 → 31.5 ms, renders 1.13–1.26× faster, the same bits in every
output (spacedg's kernels keep their sums in source order or per pixel, so no result depends on
the vector width).

What: :func:`prefer_full_width_vectors`, run when this module is imported (by
:mod:`spacedg.render.kernel_cache`, which every spacedg module with kernels imports before it
decorates one; ``import spacedg`` alone loads no numba), sets ``numba.config.CPU_FEATURES`` to
numba's own host feature string plus ``-prefer-256-bit`` when

- ``SPACEDG_NUMBA_VECTORS`` is unset or ``auto`` and the host is an x86-64 CPU of a family this was
  measured on or that keeps its clock on 512-bit work (:data:`FULL_WIDTH_CPUS`: Ice Lake and
  later Intel cores), or ``SPACEDG_NUMBA_VECTORS=512`` and the host has AVX-512 at all;
- the user set neither ``NUMBA_CPU_NAME`` nor ``NUMBA_CPU_FEATURES`` (theirs wins);
- numba's CPU target is not set up yet: numba sets it up, and fixes its features, when the first
  kernel is *decorated* (``@njit``), so a library with module-level kernels imported before
  spacedg leaves numba's default in place (correct, a little slower).

``SPACEDG_NUMBA_VECTORS=default`` keeps numba's default. numba keys its on-disk caches by the
feature string, so entries compiled both ways never mix. It is numba's setting for the process:
numba code decorated after spacedg's import is compiled with it too, and a ``fastmath`` reduction
of your own (``reassoc``) may then sum in another order than at numba's default, so its last bits
can differ.
"""

from __future__ import annotations

import os
import platform

from numba.core import config, registry

__all__ = ["FULL_WIDTH_CPUS", "FULL_WIDTH_FEATURE", "VECTORS_ENV", "full_width_vectors", "prefer_full_width_vectors"]

#: Appended to numba's host feature string: turns off LLVM's 256-bit preference.
FULL_WIDTH_FEATURE = "-prefer-256-bit"
#: ``auto`` (default), ``512`` (any AVX-512 host) or ``default`` (numba's own features).
VECTORS_ENV = "SPACEDG_NUMBA_VECTORS"
#: LLVM CPU names that get 512-bit vectors under ``auto``: Intel cores from Ice Lake on, whose clock
#: does not drop on 512-bit work (measured: emeraldrapids). Skylake-SP / Cascade Lake / Cooper Lake
#: (they do drop it) and AMD's Zen 4/5 (512-bit work in two halves) keep numba's default unless asked.
FULL_WIDTH_CPUS = frozenset({
    "icelake-client", "icelake-server", "tigerlake", "rocketlake", "sapphirerapids", "emeraldrapids",
    "graniterapids", "graniterapids-d", "diamondrapids",
})


def _target_initialised() -> bool:
    """Whether numba's CPU target has been set up (by the first decoration): its features are then fixed."""
    return "_toplevel_target_context" in vars(registry.cpu_target)


def prefer_full_width_vectors() -> bool:
    """Ask numba for 512-bit vectors where the module docstring says; ``True`` when numba's CPU
    features are now spacedg's, ``False`` when they were left as they are."""
    choice = os.environ.get(VECTORS_ENV, "auto").strip().lower()
    if choice not in ("auto", "512", "default"):
        raise ValueError(f"{VECTORS_ENV}={choice!r}: use auto (the default), 512 or default")
    if config.CPU_FEATURES is not None:
        return config.CPU_FEATURES.endswith("," + FULL_WIDTH_FEATURE)
    if choice == "default" or config.CPU_NAME is not None or _target_initialised():
        return False
    if platform.machine().lower() not in ("x86_64", "amd64"):
        return False
    from llvmlite import binding
    from numba.core.codegen import get_host_cpu_features

    features = get_host_cpu_features()
    if "+avx512f" not in features.split(","):
        return False
    if choice == "auto" and binding.get_host_cpu_name() not in FULL_WIDTH_CPUS:  # numba's CPU name when unset
        return False
    config.CPU_FEATURES = f"{features},{FULL_WIDTH_FEATURE}"
    return True


def full_width_vectors() -> bool:
    """Whether numba's CPU target compiles with 512-bit vectors preferred in this process (what its
    code generator holds; sets the target up if nothing has yet)."""
    features = registry.cpu_target.target_context.codegen()._tm_features
    return features.endswith("," + FULL_WIDTH_FEATURE)


prefer_full_width_vectors()
