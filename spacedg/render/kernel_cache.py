"""numba's on-disk kernel cache, with every data file checked against the entry that names it.

Why: numba (``cache=True``) keeps one index file per function (qualified name and source line)
mapping each compiled signature to a numbered data file. Its ``save`` loads the index, takes the
first number the index does not use, writes the index, then the data. Two processes compiling
**different** signatures of one function at once (the two test lanes on a fresh clone,
DataLoader workers or ``qa build --jobs`` on a fresh install) can both take the same number:
the index that survives then names a data file the other process wrote, and the next process
loads that entry's machine code for the wrong signature, without any error. Seen once in CI:
colour renders came out black; giving the compositor's specialisations their own names
(:func:`spacedg.render.raster_cpu._make_composite`) closed that case only.

What this does: each data file also holds the key (signature, target, source hashes) it was
written for; a load whose data file holds another key, or a file written without a key (numba's
own format, an older spacedg), is a cache miss: numba compiles again and writes the entry anew.
A wrong entry can then cost a compile, never a wrong result. Installed by importing this module,
which every spacedg module with cached kernels does before defining them; it patches
``numba.core.caching.IndexDataCacheFile`` for the whole process, so other packages' cached
kernels are checked too (their entries written before are recompiled once).
"""

from __future__ import annotations

from typing import Any

__all__ = ["ENTRY_TAG", "install", "installed"]

#: First item of every data file this module writes: ``(ENTRY_TAG, key, data)``.
ENTRY_TAG = "spacedg-kernel-cache-entry-1"


def _checked_save(plain_save: Any) -> Any:
    def save(self: Any, key: Any, data: Any) -> None:
        """numba's ``save``, the data file holding ``(ENTRY_TAG, key, data)``."""
        plain_save(self, key, (ENTRY_TAG, key, data))

    return save


def _checked_load(plain_load: Any) -> Any:
    def load(self: Any, key: Any) -> Any:
        """numba's ``load``; ``None`` (a miss: numba compiles) unless the data file was written for ``key``."""
        entry = plain_load(self, key)
        if type(entry) is tuple and len(entry) == 3 and entry[0] == ENTRY_TAG and entry[1] == key:
            return entry[2]
        return None

    return load


def install() -> bool:
    """Check numba's cache entries in this process (module docstring); idempotent. Returns whether
    the check is active (``False`` if this numba has no ``IndexDataCacheFile.save``/``load``)."""
    from numba.core import caching

    cache_file = getattr(caching, "IndexDataCacheFile", None)
    if cache_file is None or not callable(getattr(cache_file, "save", None)) or not callable(getattr(cache_file, "load", None)):
        return False
    if not getattr(cache_file, "_spacedg_checked", False):
        cache_file.save = _checked_save(cache_file.save)
        cache_file.load = _checked_load(cache_file.load)
        cache_file._spacedg_checked = True
    return True


def installed() -> bool:
    """Whether numba's cache entries are checked in this process."""
    from numba.core import caching

    return bool(getattr(getattr(caching, "IndexDataCacheFile", None), "_spacedg_checked", False))


install()
