"""The README runs as written: every bash and Python block, in order, in a scratch checkout-like folder.

The blocks run as a reader runs them, top to bottom, each building on what the earlier ones made
(``runs/demo/scenes`` from the Command line section, a bench from the Export section, …), through
:mod:`tests.readme_runner` in a separate process. The scratch folder has the checkout's
``benchmarks/`` and ``tests/`` (linked), ``../shared`` beside it when the real one exists, and its
own ``docs/`` and ``runs/``. ``SPACEDG_HOME`` points into the scratch folder and is seeded with
16 small built-in rooms (20k Gaussians, ≤ 16 views at 160×120), so the Dataset section's
``SpaceDGDataset()`` with its default scenes runs in seconds instead of building 16 full rooms
(the README states that first-use cost). Blocks that cannot run in a test say why in a
``<!-- readme-test: … -->`` directive (the test suite itself, a hub model, a GPU, an external
checkout); a hub-model block still runs up to the model load.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.readme_runner import read_blocks

REPO_ROOT = Path(__file__).resolve().parents[1]
README = REPO_ROOT / "README.md"
SHARED = REPO_ROOT.parent / "shared"
BLOCKS = read_blocks(README.read_text(encoding="utf-8"))


@pytest.fixture(scope="module")
def readme_run(tmp_path_factory) -> dict[int, dict[str, object]]:
    root = tmp_path_factory.mktemp("readme")
    work = root / "main"
    work.mkdir()
    for name in ("benchmarks", "tests"):
        (work / name).symlink_to(REPO_ROOT / name)
    (work / "docs").mkdir()
    if SHARED.is_dir():
        (root / "shared").symlink_to(SHARED)
    env = dict(os.environ, SPACEDG_HOME=str(root / "home"), PYTHONPATH=os.pathsep.join(
        [str(REPO_ROOT), *filter(None, [os.environ.get("PYTHONPATH")])]))
    spacedg = Path(sys.executable).with_name("spacedg")
    subprocess.run([str(spacedg), "scenes", "synth", "--n", "16", "--gaussians", "20000", "--min-views", "12", "--max-views", "16",
                    "--width", "160", "--height", "120", "--out", str(root / "home" / "rooms")],
                   env=env, check=True, capture_output=True, timeout=600)
    proc = subprocess.run([sys.executable, "-m", "tests.readme_runner", str(README), str(work)], cwd=REPO_ROOT, env=env,
                          capture_output=True, text=True, timeout=1200)
    results = {}
    for line in proc.stdout.splitlines():
        if line.startswith("{"):
            result = json.loads(line)
            results[int(result["line"])] = result
    if not results:
        pytest.fail(f"the README runner reported nothing (exit {proc.returncode}):\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}")
    return results


def test_the_readme_has_runnable_blocks() -> None:
    assert sum(b.directive != "skip" for b in BLOCKS) >= 10
    for block in BLOCKS:
        if block.directive in ("skip", "hub", "server", "file"):
            assert block.argument, f"README line {block.line}: the {block.directive} directive needs its argument"


@pytest.mark.parametrize("block", BLOCKS, ids=[f"line{b.line}-{b.lang}" for b in BLOCKS])
def test_readme_block(block, readme_run) -> None:
    result = readme_run.get(block.line)
    assert result is not None, f"README line {block.line}: the runner did not report this block"
    if result["status"] == "skipped":
        pytest.skip(f"README line {block.line}: {result['output']}")
    assert result["status"] == "ok", f"README line {block.line} ({block.lang}) {result['status']}:\n{block.code}\n--- output ---\n{result['output']}"
