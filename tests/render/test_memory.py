"""Freed large arrays kept in the process (:mod:`spacedg.render.memory`): where glibc puts them, and who decides.

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

# Where a 24 MiB array (a render's largest: low light's photosite grid at 640 × 480 is 22 MB) comes from,
# read from glibc's own accounting (mallinfo2 from glibc 2.33; before, mallinfo's int fields): ``mapped``,
# the bytes in separately mmapped blocks while it is alive. glibc's default maps it (above the 128 KiB
# starting threshold; unmapped again on free); kept, it comes from the heap. Then the minor page faults of
# ten more rounds of allocating, writing and freeing it.
_PROBE = """
import ctypes, json, resource, numpy as np
from spacedg.render import memory
kept = memory.keep_freed_memory()
libc = ctypes.CDLL(None)
fields = ["arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks", "uordblks", "fordblks", "keepcost"]
try:
    info = libc.mallinfo2
    kind = ctypes.c_size_t
except AttributeError:
    info = libc.mallinfo
    kind = ctypes.c_int
class Info(ctypes.Structure):
    _fields_ = [(name, kind) for name in fields]
info.restype = Info
before = info().hblkhd
array = np.ones(6 << 20, np.float32)
mapped = info().hblkhd - before
del array
faults = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(10):
    array = np.ones(6 << 20, np.float32)
    del array
faults = resource.getrusage(resource.RUSAGE_SELF).ru_minflt - faults
print(json.dumps({"kept": kept, "mapped": mapped, "faults": faults}))
"""

_ARRAY = 24 << 20
#: glibc's own malloc variables and spacedg's switch: removed from the probes' environment unless a test sets them.
_VARIABLES = ("SPACEDG_KEEP_FREED_MEMORY", "MALLOC_MMAP_THRESHOLD_", "MALLOC_TRIM_THRESHOLD_", "GLIBC_TUNABLES")


def _run(code: str, **env: str) -> str:
    clean = {k: v for k, v in os.environ.items() if k not in _VARIABLES}
    result = subprocess.run([sys.executable, "-c", code], env={**clean, **env}, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    return result.stdout.strip().splitlines()[-1]


def _probe(**env: str) -> dict:
    return json.loads(_run(_PROBE, **env))


def test_freed_arrays_stay_in_the_heap() -> None:
    kept = _probe()
    assert kept["kept"] is True
    assert kept["mapped"] < _ARRAY, kept  # from the heap, not a mapping of its own
    off = _probe(SPACEDG_KEEP_FREED_MEMORY="0")
    assert off["kept"] is False
    assert off["mapped"] >= _ARRAY, off  # glibc's default: mapped for itself
    # reused once freed: ten more rounds fault next to nothing in (a 24 MiB array is 6,144 pages)
    assert kept["faults"] < 300, kept


@pytest.mark.parametrize("env", [
    {"SPACEDG_KEEP_FREED_MEMORY": "off"},
    {"SPACEDG_KEEP_FREED_MEMORY": "False"},
    {"MALLOC_TRIM_THRESHOLD_": "1048576"},
    {"MALLOC_MMAP_THRESHOLD_": "1048576"},
    {"GLIBC_TUNABLES": "glibc.malloc.trim_threshold=1048576"},
], ids=["off", "False", "trim", "mmap", "tunable"])
def test_the_switch_and_the_users_own_malloc_settings_are_obeyed(env: dict) -> None:
    result = _probe(**env)
    assert result["kept"] is False
    if "SPACEDG_KEEP_FREED_MEMORY" in env:
        assert result["mapped"] >= _ARRAY, result  # glibc's default left in place


def test_a_tunable_about_something_else_does_not_count() -> None:
    result = _probe(GLIBC_TUNABLES="glibc.pthread.rseq=0")
    assert result["kept"] is True and result["mapped"] < _ARRAY, result


def test_a_cpu_render_applies_the_settings() -> None:
    code = (
        "import numpy as np\n"
        "from spacedg.render import memory\n"
        "assert memory._applied is None\n"
        "from spacedg.render import render, Camera, Gaussians\n"
        "g = Gaussians(means=np.zeros((1, 3), np.float32), scales=np.full((1, 3), 0.1, np.float32),"
        " quats=np.array([[1, 0, 0, 0]], np.float32), opacities=np.ones(1, np.float32),"
        " sh=np.zeros((1, 1, 3), np.float32))\n"
        "pose = np.eye(4); pose[2, 3] = -2.0\n"
        "frame = render(g, Camera(fx=20.0, fy=20.0, cx=8.0, cy=8.0, width=16, height=16, cam_to_world=pose))\n"
        "assert frame.alpha.max() > 0.5\n"
        "print(memory._applied)\n"
    )
    assert _run(code) == "True"
