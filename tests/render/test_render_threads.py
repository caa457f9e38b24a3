"""set_render_threads (spacedg.render.threads): a render worker's numba threads, and at most as many
BLAS threads for numpy (threadpoolctl), never more than the pool had, with a product's bytes unchanged."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[2]

_CHILD = textwrap.dedent(
    """
    import json, sys
    import numpy as np
    from threadpoolctl import threadpool_info
    from spacedg.render.threads import set_render_threads

    def blas():
        return sorted(pool["num_threads"] for pool in threadpool_info() if pool["user_api"] == "blas")

    rng = np.random.default_rng(7)
    points, rotation = rng.normal(size=(200_000, 3)), rng.normal(size=(3, 3))
    before_threads, before = blas(), (points @ rotation).tobytes()
    set_render_threads(int(sys.argv[1]))
    print(json.dumps({"before": before_threads, "after": blas(), "same": (points @ rotation).tobytes() == before}))
    """
)


def _child(threads: int, **env: str) -> dict:
    """Run the child in a fresh process (the test process keeps its threads); its report."""
    full = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")}
    full.update({"PYTHONPATH": str(REPO_ROOT), "NUMBA_NUM_THREADS": "2", **env})
    done = subprocess.run([sys.executable, "-c", _CHILD, str(threads)], env=full, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_a_render_worker_limits_numpys_blas_threads_too() -> None:
    seen = _child(1)
    if not seen["before"] or max(seen["before"]) == 1:
        pytest.skip(f"numpy's BLAS has {seen['before'] or 'no visible'} thread pool(s) here: nothing to limit")
    assert seen["after"] == [1] * len(seen["before"])
    assert seen["same"]  # a product's bytes do not depend on the BLAS thread count


def test_the_blas_limit_never_raises_a_pools_threads() -> None:
    seen = _child(2, OPENBLAS_NUM_THREADS="1")
    assert seen["after"] == seen["before"]
    assert seen["same"]
