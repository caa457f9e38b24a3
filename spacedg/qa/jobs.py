"""Building many scenes' question indexes at once: one process per scene, or serially.

:func:`build_indexes` runs :func:`~spacedg.qa.build.build_scene_index` for each scene folder and
yields one :class:`BuildRow` per scene as it finishes. With ``jobs=1`` the scenes are built one
after another in this process (with the per-scene progress bars); with ``jobs > 1`` a pool of
``jobs`` **spawned** processes takes one scene at a time, each rendering visibility with
``threads`` numba threads (:func:`~spacedg.render.threads.set_render_threads`; plan them with
:func:`spacedg.data.workers.pool_plan`). A scene's index depends only on its folder and the
:class:`~spacedg.qa.index.QABuildConfig` (records are seeded per scene and family; the renders
that give visibility do not depend on the thread count), so the index files are the same bytes
whatever ``jobs``, ``threads`` or the order in which scenes finish; only the timings in the meta
files differ. Spawned processes re-import the caller's main module: a script calling this with
``jobs > 1`` needs the usual ``if __name__ == "__main__":`` guard.

Splitting the scenes across machines (``spacedg qa build --shard i/n``) happens before this:
each job passes its share of the sorted folders (:func:`spacedg.data.shards.chunk_ids`).
"""

from __future__ import annotations

import multiprocessing
from collections.abc import Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path

from spacedg._checks import check_int
from spacedg.qa.build import build_scene_index
from spacedg.qa.index import QABuildConfig, SceneQA

__all__ = ["BuildRow", "build_indexes"]


@dataclass(frozen=True)
class BuildRow:
    """One scene's build, as the command reports it (records stay in the index file).

    ``seconds``: the stage timings (``visibility_s``, ``covisibility_s``, ``generate_s``, wall seconds
    on the process that built it; a reused index reports those stored in its meta file)."""

    folder: str
    scene_id: str
    path: str
    records: int
    reused: bool
    seconds: dict[str, float]

    @classmethod
    def of(cls, folder: Path | str, result: SceneQA) -> BuildRow:
        return cls(str(folder), result.scene_id, str(result.path), len(result.records), result.reused, dict(result.seconds))


@dataclass(frozen=True)
class _Task:
    """What a worker process needs to build one scene (picklable)."""

    folder: str
    config: QABuildConfig
    out_dir: str | None
    force: bool
    backend: str
    device: str | None

    def run(self, progress: bool) -> BuildRow:
        result = build_scene_index(self.folder, self.config, out_dir=self.out_dir, force=self.force,
                                   backend=self.backend, progress=progress, device=self.device)
        return BuildRow.of(self.folder, result)


def _start_worker(threads: int) -> None:
    """Pool initializer: this process renders with ``threads`` numba threads."""
    from spacedg.render.threads import set_render_threads

    set_render_threads(threads)


def _run_task(task: _Task) -> BuildRow:
    return task.run(progress=False)


def build_indexes(
    folders: Sequence[str | Path],
    config: QABuildConfig = QABuildConfig(),
    *,
    out_dir: str | Path | None = None,
    force: bool = False,
    backend: str = "auto",
    device: str | None = None,
    jobs: int = 1,
    threads: int = 1,
    progress: bool = True,
) -> Iterator[BuildRow]:
    """Build (or reuse) the index of each scene folder; yield a :class:`BuildRow` per scene as it
    finishes (module docstring). ``jobs``: processes (1 = serially, here); ``threads``: numba
    threads per process when ``jobs > 1`` (serially, this process's own setting is kept);
    ``progress``: the per-scene bars of a serial build (a pool shows none: count its rows)."""
    check_int(jobs, "build_indexes: jobs", minimum=1)
    check_int(threads, "build_indexes: threads", minimum=1)
    tasks = [_Task(str(f), config, None if out_dir is None else str(out_dir), force, backend, device) for f in folders]
    if jobs == 1 or len(tasks) <= 1:
        for task in tasks:
            yield task.run(progress)
        return
    context = multiprocessing.get_context("spawn")  # numba's and CUDA's threads are not fork-safe
    with ProcessPoolExecutor(max_workers=min(jobs, len(tasks)), mp_context=context,
                             initializer=_start_worker, initargs=(threads,)) as pool:
        futures = [pool.submit(_run_task, task) for task in tasks]
        try:
            for future in as_completed(futures):
                yield future.result()
        except BaseException:
            for future in futures:
                future.cancel()
            raise
