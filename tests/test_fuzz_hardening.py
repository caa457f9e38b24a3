"""Seeded fuzz over every public entry point (readers, renders, degradations, the command line):
hostile or random input gives a result or one clear SpaceDGError, never another exception and never
NaN/Inf. The long run (≥ 10,000 cases, per-case timeouts) is ``benchmarks/fuzz.py``; the cases are
``tests/fuzz_cases.py``."""

from __future__ import annotations

import pytest

from tests.fuzz_cases import FAMILIES, Assets, run_case

CASES_PER_FAMILY = 40  # 480 cases, ~10 s on one core


@pytest.fixture(scope="module")
def assets(tmp_path_factory) -> Assets:
    return Assets(tmp_path_factory.mktemp("fuzz_assets"))


@pytest.mark.parametrize("family", FAMILIES)
def test_fuzz_family(family: str, assets: Assets, tmp_path, monkeypatch) -> None:
    monkeypatch.setenv("SPACEDG_DISABLE_PLUGIN_AUTOLOAD", "1")
    results = [run_case(family, 20261121 + seed, assets, tmp_path / "work") for seed in range(CASES_PER_FAMILY)]
    bad = [r for r in results if r.outcome in ("traceback", "nonfinite")]
    assert not bad, "\n\n".join(f"{r.family} seed {r.seed}: {r.outcome}\n{r.detail}" for r in bad[:3])
    outcomes = {r.outcome for r in results}
    assert "clear" in outcomes or family == "render"  # the hostile inputs do reach the checks
    assert "ok" in outcomes or family in ("colmap_bin",)  # and valid ones get through
