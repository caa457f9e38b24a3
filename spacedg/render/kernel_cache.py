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

What this does: each data file of a kernel whose cache lies under a checked folder (spacedg's
package: its ``__pycache__`` folders, or their mirrors under ``NUMBA_CACHE_DIR`` or numba's
user-wide cache) also holds the key (signature, target, source hashes) it was written for; a
load whose data file holds another key, or a file written without a key (an older spacedg), is a
cache miss: numba compiles again and writes the entry anew. A wrong entry can then cost a compile,
never a wrong result. Every other package's cache keeps numba's own format untouched (so a
process without spacedg still reads it). Installed by importing this module, which every spacedg
module with cached kernels does before defining them; it wraps
``numba.core.caching.IndexDataCacheFile.save``/``load`` for the process.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

__all__ = ["ENTRY_TAG", "check_caches_under", "checked_roots", "install", "installed"]

#: First item of every data file this module writes: ``(ENTRY_TAG, key, data)``.
ENTRY_TAG = "spacedg-kernel-cache-entry-1"

#: The folders (absolute, without drive or leading separator, ending in one) whose kernels' caches are checked.
_ROOTS: list[str] = []


def _mirrored(path: str | os.PathLike[str]) -> str:
    """``path`` as numba's cache locators embed a source folder in a cache folder: absolute,
    without its drive and leading separator (``/a/b`` → ``a/b/``)."""
    rest = os.path.splitdrive(os.path.abspath(os.fspath(path)))[1]
    return rest.strip(os.sep) + os.sep


def check_caches_under(folder: str | os.PathLike[str]) -> None:
    """Also check the cache entries of kernels whose source lies under ``folder`` (spacedg's own
    package is checked from the start; a test or a plugin with cached kernels may add its folder)."""
    root = _mirrored(folder)
    if root not in _ROOTS:
        _ROOTS.append(root)


def checked_roots() -> tuple[str, ...]:
    """The folders whose kernels' cache entries are checked (:func:`check_caches_under`)."""
    return tuple(_ROOTS)


def _is_checked(cache_file: Any) -> bool:
    """Whether ``cache_file`` (an ``IndexDataCacheFile``) belongs to a kernel under a checked folder."""
    where = _mirrored(getattr(cache_file, "_cache_path", ""))
    return any(root in where for root in _ROOTS)


def _checked_save(plain_save: Any) -> Any:
    def save(self: Any, key: Any, data: Any) -> None:
        """numba's ``save``; under a checked folder the data file holds ``(ENTRY_TAG, key, data)``."""
        plain_save(self, key, (ENTRY_TAG, key, data) if _is_checked(self) else data)

    return save


def _checked_load(plain_load: Any) -> Any:
    def load(self: Any, key: Any) -> Any:
        """numba's ``load``; under a checked folder ``None`` (a miss: numba compiles) unless the data
        file was written for ``key``."""
        entry = plain_load(self, key)
        if entry is None or not _is_checked(self):
            return entry
        if type(entry) is tuple and len(entry) == 3 and entry[0] == ENTRY_TAG and entry[1] == key:
            return entry[2]
        return None

    return load


def install() -> bool:
    """Check the cache entries of spacedg's kernels in this process (module docstring); idempotent.
    Returns whether the check is active (``False`` if this numba has no
    ``IndexDataCacheFile.save``/``load``: numba's cache then works as numba's own)."""
    from numba.core import caching

    check_caches_under(Path(os.path.abspath(__file__)).parents[1])  # spacedg/, as its modules' __file__ name it
    cache_file = getattr(caching, "IndexDataCacheFile", None)
    if cache_file is None or not callable(getattr(cache_file, "save", None)) or not callable(getattr(cache_file, "load", None)):
        return False
    if not getattr(cache_file, "_spacedg_checked", False):
        cache_file.save = _checked_save(cache_file.save)
        cache_file.load = _checked_load(cache_file.load)
        cache_file._spacedg_checked = True
    return True


def installed() -> bool:
    """Whether the check is active in this process."""
    from numba.core import caching

    return bool(getattr(getattr(caching, "IndexDataCacheFile", None), "_spacedg_checked", False))


install()
