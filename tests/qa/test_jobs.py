"""Question building beyond one process: `qa build --shard i/n | env` and `--jobs N` (spacedg.qa.jobs,
spacedg.data.shards, spacedg.data.workers.pool_plan) give the same index bytes as one serial run."""

from __future__ import annotations

from pathlib import Path

import pytest

from spacedg.cli import main
from spacedg.data.workers import pool_plan
from spacedg.errors import ParameterError
from tests.conftest import private_copies

_SETTINGS = ["--families", "camera_translation", "--per-sub-type", "3", "--seed", "5"]


def _indexes(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.glob("*.qa.*.jsonl"))}


def test_shards_and_processes_write_the_bytes_of_one_serial_run(qa_room_dirs, tmp_path, monkeypatch, capsys) -> None:
    rooms = private_copies(qa_room_dirs[:2], tmp_path / "rooms")
    for key in ("RANK", "WORLD_SIZE", "SLURM_PROCID", "SLURM_NTASKS"):
        monkeypatch.delenv(key, raising=False)
    assert main(["qa", "build", *map(str, rooms), "--out", str(tmp_path / "serial"), "--jobs", "1", *_SETTINGS]) == 0
    serial = _indexes(tmp_path / "serial")
    assert len(serial) == 2
    # two jobs of a SLURM array (as separate machines would run them), each serially, into one folder
    assert main(["qa", "build", str(tmp_path / "rooms"), "--out", str(tmp_path / "sharded"), "--shard", "0/2", "--jobs", "1", *_SETTINGS]) == 0
    assert "shard 0/2: 1 of 2 scene(s)" in capsys.readouterr().out
    assert list(_indexes(tmp_path / "sharded")) == list(serial)[:1]  # room 0 of the sorted two
    monkeypatch.setenv("SLURM_ARRAY_TASK_ID", "1")
    monkeypatch.setenv("SLURM_ARRAY_TASK_COUNT", "2")
    assert main(["qa", "build", str(tmp_path / "rooms"), "--out", str(tmp_path / "sharded"), "--shard", "env", "--jobs", "1", *_SETTINGS]) == 0
    assert "shard 1/2: 1 of 2 scene(s)" in capsys.readouterr().out
    assert _indexes(tmp_path / "sharded") == serial
    # one machine, two processes (spawned; one thread each)
    assert main(["qa", "build", *map(str, rooms), "--out", str(tmp_path / "pooled"), "--jobs", "2", *_SETTINGS]) == 0
    assert "2 process(es) x" in capsys.readouterr().out
    assert _indexes(tmp_path / "pooled") == serial


@pytest.mark.parametrize(("argv", "says"), [
    (["--shard", "2/2"], "need 0 <= i < n"),
    (["--shard", "half"], "--shard must read i/n"),
    (["--shard", "env"], "none of RANK/WORLD_SIZE"),
    (["--jobs", "0"], "--jobs"),
])
def test_bad_shard_or_jobs_is_one_clear_error(qa_room_dirs, tmp_path, monkeypatch, capsys, argv, says) -> None:
    for key in ("RANK", "WORLD_SIZE", "SLURM_ARRAY_TASK_ID", "SLURM_ARRAY_TASK_COUNT", "SLURM_PROCID", "SLURM_NTASKS"):
        monkeypatch.delenv(key, raising=False)
    try:
        code = main(["qa", "build", str(qa_room_dirs[0]), "--out", str(tmp_path / "x"), *argv])
    except SystemExit as exit_:  # argparse's own type check
        code = exit_.code
    assert code == 2
    assert says in capsys.readouterr().err
    assert not (tmp_path / "x").exists() or not list((tmp_path / "x").iterdir())


def test_pool_plan_shares_the_cores(monkeypatch) -> None:
    monkeypatch.delenv("SPACEDG_RENDER_THREADS", raising=False)
    assert (pool_plan(100, cores=16).processes, pool_plan(100, cores=16).threads) == (16, 1)  # one scene per core
    assert (pool_plan(4, cores=16).processes, pool_plan(4, cores=16).threads) == (4, 4)  # few scenes: threads inside
    assert (pool_plan(4, jobs=1, cores=16).processes, pool_plan(4, jobs=1, cores=16).threads) == (1, 16)  # serial
    assert (pool_plan(9, jobs=6, cores=4).processes, pool_plan(9, jobs=6, cores=4).threads) == (6, 1)  # asked for more
    assert pool_plan(0, cores=8).processes == 1
    monkeypatch.setenv("SPACEDG_RENDER_THREADS", "3")
    assert pool_plan(100, cores=16).threads == 3
    with pytest.raises(ParameterError, match="jobs"):
        pool_plan(3, jobs=0)
