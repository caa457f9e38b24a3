"""Write spacedg's dist-info (name, version, entry points) into a folder on ``sys.path``.

For a machine where the checkout runs from ``PYTHONPATH`` without being pip-installed (the lent GPU
machine of ``benchmarks/gpu_check.sh``, which has no network): the plugin registry finds the
built-in degradations and question families through the entry points of the distribution
``spacedg`` (``importlib.metadata``), which only an installed dist-info declares::

    python benchmarks/gpu_dist_info.py /tmp/site      # then PYTHONPATH=/tmp/site:$REPO

The entry points are read from this checkout's ``pyproject.toml``, so they match its code.
"""

from __future__ import annotations

import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def write_dist_info(target: Path) -> Path:
    """``target/spacedg-VERSION.dist-info`` with METADATA, entry_points.txt, top_level.txt and
    INSTALLER; returns its path."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    folder = target / f"{project['name']}-{project['version']}.dist-info"
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "METADATA").write_text(
        f"Metadata-Version: 2.1\nName: {project['name']}\nVersion: {project['version']}\nSummary: {project['description']}\n"
    )
    lines = []
    for group, entries in [("console_scripts", project.get("scripts", {})), *project.get("entry-points", {}).items()]:
        lines.append(f"[{group}]")
        lines.extend(f"{name} = {value}" for name, value in entries.items())
        lines.append("")
    (folder / "entry_points.txt").write_text("\n".join(lines))
    (folder / "top_level.txt").write_text("spacedg\n")
    (folder / "INSTALLER").write_text("benchmarks/gpu_dist_info.py\n")
    return folder


if __name__ == "__main__":
    print(f"wrote {write_dist_info(Path(sys.argv[1]))}")
