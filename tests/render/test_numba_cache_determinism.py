"""The fast motion blur kernels give the same bits compiled fresh as loaded from numba's cache.

With ``fastmath=True`` (``reassoc`` among its flags) :func:`spacedg.render.motion_warp.doubling_pass`
computed other bits in the process that compiled it than in later processes that loaded it from
the on-disk cache (see ``benchmarks/numba_cache_determinism.py``, which covers every kernel).
Two subprocesses share one new ``NUMBA_CACHE_DIR``: the first compiles and writes the cache, the
second loads it; the kernels run on small synthetic inputs (no renderer, no scene).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

CHILD = r"""
import hashlib, numpy as np
from spacedg.render import motion_warp as mw
rng = np.random.default_rng(0)
h, w, margin = 48, 64, 12
hc, wc = h + 2 * margin, w + 2 * margin
# a smooth premultiplied canvas (r, g, b, alpha, depth x alpha) and a depth map
yy, xx = np.mgrid[0:hc, 0:wc].astype(np.float32)
depth = (1.5 + 0.5 * np.sin(xx / 7.0) * np.cos(yy / 5.0) + 0.1 * rng.random((hc, wc))).astype(np.float32)
src = np.stack([0.5 + 0.4 * np.sin(xx / (3.0 + c) + yy / (4.0 + c)) for c in range(3)]
               + [np.ones_like(xx), depth], axis=-1).astype(np.float32)
src += 0.05 * rng.random(src.shape, dtype=np.float32)
def pose(tx, ty, yaw):
    c, s = np.cos(yaw), np.sin(yaw)
    m = np.eye(4)
    m[:3, :3] = [[c, 0, s], [0, 1, 0], [-s, 0, c]]
    m[:3, 3] = [tx, ty, 0.0]
    return m
key = pose(0.0, 0.0, 0.0)
field = np.empty((hc, wc, 4), np.float32)
f = 60.0
mw.flow_field(depth, f, f, wc / 2, hc / 2, mw.relative_transform(pose(-0.4, -0.1, -0.05), key),
              mw.relative_transform(pose(0.4, 0.1, 0.05), key), field)
out = {"flow_field": field}
a, b = src, np.empty_like(src)
for j in range(2):
    mw.doubling_pass(a, field, np.float32(0.25 / 2**j), mw.FULL, b)
    out[f"doubling_pass_{j}"] = b.copy()
    a, b = b, a
acc = np.zeros((h, w, 5), np.float32)
mw.gather(a, field, margin, 0.25, 1.0, mw.FULL, acc)
out["gather"] = acc
for name, value in out.items():
    print(name, hashlib.sha256(value.tobytes()).hexdigest())
"""


def test_motion_warp_kernels_same_bits_fresh_and_cached(tmp_path: Path) -> None:
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba-cache"), SPACEDG_DISABLE_PLUGIN_AUTOLOAD="1")
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH", "")) if p)
    runs = []
    for _ in ("fresh", "cached"):
        proc = subprocess.run([sys.executable, "-c", CHILD], env=env, capture_output=True, text=True, timeout=300)
        assert proc.returncode == 0, proc.stderr
        runs.append(dict(line.split() for line in proc.stdout.splitlines()))
    assert any((tmp_path / "numba-cache").rglob("*.nbi")), "the first run wrote no numba cache"
    fresh, cached = runs
    assert fresh.keys() == cached.keys() and len(fresh) == 4
    differing = [name for name in fresh if fresh[name] != cached[name]]
    assert not differing, f"fresh-compiled vs cache-loaded bits differ: {differing}"
