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

Table lookups on AMD Zen 3 (:func:`vectorise_table_lookups`): LLVM's cost model prices an AVX2 gather
on ``znver3`` as the scalar loads it replaces (it lacks LLVM's ``fast-gather`` tuning, which Intel's
cores from Skylake on carry), so a loop that reads a table per element stays scalar there, arithmetic
and all. The sensor's noise draw (:mod:`spacedg.plugins.degradations._sensor`: two 64-bit hashes, a
Poisson table search and a normal-quantile table per value) was written as such a loop for SIMD; on a
Zen 3 host it ran scalar: 154.7 ms for 5.45 M values (low light's photosites at 640 × 480, one
thread) against 106.0 ms vectorised, the same bits (``benchmarks/sensor_speed.py --old c79a7bf``). The lookups alone are not faster gathered:
the sRGB encode (a two-entry table read per value) took 0.86 → 1.39 ms a 640 × 480 view with the
tuning on for every kernel. So the tuning is per function: a kernel calls
:func:`vectorise_table_lookups` first, and on a host of :data:`FAST_GATHER_CPUS` with AVX2 that
function alone is compiled with ``+fast-gather`` (an LLVM ``target-features`` attribute: numba's own
features plus the flag); elsewhere the call compiles to nothing. A feature string that says
``-fast-gather`` (``NUMBA_CPU_FEATURES``) turns it off. The decision's inputs are what numba keys its
cache by (target triple, CPU name, features), so an entry compiled for one host is loaded only where the
same decision holds; its rule (:data:`FAST_GATHER_CPUS`) is not in the key: a cache written before that
set changes keeps its tuning until the kernel's source changes. Tuning only: either way the same bytes.
"""

from __future__ import annotations

import os
import platform

from numba.core import config, registry, types
from numba.extending import intrinsic

__all__ = [
    "FAST_GATHER_CPUS", "FAST_GATHER_FEATURE", "FULL_WIDTH_CPUS", "FULL_WIDTH_FEATURE", "VECTORS_ENV", "full_width_vectors",
    "gathers_pay", "prefer_full_width_vectors", "vectorise_table_lookups",
]

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


#: LLVM's tuning flag that prices an AVX2 gather below the scalar loads it replaces.
FAST_GATHER_FEATURE = "+fast-gather"
#: LLVM CPU names whose table-reading loops :func:`vectorise_table_lookups` compiles with
#: :data:`FAST_GATHER_FEATURE` (measured: ``znver3``, module docstring). Intel's cores carry the tuning
#: already; other AMD cores are not measured and keep numba's default.
FAST_GATHER_CPUS = frozenset({"znver3"})


def gathers_pay(triple: str, cpu: str, features: str) -> bool:
    """Whether a kernel that reads tables per element is compiled with :data:`FAST_GATHER_FEATURE` for a
    numba target of this LLVM ``triple``, ``cpu`` name and ``features`` string (numba's ``magic_tuple``):
    an x86-64 CPU of :data:`FAST_GATHER_CPUS` with AVX2 whose features say nothing of ``fast-gather``
    already (``+fast-gather``: nothing to add; ``-fast-gather``: the user's choice, kept)."""
    flags = features.split(",")
    said = {FAST_GATHER_FEATURE, "-" + FAST_GATHER_FEATURE[1:]} & set(flags)
    return triple.startswith(("x86_64", "amd64")) and cpu in FAST_GATHER_CPUS and "+avx2" in flags and not said


@intrinsic
def vectorise_table_lookups(typingctx):  # type: ignore[no-untyped-def]
    """Call first in a numba function whose loop reads tables per element and is written to vectorise: on a
    host where :func:`gathers_pay`, that function is compiled with :data:`FAST_GATHER_FEATURE` added to
    numba's features (an LLVM ``target-features`` attribute on it alone); elsewhere nothing. Changes no
    result: only whether LLVM's loop vectoriser takes the loop (the arithmetic and its order are the
    source's). Call it in the function that holds the loop: the attribute is that function's. numba optimises
    each function in a module of its own before linking it into its callers, so it stays there; LLVM's
    inliner treats ``fast-gather`` as a tuning flag that does not block inlining, so a copy inlined into a
    caller without it (several helpers in one module) is compiled with the caller's tuning. Inside a
    ``parallel=True`` function the loop body is outlined into a function of its own, without the attribute:
    call it from a separate function the parallel loop calls (as ``_photosite_kernel._binned_rows``)."""

    def codegen(context, builder, signature, args):  # type: ignore[no-untyped-def]
        triple, cpu, features = context.codegen().magic_tuple()
        attributes = builder.function.attributes
        if gathers_pay(str(triple), str(cpu), str(features)) and isinstance(attributes, set):
            # llvmlite names only enum attributes; a string attribute is written into the IR as it is
            set.add(attributes, f'"target-features"="{features},{FAST_GATHER_FEATURE}"')
        return context.get_dummy_value()

    return types.void(), codegen


prefer_full_width_vectors()
