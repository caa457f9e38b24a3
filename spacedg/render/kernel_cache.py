"""numba's on-disk kernel cache, with every data file of spacedg's kernels checked against the entry that names it.

Why: numba (``cache=True``) keeps one index file per function (qualified name and source line)
mapping each compiled signature to a numbered data file. Its ``save`` loads the index, takes the
first number the index does not use, writes the index, then the data. Two processes compiling
**different** signatures of one function at once (the two test lanes on a fresh clone,
DataLoader workers or ``qa build --jobs`` on a fresh install) can both take the same number:
the index that survives then names a data file the other process wrote, and the next process
loads that entry's machine code for the wrong signature, without any error. Seen once in CI:
colour renders came out black; giving the compositor's specialisations their own names
(:func:`spacedg.render.raster_cpu._make_composite`) closed that case only.

What this does: a kernel whose source file lies under a checked folder (spacedg's package;
:func:`check_caches_under` adds one) caches through :class:`CheckedCacheFile`: its files are
named ``<numba's name>.checked.nbi`` / ``.checked.<n>.nbc`` and each data file also holds the
key (signature, target, source hashes) it was written for; a load whose data file holds another
key is a cache miss: numba compiles again and writes the entry anew. A wrong entry can then cost a
compile, never a wrong result. The decision is made from the kernel's source file, so it holds
wherever numba puts the cache (``__pycache__``, ``NUMBA_CACHE_DIR``, the user-wide cache). Every
other kernel keeps numba's own files, untouched, and numba without this module never opens the
``.checked`` files (other names). Installed by importing this module, which every spacedg module
with cached kernels does before defining them (a test holds them to it): it wraps
``numba.core.caching.Cache.__init__`` for the process.
"""

from __future__ import annotations

import inspect
import os
from pathlib import Path
from typing import Any

import numpy as np

from numba.core import caching

from spacedg.render import cpu_target  # noqa: F401 - numba's CPU features set before any kernel compiles

__all__ = ["CHECKED_SUFFIX", "ENTRY_TAG", "CheckedCacheFile", "check_caches_under", "install", "installed", "is_checked_source", "read_only"]

#: First item of every data file a :class:`CheckedCacheFile` writes: ``(ENTRY_TAG, key, data)``.
ENTRY_TAG = "spacedg-kernel-cache-entry-1"
#: Added to numba's file name base of a checked kernel's cache files.
CHECKED_SUFFIX = ".checked"

#: The folders (real paths) whose kernels' caches are checked.
_ROOTS: list[str] = []


class CheckedCacheFile(caching.IndexDataCacheFile):
    """numba's index and data files, each data file holding the key it was written for (module docstring)."""

    def save(self, key: Any, data: Any) -> None:
        """Save ``(ENTRY_TAG, key, data)`` as numba saves ``data``."""
        super().save(key, (ENTRY_TAG, key, data))

    def load(self, key: Any) -> Any:
        """numba's entry for ``key``, or ``None`` (a miss: numba compiles) unless its data file was written for ``key``."""
        entry = super().load(key)
        if type(entry) is tuple and len(entry) == 3 and entry[0] == ENTRY_TAG and entry[1] == key:
            return entry[2]
        return None


def check_caches_under(folder: str | os.PathLike[str]) -> None:
    """Also check the caches of kernels whose source file lies under ``folder`` (spacedg's package is
    checked from the start; a plugin with cached kernels, or a test, may add its own folder). Takes
    effect for kernels defined afterwards."""
    root = os.path.realpath(os.fspath(folder))
    if root not in _ROOTS:
        _ROOTS.append(root)


def is_checked_source(path: str | os.PathLike[str]) -> bool:
    """Whether a kernel defined in the source file ``path`` caches through :class:`CheckedCacheFile`
    (the file lies under a checked folder, compared by path components after resolving links)."""
    real = os.path.realpath(os.fspath(path))
    for root in _ROOTS:
        try:
            if os.path.commonpath([real, root]) == root:
                return True
        except ValueError:  # another drive
            continue
    return False


def _checked_init(plain_init: Any) -> Any:
    def __init__(self: Any, py_func: Any) -> None:
        """numba's ``Cache.__init__``; a kernel under a checked folder then caches through :class:`CheckedCacheFile`."""
        plain_init(self, py_func)
        try:
            source = inspect.getfile(py_func)
        except TypeError:
            return
        if is_checked_source(source):
            self._cache_file = CheckedCacheFile(
                cache_path=self._cache_path, filename_base=self._impl.filename_base + CHECKED_SUFFIX,
                source_stamp=self._impl.locator.get_source_stamp(),
            )

    __init__._spacedg_checked = True  # type: ignore[attr-defined]
    return __init__


def install() -> bool:
    """Check the caches of spacedg's kernels in this process (module docstring); idempotent. Returns
    whether the check is active (``False`` if this numba's ``Cache`` does not build its cache file
    in ``__init__`` as 0.60–0.68 do: numba's cache then works as numba's own)."""
    check_caches_under(Path(__file__).resolve().parents[1])
    init = getattr(caching.Cache, "__init__", None)
    if init is None or not hasattr(caching, "IndexDataCacheFile"):
        return False
    if not getattr(init, "_spacedg_checked", False):
        caching.Cache.__init__ = _checked_init(init)
    return True


def installed() -> bool:
    """Whether the check is active in this process."""
    return bool(getattr(caching.Cache.__init__, "_spacedg_checked", False))


def read_only(array: np.ndarray) -> np.ndarray:
    """A read-only view of ``array`` (the same memory) to hand a kernel.

    numba compiles, and caches, a kernel once per combination of its array arguments' writeability:
    fed a frozen array in one call and a fresh one in the next, a kernel compiled twice (4–8 s each
    for the compositor, in every process whose cache lacked the second). Frozen: a scene's instance
    ids (a scene without them gets a fresh fill), the render the pipeline hands the first step of a
    linear chain (the next step gets the previous one's new array). The wrappers of the kernels
    that meet both (the compositor's ids, the sensor's input and skip flags, the drops' input, the
    sRGB encoder and decoder) pass them through this, so both share one signature, the one
    ``spacedg kernels`` compiles."""
    view = array.view()
    view.flags.writeable = False
    return view


install()
