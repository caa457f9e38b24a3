"""Defocus keeps a view's light (spacedg.render.defocus, spacedg.render.defocus_flux): a wall at every aperture up
to the hard limit, a room against the exact thin lens, an object on an empty background, both backends;
r = 0 is the sharp render bit for bit.

What is compared (means over the whole frame):

- uniform wall — an opaque plane far wider than the widest blurred footprint, so light enters the
  frame from outside as much as leaves it: mean linear radiance and mean alpha of the blurred render
  within 1 % of the sharp render, apertures 2–1000 px (the plugin's hard limit; r = aperture / 2);
- room (320×240) — mean radiance within 6 % and coverage within 4 % of the exact thin lens (the
  average of 32 sharp renders from points over the lens) at the bench apertures; coverage within 3 %
  of the sharp render up to the hard limit at 64×48.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.render_helpers import camera, random_gaussians, thin_lens_means, uniform_wall
from spacedg.render import Camera, Defocus, render
from spacedg.render.gaussians import Gaussians

HARD_LIMIT = 1000.0  # the defocus plugin's aperture limit, px


def wall_ratios(aperture: float, backend: str) -> tuple[float, float]:
    cam = Camera(40.0, 40.0, 32.0, 24.0, 64, 48, np.eye(4))
    r = aperture / 2.0  # depth 3 m, focus 1.5 m
    wall = uniform_wall(32.0 + 2.6 * r + 16.0)
    sharp = render(wall, cam, backend=backend)
    blurred = render(wall, cam, defocus=Defocus(aperture, 1.5), backend=backend)
    return float(blurred.rgb.mean() / sharp.rgb.mean()), float(blurred.alpha.mean() / sharp.alpha.mean())


@pytest.mark.parametrize("aperture", [2.0, 5.0, 10.0, 15.0, 50.0, 200.0, HARD_LIMIT])
def test_a_wall_keeps_its_light_at_every_aperture(aperture: float) -> None:
    radiance, coverage = wall_ratios(aperture, "cpu")
    assert radiance == pytest.approx(1.0, abs=0.01) and coverage == pytest.approx(1.0, abs=0.01), (radiance, coverage)


@pytest.mark.parametrize("aperture", [5.0, 50.0])
def test_a_wall_keeps_its_light_on_the_torch_path(aperture: float) -> None:
    radiance, coverage = wall_ratios(aperture, "torch")
    assert radiance == pytest.approx(1.0, abs=0.01) and coverage == pytest.approx(1.0, abs=0.01), (radiance, coverage)


@pytest.fixture(scope="module")
def room_views(small_room):
    names = sorted(small_room.views)
    return small_room.gaussians, [small_room.views[names[i]].resized(320, 240) for i in (0, len(names) // 3, 2 * len(names) // 3)]


@pytest.mark.parametrize("aperture, focus", [(5.0, 1.5), (10.0, 1.5), (15.0, 1.5), (10.0, 3.0), (15.0, 3.0)])
def test_a_room_matches_the_thin_lens(room_views, aperture: float, focus: float) -> None:
    gaussians, cams = room_views
    for cam in cams:
        blurred = render(gaussians, cam, defocus=Defocus(aperture, focus))
        radiance, coverage = thin_lens_means(gaussians, cam, aperture, focus)
        assert blurred.rgb.mean() == pytest.approx(radiance, rel=0.06)
        assert blurred.alpha.mean() == pytest.approx(coverage, rel=0.04)


@pytest.mark.parametrize("backend", ["cpu", "torch"])
def test_a_room_stays_covered_up_to_the_hard_limit(room_views, backend: str) -> None:
    """Coverage within 3 % of the sharp render at apertures 200 and 1000 px on three views (the torch twin:
    one view at 1000 px, its tile chunks being slow on CPU)."""
    gaussians, cams = room_views
    for cam in cams if backend == "cpu" else cams[:1]:
        small = cam.resized(64, 48)
        sharp = render(gaussians, small, backend=backend)
        for aperture in (200.0, HARD_LIMIT) if backend == "cpu" else (HARD_LIMIT,):
            blurred = render(gaussians, small, defocus=Defocus(aperture, 3.0), backend=backend)
            assert np.isfinite(blurred.rgb).all()
            assert blurred.alpha.mean() == pytest.approx(sharp.alpha.mean(), rel=0.03), aperture


@pytest.mark.parametrize("backend", ["cpu", "torch"])
def test_light_from_outside_the_view_enters_it(backend: str) -> None:
    """A Gaussian 30 px left of the view, blurred to r = 20 px, lights the view's left edge (no culling
    without a margin), with the same total alpha whichever backend."""
    cam = Camera(40.0, 40.0, 32.0, 24.0, 64, 48, np.eye(4))
    g = Gaussians([[-62 * 3.0 / 40.0, 0.0, 3.0]], [[1.0, 0, 0, 0]], [[0.05, 0.05, 0.05]], [0.9], np.ones((1, 1, 3)))
    assert render(g, cam, backend=backend).alpha.max() == 0.0
    blurred = render(g, cam, defocus=Defocus(40.0, 1.5), backend=backend)
    assert blurred.alpha[:, :8].sum() > 0.01 and blurred.alpha[:, -8:].sum() < blurred.alpha[:, :8].sum() * 1e-3


def test_aperture_zero_and_all_in_focus_are_the_sharp_render_bit_for_bit() -> None:
    g = random_gaussians(400, np.random.default_rng(1), depth=(2.5, 2.5))
    cam = camera(96, 72)
    sharp = render(g, cam, outputs="all")
    for defocus in (Defocus(0.0, 2.0), Defocus(30.0, 2.5)):
        frame = render(g, cam, outputs="all", defocus=defocus)
        for name in ("rgb", "alpha", "depth", "median_depth", "instance_ids"):
            np.testing.assert_array_equal(getattr(frame, name), getattr(sharp, name), err_msg=name)


@pytest.mark.parametrize("scale", [1e6, 1e12, 1e20, 3e38])
def test_backends_agree_on_huge_gaussians(scale: float) -> None:
    """A Gaussian of any finite size renders the same on both backends (both project covariances in
    float64 and cap footprint radii at 2³⁰ px): seen from inside or from afar it covers the view."""
    cam = Camera(20.0, 20.0, 12.0, 8.0, 24, 16, np.eye(4))
    for z in (0.5, 3.0, 1e6):
        g = Gaussians([[0.3, -0.2, z]], [[1.0, 0, 0, 0]], [[scale, scale, scale]], [0.8], np.ones((1, 1, 3)))
        cpu = render(g, cam, outputs="all", backend="cpu")
        torch_ = render(g, cam, outputs="all", backend="torch")
        np.testing.assert_allclose(cpu.alpha, torch_.alpha, atol=1e-5)
        np.testing.assert_allclose(cpu.rgb, torch_.rgb, atol=1e-5)
        assert cpu.alpha.min() > 0.5  # it covers the view (from afar, most of it)


# ---------------------------------------------------------------- issue 21 part 3: the cheaper passes
def test_the_measurement_frame_is_half_the_view_in_whole_tiles_centred() -> None:
    from spacedg.render.defocus import MEASURE_SCALE, measurement_camera

    cam = Camera(100.0, 90.0, 224.0, 168.0, 448, 336, np.eye(4))
    wide = measurement_camera(cam, 63)
    assert MEASURE_SCALE == 0.5 and (wide.width, wide.height) == (288, 240)  # ceil(574 / 2) = 287 → 288; 231 → 240
    assert (wide.fx, wide.fy) == (50.0, 45.0)
    assert wide.cx == pytest.approx((224.0 + 63) * 0.5 + 0) and wide.cy == pytest.approx((168.0 + 63) * 0.5 + 4)
    assert measurement_camera(cam, 63, 1.0).width == 574  # full resolution: the frame as it was


@pytest.mark.parametrize("backend", ["cpu", "torch"])
def test_a_view_blurred_everywhere_is_composited_coarse_with_its_light(room_views, backend: str, monkeypatch) -> None:
    """Every visible Gaussian blurred by >= COMPOSITE_MIN_COC px: the blurred view is composited on a 2× or 4×
    coarser grid and upsampled; it keeps its light and is within 1/255 mean of the full-resolution composite."""
    from spacedg.render import defocus as model

    gaussians, cams = room_views
    cam = cams[1]
    defocus = Defocus(40.0, 30.0)  # focus far behind the room: everything blurred by >= 25 px
    coarse = render(gaussians, cam, defocus=defocus, backend=backend, outputs="rgb,depth")
    monkeypatch.setattr(model, "COMPOSITE_MIN_COC", 0.0)  # full-resolution composite (the model before)
    monkeypatch.setattr(model, "TILE_SAMPLE_MIN_COC", 0.0)
    # the full composite's reference is the compiled backend's for both (the backends agree on a coarse composite,
    # test_the_backends_agree_on_a_coarse_composite; torch's full composite took 12 of this test's 14 s)
    full = render(gaussians, cam, defocus=defocus, backend="cpu", outputs="rgb,depth")
    assert coarse.stats["pairs"] < 0.4 * full.stats["pairs"]
    assert coarse.rgb.mean() == pytest.approx(full.rgb.mean(), rel=0.005)
    assert coarse.alpha.mean() == pytest.approx(full.alpha.mean(), rel=0.005)
    assert np.abs(coarse.rgb - full.rgb).mean() < 1.0 / 255
    covered = full.alpha > 0.5
    assert np.abs(coarse.depth - full.depth)[covered].mean() < 0.01 * full.depth[covered].mean()


def test_the_backends_agree_on_a_coarse_composite() -> None:
    """Light and coverage agree; an id may differ only where the two backends' median hits are two
    Gaussians at the same depth (the transmittance crosses 0.5 within float32 rounding: 16 pixels,
    one coarse pixel, at 0.7 mm apart)."""
    g = random_gaussians(3000, np.random.default_rng(0))
    cam = camera(96, 72)
    from spacedg.render import defocus as model
    from spacedg.render import project_cpu
    from spacedg.render.settings import RasterSettings

    for defocus in (Defocus(30.0, 0.5), Defocus(60.0, 0.3)):
        assert model.composite_factor(*project_cpu.project_gaussians(g, cam, RasterSettings(), defocus, True), 96, 72) == 4
        compiled = render(g, cam, defocus=defocus, backend="cpu", outputs="all")
        reference = render(g, cam, defocus=defocus, backend="torch", outputs="all")
        assert np.abs(compiled.rgb - reference.rgb).max() < 1e-3
        assert np.abs(compiled.alpha - reference.alpha).max() < 1e-4
        differ = compiled.instance_ids != reference.instance_ids
        assert differ.mean() < 0.01
        np.testing.assert_allclose(compiled.median_depth[differ], reference.median_depth[differ], rtol=1e-3)


# ---------------------------------------------------------------- issue 29: the thin-lens reference
def test_the_thin_lens_keeps_the_focus_plane_and_blurs_by_the_circle_of_confusion() -> None:
    """Over the reference's lens points, a point on the focus plane projects to one pixel and a point at
    depth d spreads with standard deviation aperture·|d − focus|/d px on each axis (the model's r)."""
    from spacedg.render.thin_lens import lens_camera, lens_offsets

    cam = Camera(50.0, 40.0, 32.0, 24.0, 64, 48, np.eye(4))
    defocus = Defocus(6.0, 2.0)
    offsets = lens_offsets(4096)
    assert np.abs(offsets.mean(axis=0)).max() < 0.01 and np.allclose(np.cov(offsets.T), np.eye(2), atol=0.02)
    for depth in (2.0, 1.0, 5.0):
        point = np.array([[0.3, -0.2, depth]])
        uv = np.array([lens_camera(cam, defocus, b).project(point)[0][0] for b in offsets[::8]])
        r = 6.0 * abs(depth - 2.0) / depth
        assert uv.std(axis=0) == pytest.approx([r, r], abs=0.02 * r + 1e-9)
        assert uv.mean(axis=0) == pytest.approx(cam.project(point)[0][0], abs=1e-6 + 0.02 * r)


def _ball_case(backend: str, aperture: float, focus: float) -> tuple[float, float, float]:
    """(light / clean, light / reference, PSNR against the thin lens, 16 points) of an opaque ball on nothing."""
    from spacedg.render.thin_lens import thin_lens_render

    from tests.render_helpers import opaque_ball

    g = opaque_ball()
    cam = Camera(60.0, 60.0, 32.0, 24.0, 64, 48, np.eye(4))
    defocus = Defocus(aperture, focus)
    clean = render(g, cam, backend=backend)
    blurred = render(g, cam, defocus=defocus, backend=backend)
    ref = thin_lens_render(g, cam, defocus, samples=16)
    encode = lambda x: np.clip(x, 0.0, 1.0) ** (1 / 2.2)  # noqa: E731
    mse = float(np.mean((encode(blurred.rgb) - encode(ref["rgb"])) ** 2))
    return float(blurred.rgb.mean() / clean.rgb.mean()), float(blurred.rgb.mean() / ref["rgb"].mean()), 10.0 * np.log10(1.0 / mse)


@pytest.mark.parametrize("backend", ["cpu", "torch"])
@pytest.mark.parametrize("aperture, focus", [(3.0, 1.5), (6.0, 6.0)])
def test_an_object_on_an_empty_background_keeps_its_light(backend: str, aperture: float, focus: float) -> None:
    """An opaque ball in front of nothing (issue 29: the blurred view had +19 % to +34 % of the light):
    light within 1 % of the clean render (at (6, 6) the reference has +2.4 %: its 0.6 m lens sees round
    the 1 m ball, which the model does not reproduce)."""
    light, _, _ = _ball_case(backend, aperture, focus)
    assert light == pytest.approx(1.0, abs=0.01)


@pytest.mark.xfail(reason="issue 29: 30.9 dB. 1500 splats stacked ~20 alpha deep, blurred to 1.5 px (their own sigma 0.8 px): "
                   "the spread alpha saturates (1 - exp(-sum)) out to ~1.3 r past the rim, so the blurred rim is steeper than the "
                   "lens's; the flux step keeps the light (0.9998) but not the rim's shape (FLUX_LENGTH 0 to 0.5: 30.9-32.3 dB)", strict=False)
def test_an_object_on_an_empty_background_matches_the_thin_lens() -> None:
    """PSNR >= 35 dB against the thin-lens reference (16 points) for the ball at aperture 3, focus 1.5."""
    light, versus_ref, db = _ball_case("cpu", 3.0, 1.5)
    assert versus_ref == pytest.approx(1.0, abs=0.01) and db >= 35.0, (light, versus_ref, db)


def test_the_compiled_coarse_steps_are_the_numpy_arithmetic_byte_for_byte() -> None:
    """coarse_view and the bilinear upsampling against their numpy forms (the implementation before they were compiled)."""
    from spacedg.render import defocus as model
    from spacedg.render import project_cpu
    from spacedg.render.project_cpu import CA, CB, CC, PX, PY, RADX, RADY
    from spacedg.render.settings import RasterSettings

    def coarse_numpy(packed, rects, width, height, factor):  # type: ignore[no-untyped-def]
        f = float(factor)
        w2, h2 = -(-width // factor), -(-height // factor)
        packed = packed.copy()
        packed[:, [PX, PY]] /= np.float32(f)
        packed[:, [CA, CB, CC]] *= np.float32(f * f)
        packed[:, [RADX, RADY]] = np.ceil(packed[:, [RADX, RADY]] / np.float32(f))
        tiles = np.array([(w2 + 15) // 16, (h2 + 15) // 16], np.float64)
        mean, rad = packed[:, [PX, PY]].astype(np.float64), packed[:, [RADX, RADY]].astype(np.float64)
        lo = np.minimum(np.clip(np.floor((mean - rad) / 16.0), 0, None), tiles)
        hi = np.minimum(np.clip(np.ceil((mean + rad) / 16.0), 0, None), tiles)
        keep = (rects[:, 1] > rects[:, 0]) & (hi > lo).all(axis=1)
        return packed, (np.stack([lo[:, 0], hi[:, 0], lo[:, 1], hi[:, 1]], axis=1) * keep[:, None]).astype(rects.dtype), w2, h2

    def bilinear_numpy(image, factor, width, height):  # type: ignore[no-untyped-def]
        y0, y1, ty = model._bilinear_axis(height, image.shape[0], factor)
        x0, x1, tx = model._bilinear_axis(width, image.shape[1], factor)
        shape = (-1, 1) + (1,) * (image.ndim - 2)
        rows = image[y0] * (1 - ty.reshape(shape)) + image[y1] * ty.reshape(shape)
        shape = (1, -1) + (1,) * (image.ndim - 2)
        return (rows[:, x0] * (1 - tx.reshape(shape)) + rows[:, x1] * tx.reshape(shape)).astype(np.float32)

    g = random_gaussians(3000, np.random.default_rng(5))
    for width, height in ((96, 72), (97, 61)):
        cam = camera(width, height)
        packed, rects = project_cpu.project_gaussians(g, cam, RasterSettings(), Defocus(20.0, 0.4), True)
        for factor in (2, 4):
            got, want = model.coarse_view(packed, rects, width, height, factor), coarse_numpy(packed, rects, width, height, factor)
            assert np.array_equal(got[0].view(np.uint32), want[0].view(np.uint32)) and np.array_equal(got[1], want[1])
            assert got[1].dtype == want[1].dtype and got[2:] == want[2:]
    rng = np.random.default_rng(6)
    for shape, factor, width, height in (((36, 48, 3), 2, 96, 72), ((18, 24), 4, 96, 72), ((31, 49), 2, 97, 61)):
        image = rng.random(shape, dtype=np.float32)
        got, want = model._bilinear(image, factor, width, height), bilinear_numpy(image, factor, width, height)
        assert got.shape == want.shape and np.array_equal(got.view(np.uint32), want.view(np.uint32))


@pytest.mark.parametrize("lens", ["pinhole", "fisheye"])
def test_the_sharp_pass_projected_with_the_view_is_its_own_projection_byte_for_byte(lens: str) -> None:
    """project_with_sharp (the defocused view and the sharp pass's grid in one pass) gives the bytes of the two
    separate projections: random Gaussians partly outside the frame and behind the camera, capture-scaled and
    antialiased dilations, with and without defocus, the sharp grid at ½ and 1, colour or not for the view."""
    from dataclasses import replace

    from spacedg.render import RasterSettings, look_at, project_cpu
    from spacedg.render.camera import FisheyeLens
    from spacedg.render.defocus import measurement_camera, measurement_settings

    rng = np.random.default_rng(4848)
    checked = 0
    for trial in range(4):
        g = random_gaussians(1500, rng, depth=(-6.0, 6.0), half_width=6.0, scale=(0.005, 0.4))
        pose = look_at(np.zeros(3), rng.normal(size=3) * 2.0 + np.array([0.0, 0.0, 5.0]), np.array([0.0, -1.0, 0.0]))
        width, height = int(rng.integers(50, 140)), int(rng.integers(40, 110))
        cam = Camera(float(rng.uniform(40, 120)), float(rng.uniform(40, 120)), width * 0.45, height * 0.55, width, height, pose)
        if lens == "fisheye":
            cam = replace(cam, fisheye=FisheyeLens(-0.2, 2e-4, 1e-4, 0.0, 1.5))
        if trial % 2:
            cam = replace(cam, capture_focal=(cam.fx * 2.7, cam.fy * 2.7))
        settings = RasterSettings(antialiased=trial == 2)
        for defocus in (None, Defocus(float(rng.uniform(2.0, 12.0)), float(rng.uniform(0.5, 4.0)))):
            for scale in (0.5, 1.0):
                sharp_cam, sharp_settings = measurement_camera(cam, 0, scale), measurement_settings(settings, scale)
                want_color = trial != 3
                got = project_cpu.project_with_sharp(g, cam, settings, defocus, want_color, sharp_cam, sharp_settings)
                want = (*project_cpu.project_gaussians(g, cam, settings, defocus, want_color),
                        *project_cpu.project_gaussians(g, sharp_cam, sharp_settings, None, True))
                for a, b in zip(got, want):
                    assert a.shape == b.shape and a.dtype == b.dtype and np.array_equal(a.view(np.uint32), b.view(np.uint32))
                assert np.count_nonzero(got[3][:, 1] > got[3][:, 0]) > 20
                checked += 1
    assert checked == 16
    with pytest.raises(ValueError, match="pose and lens"):
        moved = cam.with_pose(look_at(np.ones(3), np.zeros(3), np.array([0.0, -1.0, 0.0])))
        project_cpu.project_with_sharp(g, cam, settings, None, True, measurement_camera(moved, 0, 0.5), settings)


def _near_blurred_far_sharp(seed: int, width: int = 160, height: int = 112, side: float = 1.0) -> tuple[Gaussians, Camera, Defocus]:
    """Near furniture blurred by 6 px (the clamp) on the left of a far textured wall in focus on the right (a mixed
    view: the whole-view coarse rule does not apply; ``side = -1``: mirrored), 160 × 112 px by default."""
    rng = np.random.default_rng(seed)
    near = random_gaussians(1500, rng, depth=(0.8, 1.2), half_width=0.3, scale=(0.005, 0.04), opacity=(0.3, 1.0))
    far = random_gaussians(4000, rng, depth=(5.8, 6.2), half_width=1.6, scale=(0.01, 0.05), opacity=(0.5, 1.0))
    shift = lambda g, dx: g.means + np.array([dx, 0.0, 0.0])  # noqa: E731 - near on the left, far on the right
    parts = {"means": np.concatenate([shift(near, -0.25 * side), shift(far, 2.2 * side)])}
    parts.update({k: np.concatenate([getattr(near, k), getattr(far, k)]) for k in ("quats", "scales", "opacities", "sh", "instance_ids")})
    both = Gaussians(parts["means"], parts["quats"], parts["scales"], parts["opacities"], parts["sh"], parts["instance_ids"])
    return both, Camera(110.0, 110.0, width / 2, height / 2, width, height, np.eye(4)), Defocus(2.0, 6.0)


@pytest.mark.parametrize(("seed", "width", "height", "side"), [(0, 160, 112, 1.0), (1, 151, 101, 1.0), (1, 150, 98, -1.0)])
def test_widely_blurred_tiles_are_sampled_every_2_px_and_the_rest_is_the_full_composite(seed: int, width: int, height: int, side: float) -> None:
    """rasterize(sample_min_coc=4): tiles whose every Gaussian is blurred by >= 4 px are composited at the centres of
    their 2 × 2 blocks and upsampled; every other tile is the full-resolution composite bit for bit. The sampled
    tiles stay within 40 dB of the full composite (light within 0.5 %), also in the partial tiles of an odd-sized
    view, alpha in [0, 1], depth finite; each 2 × 2 block of a sampled tile carries one median depth and one id (a
    Gaussian's depth and id, or none); and alpha alone, colour alone and depth alone give the same bytes for what they
    ask for (depth: within float32 rounding, as the full composite's specialisations)."""
    from spacedg.render import RasterSettings, project_cpu, raster_cpu
    from spacedg.render.defocus import TILE_SAMPLE_MIN_COC, composite_factor

    g, cam, defocus = _near_blurred_far_sharp(seed, width, height, side)
    settings = RasterSettings()
    packed, rects = project_cpu.project_gaussians(g, cam, settings, defocus, True)
    assert composite_factor(packed, rects, cam.width, cam.height) == 1  # not the whole-view rule
    args = (packed, rects, g.instance_ids, width, height, settings.alpha_max, True, True, True, True)
    full = raster_cpu.rasterize(*args)
    mixed = raster_cpu.rasterize(*args, sample_min_coc=TILE_SAMPLE_MIN_COC)
    offsets, gauss = raster_cpu.bin_visible(packed, rects, width, height, True)
    tiles = raster_cpu.sampled_tiles(offsets, gauss, packed, np.float32(TILE_SAMPLE_MIN_COC)).reshape(7, 10).astype(bool)
    assert 0.1 < tiles.mean() < 0.9 and tiles[-1].any()  # some sampled tiles on the bottom edge, and mirrored on the right
    assert side > 0 or tiles[:, -1].any()
    sampled = np.kron(tiles, np.ones((16, 16), bool))[:height, :width]
    for name in ("rgb", "alpha", "depth", "median_depth", "instance_ids"):
        assert np.array_equal(full[name][~sampled], mixed[name][~sampled]), name
        assert not np.array_equal(full[name][sampled], mixed[name][sampled]) or name == "instance_ids", name
    err = np.mean((full["rgb"][sampled] - mixed["rgb"][sampled]) ** 2)
    assert 10 * np.log10(1.0 / err) > 40.0
    edge = sampled & ((np.arange(height)[:, None] >= height - 8) | (np.arange(width)[None, :] >= width - 8))  # bottom and right
    assert np.abs(full["rgb"][edge] - mixed["rgb"][edge]).mean() < 0.01
    assert abs(mixed["rgb"][sampled].sum() / full["rgb"][sampled].sum() - 1.0) < 5e-3
    assert 0.0 <= mixed["alpha"].min() and mixed["alpha"].max() <= 1.0 and np.isfinite(mixed["depth"]).all()
    allowed = {"median_depth": {0.0, *packed[:, project_cpu.DEPTH].tolist()}, "instance_ids": {-1, *g.instance_ids.tolist()}}
    even_h, even_w = height // 2 * 2, width // 2 * 2
    for name in ("median_depth", "instance_ids"):
        blocks = mixed[name][:even_h, :even_w].reshape(even_h // 2, 2, even_w // 2, 2).transpose(0, 2, 1, 3).reshape(even_h // 2, even_w // 2, 4)
        block_sampled = sampled[:even_h:2, :even_w:2]
        assert (blocks[block_sampled] == blocks[block_sampled][:, :1]).all()
        assert set(np.unique(mixed[name][sampled]).tolist()) <= allowed[name]
    for want_color, want_depth, want_ids in ((False, False, False), (True, False, False), (False, True, False)):
        part = raster_cpu.rasterize(packed, rects, g.instance_ids, width, height, settings.alpha_max, want_color, want_depth, want_ids, True,
                                    sample_min_coc=TILE_SAMPLE_MIN_COC)
        asked = ["alpha"] + ["rgb"] * want_color + ["median_depth", "instance_ids"] * want_ids
        assert all(np.array_equal(part[name], mixed[name]) for name in asked), (want_color, want_depth, want_ids)
        # depth: the compositor's specialisations contract its sums differently (1 ulp, as without sampling)
        assert not want_depth or np.allclose(part["depth"], mixed["depth"], rtol=1e-5, atol=1e-6)


def test_a_mixed_view_renders_its_sampled_tiles_and_keeps_its_light(monkeypatch) -> None:
    """Through render(): the mixed view's light stays within 0.5 % of the same render composited at full resolution
    everywhere (the sampling turned off), and within 40 dB of it."""
    from spacedg.render import defocus as model

    g, cam, defocus = _near_blurred_far_sharp(2)
    sampled = render(g, cam, defocus=defocus, backend="cpu")
    monkeypatch.setattr(model, "TILE_SAMPLE_MIN_COC", 0.0)  # every tile composited in full
    full = render(g, cam, defocus=defocus, backend="cpu")
    assert not np.array_equal(sampled.rgb, full.rgb)
    assert abs(sampled.rgb.mean() / full.rgb.mean() - 1.0) < 5e-3
    assert 10 * np.log10(1.0 / np.mean((sampled.rgb - full.rgb) ** 2)) > 40.0


def test_the_sharp_pass_is_projected_alongside_only_when_it_can_be_coarse(monkeypatch) -> None:
    """The view and the sharp pass's half-resolution grid are projected together only when the blur can be wide
    enough for that grid (flux_scale of max_radius is ½); a very mild blur (aperture 0.3 px, max_radius 0.9)
    projects the view alone, and its render is the same either way."""
    from spacedg.render import project_cpu

    calls: list[float] = []
    paired = project_cpu.project_with_sharp

    def counting(*args, **kwargs):  # type: ignore[no-untyped-def]
        calls.append(args[3].aperture)
        return paired(*args, **kwargs)

    monkeypatch.setattr(project_cpu, "project_with_sharp", counting)
    g = random_gaussians(2000, np.random.default_rng(5))
    cam = camera(96, 72)
    mild = render(g, cam, defocus=Defocus(0.3, 2.0), backend="cpu")
    render(g, cam, defocus=Defocus(6.0, 2.0), backend="cpu")
    assert calls == [6.0]
    monkeypatch.setattr(project_cpu, "project_with_sharp", lambda *a, **k: paired(*a, **k))
    from spacedg.render import composite

    monkeypatch.setattr(composite, "_sharp_pass_may_be_coarse", lambda defocus: True)  # paired anyway: the same image
    again = render(g, cam, defocus=Defocus(0.3, 2.0), backend="cpu")
    assert np.array_equal(mild.rgb, again.rgb) and np.array_equal(mild.alpha, again.alpha)


def test_widely_blurred_tiles_of_a_coarse_composite_are_sampled_too(monkeypatch) -> None:
    """A view composited at 2× (every Gaussian blurred by >= 4 px, some by < 8): its tiles whose every Gaussian is
    blurred by >= 8 px (tile_sample_min_coc(2)) are sampled every 2 coarse px; the render keeps its light (0.5 %) and
    stays within 40 dB of the same view with no tile sampled. At 4× nothing more is sampled (COMPOSITE_MAX_FACTOR)."""
    from spacedg.render import RasterSettings, project_cpu, raster_cpu
    from spacedg.render import defocus as model

    assert (model.tile_sample_min_coc(1), model.tile_sample_min_coc(2), model.tile_sample_min_coc(4)) == (4.0, 8.0, 0.0)
    g, cam, _ = _near_blurred_far_sharp(3, 224, 160)
    defocus = Defocus(12.0, 3.0)  # the far wall blurred by 5.8-6.2 px, the near furniture by 24
    packed, rects = project_cpu.project_gaussians(g, cam, RasterSettings(), defocus, True)
    assert model.composite_factor(packed, rects, cam.width, cam.height) == 2
    coarse, coarse_rects, width, height = model.coarse_view(packed, rects, cam.width, cam.height, 2)
    offsets, gauss = raster_cpu.bin_visible(coarse, coarse_rects, width, height, True)
    share = raster_cpu.sampled_tiles(offsets, gauss, coarse, np.float32(model.tile_sample_min_coc(2))).mean()
    assert 0.1 < share < 0.9
    sampled = render(g, cam, defocus=defocus, backend="cpu")
    monkeypatch.setattr(model, "TILE_SAMPLE_MIN_COC", 0.0)  # no tile sampled, at any factor
    whole = render(g, cam, defocus=defocus, backend="cpu")
    assert not np.array_equal(sampled.rgb, whole.rgb)
    assert abs(sampled.rgb.mean() / whole.rgb.mean() - 1.0) < 5e-3
    assert 10 * np.log10(1.0 / np.mean((sampled.rgb - whole.rgb) ** 2)) > 40.0
    assert np.isfinite(sampled.rgb).all() and 0.0 <= sampled.alpha.min() and sampled.alpha.max() <= 1.0
