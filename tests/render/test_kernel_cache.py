"""numba's on-disk cache with checked entries (spacedg.render.kernel_cache): an index entry that
names another signature's data file (two processes saving at once) is a miss, never wrong code;
other packages' kernels keep numba's own cache files."""

from __future__ import annotations

import os
import pickle
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from numba.core.caching import IndexDataCacheFile

from spacedg.render import kernel_cache
from spacedg.render.kernel_cache import CheckedCacheFile

REPO_ROOT = Path(__file__).resolve().parents[2]
PACKAGE = REPO_ROOT / "spacedg"


def _checked_file(folder: Path) -> CheckedCacheFile:
    (folder / "__pycache__").mkdir(parents=True, exist_ok=True)  # numba's locator makes it
    return CheckedCacheFile(str(folder / "__pycache__"), "kernel-12.py311.checked", ("source stamp", 1))


def test_the_check_is_installed_for_spacedgs_own_kernels(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    import spacedg.render.raster_cpu as raster_cpu

    assert kernel_cache.installed() and kernel_cache.install() and kernel_cache.installed()  # idempotent
    assert type(raster_cpu.bin_tiles._cache._cache_file) is CheckedCacheFile
    assert kernel_cache.is_checked_source(PACKAGE / "render" / "raster_cpu.py")
    assert not kernel_cache.is_checked_source(REPO_ROOT / "tests" / "render" / "test_kernel_cache.py")
    monkeypatch.setattr(kernel_cache, "_ROOTS", [str((tmp_path / "pkg").resolve())])
    assert kernel_cache.is_checked_source(tmp_path / "pkg" / "sub" / "kernels.py")
    assert not kernel_cache.is_checked_source(tmp_path / "pkg2" / "kernels.py")  # a sibling sharing the prefix
    assert not kernel_cache.is_checked_source(tmp_path / "other" / "pkg" / "kernels.py")  # the name deeper in a path


def test_other_packages_kernels_keep_numbas_own_cache_files() -> None:
    import numba

    @numba.njit(cache=True)
    def elsewhere(x):  # pragma: no cover - compiled; defined outside spacedg's package
        return x + 1

    assert type(elsewhere._cache._cache_file) is IndexDataCacheFile


def test_an_entry_naming_another_keys_data_is_a_miss(tmp_path: Path) -> None:
    cache = _checked_file(tmp_path)
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
    cache = _checked_file(tmp_path)
    key = ("float32",)
    cache.save(key, "anything")
    name = cache._load_index()[key]
    cache._save_data(name, ("numba's own format",))
    assert cache.load(key) is None
    cache.save(key, ("recompiled",))
    assert cache.load(key) == ("recompiled",)


def test_every_spacedg_module_with_cached_kernels_installs_the_check_first() -> None:
    """The check applies to kernels defined after its import: each module with ``cache=True`` imports it before any."""
    for path in sorted(PACKAGE.rglob("*.py")):
        text = path.read_text(encoding="utf-8")
        first_cached = text.find("cache=True")
        if first_cached < 0 or path.name == "kernel_cache.py":
            continue
        found = re.search(r"^from spacedg\.render import kernel_cache\b", text, flags=re.MULTILINE)
        assert found and found.start() < first_cached, f"{path.relative_to(REPO_ROOT)} defines cached kernels without importing kernel_cache first"


_KERNEL = textwrap.dedent(
    """
    import os
    import numba
    from spacedg.render import kernel_cache

    kernel_cache.check_caches_under(os.path.dirname(os.path.abspath(__file__)))

    @numba.njit(cache=True)
    def scaled(x):
        return x * 3

    values = (scaled(2), scaled(0.5))
    print(repr(values[0]), repr(values[1]), len(scaled.stats.cache_misses), flush=True)
    """
)


def _run(folder: Path) -> str:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO_ROOT), str(folder)])}
    done = subprocess.run([sys.executable, str(folder / "kernel_module.py")], env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    return done.stdout.strip()


def test_a_real_kernel_survives_crossed_cache_entries(tmp_path: Path) -> None:
    """Two signatures of one cached kernel, their index entries crossed as the race leaves them:
    the next process computes the right values (it recompiles both), the one after loads them."""
    (tmp_path / "kernel_module.py").write_text(_KERNEL)
    assert _run(tmp_path) == "6 1.5 2"  # compiled both
    [index_path] = list((tmp_path / "__pycache__").glob("kernel_module.scaled-*.checked.nbi"))
    with open(index_path, "rb") as f:
        version = pickle.load(f)
        stamp, overloads = pickle.loads(f.read())
    assert len(overloads) == 2
    (key_a, name_a), (key_b, name_b) = overloads.items()
    with open(index_path, "wb") as f:
        pickle.dump(version, f, protocol=-1)
        f.write(pickle.dumps((stamp, {key_a: name_b, key_b: name_a}), protocol=-1))
    assert _run(tmp_path) == "6 1.5 2"  # both entries refused: compiled again, right values
    assert _run(tmp_path) == "6 1.5 0"  # and now both loaded from the cache
