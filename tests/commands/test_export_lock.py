"""``spacedg export``: one process per shard output. A second run of a shard that is being written
fails at once with one line naming the shard, the first process and the lock file (it used to
fail later on a missing ``.tmp`` file); other shards are not blocked; the lock goes with its run."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from spacedg.cli import main
from spacedg.commands.export import _shard_lock
from spacedg.errors import ParameterError


class _FakeDataset:
    """Enough of SpaceDGDataset for ``export`` to reach the shard lock (nothing is rendered)."""

    def __init__(self, *args: object, **kwargs: object) -> None:
        self.scene_splits = {"room": "bench"}
        self.scene_dirs = [Path("room")]
        self.records = [object()]
        self.skipped: dict = {}

    def __len__(self) -> int:
        return 1


def test_a_shard_being_written_is_refused_naming_its_writer(tmp_path: Path, capsys, monkeypatch: pytest.MonkeyPatch) -> None:
    import spacedg.data.dataset
    import spacedg.data.export

    def never(*args: object, **kwargs: object) -> None:
        raise AssertionError("export_bench ran while the shard was locked")

    monkeypatch.setattr(spacedg.data.dataset, "SpaceDGDataset", _FakeDataset)
    monkeypatch.setattr(spacedg.data.export, "export_bench", never)
    out = tmp_path / "bench"
    with _shard_lock(out, (1, 2)) as lock:
        assert lock.path == out / ".shard-1-of-2.lock" and lock.path.is_file()
        code = main(["export", "--out", str(out), "--shard", "1/2", "--no-progress", "--no-debias"])
        err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
        assert code == 2 and len(err) == 1, err
        assert f"shard 1/2 of {out} is being written by another process (pid {os.getpid()}" in err[0]
        assert str(lock.path) in err[0] and "wait for it" in err[0]
        with _shard_lock(out, (0, 2)):  # another shard of the same export is free
            pass
    assert not (out / ".shard-1-of-2.lock").exists()  # released and removed with its run
    with _shard_lock(out, (1, 2)):  # and the shard can be taken again
        pass


def test_the_lock_is_exclusive_in_one_process_too(tmp_path: Path) -> None:
    with _shard_lock(tmp_path, (0, 1)):
        with pytest.raises(ParameterError, match=r"shard 0/1 .* is being written by another process \(pid \d+"):
            with _shard_lock(tmp_path, (0, 1)):
                pass
