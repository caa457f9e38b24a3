"""Every subcommand checks its arguments before any work: bad numbers and unusable ``--out``
paths are one line with exit status 2 (``spacedg <command>: error: …`` from the parser, ``spacedg:
error: …`` from the handler), never a traceback, and nothing is written."""

from __future__ import annotations

import argparse
import inspect
import json
from pathlib import Path

import pytest

from spacedg.cli import build_parser, main
from spacedg.commands import _args
from tests.eval_fixtures import write_bench

UNWRITABLE = "/proc/spacedg-cannot-write-here"  # not even root can create files in /proc


def _fails(capsys: pytest.CaptureFixture[str], argv: list[str], *needles: str) -> str:
    try:
        code = main(argv)
    except SystemExit as exit_:  # a usage error, raised by the parser
        code = exit_.code
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2, err
    assert len(lines) == 1 and lines[0].startswith(("spacedg: error: ", f"spacedg {argv[0]}")), err
    assert "Traceback" not in err and "usage:" not in err, err
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])
    return lines[0]


@pytest.fixture()
def a_file(tmp_path: Path) -> Path:
    path = tmp_path / "a_file"
    path.write_text("x")
    return path


SYNTH = ["scenes", "synth", "--n", "1", "--num-gaussians", "10000", "--image-size", "64x48"]


@pytest.mark.parametrize(("extra", "needles"), [
    (["--min-views", "10", "--max-views", "2"], ["--min-views 10 is more than --max-views 2"]),
    (["--min-views", "0"], ["argument --min-views: must be a whole number >= 1, got 0"]),
    (["--seed", "-3"], ["argument --seed: must be a non-negative integer"]),
    (["--seed", "9223372036854775807", "--n", "2"], ["--seed + --n - 1 (the last room's seed) must be a non-negative integer"]),
    (["--image-size", "4x48"], ["argument --image-size: 4x48: width and height must be >= 8 pixels"]),
    (["--splat-size", "nan"], ["argument --splat-size: must be a finite number > 0 metres, got 'nan'"]),
    (["--splat-size", "0"], ["argument --splat-size: must be a finite number > 0 metres, got 0"]),
    (["--num-gaussians", "5"], ["argument --num-gaussians: must be a whole number from 10000 to 5000000, got 5"]),
])
def test_scenes_synth_numbers(capsys, tmp_path: Path, extra: list[str], needles: list[str]) -> None:
    out = tmp_path / "rooms"
    _fails(capsys, [*SYNTH, "--out", str(out), *extra], *needles)
    assert not out.exists()


def test_scenes_synth_out_checked_first(capsys, tmp_path: Path, a_file: Path) -> None:
    _fails(capsys, [*SYNTH, "--out", str(a_file / "rooms")], f"{a_file} is a file, not a folder")
    _fails(capsys, [*SYNTH, "--out", str(a_file)], "is a file; pass a folder")
    _fails(capsys, [*SYNTH, "--out", UNWRITABLE + "/rooms"], "cannot write in /proc")


@pytest.mark.parametrize("command", [
    ["scenes", "preview", "SCENE", "--out", "OUT/x.png"],
    ["render", "SCENE", "--view", "v", "--out", "OUT/x.png"],
    ["gallery", "SCENE", "--out", "OUT/x.png"],
    ["qa", "preview", "SCENE", "--out", "OUT/x.png"],
    ["qa", "build", "SCENE", "--out", "OUT/idx"],
    ["export", "--out", "OUT/bench", "--scenes", "SCENE"],
    ["predict", "--model", "M", "--bench", "B", "--out", "OUT/p.jsonl"],
    ["eval", "p.jsonl", "--out", "OUT/report"],
])
def test_every_out_is_checked_before_work(capsys, tmp_path: Path, a_file: Path, command: list[str]) -> None:
    for bad, needle in ((str(a_file), "is a file, not a folder"), (UNWRITABLE, "cannot write in /proc")):
        argv = [part.replace("OUT", bad).replace("SCENE", str(tmp_path / "no-scene")) for part in command]
        _fails(capsys, argv, needle)


@pytest.mark.parametrize(("argv", "needles"), [
    (["scenes", "preview", "S", "--out", "x.png", "--columns", "0"],
     ["argument --columns: must be a whole number from 1 to 64 floor plans per row, got 0"]),
    (["qa", "preview", "S", "--out", "x.png", "--seed", "-2"], ["argument --seed: must be a non-negative integer"]),
    (["qa", "build", "S", "--per-sub-type", "0"], ["argument --per-sub-type: must be a whole number >= 1, got 0"]),
    (["qa", "audit", "S", "--null", "-1"], ["argument --null: must be a whole number from 0 to 10000 runs, got -1"]),
    (["qa", "audit", "S", "--show", "-3"], ["argument --show: must be a whole number >= 0, got -3"]),
    (["gallery", "S", "--out", "x.png", "--seed", "-1"], ["argument --seed: must be a non-negative integer"]),
    (["render", "S", "--view", "v", "--out", "x.png", "--motion", "0,0,0,0,0,0.1", "--sub-steps", "0"],
     ["argument --sub-steps: must be a whole number from 1 to 4096"]),
    (["export", "--out", "o", "--clean-prob", "1.5"], ["argument --clean-prob: must be a number from 0 to 1"]),
    (["export", "--out", "o", "--clean-prob", "nan"], ["argument --clean-prob: must be a number from 0 to 1"]),
    (["export", "--out", "o", "--max-questions", "0"], ["argument --max-questions: must be a whole number >= 1"]),
    (["export", "--out", "o", "--per-sub-type", "0"], ["argument --per-sub-type: must be a whole number >= 1"]),
    (["export", "--out", "o", "--seed", "-1"], ["argument --seed: must be a non-negative integer"]),
    (["predict", "--model", "m", "--bench", "b", "--out", "p.jsonl", "--batch-size", "0"],
     ["argument --batch-size: must be a whole number >= 1"]),
    (["predict", "--model", "m", "--bench", "b", "--out", "p.jsonl", "--min-pixels", "900", "--max-pixels", "10"],
     ["--min-pixels 900 is more than --max-pixels 10"]),
    (["predict", "--model", "m", "--bench", "b", "--out", "p.txt"], ["write a .jsonl file"]),
    (["review", "b", "--port", "65536"], ["--port must be a whole number from 0 to 65535"]),
])
def test_numbers_are_checked(capsys, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, argv: list[str], needles: list[str]) -> None:
    monkeypatch.chdir(tmp_path)
    _fails(capsys, argv, *needles)
    assert list(tmp_path.iterdir()) == []  # nothing written


def test_predict_max_new_tokens_zero_writes_no_sidecar(capsys, tmp_path: Path) -> None:
    """The finding: --max-new-tokens 0 was a traceback and left a sidecar that refused reruns."""
    bench = write_bench(tmp_path / "bench")
    out = tmp_path / "preds.jsonl"
    _fails(capsys, ["predict", "--model", str(tmp_path / "model"), "--bench", str(bench), "--out", str(out),
                    "--max-new-tokens", "0"], "argument --max-new-tokens: must be a whole number from 1")
    assert not out.exists() and not (tmp_path / "preds.jsonl.meta.json").exists()


def test_predict_library_checks_tokens_before_anything(tmp_path: Path) -> None:
    from spacedg.errors import ParameterError
    from spacedg.eval.bench import load_bench
    from spacedg.eval.predict import bench_source, predict

    source = bench_source(load_bench(write_bench(tmp_path / "bench")))
    for tokens in (0, -5):
        with pytest.raises(ParameterError, match="--max-new-tokens must be a whole number >= 1"):
            predict(("model", "processor"), source, tmp_path / "p.jsonl", max_new_tokens=tokens, progress=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bench"]


def test_an_empty_output_starts_over_whatever_its_sidecar_says(tmp_path: Path) -> None:
    from spacedg.eval.predict import _existing

    out = tmp_path / "p.jsonl"
    out.write_bytes(b"")
    (tmp_path / "p.jsonl.meta.json").write_text(json.dumps({"variant": "cot", "generation": {"max_new_tokens": 0}}))
    assert _existing(out, {"variant": "default", "generation": {"max_new_tokens": 32}}) == set()
    out.write_bytes(b'{"index": 1, "prediction": "A"}\n')
    with pytest.raises(Exception, match="holds a run with another"):
        _existing(out, {"variant": "default", "generation": {"max_new_tokens": 32}})


def test_a_second_predict_on_one_out_fails_naming_the_first(tmp_path: Path) -> None:
    from spacedg.errors import ParameterError
    from spacedg.eval.bench import load_bench
    from spacedg.eval.predict import bench_source, predict
    from spacedg.files import exclusive_lock

    source = bench_source(load_bench(write_bench(tmp_path / "bench")))
    out = tmp_path / "preds.jsonl"
    with exclusive_lock(tmp_path / "preds.jsonl.lock", "held by the first run"):
        with pytest.raises(ParameterError, match=r"preds.jsonl is being written by another spacedg predict \(pid \d+"):
            predict(("model", "processor"), source, out, progress=False)
    assert not out.exists() and not (tmp_path / "preds.jsonl.meta.json").exists()


def _leaf_commands() -> list[tuple[str, argparse.ArgumentParser]]:
    """Every runnable ``spacedg`` subcommand (``"qa build"``, ``"render"``, …) and its parser."""
    found: list[tuple[str, argparse.ArgumentParser]] = []

    def walk(parser: argparse.ArgumentParser, path: str) -> None:
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, child in action.choices.items():
                    if child.get_default("func") is not None:
                        found.append((f"{path} {name}".strip(), child))
                    walk(child, f"{path} {name}")

    walk(build_parser(), "")
    return found


def test_every_subcommand_has_a_handler_and_its_docstring_as_description() -> None:
    leaves = dict(_leaf_commands())
    assert {"scenes synth", "scenes import", "render", "gallery", "qa build", "qa audit", "export", "predict", "eval",
            "review", "plugins"} <= set(leaves)
    for name, parser in leaves.items():
        handler = parser.get_default("func")
        assert callable(handler), name
        doc = inspect.getdoc(handler)
        if doc:  # the handler's docstring is what `spacedg NAME --help` describes
            assert parser.description == doc, name
        assert parser.description, f"{name} has no description"


def test_add_command_registers_parser_handler_and_description() -> None:
    def handler(args: argparse.Namespace) -> int:
        """Does the thing."""
        return 0

    root = argparse.ArgumentParser()
    sub = root.add_subparsers(dest="command")
    parser = _args.add_command(sub, "thing", handler, help="short")
    assert parser.description == "Does the thing."
    assert root.parse_args(["thing"]).func is handler
    explicit = _args.add_command(sub, "other", lambda args: 0, help="short", description="long text")
    assert explicit.description == "long text"
    assert _args.add_command(sub, "bare", lambda args: 0, help="short only").description == "short only"
