"""The chain grammar, one type: parse, canonical name and text, severities, mixtures, provenance."""

from __future__ import annotations

import pytest

from spacedg.data.chain import CLEAN, MIXTURES, Chain, DegradationChoice
from spacedg.errors import ParameterError


@pytest.mark.parametrize(
    ("given", "name", "text"),
    [
        (None, CLEAN, "clean"),
        ("clean", CLEAN, "clean"),
        ("  ", CLEAN, "clean"),
        ("haze", "haze", "haze"),
        ("haze:3+low_res", "haze+low_res", "haze:3+low_res"),
        (" haze : 3 + low_res ", "haze+low_res", "haze:3+low_res"),
        ("night_capture", "night_capture", "night_capture"),
        ("night_capture+jpeg_compression:1", "night_capture+jpeg_compression", "night_capture+jpeg_compression:1"),
        ({"name": "haze", "preset": "2"}, "haze", "haze:2"),
        (("low_res", "4"), "low_res", "low_res:4"),
        (["haze", {"name": "low_res"}], "haze+low_res", "haze+low_res"),
    ],
)
def test_parse_name_and_text(given, name: str, text: str) -> None:
    chain = Chain.parse(given)
    assert chain.name == name and chain.text == text == str(chain)
    assert Chain.parse(chain.text) == chain or not isinstance(given, str) and chain.text == text
    assert Chain.parse(chain) is chain


def test_with_severity_leaves_mixtures_and_given_presets() -> None:
    chain = Chain.parse("haze+low_res:3+night_capture").with_severity("2")
    assert chain.text == "haze:2+low_res:3+night_capture"
    assert chain.name == "haze+low_res+night_capture"


def test_mixtures_expand_at_the_mixture_preset() -> None:
    for name, recipe in MIXTURES.items():
        choices = Chain.parse(name).choices("1")
        assert choices[0] == DegradationChoice(recipe.primary)
        assert [c.preset for c in choices[1:]] == ["1"] * len(recipe.auxiliaries)
    with pytest.raises(ParameterError, match="takes no preset"):
        Chain.parse("night_capture:3")


def test_provenance_resolves_every_part_in_physical_order() -> None:
    provenance = Chain.parse("night_capture").provenance(seed=7)
    assert [p["name"] for p in provenance] == ["motion_blur", "low_light", "low_res"]  # raster, linear, display
    assert [p["preset"] for p in provenance] == ["2", "bench", "2"]
    assert provenance == Chain.parse("low_res:2+low_light+motion_blur:2").provenance(seed=7)  # order given is irrelevant
    explicit = Chain.parse({"name": "haze", "params": {"density": 4.0, "airlight": 0.8, "depth_ref": 0.0}}).provenance(0)
    assert explicit[0]["preset"] is None and explicit[0]["params"]["density"] == 4.0


def test_check_fails_early_for_every_severity() -> None:
    assert Chain.parse("haze").check(("1", "5")).text == "haze"
    with pytest.raises(ParameterError, match="appears twice"):
        Chain.parse("haze+haze").check()
