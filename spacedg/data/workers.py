"""How many DataLoader workers, and how many renderer threads each, from the machine.

Online rendering is CPU work that must keep an accelerator fed: the training process (the
main one) needs a core for the loop, the collator and host-to-device copies; every DataLoader
worker renders samples. The defaults (:func:`loader_plan`):

- ``cores`` = the CPUs this process may run on (``os.sched_getaffinity``: a container's or a
  job scheduler's cpuset, not the machine's count; ``os.cpu_count()`` where affinity is not
  available), divided by the processes sharing them on this node (``LOCAL_WORLD_SIZE`` under
  torchrun, one per GPU);
- ``workers = min(8, cores // 2)``: half the cores render in separate processes (0 on a
  one-core machine, where a worker would only add a copy of every sample); more than 8
  rarely helps one GPU and multiplies each worker's scene cache (memory);
- ``render_threads = max(1, cores // (workers + 1))``: numba threads of each worker's
  kernels, so workers × threads never oversubscribes the cores (the main process keeps one
  share). With ``workers = 0`` the main process renders with numba's default (all cores).

Every value is overridable: ``SpaceDGDataset(workers=…, render_threads=…)``, the SFT config's
``train.dataloader_num_workers`` (an integer instead of ``auto``), or the environment
variable ``SPACEDG_WORKERS`` / ``SPACEDG_RENDER_THREADS`` (integers; read by :func:`loader_plan`).
Counts are integers (processes, threads); nothing here measures time.

A pool of independent tasks (``spacedg qa build``: one process per scene) is planned the same
way by :func:`pool_plan`, except that its parent only waits, so it keeps no share: ``processes =
min(tasks, cores)`` and ``threads = max(1, cores // processes)`` (``SPACEDG_RENDER_THREADS``
overrides the threads).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

from spacedg._checks import check_int
from spacedg.errors import ParameterError

__all__ = ["LoaderPlan", "PoolPlan", "available_cores", "loader_plan", "pool_plan", "MAX_WORKERS"]

#: Most DataLoader workers chosen by default (per training process).
MAX_WORKERS = 8


@dataclass(frozen=True)
class LoaderPlan:
    """``workers`` DataLoader processes with ``render_threads`` numba threads each, on ``cores`` CPUs."""

    cores: int
    workers: int
    render_threads: int


def available_cores() -> int:
    """CPUs this process may run on (its affinity mask), at least 1."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # macOS, Windows
        return max(1, os.cpu_count() or 1)


def _env_int(name: str) -> int | None:
    value = os.environ.get(name)
    if value is None or value.strip() == "":
        return None
    try:
        number = int(value)
    except ValueError:
        raise ParameterError(f"environment variable {name} must be an integer, got {value!r}") from None
    if number < 0:
        raise ParameterError(f"environment variable {name} must be >= 0, got {number}")
    return number


def loader_plan(cores: int | None = None, processes: int | None = None, workers: int | None = None,
                render_threads: int | None = None) -> LoaderPlan:
    """The default plan (module docstring) for ``cores`` CPUs shared by ``processes`` training
    processes (default: this process's affinity, ``LOCAL_WORLD_SIZE`` or 1); ``workers`` and
    ``render_threads`` (or ``SPACEDG_WORKERS`` / ``SPACEDG_RENDER_THREADS``) override the choice."""
    for name, value, low in (("cores", cores, 1), ("processes", processes, 1), ("workers", workers, 0), ("render_threads", render_threads, 1)):
        if value is not None:
            check_int(value, f"loader_plan: {name}", minimum=low)
    total = available_cores() if cores is None else int(cores)
    if processes is None:
        processes = _env_int("LOCAL_WORLD_SIZE") or 1
    share = max(1, total // max(1, int(processes)))
    if workers is None:
        workers = _env_int("SPACEDG_WORKERS")
    if workers is None:
        workers = min(MAX_WORKERS, share // 2)
    if workers < 0:
        raise ParameterError(f"loader_plan: workers must be >= 0, got {workers}")
    if render_threads is None:
        render_threads = _env_int("SPACEDG_RENDER_THREADS")
    if render_threads is None:
        render_threads = max(1, share // (workers + 1)) if workers > 0 else share
    if render_threads < 1:
        raise ParameterError(f"loader_plan: render_threads must be >= 1, got {render_threads}")
    return LoaderPlan(cores=share, workers=int(workers), render_threads=int(render_threads))


@dataclass(frozen=True)
class PoolPlan:
    """``processes`` worker processes with ``threads`` numba threads each, on ``cores`` CPUs."""

    cores: int
    processes: int
    threads: int


def pool_plan(tasks: int, jobs: int | None = None, cores: int | None = None) -> PoolPlan:
    """Processes and threads for ``tasks`` independent tasks (module docstring): ``jobs``
    processes (default ``min(tasks, cores)``; never more than ``tasks``, at least 1), each with
    ``cores // processes`` threads (``SPACEDG_RENDER_THREADS`` overrides); ``cores`` defaults to
    this process's affinity."""
    check_int(tasks, "pool_plan: tasks", minimum=0)
    for name, value in (("jobs", jobs), ("cores", cores)):
        if value is not None:
            check_int(value, f"pool_plan: {name}", minimum=1)
    total = available_cores() if cores is None else int(cores)
    processes = max(1, min(max(tasks, 1), total if jobs is None else int(jobs)))
    threads = _env_int("SPACEDG_RENDER_THREADS") or max(1, total // processes)
    return PoolPlan(cores=total, processes=processes, threads=int(threads))
