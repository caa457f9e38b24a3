"""The cyclic collector's pause around question generation is scoped and restores its state."""

from __future__ import annotations

import gc

import pytest

from spacedg.qa.gc_pause import collector_paused


@pytest.fixture(autouse=True)
def _collector_enabled():
    was = gc.isenabled()
    gc.enable()
    yield
    (gc.enable if was else gc.disable)()


def test_paused_inside_and_restored_after():
    with collector_paused():
        assert not gc.isenabled()
    assert gc.isenabled()


def test_restored_after_an_exception():
    with pytest.raises(ValueError):
        with collector_paused():
            raise ValueError("boom")
    assert gc.isenabled()


def test_nested_pause_leaves_the_outer_one_and_a_disabled_collector_alone():
    with collector_paused():
        with collector_paused():
            assert not gc.isenabled()
        assert not gc.isenabled()  # the inner exit does not end the outer pause
    assert gc.isenabled()
    gc.disable()
    with collector_paused():
        pass
    assert not gc.isenabled()  # disabled on entry: stays disabled


def test_generation_pauses_the_collector_and_restores_it(monkeypatch, room_records):
    """generate_records runs its families with the collector paused and leaves it running."""
    from spacedg.qa import build
    from spacedg.qa.index import QABuildConfig

    seen: list[bool] = []
    real = build._family_records

    def spy(*args, **kwargs):
        seen.append(gc.isenabled())
        return real(*args, **kwargs)

    monkeypatch.setattr(build, "_family_records", spy)
    scene = room_records[0][0]
    assert build.generate_records(scene, QABuildConfig(seed=7, families=("object_counting",)))
    assert seen == [False] and gc.isenabled()
