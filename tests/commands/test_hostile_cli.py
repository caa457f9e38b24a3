"""A hostile run of bad command lines over every ``spacedg`` command, in-process through
:func:`spacedg.cli.main`: each exits 2 with exactly one line on stderr naming the option (or the
value) at fault, never a traceback and never argparse's usage block.

The lines are generated from the parsers themselves (an unknown option for every command, a
missing value for every option that takes one, a bad choice for every choice, out-of-range and
malformed values for every number, device and size), plus hand-written ones the handlers refuse
before any work. All fail at parse time or at the handler's first checks, so the run stays fast.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import traceback
from pathlib import Path

import pytest

from tests.commands.test_vocabulary import _parsers
from spacedg.cli import build_parser, main
from spacedg.commands import _args
from spacedg.commands.sizes import image_side, image_size, pixel_budget

W = "<work>"  # replaced by the test's folder

#: For every command, the arguments that make the rest of a line parse (paths that do not exist).
BASE: dict[str, list[str]] = {
    "scenes synth": ["--n", "1", "--out", f"{W}/synth"],
    "scenes import": [f"{W}/no-src", "--out", f"{W}/imported"],
    "scenes info": [f"{W}/no-scene"],
    "scenes preview": [f"{W}/no-scene", "--out", f"{W}/plans.png"],
    "render": [f"{W}/no-scene", "--view", "v", "--out", f"{W}/r.png"],
    "gallery": [f"{W}/no-scene", "--out", f"{W}/g.png"],
    "qa build": [f"{W}/no-scene"],
    "qa preview": [f"{W}/no-scene", "--out", f"{W}/q.png"],
    "qa stats": [f"{W}/no-index"],
    "qa audit": [f"{W}/no-index"],
    "export": ["--out", f"{W}/export"],
    "predict": ["--model", f"{W}/no-model", "--bench", f"{W}/no-bench", "--out", f"{W}/p.jsonl"],
    "eval": [f"{W}/p.jsonl", "--out", f"{W}/report"],
    "review": [f"{W}/no-bench"],
    "plugins": [],
    "kernels": [],
}
#: Device names no machine has.
BAD_DEVICES = ["cuda:99", "tpu", "", "cuda:x", "cuda:-1", "gpu0"]


def _leaves() -> dict[str, argparse.ArgumentParser]:
    """The parsers of commands that run (those with a handler), by command path."""
    return {path: parser for path, parser in _parsers().items() if parser.get_default("func") is not None}


def _bad_values(action: argparse.Action) -> list[str]:
    """Values the option's type or choices refuse."""
    kind = action.type
    if action.choices is not None:
        return ["nope"]
    if isinstance(kind, _args.Ranged):
        low = int(kind.low) - 1 if kind.accepts.startswith(("a whole", "a non-")) else -1
        values = ["abc", str(low), "1e400" if "finite" in kind.accepts or "number from" in kind.accepts else "1.5"]
        if kind.high is not None:
            values.append(str(int(kind.high) + 1) if "whole" in kind.accepts or "integer" in kind.accepts else str(kind.high * 2))
        return values
    if kind is _args.device_option:
        return BAD_DEVICES
    if kind is image_size:
        return ["0x0", "640", "abcxdef", "100000x100000"]
    if kind in (image_side, pixel_budget):
        return ["0", "abc", "9" * 5000]
    if kind is int:
        return ["abc", "1.5"]
    return []


def _generated() -> list[tuple[list[str], str]]:
    """(argv, what the error line must name) for every option of every command."""
    cases: list[tuple[list[str], str]] = [(["nope"], "nope"), (["scenes", "nope"], "nope"), (["qa", "nope"], "nope")]
    leaves = _leaves()
    assert set(leaves) == set(BASE), "a new command needs a BASE line"
    for path, parser in sorted(leaves.items()):
        head = [*path.split(), *BASE[path]]
        cases.append(([*head, "--no-such-option"], "--no-such-option"))
        for action in parser._actions:
            options = [o for o in action.option_strings if o.startswith("--") and o != "--help"]
            if not options:
                continue
            option = options[0]
            if action.nargs not in (0, "*", "?"):
                cases.append(([*head, option], option))  # the value is missing
            cases.extend(([*head, option, value], option) for value in _bad_values(action))
    return cases


#: Lines the parser accepts and the handler refuses before any work (argv, needle).
HANDLED: list[tuple[list[str], str]] = [
    (["scenes", "synth", "--n", "1", "--out", f"{W}/s", "--min-views", "10", "--max-views", "2"], "--min-views"),
    (["scenes", "synth", "--n", "2", "--out", f"{W}/s", "--seed", str(2**63 - 1)], "--seed"),
    (["scenes", "synth", "--n", "1", "--out", f"{W}/a_file"], "--out"),
    (["scenes", "preview", f"{W}/no-scene", "--out", f"{W}/plans.jpg"], "--out"),
    (["render", f"{W}/no-scene", "--out", f"{W}/r.png"], "--view"),
    (["render", f"{W}/no-scene", "--view", "v"], "--out"),
    (["render", f"{W}/no-scene", "--view", "v", "--out", f"{W}/r.jpg"], "--out"),
    (["render", f"{W}/no-scene", "--view", "v", "--out", f"{W}/r.png", "--depth-out", f"{W}/r.png"], "--depth-out"),
    (["render", f"{W}/no-scene", "--view", "v", "--out", f"{W}/r.png", "--defocus", "4"], "--defocus"),
    (["render", f"{W}/no-scene", "--view", "v", "--out", f"{W}/r.png", "--fisheye", "1,2"], "--fisheye"),
    (["render", f"{W}/no-scene", "--view", "v", "--out", f"{W}/r.png", "--fisheye", "0,0,0,0,4"], "--fisheye"),
    (["render", f"{W}/no-scene", "--view", "v", "--out", f"{W}/r.png", "--motion", "0,0,x,0,0,0"], "--motion"),
    (["render", f"{W}/no-scene", "--view", "v", "--out", f"{W}/r.png", "--sub-steps", "4"], "--sub-steps"),
    (["gallery", f"{W}/no-scene", "--out", f"{W}/g.jpg"], "--out"),
    (["qa", "build", f"{W}/no-scene", "--out", f"{W}/a_file"], "--out"),
    (["qa", "preview", f"{W}/no-scene", "--out", f"{W}/q.jpg"], "--out"),
    (["export", "--out", f"{W}/e", "--shard", "3/2"], "--shard"),
    (["export", "--out", f"{W}/e", "--shard", "x"], "--shard"),
    (["export", "--out", f"{W}/e", "--split-fractions", "a,b"], "--split-fractions"),
    (["export", "--out", f"{W}/e", "--all-bench", "--split-fractions", "0,1"], "--all-bench"),
    (["export", "--out", f"{W}/e", "--all-bench", "--split", "train"], "--all-bench"),
    (["export", "--out", f"{W}/a_file"], "--out"),
    (["predict", "--model", "m", "--bench", "b", "--out", f"{W}/p.txt"], "--out"),
    (["predict", "--model", "m", "--bench", "b", "--out", f"{W}/p.jsonl", "--min-pixels", "900", "--max-pixels", "10"],
     "--min-pixels"),
    (["predict", "--model", "m", "--bench", "b", "--scenes", "s", "--out", f"{W}/p.jsonl"], "--scenes"),
    (["eval", "p.jsonl", "--out", f"{W}/a_file"], "--out"),
    (["review", f"{W}/no-bench", "--port", "70000"], "--port"),
    (["review", f"{W}/no-bench", "--port", "-1"], "--port"),
    (["review", f"{W}/no-bench", "--reviewer", " "], "--reviewer"),
]

CASES = _generated() + HANDLED


def test_the_run_is_hostile_enough() -> None:
    assert len(CASES) >= 120
    commands = {" ".join(argv[:2]) if argv[0] in ("scenes", "qa") else argv[0] for argv, _ in CASES}
    assert {f"{path}" for path in BASE} <= commands


def _run(argv: list[str]) -> tuple[int, str]:
    err = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        try:
            code = main(argv)
        except SystemExit as exit_:
            code = exit_.code if isinstance(exit_.code, int) else 1
        except BaseException as caught:  # noqa: BLE001 - what this test hunts
            return -1, "".join(traceback.format_exception(caught))
    return code, err.getvalue()


@pytest.mark.parametrize(("argv", "needle"), CASES, ids=[" ".join(argv)[:90] for argv, _ in CASES])
def test_a_bad_line_fails_with_one_line_naming_it(argv: list[str], needle: str, tmp_path: Path,
                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    (tmp_path / "a_file").write_text("x")
    argv = [part.replace(W, str(tmp_path)) for part in argv]
    code, err = _run(argv)
    lines = [line for line in err.splitlines() if line.strip()]
    assert "Traceback" not in err and "usage:" not in err, err
    assert code == 2, err
    assert len(lines) == 1, err
    assert lines[0].startswith("spacedg") and ": error: " in lines[0], err
    assert needle in lines[0], (needle, lines[0])
    written = sorted(p.name for p in tmp_path.iterdir())
    assert written == ["a_file"], written  # nothing written
