"""Freed large arrays kept in the process (:mod:`spacedg.render.memory`): no page faults for repeated buffers.

Each case runs in a fresh interpreter: the malloc settings are process-wide and set once.
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys

import pytest

pytestmark = pytest.mark.skipif(
    not sys.platform.startswith("linux") or platform.libc_ver()[0] != "glibc", reason="mallopt is glibc's"
)

# An array allocated, written and freed again and again, 40 MB: above the 32 MiB glibc's own threshold never
# rises past, so by default it is mapped afresh every time (smaller ones are, once freed heap at the top is
# trimmed; a full-size 1752 × 1168 render's arrays are 8–25 MB). The minor faults of the last 10 rounds.
_PROBE = """
import json, resource, numpy as np
from spacedg.render.memory import keep_freed_memory
kept = keep_freed_memory()
again = keep_freed_memory()
def round_trip():
    a = np.empty(10 << 20, np.float32)
    a.fill(1.0)
    del a
for _ in range(10):
    round_trip()
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(10):
    round_trip()
print(json.dumps({"kept": kept, "again": again, "faults": resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before}))
"""


def _probe(**env: str) -> dict:
    clean = {k: v for k, v in os.environ.items() if k not in ("SPACEDG_KEEP_FREED_MEMORY", "MALLOC_MMAP_THRESHOLD_",
                                                               "MALLOC_TRIM_THRESHOLD_", "GLIBC_TUNABLES")}
    result = subprocess.run([sys.executable, "-c", _PROBE], env={**clean, **env}, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    return json.loads(result.stdout.strip().splitlines()[-1])


def test_freed_arrays_are_reused_without_page_faults() -> None:
    kept = _probe()
    assert kept["kept"] is True and kept["again"] is True
    off = _probe(SPACEDG_KEEP_FREED_MEMORY="0")
    assert off["kept"] is False
    # glibc's default maps the array afresh every round: each faults its pages in again (fewer faults than
    # pages where the kernel backs the mapping with 2 MB huge pages)
    assert off["faults"] >= 10 * 20, off
    assert kept["faults"] <= 0.02 * off["faults"], (kept, off)  # reused from the heap: nothing faulted in again


def test_the_users_own_malloc_settings_are_left_alone() -> None:
    assert _probe(MALLOC_TRIM_THRESHOLD_="1048576")["kept"] is False
    assert _probe(GLIBC_TUNABLES="glibc.malloc.trim_threshold=1048576")["kept"] is False


def test_a_render_applies_the_settings() -> None:
    code = (
        "import numpy as np\n"
        "from spacedg.render import memory\n"
        "assert memory._applied is None\n"
        "from spacedg.render import render, Camera, Gaussians\n"
        "g = Gaussians(means=np.zeros((1, 3), np.float32), scales=np.full((1, 3), 0.1, np.float32),"
        " quats=np.array([[1, 0, 0, 0]], np.float32), opacities=np.ones(1, np.float32),"
        " sh=np.zeros((1, 1, 3), np.float32))\n"
        "pose = np.eye(4); pose[2, 3] = -2.0\n"
        "render(g, Camera(fx=20.0, fy=20.0, cx=8.0, cy=8.0, width=16, height=16, cam_to_world=pose))\n"
        "print(memory._applied)\n"
    )
    env = {k: v for k, v in os.environ.items() if k not in ("SPACEDG_KEEP_FREED_MEMORY", "MALLOC_MMAP_THRESHOLD_",
                                                             "MALLOC_TRIM_THRESHOLD_", "GLIBC_TUNABLES")}
    result = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip().splitlines()[-1] == "True"
