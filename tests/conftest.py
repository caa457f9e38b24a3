"""Shared fixtures: repository paths, the shared splat data, and small synthetic rooms."""

from __future__ import annotations

import importlib
import os
import shutil
import signal
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from spacedg.plugins import AUTOLOAD_ENV, PLUGINS_ENV, reset_registry

REPO_ROOT = Path(__file__).resolve().parents[1]
SHARED_SPLATS = REPO_ROOT.parent / "shared" / "data" / "splats"
#: Example third-party plugin packages (pip-installed into temporary folders by ``installed``
#: and ``installed_family``).
EXAMPLES = Path(__file__).resolve().parent / "plugins"
#: The example question-family package (installed on its own, so the degradation examples'
#: tests see exactly the plugins they expect).
FAMILY_EXAMPLE = "spacedg-nearest-object"


@pytest.fixture(scope="session")
def shared_splats() -> Path:
    """The real .splat objects beside the checkout; tests using it skip cleanly without it."""
    if not SHARED_SPLATS.is_dir():
        pytest.skip(f"shared splat data not found at {SHARED_SPLATS}")
    return SHARED_SPLATS


@pytest.fixture(scope="session")
def small_room():
    """A small but complete synthetic room (30k Gaussians), generated once per session."""
    from spacedg.scene.synthetic import RoomConfig, generate_room

    return generate_room(7, RoomConfig(gaussians=30_000, row_probability=0.0))  # the test world before wall rows


def private_copies(dirs: list[Path], root: Path, *, indexes: bool = False) -> list[Path]:
    """Copies of scene folders under ``root``, with their visibility caches and, unless
    ``indexes``, without question indexes (tests that build indexes write into the scene folders)."""
    ignore = None if indexes else shutil.ignore_patterns("*.qa.*")
    return [Path(shutil.copytree(d, root / d.name, ignore=ignore)) for d in dirs]


@pytest.fixture(scope="session")
def qa_room_dirs(tmp_path_factory) -> list[Path]:
    """Four small synthetic rooms (30k Gaussians, 24–32 views at 320×240, random world frames)
    saved as native scene folders, for question-index tests.

    Each folder's ``cache/`` holds its visibility and covisibility at the default sizes (what
    ``qa build`` computes first), computed once here: every copy of the rooms reuses them (the
    entries are keyed by scene, cameras and parameters, so a stale one is never read)."""
    from spacedg.scene.io import load_scene, save_scene
    from spacedg.scene.synthetic import CaptureConfig, RoomConfig, generate_room
    from tests.room_qa import prepare_room

    root = tmp_path_factory.mktemp("qa_rooms")
    dirs = []
    for seed in (11, 12, 13, 14):
        config = RoomConfig(gaussians=30_000, capture=CaptureConfig(320, 240, 24, 32), row_probability=0.0)  # the test world before wall rows
        folder = root / f"room-{seed:06d}"
        save_scene(generate_room(seed, config, scene_id=folder.name), folder)
        prepare_room(load_scene(folder), folder / "cache")
        dirs.append(folder)
    return dirs


@pytest.fixture(scope="session")
def indexed_room_dirs(qa_room_dirs, tmp_path_factory) -> list[Path]:
    """Copies of the four session rooms with their full default question index
    (``QABuildConfig()``, what a dataset without ``qa_config`` builds), built once per session;
    copy them with ``private_copies(..., indexes=True)`` before building anything else into them."""
    from spacedg.data.dataset import SpaceDGDataset

    dirs = private_copies(qa_room_dirs, tmp_path_factory.mktemp("indexed_rooms"))
    SpaceDGDataset("train", scenes=dirs)  # builds the four default indexes (in a separate interpreter)
    return dirs


@pytest.fixture(scope="session")
def room_records(qa_room_dirs) -> list[tuple[object, list[object]]]:
    """The four session rooms prepared for questions (visibility from their caches) with every
    family's records at :data:`tests.room_qa.ROOM_CONFIG`, generated once per session:
    ``[(scene, records), ...]`` in room order (read-only: tests must not change them)."""
    from spacedg.scene.io import load_scene
    from tests.room_qa import ROOM_CONFIG, generate, prepare_room

    out = []
    for folder in qa_room_dirs:
        scene = prepare_room(load_scene(folder), folder / "cache")
        out.append((scene, generate(scene, ROOM_CONFIG)))
    return out


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(1234)


# ------------------------------------------------------ third-party plugins
@dataclass(frozen=True)
class Installed:
    main: Path  # spacedg-vignetting + spacedg-broken
    clash: Path  # spacedg-clash


def _pip_install(target: Path, sources: list[Path]) -> None:
    cmd = [sys.executable, "-m", "pip", "install", "--no-deps", "--no-build-isolation", "--no-index", "--quiet",
           "--disable-pip-version-check", "--target", str(target), *map(str, sources)]
    result = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    if result.returncode != 0:
        raise RuntimeError(f"pip install failed ({result.returncode}):\n{result.stdout}\n{result.stderr}")


@pytest.fixture(scope="session")
def installed(tmp_path_factory: pytest.TempPathFactory) -> Installed:
    """Build and install the example plugins (copies, so the source tree stays clean)."""
    root = tmp_path_factory.mktemp("plugin_examples")
    copies = {}
    for name in ("spacedg-vignetting", "spacedg-broken", "spacedg-clash"):
        copies[name] = root / "src" / name
        shutil.copytree(EXAMPLES / name, copies[name], ignore=shutil.ignore_patterns("build", "*.egg-info", "__pycache__"))
    main, clash = root / "site_main", root / "site_clash"
    _pip_install(main, [copies["spacedg-vignetting"], copies["spacedg-broken"]])
    _pip_install(clash, [copies["spacedg-clash"]])
    return Installed(main, clash)


@pytest.fixture(scope="session")
def installed_family(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Build and install the example question family (a copy) into a folder of its own; returns that folder."""
    root = tmp_path_factory.mktemp("family_example")
    source = root / "src" / FAMILY_EXAMPLE
    shutil.copytree(EXAMPLES / FAMILY_EXAMPLE, source, ignore=shutil.ignore_patterns("build", "*.egg-info", "__pycache__"))
    target = root / "site"
    _pip_install(target, [source])
    return target


@pytest.fixture
def clean_env(monkeypatch: pytest.MonkeyPatch):
    """No plugin environment variables; a fresh registry before and after."""
    monkeypatch.delenv(AUTOLOAD_ENV, raising=False)
    monkeypatch.delenv(PLUGINS_ENV, raising=False)
    reset_registry()
    yield monkeypatch
    reset_registry()


@pytest.fixture
def third_party(installed: Installed, clean_env: pytest.MonkeyPatch):
    """The vignetting and broken examples on sys.path (discoverable through their metadata)."""
    clean_env.syspath_prepend(str(installed.main))
    importlib.invalidate_caches()
    reset_registry()
    yield clean_env
    reset_registry()


@pytest.fixture
def family_plugin(installed_family: Path, clean_env: pytest.MonkeyPatch):
    """The example question family on sys.path, and on PYTHONPATH for child processes (the CLI,
    the dataset's index builder), discoverable through its installed metadata."""
    clean_env.syspath_prepend(str(installed_family))
    clean_env.setenv("PYTHONPATH", os.pathsep.join(p for p in (str(installed_family), os.environ.get("PYTHONPATH", "")) if p))
    importlib.invalidate_caches()
    reset_registry()
    yield clean_env
    reset_registry()


def ctrl_c_reaches_child() -> None:
    """``preexec_fn`` of a subprocess a test sends SIGINT to: SIGINT back to its default, so the
    child's Python installs its Ctrl+C handler even when the test run itself ignores SIGINT (a
    background job of a non-interactive shell does)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


@pytest.fixture
def ctrl_c_handler():
    """Python's own SIGINT handler in this process for one test (restored afterwards), for a test
    that delivers SIGINT to itself while the test run ignores SIGINT."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


def pytest_collection_finish(session: pytest.Session) -> None:
    """Start the README and docs runner (tests/test_readme.py) as soon as it is known to be needed:
    it runs in its own process beside the rest of the suite (the machine has two cores), and its
    test waits for it."""
    if any(item.nodeid.startswith("tests/test_readme.py::test_block") for item in session.items):
        from tests import test_readme

        test_readme.launch()


def pytest_sessionfinish(session: pytest.Session) -> None:
    """Stop the README runner if the session ended before its test, and remove its scratch folder."""
    module = sys.modules.get("tests.test_readme")
    if module is not None:
        module.close_launch()
