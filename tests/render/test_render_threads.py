"""set_render_threads (spacedg.render.threads): a render worker's numba threads, and at most as many
BLAS threads for numpy (threadpoolctl), with a matrix product's bytes unchanged."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[2]

_CHILD = textwrap.dedent(
    """
    import json
    import numpy as np
    from threadpoolctl import threadpool_info
    from spacedg.render.threads import set_render_threads

    def blas():
        return sorted(pool["num_threads"] for pool in threadpool_info() if pool["user_api"] == "blas")

    rng = np.random.default_rng(7)
    points, rotation = rng.normal(size=(200_000, 3)), rng.normal(size=(3, 3))
    before_threads, before = blas(), (points @ rotation).tobytes()
    set_render_threads(1)
    print(json.dumps({"before": before_threads, "after": blas(), "same": (points @ rotation).tobytes() == before}))
    """
)


def test_a_render_worker_limits_numpys_blas_threads_too() -> None:
    """In a fresh process (the test process keeps its threads): BLAS on one thread after
    ``set_render_threads(1)``, the product's bytes the same as on the default pool."""
    env = {**os.environ, "PYTHONPATH": str(REPO_ROOT), "NUMBA_NUM_THREADS": "2"}
    env.pop("OPENBLAS_NUM_THREADS", None)
    env.pop("OMP_NUM_THREADS", None)
    done = subprocess.run([sys.executable, "-c", _CHILD], env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    seen = json.loads(done.stdout.strip().splitlines()[-1])
    assert seen["before"], "numpy's BLAS is not visible to threadpoolctl"
    assert seen["after"] == [1] * len(seen["before"])
    assert seen["same"]
