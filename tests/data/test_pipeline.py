"""The sample pipeline: chains, shared renders, order, seeds, provenance, mixtures, errors."""

from __future__ import annotations

import numpy as np
import pytest

from spacedg.data.chain import BENCH_DEGRADATIONS, MIXTURES, DegradationChoice, parse_chain, resolve_chain
from spacedg.data.pipeline import PipelineOptions, degrade, degrade_image, degrade_variants
from spacedg.errors import InvalidDataError, ParameterError, PluginError, UnknownPluginError
from spacedg.render.request import RenderRequest

SMALL = PipelineOptions(image_size=(96, 72))
POST_RENDER = ("haze", "water_droplets", "low_light", "over_exposure", "jpeg_compression", "low_res")
#: Parameters at which each built-in degradation does nothing.
ZERO_STRENGTH = {
    "defocus": {"aperture": 0.0, "depth": 2.0},
    "motion_blur": {"trans": 0.0, "rot": 0.0, "sub_steps": 80},
    "haze": {"density": 0.0},
    "water_droplets": {"radius": 0.0},
    "low_light": {"exposure": 1.0, "k": 0.0, "sigma_read": 0.0, "gain": 1.0},
    "over_exposure": {"exposure": 1.0, "k": 0.0, "sigma_read": 0.0},
    "low_res": {"scale": 1.0},
}


@pytest.fixture(scope="module")
def views(small_room) -> list[str]:
    return list(small_room.views)[:2]


@pytest.fixture
def render_log(monkeypatch: pytest.MonkeyPatch) -> list[RenderRequest]:
    """Every RenderRequest rendered during the test."""
    log: list[RenderRequest] = []
    original = RenderRequest.render

    def spy(self, *args, **kwargs):  # type: ignore[no-untyped-def]
        log.append(self)
        return original(self, *args, **kwargs)

    monkeypatch.setattr(RenderRequest, "render", spy)
    return log


def test_clean_images_shape_and_provenance(small_room, views) -> None:
    out = degrade(small_room, views, None, seed=1, options=SMALL)
    assert out.images.shape == (2, 72, 96, 3) and out.images.dtype == np.uint8
    assert out.views == tuple(views) and out.degradations == [] and out.sub_steps == [1, 1]
    assert out.images.std() > 5  # a real picture, not a blank


def test_post_render_variants_share_one_clean_render(small_room, views, render_log) -> None:
    results = degrade_variants(small_room, views, ["clean", *POST_RENDER], seed=2, options=SMALL)
    assert len(render_log) == len(views)  # one render per view for all seven variants
    assert render_log[0].outputs == {"rgb", "depth", "alpha"}  # depth because haze needs it
    clean = results[0].images
    for name, result in zip(POST_RENDER, results[1:]):
        assert result.degradations[0]["name"] == name
        assert not np.array_equal(result.images, clean), name


def test_no_depth_pass_without_a_depth_hungry_degradation(small_room, views, render_log) -> None:
    degrade_variants(small_room, views, ["clean", "low_light", "jpeg_compression"], seed=2, options=SMALL)
    assert all(r.outputs == {"rgb"} for r in render_log)


def test_raster_degradations_merge_into_one_render_per_view(small_room, views, render_log) -> None:
    out = degrade(small_room, views, "distortion+defocus+motion_blur:1", seed=3, options=SMALL)
    assert len(render_log) == len(views)
    request = render_log[0]
    assert request.camera.fisheye is not None and request.defocus is not None and request.motion is not None
    assert request.motion.fast  # the default motion mode
    assert [d["name"] for d in out.degradations] == ["distortion", "defocus", "motion_blur"]
    assert all(n >= 1 for n in out.sub_steps)


def test_bench_protocol_renders_once_per_raster_degradation(small_room, views, render_log) -> None:
    results = degrade_variants(small_room, views, ["clean", *BENCH_DEGRADATIONS], seed=4, options=SMALL)
    assert len(results) == 10
    assert len(render_log) == 4 * len(views)  # clean (shared by six) + defocus + distortion + motion blur


def test_order_does_not_matter_and_seeds_are_deterministic(small_room, views) -> None:
    a = degrade(small_room, views, ["low_res:3", "haze:2", "water_droplets:4"], seed=5, options=SMALL)
    b = degrade(small_room, views, "water_droplets:4+haze:2+low_res:3", seed=5, options=SMALL)
    assert np.array_equal(a.images, b.images)
    assert [d["name"] for d in a.degradations] == ["haze", "water_droplets", "low_res"]  # physical order
    c = degrade(small_room, views, "water_droplets:4+haze:2+low_res:3", seed=6, options=SMALL)
    assert not np.array_equal(a.images, c.images)


def test_a_degradation_draws_the_same_parameters_in_every_chain(small_room, views) -> None:
    alone, mixed = degrade_variants(small_room, views, ["haze", "haze+jpeg_compression"], seed=7, options=SMALL)
    assert alone.degradations[0] == mixed.degradations[0]


def test_provenance_reproduces_the_images(small_room, views) -> None:
    first = degrade(small_room, views, "night_capture", seed=8, options=SMALL)
    explicit = [{"name": d["name"], "params": d["params"]} for d in first.degradations]
    again = degrade(small_room, views, explicit, seed=8, options=SMALL)
    assert np.array_equal(first.images, again.images)
    assert all(d["preset"] is None for d in again.degradations)  # every value explicit
    assert {d["name"] for d in first.degradations} == {"low_light", "motion_blur", "low_res"}
    assert all(isinstance(d["seed"], int) and d["seed"] >= 0 for d in first.degradations)


@pytest.mark.parametrize("name", sorted(ZERO_STRENGTH))
def test_zero_strength_is_the_clean_image(small_room, views, name: str) -> None:
    clean = degrade(small_room, views, None, seed=9, options=SMALL).images
    out = degrade(small_room, views, {"name": name, "params": ZERO_STRENGTH[name]}, seed=9, options=SMALL).images
    assert np.array_equal(out, clean), name


def test_jpeg_at_quality_100_is_close_to_clean(small_room, views) -> None:
    clean = degrade(small_room, views, None, seed=9, options=SMALL).images.astype(float)
    out = degrade(small_room, views, ("jpeg_compression", {"quality": 100}), seed=9, options=SMALL).images
    assert 10 * np.log10(255**2 / np.mean((out - clean) ** 2)) > 35


@pytest.mark.parametrize("name", BENCH_DEGRADATIONS)
def test_distance_to_clean_rises_with_severity(small_room, views, name: str) -> None:
    chains = ["clean", *(f"{name}:{level}" for level in "12345")]
    results = degrade_variants(small_room, views[:1], chains, seed=10, options=SMALL)
    clean = results[0].images.astype(np.float64)
    distances = [float(np.abs(r.images - clean).mean()) for r in results[1:]]
    # at 96×72 px the mildest motion can be sub-pixel, which the renderer skips by design; low_res's
    # milder cameras (≥ 175 px on the shorter side, stated at 1752×1168) out-resolve a 72-px image; defocus's
    # mildest aperture (0.51-1 px at 1752×1168) is under half a pixel at 72 px, which renders sharp
    assert (distances[0] > 0 or name in ("motion_blur", "low_res", "defocus")) and distances[-1] > max(distances[0], 0.5), (name, distances)
    assert all(b >= a * 0.97 for a, b in zip(distances, distances[1:])), (name, distances)


def test_mixtures_expand_primary_at_bench_auxiliaries_milder() -> None:
    assert len(MIXTURES) == 6
    for name, recipe in MIXTURES.items():
        chain = parse_chain(name)
        assert chain[0] == DegradationChoice(recipe.primary)
        assert all(c.preset == "2" for c in chain[1:]) and len(chain) == 1 + len(recipe.auxiliaries)
    assert [c.preset for c in parse_chain("backlit_dynamics", mixture_preset="1")] == [None, "1"]


def test_every_mixture_runs(small_room, views) -> None:
    results = degrade_variants(small_room, views[:1], list(MIXTURES), seed=11, options=SMALL)
    for name, result in zip(MIXTURES, results):
        names = {d["name"] for d in result.degradations}
        assert names == {MIXTURES[name].primary, *MIXTURES[name].auxiliaries}
        primary = next(d for d in result.degradations if d["name"] == MIXTURES[name].primary)
        assert primary["preset"] == "bench"


def test_fisheye_corners_stay_black_after_linear_light(small_room, views) -> None:
    strong = {"name": "distortion", "params": {"k1": -1.0, "k2": 0.0, "k3": 0.0, "k4": 0.0, "max_theta": 1.5}}
    out = degrade(small_room, views[:1], [strong, "over_exposure"], seed=12, options=SMALL).images[0]
    assert (out[0, 0] == 0).all() and (out[-1, -1] == 0).all()


@pytest.mark.parametrize(
    ("chain", "error", "pattern"),
    [
        ("hazy", UnknownPluginError, "Did you mean 'haze'"),
        ("night_captur", UnknownPluginError, "mixture 'night_capture'"),
        ("haze:7", ParameterError, "unknown preset '7'"),
        ({"name": "haze", "params": {"densty": 1.0}}, ParameterError, "unknown parameter 'densty'"),
        ({"name": "low_res", "params": {"scale": 2.0}}, ParameterError, "outside its hard limits"),
        ("haze+haze:2", ParameterError, "appears twice"),
        ("night_capture+low_light", ParameterError, "appears twice"),
        ({"name": "haze", "strength": 1}, ParameterError, "may have 'preset' and 'params'"),
        (3.5, ParameterError, "cannot read a degradation"),
    ],
)
def test_bad_chains_fail_clearly(chain, error, pattern: str) -> None:
    with pytest.raises(error, match=pattern):
        resolve_chain(chain, seed=0)


def test_bad_views_and_options(small_room) -> None:
    with pytest.raises(ParameterError, match="has no view 'nope'"):
        degrade(small_room, ["nope"], None, options=SMALL)
    with pytest.raises(ParameterError, match=r"motion must be one of \['fast', 'reference'\]"):
        PipelineOptions(motion="quick")  # type: ignore[arg-type]
    with pytest.raises(ParameterError, match="image_size"):
        PipelineOptions(image_size=(0, 10))


def test_degrade_image_on_a_photo() -> None:
    photo = np.random.default_rng(0).integers(0, 256, (40, 50, 3), dtype=np.uint8)
    out, provenance = degrade_image(photo, "low_res:3+jpeg_compression:2", seed=1)
    assert out.shape == photo.shape and [p["name"] for p in provenance] == ["low_res", "jpeg_compression"]
    same, _ = degrade_image(photo, ["low_light:1"], seed=1)
    assert same.mean() < photo.mean()
    hazy, _ = degrade_image(photo, "haze", seed=1, depth=np.full((40, 50), 3.0))
    assert hazy.mean() > photo.mean()
    with pytest.raises(InvalidDataError, match="needs the rendered 'depth'"):
        degrade_image(photo, "haze", seed=1)
    with pytest.raises(ParameterError, match="cannot apply raster-stage"):
        degrade_image(photo, "defocus", seed=1)


def test_a_broken_plugin_output_is_named(small_room, views, monkeypatch) -> None:
    from dataclasses import replace

    from spacedg.data import chain as chain_module
    from spacedg.plugins.degradations import low_res

    broken = replace(low_res.SPEC, apply=lambda image, params, rng: image[:, :-1])
    monkeypatch.setattr(chain_module, "get_degradation", lambda name: broken)
    with pytest.raises(PluginError, match="display degradation 'low_res' must return uint8"):
        degrade(small_room, views[:1], "low_res", options=SMALL)


def test_third_party_degradation_runs_through_the_pipeline(third_party, small_room, views) -> None:
    clean = degrade(small_room, views, None, seed=13, options=SMALL).images
    out = degrade(small_room, views, "vignetting:5+low_res:1", seed=13, options=SMALL)
    assert [d["name"] for d in out.degradations] == ["vignetting", "low_res"]
    corner, centre = (0, 0), (36, 48)
    assert out.images[0][corner].mean() < clean[0][corner].mean()  # darker corners …
    assert abs(int(out.images[0][centre].mean()) - int(clean[0][centre].mean())) <= 12  # … not centre
    mixed = degrade(small_room, views, ["vignetting", "haze"], seed=13, options=SMALL)
    assert [d["name"] for d in mixed.degradations] == ["haze", "vignetting"]  # order 10 before 25


def test_scene_camera_lookup_suggests_close_names(small_room) -> None:
    name = next(iter(small_room.views))
    assert small_room.camera(name) is small_room.views[name]
    with pytest.raises(ParameterError, match=rf"no view '{name[:-1]}x'; did you mean"):
        small_room.camera(name[:-1] + "x")


def test_render_cache_shares_clean_renders_across_calls(small_room, views, render_log) -> None:
    """A render cache keeps clean renders between calls (post-render chains reuse them, raster
    chains never do) and changes no byte."""
    from spacedg.data.pipeline import frames_nbytes
    from spacedg.scene.store import ByteLRU

    cache = ByteLRU(1 << 30, frames_nbytes)
    plain = [degrade(small_room, views, chain, seed=4, options=SMALL).images for chain in ("clean", "jpeg_compression", "defocus")]
    render_log.clear()
    cached = [degrade(small_room, views, chain, seed=4, options=SMALL, render_cache=cache).images for chain in ("clean", "jpeg_compression", "defocus")]
    assert all(np.array_equal(a, b) for a, b in zip(plain, cached))
    assert len(render_log) == 2 * len(views)  # one clean set (shared by jpeg) + one defocus set
    assert cache.hits == 1 and len(cache) == 1 and cache.bytes > 0
