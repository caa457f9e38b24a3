"""``kill -9`` a process that is editing a bench through :class:`ReviewStore`, then compare the
reviewed TSV left on disk with what its log says it should be.

Run as a script (``python -m tests.review.crash_trials BENCH_DIR TRIALS SEED``) it prints one
JSON line ``{"trials": n, "lagging": k, "after_restart_mismatches": m, "temps_left": t}``:
``lagging`` counts trials whose TSV, before any restart, differed from the log's replay;
``after_restart_mismatches`` those still differing after the next start (must be 0). Each
trial forks a child that edits as fast as it can and is killed after a random 2–40 ms.
"""

from __future__ import annotations

import json
import os
import random
import shutil
import signal
import sys
import tempfile
import time
from pathlib import Path


def _hammer(bench: Path, seed: int) -> None:  # pragma: no cover - runs in the killed child
    from spacedg.review import ReviewStore

    store = ReviewStore(bench, lock=True)
    rng = random.Random(seed)
    while True:
        if rng.random() < 0.5:
            store.edit(0, {"answer": rng.choice("ABCD")}, "crash")
        else:
            index = rng.randrange(1, 15)
            store.set_dropped(index, not store.item(index)["dropped"], "crash")


def _replayed(bench: Path) -> bytes:
    """The TSV the log implies: a fresh store over copies of the table and the log."""
    from spacedg.review import ReviewStore

    with tempfile.TemporaryDirectory() as tmp:
        copy = Path(tmp)
        shutil.copy(bench / "bench.tsv", copy / "bench.tsv")
        if (bench / "bench.reviewed.log.jsonl").exists():
            shutil.copy(bench / "bench.reviewed.log.jsonl", copy / "bench.reviewed.log.jsonl")
        return ReviewStore(copy).out.read_bytes()


def run_trials(bench: Path, trials: int, seed: int) -> dict[str, int]:
    from spacedg.review import ReviewStore

    rng = random.Random(seed)
    lagging = after = temps = 0
    for trial in range(trials):
        pid = os.fork()
        if pid == 0:  # pragma: no cover - child
            try:
                _hammer(bench, seed * 1000 + trial)
            finally:
                os._exit(0)
        time.sleep(rng.uniform(0.002, 0.040) + 0.15)  # the child's start (imports done: fork) then edits
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
        on_disk = (bench / "bench.reviewed.tsv").read_bytes()
        lagging += on_disk != _replayed(bench)
        temps += any(p.name.startswith(".bench.reviewed.tsv.") for p in bench.iterdir())
        restarted = ReviewStore(bench, lock=True)  # the next start repairs
        after += restarted.out.read_bytes() != _replayed(bench)
        restarted.close()
    return {"trials": trials, "lagging": lagging, "after_restart_mismatches": after, "temps_left": temps}


if __name__ == "__main__":  # pragma: no cover - run by tests/review/test_crash.py and by hand
    import spacedg.review.store  # noqa: F401 - imported once, before forking

    print(json.dumps(run_trials(Path(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]))))
