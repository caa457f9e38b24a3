"""numba's on-disk cache with checked entries (spacedg.render.kernel_cache): an index entry that
names another signature's data file (two processes saving at once) is a miss, never wrong code."""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
import textwrap
from pathlib import Path

from numba.core.caching import IndexDataCacheFile

from spacedg.render import kernel_cache

REPO_ROOT = Path(__file__).resolve().parents[2]


def _cache_file(folder: Path, checked: bool = True) -> IndexDataCacheFile:
    """A cache file of a kernel whose source lies in ``folder`` (its ``__pycache__``), checked or not."""
    if checked:
        kernel_cache.check_caches_under(folder)
    (folder / "__pycache__").mkdir(parents=True, exist_ok=True)  # numba's locator makes it
    return IndexDataCacheFile(str(folder / "__pycache__"), "kernel-12.py311", ("source stamp", 1))


def test_the_check_is_installed_by_the_kernel_modules_for_spacedgs_own_caches() -> None:
    import spacedg
    import spacedg.render.raster_cpu  # noqa: F401 - any kernel module installs it

    assert kernel_cache.installed()
    assert kernel_cache.install()  # idempotent
    assert kernel_cache.installed()
    package = Path(spacedg.__file__).parent
    assert kernel_cache._is_checked(IndexDataCacheFile(str(package / "render" / "__pycache__"), "k-1.py311", ("stamp", 1)))
    mirrored = str(package / "render").lstrip("/")  # NUMBA_CACHE_DIR and the user-wide cache mirror the source folder
    assert kernel_cache._is_checked(IndexDataCacheFile(f"/var/cache/numba/{mirrored}", "k-1.py311", ("stamp", 1)))
    assert not kernel_cache._is_checked(IndexDataCacheFile(str(package.with_name("spacedg_other") / "__pycache__"), "k-1.py311", ("stamp", 1)))


def test_other_packages_caches_keep_numbas_own_format(tmp_path: Path) -> None:
    """A process without spacedg must still read them: no key is added, none is asked for."""
    cache = _cache_file(tmp_path / "elsewhere", checked=False)
    cache.save(("float64",), ("machine code",))
    name = cache._load_index()[("float64",)]
    assert cache._load_data(name) == ("machine code",)
    assert cache.load(("float64",)) == ("machine code",)


def test_an_entry_naming_another_keys_data_is_a_miss(tmp_path: Path) -> None:
    cache = _cache_file(tmp_path)
    mine, theirs = ("float64",), ("int64",)
    cache.save(mine, ("machine code for float64",))
    assert cache.load(mine) == ("machine code for float64",)
    name = cache._load_index()[mine]
    # the race: another process took the same free number for its own key and its index won,
    # while this process's data file is the one on disk
    cache._save_index({theirs: name})
    assert cache._load_data(name)[1] == mine  # numba alone would hand this to the int64 caller
    assert cache.load(theirs) is None  # a miss: numba compiles int64 again
    assert cache.load(mine) is None  # its entry is gone from the index: a miss too
    cache.save(theirs, ("machine code for int64",))
    assert cache.load(theirs) == ("machine code for int64",)


def test_a_data_file_without_its_key_is_a_miss(tmp_path: Path) -> None:
    cache = _cache_file(tmp_path)
    key = ("float32",)
    cache.save(key, "anything")
    name = cache._load_index()[key]
    cache._save_data(name, ("numba's own format",))  # written by numba without the check, or an older spacedg
    assert cache.load(key) is None
    cache.save(key, ("recompiled",))
    assert cache.load(key) == ("recompiled",)


_KERNEL = textwrap.dedent(
    """
    import sys
    import os
    import numba
    from spacedg.render import kernel_cache

    kernel_cache.check_caches_under(os.path.dirname(os.path.abspath(__file__)))

    @numba.njit(cache=True)
    def scaled(x):
        return x * 3

    print(repr(scaled(2)), repr(scaled(0.5)), flush=True)
    """
)


def _run(folder: Path) -> str:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO_ROOT), str(folder)])}
    done = subprocess.run([sys.executable, str(folder / "kernel_module.py")], env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    return done.stdout.strip()


def test_a_real_kernel_survives_crossed_cache_entries(tmp_path: Path) -> None:
    """Two signatures of one cached kernel, their index entries crossed as the race leaves them:
    the next process computes the right values (it recompiles) and then loads them from the cache."""
    (tmp_path / "kernel_module.py").write_text(_KERNEL)
    assert _run(tmp_path) == "6 1.5"
    [index_path] = list((tmp_path / "__pycache__").glob("kernel_module.scaled-*.nbi"))
    with open(index_path, "rb") as f:
        version = pickle.load(f)
        stamp, overloads = pickle.loads(f.read())
    assert len(overloads) == 2
    (key_a, name_a), (key_b, name_b) = overloads.items()
    with open(index_path, "wb") as f:
        pickle.dump(version, f, protocol=-1)
        f.write(pickle.dumps((stamp, {key_a: name_b, key_b: name_a}), protocol=-1))
    assert _run(tmp_path) == "6 1.5"
    assert _run(tmp_path) == "6 1.5"
