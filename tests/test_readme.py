"""The README and the documentation pages run as written: every bash and Python block, in order,
in a scratch checkout-like folder.

The README's blocks run first, top to bottom, each building on what the earlier ones made (the
tour's four small rooms in ``runs/demo/scenes``, its bench in ``runs/demo/bench``, its tiny VLM,
…); then each ``docs/*.md`` page's blocks, which continue from the tour's files (each page in a
fresh Python namespace). Everything runs through :mod:`tests.readme_runner` in one separate
process. The scratch folder has the checkout's ``benchmarks/`` and ``tests/`` (linked),
``../shared`` beside it when the real one exists, and its own ``docs/`` and ``runs/``;
``SPACEDG_HOME`` points into it, so nothing touches the user's cache. The tour's rooms are small
(20k Gaussians, 16 views at 160×120), which keeps the whole run short. Blocks that cannot run in
a test say why in a ``<!-- readme-test: … -->`` directive (the test suite itself, a hub model, a
GPU, a cluster, an external checkout); a hub-model block still runs up to the model load.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

from tests.readme_runner import Block, read_blocks

REPO_ROOT = Path(__file__).resolve().parents[1]
README = REPO_ROOT / "README.md"
DOCS = REPO_ROOT / "docs"
SHARED = REPO_ROOT.parent / "shared"
#: The README, then every documentation page (docs/api/ holds only generated reference pages).
PAGES = [README, *sorted(DOCS.glob("*.md"))]
#: What the issue allows the README to be: a guide, not a lab notebook.
README_MAX_LINES = 350


def _name(path: Path) -> str:
    return path.relative_to(REPO_ROOT).as_posix()


BLOCKS: list[Block] = [b for page in PAGES for b in read_blocks(page.read_text(encoding="utf-8"), _name(page))]


class Launch:
    """The runner's process, started as soon as collection finishes (``tests/conftest.py``,
    :func:`launch`) so that it runs beside the rest of the suite on the machine's second core;
    :meth:`results` waits for it. Its scratch folder is removed when the session ends."""

    def __init__(self) -> None:
        self.root = Path(tempfile.mkdtemp(prefix="spacedg-readme-"))
        work = self.root / "main"
        work.mkdir()
        for name in ("benchmarks", "tests"):
            (work / name).symlink_to(REPO_ROOT / name)
        (work / "docs").mkdir()
        if SHARED.is_dir():
            (self.root / "shared").symlink_to(SHARED)
        env = dict(os.environ, SPACEDG_HOME=str(self.root / "home"), PYTHONPATH=os.pathsep.join(
            [str(REPO_ROOT), *filter(None, [os.environ.get("PYTHONPATH")])]))
        self.stdout, self.stderr = (self.root / "runner.out").open("w+"), (self.root / "runner.err").open("w+")
        self.proc = subprocess.Popen([sys.executable, "-m", "tests.readme_runner", *map(_name, PAGES), str(work)],
                                     cwd=REPO_ROOT, env=env, stdout=self.stdout, stderr=self.stderr, text=True)

    def results(self, timeout: float = 2400) -> dict[tuple[str, int], dict[str, object]]:
        """Every block's result by (file, line), once the runner has finished."""
        code = self.proc.wait(timeout=timeout)
        self.stdout.seek(0)
        out = self.stdout.read()
        results = {}
        for line in out.splitlines():
            if line.startswith("{"):
                result = json.loads(line)
                results[(str(result["file"]), int(result["line"]))] = result
        if not results:
            self.stderr.seek(0)
            pytest.fail(f"the runner reported nothing (exit {code}):\n{out[-3000:]}\n{self.stderr.read()[-3000:]}")
        return results

    def close(self) -> None:
        """Stop the runner if it still runs (an aborted session) and remove its scratch folder."""
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()
        self.stdout.close()
        self.stderr.close()
        shutil.rmtree(self.root, ignore_errors=True)


_LAUNCH: Launch | None = None


def launch() -> Launch:
    """Start the runner once per session (idempotent)."""
    global _LAUNCH
    if _LAUNCH is None:
        _LAUNCH = Launch()
    return _LAUNCH


def close_launch() -> None:
    """End of session: see :meth:`Launch.close`."""
    global _LAUNCH
    if _LAUNCH is not None:
        _LAUNCH.close()
        _LAUNCH = None


@pytest.fixture(scope="module")
def readme_run() -> dict[tuple[str, int], dict[str, object]]:
    return launch().results()


def test_the_readme_is_a_guide() -> None:
    lines = README.read_text(encoding="utf-8").count("\n")
    assert lines <= README_MAX_LINES, f"README.md has {lines} lines; keep it a guide (≤ {README_MAX_LINES}) and move details to docs/"


def test_the_pages_have_runnable_blocks() -> None:
    assert sum(b.directive != "skip" for b in BLOCKS if b.source == "README.md") >= 10
    for block in BLOCKS:
        if block.directive in ("skip", "hub", "server", "file"):
            assert block.argument, f"{block.source} line {block.line}: the {block.directive} directive needs its argument"


def test_files_written_by_several_pages_agree() -> None:
    """A plugin file shown in the README and in docs/plugins.md is one file: the copies may not drift."""
    by_name: dict[str, Block] = {}
    for block in BLOCKS:
        if block.directive == "file":
            first = by_name.setdefault(block.argument, block)
            assert first.code == block.code, f"{block.argument}: {first.source} line {first.line} and {block.source} line {block.line} differ"


_LINK = re.compile(r"\]\(([^)#\s]+)(?:#[^)]*)?\)")


def test_the_readme_links_resolve() -> None:
    """Every relative link and picture of the README names a file of the checkout (docs pages are
    checked by ``mkdocs build --strict``, tests/test_docs_site.py)."""
    for target in _LINK.findall(README.read_text(encoding="utf-8")):
        if "://" not in target:
            assert (REPO_ROOT / target).exists(), f"README.md links to {target}, which does not exist"


@pytest.mark.parametrize("block", BLOCKS, ids=[f"{b.source}:{b.line}-{b.lang}" for b in BLOCKS])
def test_block(block: Block, readme_run) -> None:
    result = readme_run.get((block.source, block.line))
    assert result is not None, f"{block.source} line {block.line}: the runner did not report this block"
    if result["status"] == "skipped":
        pytest.skip(f"{block.source} line {block.line}: {result['output']}")
    assert result["status"] == "ok", (
        f"{block.source} line {block.line} ({block.lang}) {result['status']}:\n{block.code}\n--- output ---\n{result['output']}")
