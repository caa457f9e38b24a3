"""Freed image buffers kept in the process: no page fault for every large array a render allocates.

glibc's ``malloc`` maps an allocation at or above its mmap threshold (128 KiB at start) afresh with
``mmap`` and unmaps it on ``free``; each time one is freed, the threshold rises to its size (at most
32 MiB) and the trim threshold to twice that, and whenever more than the trim threshold lies free at the
top of the heap it is returned to the kernel. A render allocates and frees arrays of a few sizes over and
over (a 640 × 480 view's decoded colour, 3.7 MB; the rasterizer's outputs and pair lists; motion blur's
keyframe canvases, whose size changes from view to view), so the heap top was returned and faulted in
again by the next item's first writes: a fault is a kernel entry that zeroes 4 KiB, several microseconds
in a virtual machine.

Measured on the 4 built-in rooms at 640 × 480, a clean and a motion-blurred dataset item read in turn
(``SpaceDGDataset``, 0 workers, 24 items each, two alternated runs): 182,000 → 24,000 minor faults,
0.71 → 0.19 s of system time, the clean item 46.7 → 42.7 ms and the motion-blurred one 256 → 230 ms.
The same bytes: only where the memory comes from changes. A trim threshold of 32 MiB kept none of it
(247,000 faults with low light's items among them, against 234,000 by default and 49,000 at 64 or 128 MiB).

:func:`keep_freed_memory` (called by :func:`spacedg.render.render` before a render on the compiled CPU
path; a DataLoader worker forked after its parent rendered inherits it, any other applies it at its own
first render) sets ``M_MMAP_THRESHOLD`` to :data:`MMAP_THRESHOLD_BYTES` (smaller arrays come from the
heap and are reused) and ``M_TRIM_THRESHOLD`` to :data:`TRIM_THRESHOLD_BYTES` (up to that much free
memory at the top of the main heap is kept). Setting either also fixes both for good (glibc's dynamic
adjustment stops). What it costs: the process's resident memory stays near its high-water mark between
items instead of dropping, and the heaps of other threads (64 MiB each at most) are no longer trimmed,
so memory a thread freed stays with it.

Nothing is done when ``SPACEDG_KEEP_FREED_MEMORY`` is ``0``, ``false``, ``no`` or ``off``, when the user
set glibc's own malloc variables (``MALLOC_MMAP_THRESHOLD_``, ``MALLOC_TRIM_THRESHOLD_``, or a
``glibc.malloc.`` tunable in ``GLIBC_TUNABLES``), or on a C library without ``mallopt`` (macOS, musl).
"""

from __future__ import annotations

import ctypes
import os
import sys

__all__ = ["MMAP_THRESHOLD_BYTES", "TRIM_THRESHOLD_BYTES", "keep_freed_memory"]

#: Allocations below this many bytes come from the heap (and are reused once freed): every array of a
#: 640 × 480 render and low light's photosite grid (22 MB); the largest glibc accepts before 2.35 (half its
#: 64 MiB heap size).
MMAP_THRESHOLD_BYTES = 32 << 20
#: Free memory at the top of the main heap kept for later allocations, up to this many bytes (32 MiB kept
#: too little of a motion-blurred item's, 64 MiB all of it: module docstring).
TRIM_THRESHOLD_BYTES = 128 << 20
#: ``mallopt`` parameters (glibc's ``malloc.h``).
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
#: Values of ``SPACEDG_KEEP_FREED_MEMORY`` that leave malloc alone.
_OFF = frozenset({"0", "false", "no", "off"})

_applied: bool | None = None


def keep_freed_memory() -> bool:
    """Keep freed large arrays in this process's heap (module docstring); whether the settings are in
    force. Idempotent and cheap after the first call (a race between threads on the first call sets the
    same values twice); never raises."""
    global _applied
    if _applied is None:
        _applied = _apply()
    return _applied


def _users_own_settings() -> bool:
    """Whether the environment sets glibc's malloc already (then it is the user's to keep)."""
    return ("MALLOC_MMAP_THRESHOLD_" in os.environ or "MALLOC_TRIM_THRESHOLD_" in os.environ
            or "glibc.malloc." in os.environ.get("GLIBC_TUNABLES", ""))


def _apply() -> bool:
    if os.environ.get("SPACEDG_KEEP_FREED_MEMORY", "1").strip().lower() in _OFF or _users_own_settings():
        return False
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None)
    except OSError:
        return False
    # glibc only: musl has mallopt as a no-op stub and no version call
    if not (hasattr(libc, "mallopt") and hasattr(libc, "gnu_get_libc_version")):
        return False
    mallopt = libc.mallopt
    mallopt.argtypes, mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    return mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES) == 1 and mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES) == 1
