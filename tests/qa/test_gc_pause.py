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
    """generate_records runs its families with the collector paused (no judge) and leaves it running."""
    from spacedg.qa import build
    from spacedg.qa.index import QABuildConfig

    seen: list[bool] = []
    real = build._family_records

    def spy(*args, **kwargs):
        seen.append(gc.isenabled())
        return real(*args, **kwargs)

    monkeypatch.setattr(build, "_family_records", spy)
    scene = room_records[0][0]
    config = QABuildConfig(seed=7, families=("object_counting",))
    assert build.generate_records(scene, config)
    assert seen == [False] and gc.isenabled()
    build.generate_records(scene, config, judge=lambda image, label, description: "KEEP")
    assert seen == [False, True] and gc.isenabled()  # with a judge (renders, maybe a model) nothing is paused


def test_reading_an_index_pauses_the_collector_and_restores_it(monkeypatch, room_records, tmp_path):
    """read_index parses its records with the collector paused, and gives back what was written."""
    from spacedg.plugins.qa_record import QARecord
    from spacedg.qa.index import read_index, write_index

    records = list(room_records[0][1][:5])
    write_index(tmp_path / "s.qa.jsonl", tmp_path / "s.qa.meta.json", records, {})
    seen: list[bool] = []
    real = QARecord.from_json.__func__

    def spy(cls, text):
        seen.append(gc.isenabled())
        return real(cls, text)

    monkeypatch.setattr(QARecord, "from_json", classmethod(spy))
    assert read_index(tmp_path / "s.qa.jsonl") == records
    assert seen == [False] * len(records) and gc.isenabled()
