"""Worker and renderer-thread defaults (:mod:`spacedg.data.workers`): pure arithmetic on core counts."""

from __future__ import annotations

import pytest

from spacedg.data.workers import MAX_WORKERS, available_cores, loader_plan
from spacedg.errors import ParameterError


@pytest.fixture(autouse=True)
def _clean_env(monkeypatch: pytest.MonkeyPatch) -> None:
    for name in ("LOCAL_WORLD_SIZE", "SPACEDG_WORKERS", "SPACEDG_RENDER_THREADS"):
        monkeypatch.delenv(name, raising=False)


@pytest.mark.parametrize(
    "cores, workers, threads",
    [(1, 0, 1), (2, 1, 1), (4, 2, 1), (8, 4, 1), (16, 8, 1), (32, 8, 3), (64, 8, 7)],
)
def test_default_plan_from_cores(cores: int, workers: int, threads: int) -> None:
    plan = loader_plan(cores=cores, processes=1)
    assert (plan.workers, plan.render_threads) == (workers, threads)
    assert plan.workers <= MAX_WORKERS
    assert plan.workers * plan.render_threads < max(cores, 2)  # the main process keeps a share


def test_cores_are_shared_by_the_processes_of_a_node(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("LOCAL_WORLD_SIZE", "4")
    plan = loader_plan(cores=32)
    assert (plan.cores, plan.workers, plan.render_threads) == (8, 4, 1)


def test_overrides_by_argument_and_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    assert loader_plan(cores=16, processes=1, workers=2).render_threads == 5
    assert loader_plan(cores=16, processes=1, workers=0).render_threads == 16  # main process renders
    monkeypatch.setenv("SPACEDG_WORKERS", "3")
    monkeypatch.setenv("SPACEDG_RENDER_THREADS", "2")
    plan = loader_plan(cores=16, processes=1)
    assert (plan.workers, plan.render_threads) == (3, 2)
    monkeypatch.setenv("SPACEDG_WORKERS", "many")
    with pytest.raises(ParameterError, match="SPACEDG_WORKERS"):
        loader_plan(cores=16)


def test_available_cores_is_the_affinity_mask() -> None:
    import os

    assert available_cores() >= 1
    if hasattr(os, "sched_getaffinity"):
        assert available_cores() == len(os.sched_getaffinity(0))


def test_bad_counts_are_refused() -> None:
    with pytest.raises(ParameterError, match="workers"):
        loader_plan(cores=4, workers=-1)
    with pytest.raises(ParameterError, match="render_threads"):
        loader_plan(cores=4, render_threads=0)
