"""The documentation site builds: ``mkdocs build --strict`` (mkdocs.yml, docs/, the API reference
that mkdocstrings generates from the docstrings) with no warning, into a scratch folder.

A strict build fails on a broken link or anchor between pages, a page missing from the
navigation, a picture that is not there, and a docstring of the API pages that griffe cannot
parse (e.g. a documented parameter the signature does not have).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]


def _mkdocs() -> list[str]:
    try:
        import mkdocs  # noqa: F401 - only checks that the test extra is installed
        import mkdocstrings  # noqa: F401
    except ImportError as err:  # pragma: no cover - the test extra installs them
        pytest.fail(f"the documentation tools are missing ({err}); install the test extra: pip install -e '.[test]'")
    return [sys.executable, "-m", "mkdocs"]


def test_every_page_is_in_the_navigation() -> None:
    config = (REPO_ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    for page in (REPO_ROOT / "docs").rglob("*.md"):
        name = page.relative_to(REPO_ROOT / "docs").as_posix()
        assert f" {name}" in config, f"docs/{name} is not in mkdocs.yml's nav"


def test_the_site_builds_strictly(tmp_path: Path) -> None:
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1", PYTHONPATH=os.pathsep.join(
        [str(REPO_ROOT), *filter(None, [os.environ.get("PYTHONPATH")])]))
    proc = subprocess.run([*_mkdocs(), "build", "--strict", "--site-dir", str(tmp_path / "site")], cwd=REPO_ROOT, env=env,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, f"mkdocs build --strict failed:\n{proc.stdout[-4000:]}\n{proc.stderr[-4000:]}"
    for page in ("index.html", "api/dataset/index.html", "architecture/index.html"):
        assert (tmp_path / "site" / page).is_file(), f"the site has no {page}"
    assert "SpaceDGDataset" in (tmp_path / "site" / "api" / "dataset" / "index.html").read_text(encoding="utf-8")
