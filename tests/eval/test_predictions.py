"""Reading prediction files: an index repeated with the same prediction is counted once and
reported (two runs appended to one file); with another prediction it is an error."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from spacedg.cli import main
from spacedg.errors import FileFormatError, SpaceDGWarning
from spacedg.eval.predictions import read_predictions


def _write(path: Path, lines: list[dict]) -> Path:
    path.write_text("".join(json.dumps(line) + "\n" for line in lines), encoding="utf-8")
    return path


def test_repeated_lines_are_counted_and_reported(tmp_path: Path) -> None:
    lines = [{"index": i, "prediction": "A"} for i in range(5)]
    path = _write(tmp_path / "p.jsonl", lines + lines[1:])  # a second run appended four of them again
    with pytest.warns(SpaceDGWarning, match=r"p.jsonl: 4 line\(s\) repeat an index already answered .*first: index 1"):
        preds = read_predictions(path)
    assert preds.predictions == {i: "A" for i in range(5)}


def test_no_warning_without_repeats(tmp_path: Path, recwarn: pytest.WarningsRecorder) -> None:
    read_predictions(_write(tmp_path / "p.jsonl", [{"index": i, "prediction": "A"} for i in range(3)]))
    assert not [w for w in recwarn if issubclass(w.category, SpaceDGWarning)]


def test_a_repeated_index_with_another_prediction_is_an_error(tmp_path: Path) -> None:
    path = _write(tmp_path / "p.jsonl", [{"index": 0, "prediction": "A"}, {"index": 0, "prediction": "B"}])
    with pytest.raises(FileFormatError, match="p.jsonl:2: index 0 has two different predictions"):
        read_predictions(path)


def test_cli_prints_the_warning_on_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from tests.eval_fixtures import bench_rows

    rows = bench_rows()
    lines = [{**row, "prediction": str(row["answer"])} for row in rows]
    path = _write(tmp_path / "p.jsonl", lines + lines[:3])
    code = main(["eval", str(path), "--out", str(tmp_path / "report"), "--no-plots"])
    err = capsys.readouterr().err
    assert code == 0, err
    (warning,) = [line for line in err.splitlines() if line.startswith("spacedg: warning:")]
    assert "3 line(s) repeat an index" in warning and "Traceback" not in err
