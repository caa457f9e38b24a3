"""Every chain form the README lists, over every built-in degradation: one canonical text that reads
back to an equal chain (``parse(text(chain)) == chain``), equal after pickling, hashable."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from spacedg.data.chain import BENCH_DEGRADATIONS, MIXTURES, Chain, DegradationChoice, Params, ResolvedDegradation, split_chains
from spacedg.errors import ParameterError
from spacedg.plugins.registry import get_degradation


def _full_params(name: str, seed: int = 3) -> dict[str, int | float]:
    """Every parameter of ``name``, drawn from its bench preset (floats with many digits)."""
    return get_degradation(name).sample_params("bench", np.random.default_rng(seed))


def _forms(name: str) -> list[object]:
    """Every way a user can write one item of ``name`` (README, chain.py docstring)."""
    spec = get_degradation(name)
    full = _full_params(name)
    first = next(iter(full))
    return [
        name,
        *(f"{name}:{preset}" for preset in spec.presets),
        {"name": name},
        {"name": name, "preset": "3"},
        {"name": name, "params": full},
        {"name": name, "preset": "2", "params": {first: full[first]}},
        (name, "4"),
        (name, {first: full[first]}),
        DegradationChoice(name, "1"),
        [name, "clean"],  # a list (clean adds nothing)
    ]


ALL_FORMS = [(name, form) for name in BENCH_DEGRADATIONS for form in _forms(name)]
COMPOSED = [
    *MIXTURES,  # each mixture by name
    "night_capture+jpeg_compression:1",
    "haze:3+low_res",
    ["defocus:2", {"name": "jpeg_compression", "params": {"quality": 30}}],
    [{"name": "haze", "params": {"density": 3.5}}, "motion_blur:5", ("low_res", "2")],
    "+".join(BENCH_DEGRADATIONS),  # all nine in one chain
    [{"name": n, "params": _full_params(n, 9)} for n in BENCH_DEGRADATIONS],
    None,
    "clean",
]


@pytest.mark.parametrize(("name", "form"), ALL_FORMS, ids=[f"{n}-{i}" for i, (n, _) in enumerate(ALL_FORMS)])
def test_every_form_of_every_builtin_reads_back_from_its_text(name: str, form: object) -> None:
    chain = Chain.parse(form)
    assert chain.name == name
    for candidate in (chain, chain.with_severity("bench"), chain.with_severity("5")):
        assert Chain.parse(candidate.text) == candidate, candidate.text
        again = pickle.loads(pickle.dumps(candidate))
        assert again == candidate and hash(again) == hash(candidate) and again.text == candidate.text
    chain.check()  # and it resolves


@pytest.mark.parametrize("form", COMPOSED, ids=range(len(COMPOSED)))
def test_composed_chains_read_back_from_their_text(form: object) -> None:
    chain = Chain.parse(form)
    assert Chain.parse(chain.text) == chain
    assert Chain.parse(chain.with_severity("2").text) == chain.with_severity("2")
    assert pickle.loads(pickle.dumps(chain)) == chain
    assert chain.provenance(5) == Chain.parse(chain.text).provenance(5)


def test_explicit_params_have_an_exact_text() -> None:
    chain = Chain.parse({"name": "haze", "params": {"density": 3.5, "airlight": np.float32(0.1)}})
    assert chain.text == "haze(density=3.5, airlight=0.10000000149011612)"  # numpy values become plain floats
    assert chain.with_severity("bench").text == "haze:bench(density=3.5, airlight=0.10000000149011612)"
    assert Chain.parse("low_res(scale=1e-05)+haze(density=1e+16)").items[1].params == {"density": 1e16}
    assert isinstance(chain.items[0].params, Params) and chain.items[0].params == {"airlight": 0.10000000149011612, "density": 3.5}
    assert Chain.parse({"name": "haze", "params": {}}) == Chain.parse("haze")  # no params is no params


def test_split_chains_keeps_parameters_together() -> None:
    assert split_chains("haze(density=3.5, airlight=0.8),low_res:3") == ["haze(density=3.5, airlight=0.8)", "low_res:3"]
    with pytest.raises(ParameterError, match="unbalanced"):
        split_chains("haze(density=3.5")


@pytest.mark.parametrize(("given", "pattern"), [
    ("haze(density)", "key=value"),
    ("haze(density=thick)", "must be a number"),
    ("haze(density=1, density=2)", "each once"),
    ("haze:(x=1", "unbalanced"),
    ("haze!", "cannot read a degradation"),
    ("haze++low_res", "cannot read a degradation"),
    ({"name": "night_capture", "preset": "3"}, "takes no preset"),
    ({"name": "night_capture", "params": {"exposure": 0.1}}, "takes no preset or params"),
    ({"name": "haze", "params": {"density": float("nan")}}, "finite number"),
    ({"name": "haze", "params": {"density": True}}, "finite number"),
    # a value that is no number under a name the degradation does not take: the unknown name is the error
    ({"name": "motion_blur", "params": {"translation": [0.05, 0.0, 0.0]}}, r"unknown parameter 'translation'\. Did you mean 'trans'\?"),
    ({"name": "motion_blur", "params": {"trans": [0.05, 0.0, 0.0]}}, r"'motion_blur': parameter 'trans' must be a finite number \(m\)"),
    ({"name": "haze", "params": [("density", 1.0)]}, "mapping"),
    ({"name": 7}, "degradation name"),
    ({"name": "haze", "preset": "a b"}, "preset must be a name"),
])
def test_malformed_items_fail_at_parse(given: object, pattern: str) -> None:
    with pytest.raises(ParameterError, match=pattern):
        Chain.parse(given)


def test_provenance_entries_read_back() -> None:
    chain = Chain.parse("night_capture+haze(density=2.0)")
    for entry in chain.provenance(11, scene_depth=3.0):
        step = ResolvedDegradation.from_provenance(entry)
        assert step.provenance() == entry
    with pytest.raises(ParameterError, match="'name', 'params', 'seed'"):
        ResolvedDegradation.from_provenance({"name": "haze", "params": {}})
    with pytest.raises(ParameterError, match="seed must be an integer"):
        ResolvedDegradation.from_provenance({**chain.provenance(1)[0], "seed": -1})
