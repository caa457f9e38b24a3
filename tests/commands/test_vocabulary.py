"""One vocabulary on the command line: walks every parser of ``spacedg`` (recursively over its
sub-commands) and holds one option name per concept, the one table of deprecated spellings
(each warns on one line, raises a DeprecationWarning and lands where its new option does),
a checked torch device behind every ``--device``, a range behind every number, and no command
writing what its name does not say (``qa preview`` reads the question index, never builds it)."""

from __future__ import annotations

import argparse
import re
from pathlib import Path

import pytest

from spacedg.cli import build_parser, main
from spacedg.commands import _args, _vocabulary
from spacedg.commands.scenes import SYNTH_SIZE

#: concept → (a pattern that catches an option speaking of it, the names it may have).
CONCEPTS: dict[str, tuple[re.Pattern[str], set[str]]] = {
    "question families": (re.compile(r"famil|question-type|^--types?$"), {"--families"}),
    "image size": (re.compile(r"^--(width|height|size|resolution|image-.*|img.*|.*-(width|height|resolution))$"),
                   {"--image-size", "--thumb-width"}),
    "torch device": (re.compile(r"device|gpu|cuda"), {"--device"}),
    "ScanNet++ camera": (re.compile(r"^--camera$|scannet|dslr|iphone"), {"--scannetpp-camera"}),
    "Gaussians": (re.compile(r"gaussian"), {"--num-gaussians", "--gaussians-file"}),
    "seed": (re.compile(r"seed"), {"--seed"}),
    "output": (re.compile(r"^--(out|output|outdir|out-dir|output-dir|dest)$"), {"--out"}),
    "items per chunk": (re.compile(r"chunk|shard-size"), {"--shard-size"}),
}
#: Numeric options checked by their own library instead of a ranged argparse type, and why.
NUMBERS_CHECKED_ELSEWHERE = {
    ("review", "--port"): "spacedg.review.server.check_port (tests/review hold its message)",
}


def _parsers() -> dict[str, argparse.ArgumentParser]:
    """Every parser by command path: ``""`` (the root), ``"scenes"``, ``"scenes synth"``, …"""
    found: dict[str, argparse.ArgumentParser] = {}

    def walk(parser: argparse.ArgumentParser, path: str) -> None:
        found[path] = parser
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, child in action.choices.items():
                    walk(child, f"{path} {name}".strip())

    walk(build_parser(), "")
    return found


PARSERS = _parsers()
LEAVES = {path: parser for path, parser in PARSERS.items() if parser.get_default("func") is not None}


def _options(parser: argparse.ArgumentParser) -> dict[str, argparse.Action]:
    return {option: action for action in parser._actions for option in action.option_strings if option.startswith("--")}


def _deprecated(path: str) -> set[str]:
    return {alias.old for alias in _vocabulary.deprecated_for(path)}


def test_the_walk_finds_every_command() -> None:
    assert {"scenes synth", "scenes import", "scenes info", "scenes preview", "render", "gallery", "qa build", "qa preview",
            "qa stats", "qa audit", "export", "predict", "eval", "review", "plugins", "kernels"} == set(LEAVES)
    assert all(isinstance(parser, _args.CommandParser) for parser in PARSERS.values())


@pytest.mark.parametrize("path", sorted(PARSERS))
def test_every_option_speaks_the_vocabulary(path: str) -> None:
    for option in sorted(set(_options(PARSERS[path])) - _deprecated(path) - {"--help"}):
        for concept, (pattern, allowed) in CONCEPTS.items():
            if pattern.search(option):
                assert option in allowed, f"spacedg {path} {option}: {concept} is spelled {sorted(allowed)}"


def test_the_deprecated_options_are_exactly_the_table() -> None:
    registered = {
        (path, option)
        for path, parser in PARSERS.items()
        for option, action in _options(parser).items()
        if isinstance(action, _vocabulary.DeprecatedOption)
    }
    table = {(alias.command, alias.old) for alias in _vocabulary.DEPRECATED}
    assert registered == table
    assert len(table) == len(_vocabulary.DEPRECATED)  # one row per old spelling
    for path, option in table:
        action = _options(PARSERS[path])[option]
        assert action.help == argparse.SUPPRESS  # not offered in --help
        assert action.alias.new in _options(PARSERS[path]), f"{path} {option} maps to a missing {action.alias.new}"


@pytest.mark.parametrize("path", sorted(LEAVES))
def test_every_device_is_a_checked_torch_device(path: str) -> None:
    action = _options(LEAVES[path]).get("--device")
    if action is not None and "--device" not in _deprecated(path):
        assert action.type is _args.device_option and action.default is None


@pytest.mark.parametrize("path", sorted(LEAVES))
def test_every_number_has_a_range(path: str) -> None:
    for option, action in _options(LEAVES[path]).items():
        if action.type in (int, float):
            assert (path, option) in NUMBERS_CHECKED_ELSEWHERE, f"spacedg {path} {option}: a bare {action.type.__name__}"
        if isinstance(action.type, _args.Ranged):
            assert action.type.low is not None and action.type.accepts.startswith(("a whole number", "a finite", "a number", "a non-"))


# ---------------------------------------------------------------------------- deprecated spellings
#: command → the required arguments of a parse.
REQUIRED = {
    "qa preview": ["S", "--out", "x.png"],
    "export": ["--out", "o"],
    "scenes synth": ["--n", "1", "--out", "o"],
    "scenes import": ["src", "--out", "o"],
    "render": ["S"],
}
#: (command, old option) → (old arguments, the same said with the new option).
EXAMPLES = {
    ("qa preview", "--types"): (["--types", "object_counting,camera_rotation"], ["--families", "object_counting,camera_rotation"]),
    ("export", "--question-types"): (["--question-types", "object_counting"], ["--families", "object_counting"]),
    ("export", "--chunk-size"): (["--chunk-size", "50"], ["--shard-size", "50"]),
    ("scenes synth", "--gaussians"): (["--gaussians", "40000"], ["--num-gaussians", "40000"]),
    ("scenes synth", "--width"): (["--width", "160"], ["--image-size", f"160x{SYNTH_SIZE[1]}"]),
    ("scenes synth", "--height"): (["--height", "120"], ["--image-size", f"{SYNTH_SIZE[0]}x120"]),
    ("scenes import", "--gaussians"): (["--gaussians", "g.ply"], ["--gaussians-file", "g.ply"]),
    ("scenes import", "--device"): (["--device", "iphone"], ["--scannetpp-camera", "iphone"]),
    ("render", "--width"): (["--width", "80", "--height", "60"], ["--image-size", "80x60"]),
    ("render", "--height"): (["--height", "60", "--width", "80"], ["--image-size", "80x60"]),
}


def _mapped(namespace: argparse.Namespace, command: str) -> dict:
    """The namespace with the deprecated --width / --height mapped onto --image-size."""
    values = vars(namespace).copy()
    if "width" in values or "height" in values:
        values["image_size"] = _args.image_size_of(namespace, SYNTH_SIZE if command == "scenes synth" else None)
        values.pop("width", None)
        values.pop("height", None)
    if command == "scenes synth" and values.get("image_size") is None:
        values["image_size"] = SYNTH_SIZE
    return values


def test_every_alias_has_an_example() -> None:
    assert set(EXAMPLES) == {(alias.command, alias.old) for alias in _vocabulary.DEPRECATED}


@pytest.mark.parametrize("alias", _vocabulary.DEPRECATED, ids=lambda a: f"{a.command} {a.old}")
def test_each_alias_warns_and_maps(alias: _vocabulary.Alias, capsys: pytest.CaptureFixture[str]) -> None:
    old, new = EXAMPLES[(alias.command, alias.old)]
    head = [*alias.command.split(), *REQUIRED[alias.command]]
    with pytest.warns(DeprecationWarning, match=f"{alias.old} is deprecated and goes in the next release; use {re.escape(alias.usage)}"):
        parsed_old = build_parser().parse_args([*head, *old])
    lines = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    line = f"spacedg {alias.command}: warning: {alias.old} is deprecated and goes in the next release; use {alias.usage}"
    assert line in lines and all(": warning: " in other and " is deprecated " in other for other in lines)
    assert len(lines) == sum(token.startswith("--") for token in old)  # one line per old option
    parsed_new = build_parser().parse_args([*head, *new])
    assert capsys.readouterr().err == ""
    assert _mapped(parsed_old, alias.command) == _mapped(parsed_new, alias.command)


def test_old_spellings_of_the_byte_identity_benchmark_still_parse(capsys: pytest.CaptureFixture[str]) -> None:
    """benchmarks/byte_identity.py keeps the old spellings (its recorded hashes stay comparable)."""
    argv = ["scenes", "synth", "--n", "3", "--seed", "0", "--gaussians", "40000", "--min-views", "16",
            "--max-views", "20", "--width", "160", "--height", "120", "--out", "o"]
    with pytest.warns(DeprecationWarning):
        old = build_parser().parse_args(argv)
    new = build_parser().parse_args(["scenes", "synth", "--n", "3", "--seed", "0", "--num-gaussians", "40000", "--min-views",
                                     "16", "--max-views", "20", "--image-size", "160x120", "--out", "o"])
    assert _mapped(old, "scenes synth") == _mapped(new, "scenes synth")
    assert (old.num_gaussians, _args.image_size_of(old, SYNTH_SIZE)) == (40000, (160, 120))
    assert len(capsys.readouterr().err.splitlines()) == 3


def test_both_spellings_at_once_are_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.warns(DeprecationWarning):
        code = main(["scenes", "synth", "--n", "1", "--out", str(tmp_path / "o"), "--width", "64", "--image-size", "64x48"])
    assert code == 2 and "--image-size and the deprecated --width/--height are alternatives" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


# ---------------------------------------------------------------------------- names say what is written
def test_qa_preview_reads_the_index_and_never_builds_it(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    import spacedg
    from spacedg.scene.synthetic import CaptureConfig

    room = tmp_path / "room"
    spacedg.save_scene(spacedg.generate_room(0, spacedg.RoomConfig(gaussians=10_000, capture=CaptureConfig(64, 48, 2, 2))), room)
    before = sorted(p.relative_to(room) for p in room.rglob("*"))
    assert main(["qa", "preview", str(room), "--out", str(tmp_path / "q.png")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no question index room-000000.qa.jsonl" in err
    assert f"spacedg qa build {room}" in err
    assert sorted(p.relative_to(room) for p in room.rglob("*")) == before  # no index, no visibility cache
    assert not (tmp_path / "q.png").exists()
