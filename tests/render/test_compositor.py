"""Compositing oracles: both tile compositors against a tile-free brute force, and against each other."""

from __future__ import annotations

import functools

import numpy as np
import pytest
import torch

from tests.render_helpers import brute_force_composite, camera, random_gaussians
from spacedg.render import Gaussians, RasterSettings, render
from spacedg.render import project_cpu, raster_cpu, raster_torch
from spacedg.render.project_torch import Projected
from spacedg.render.project_cpu import AMIN, CA, CB, CBL, CC, CR, DEPTH, OPA, PX, PY, RADX, RADY

SETTINGS = RasterSettings()
#: Every output of a composite with colour, depth and ids.
_OUTPUTS = ("rgb", "alpha", "depth", "median_depth", "instance_ids")


def as_projected(packed: np.ndarray, rects: np.ndarray) -> Projected:
    """The compiled projection's output as the torch compositor's input (float64)."""
    t = torch.from_numpy(packed.astype(np.float64))
    visible = torch.from_numpy(rects[:, 1] > rects[:, 0])
    radii = torch.stack([t[:, RADX], t[:, RADY]], 1).to(torch.int32) * visible[:, None]
    return Projected(
        t[:, [PX, PY]], t[:, [CA, CB, CC]], t[:, OPA], t[:, CR : CBL + 1], t[:, DEPTH], radii, torch.from_numpy(rects.copy()),
        t[:, AMIN],
    )


def scene_and_projection(seed: int, n: int, width: int, height: int, **kw):
    rng = np.random.default_rng(seed)
    gaussians = random_gaussians(n, rng, **kw)
    cam = camera(width, height)
    packed, rects = project_cpu.project_gaussians(gaussians, cam, SETTINGS)
    return gaussians, cam, packed, rects


@functools.cache
def _small_case(seed: int) -> tuple:
    """200 Gaussians at 29×23 and their brute-force composite, once per seed (both binnings of a
    seed compare against the same oracle; no test writes to these arrays)."""
    gaussians, cam, packed, rects = scene_and_projection(seed, 200, 29, 23, scale=(0.05, 0.5), opacity=(0.3, 1.0))
    oracle = brute_force_composite(packed, rects, gaussians.instance_ids, cam.width, cam.height, SETTINGS.alpha_max)
    return gaussians, cam, packed, rects, oracle


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("tight", [True, False])
def test_compiled_compositor_matches_brute_force(seed: int, tight: bool) -> None:
    gaussians, cam, packed, rects, oracle = _small_case(seed)
    assert (rects[:, 1] > rects[:, 0]).sum() > 20
    ids = gaussians.instance_ids
    got = raster_cpu.rasterize(packed, rects, ids, cam.width, cam.height, SETTINGS.alpha_max, True, True, True, tight)
    for name in ("rgb", "alpha"):
        np.testing.assert_allclose(got[name], oracle[name], atol=1e-5, err_msg=name)
    np.testing.assert_allclose(got["depth"], oracle["depth"], rtol=1e-5, atol=1e-5)  # metres: float32 relative
    np.testing.assert_array_equal(got["median_depth"], oracle["median_depth"].astype(np.float32))
    np.testing.assert_array_equal(got["instance_ids"], oracle["instance_ids"])
    assert (got["instance_ids"] >= 0).any() and (got["alpha"] > 0.5).mean() > 0.3 and (got["alpha"] > 0.99).any()


@functools.cache
def _saturated_case() -> tuple:
    """1500 Gaussians at 40×30 and their brute-force composite, computed once for the eight
    specialisations below (the oracle is the expensive part; no test writes to these arrays)."""
    gaussians, cam, packed, rects = scene_and_projection(7, 1500, 40, 30, scale=(0.05, 0.5), opacity=(0.5, 1.0))
    oracle = brute_force_composite(packed, rects, gaussians.instance_ids, cam.width, cam.height, SETTINGS.alpha_max)
    return gaussians, cam, packed, rects, oracle


@pytest.mark.parametrize("flags", [(c, d, i) for c in (True, False) for d in (True, False) for i in (True, False)])
def test_every_output_specialisation_matches_brute_force(flags: tuple[bool, bool, bool]) -> None:
    """Each compiled specialisation of the compositor (output flags as constants) against the brute force:
    the tiles hold more than one gathered batch of Gaussians and saturate, so batching and the
    early exit are exercised; outputs not asked for are left untouched."""
    want_color, want_depth, want_ids = flags
    gaussians, cam, packed, rects, oracle = _saturated_case()
    ids = gaussians.instance_ids
    offsets, _ = raster_cpu.bin_visible(packed, rects, cam.width, cam.height, True)
    assert np.diff(offsets).max() > 2 * 32
    got = raster_cpu.rasterize(packed, rects, ids, cam.width, cam.height, SETTINGS.alpha_max, *flags, True)
    np.testing.assert_allclose(got["alpha"], oracle["alpha"], atol=1e-5)
    assert (got["alpha"] > 0.999).mean() > 0.5  # most pixels saturate: the early exit is taken
    if want_color:
        np.testing.assert_allclose(got["rgb"], oracle["rgb"], atol=1e-5)
    else:
        assert got["rgb"].shape == (1, 1, 3) and not got["rgb"].any()
    if want_depth:
        np.testing.assert_allclose(got["depth"], oracle["depth"], rtol=1e-5, atol=1e-5)
    else:
        assert got["depth"].shape == (1, 1) and not got["depth"].any()
    if want_ids:
        np.testing.assert_array_equal(got["median_depth"], oracle["median_depth"].astype(np.float32))
        np.testing.assert_array_equal(got["instance_ids"], oracle["instance_ids"])
    else:
        assert got["instance_ids"].shape == (1, 1) and (got["instance_ids"] == -1).all()


@pytest.mark.parametrize("seed", [3, 4])
def test_torch_compositor_matches_brute_force(seed: int) -> None:
    gaussians, cam, packed, rects = scene_and_projection(seed, 200, 29, 23, scale=(0.05, 0.5), opacity=(0.3, 1.0))
    ids = gaussians.instance_ids
    oracle = brute_force_composite(packed, rects, ids, cam.width, cam.height, SETTINGS.alpha_max)
    proj = as_projected(packed, rects)
    offsets, gauss = raster_torch.bin_tiles(proj, cam.width, cam.height, tight=True)
    got = raster_torch.composite(
        proj, offsets, gauss, torch.from_numpy(ids.copy()), cam.width, cam.height, SETTINGS.alpha_max, True, True, True, chunk=7
    )
    for name in ("rgb", "alpha"):
        np.testing.assert_allclose(got[name].numpy(), oracle[name], atol=1e-5, err_msg=name)
    np.testing.assert_allclose(got["depth"].numpy(), oracle["depth"], rtol=1e-5, atol=1e-5)
    np.testing.assert_array_equal(got["median_depth"].numpy(), oracle["median_depth"])
    np.testing.assert_array_equal(got["instance_ids"].numpy(), oracle["instance_ids"])


def test_tight_binning_drops_pairs_but_not_pixels() -> None:
    gaussians, cam, packed, rects = scene_and_projection(5, 3000, 160, 120, scale=(0.01, 0.2))
    ids = gaussians.instance_ids
    loose = raster_cpu.rasterize(packed, rects, ids, cam.width, cam.height, 0.99, True, True, True, False)
    tight = raster_cpu.rasterize(packed, rects, ids, cam.width, cam.height, 0.99, True, True, True, True)
    assert tight["n_pairs"] < loose["n_pairs"]
    for name in _OUTPUTS:
        np.testing.assert_array_equal(tight[name], loose[name], err_msg=name)
    # the torch binning drops exactly the same pairs
    offsets, gauss = raster_torch.bin_tiles(as_projected(packed, rects), cam.width, cam.height, tight=True)
    assert gauss.numel() == tight["n_pairs"]


@pytest.mark.parametrize("sh_degree", [0, 3])
def test_compiled_and_torch_paths_agree_on_full_frames(sh_degree: int) -> None:
    """Projection + binning + compositing, end to end, the two implementations held to each other."""
    rng = np.random.default_rng(10 + sh_degree)
    gaussians = random_gaussians(6000, rng, sh_degree=sh_degree, scale=(0.005, 0.08))
    cam = camera(320, 240)
    a = render(gaussians, cam, outputs="all", backend="cpu")
    b = render(gaussians, cam, outputs="all", backend="torch")
    assert a.stats["visible"] == b.stats["visible"] and a.stats["pairs"] == b.stats["pairs"]
    for name in ("rgb", "alpha"):
        diff = np.abs(getattr(a, name) - getattr(b, name))
        assert diff.mean() < 1e-5 and diff.max() < 5e-3, (name, diff.mean(), diff.max())
    covered = (a.alpha > 0.5) & (b.alpha > 0.5)
    assert np.abs(a.depth - b.depth)[covered].mean() < 1e-4
    assert (a.instance_ids == b.instance_ids).mean() > 0.999
    assert (a.median_depth == b.median_depth).mean() > 0.999


def test_only_requested_outputs_are_returned() -> None:
    gaussians = random_gaussians(500, np.random.default_rng(1))
    frame = render(gaussians, camera(64, 48), outputs="depth")
    assert frame.rgb is None and frame.instance_ids is None and frame.median_depth is None
    assert frame.depth is not None and frame.alpha.shape == (48, 64)
    full = render(gaussians, camera(64, 48), outputs="all")
    # the same numbers up to float32 rounding (the compiled variants contract FMAs differently)
    np.testing.assert_allclose(frame.depth, full.depth, rtol=1e-6)
    np.testing.assert_allclose(frame.alpha, full.alpha, atol=1e-6)


def test_opaque_plane_depth_is_its_distance() -> None:
    """A dense fronto-parallel plane at z = 3 m: expected and median depth are 3 where alpha > ½."""
    grid = np.stack(np.meshgrid(np.arange(-2.0, 2.0, 0.02), np.arange(-1.5, 1.5, 0.02)), -1).reshape(-1, 2)
    n = grid.shape[0]
    means = np.column_stack([grid, np.full(n, 3.0)])
    from spacedg.render.gaussians import Gaussians

    plane = Gaussians(
        means, np.tile([1.0, 0, 0, 0], (n, 1)), np.tile([0.015, 0.015, 1e-6], (n, 1)), np.ones(n), np.zeros((n, 1, 3))
    )
    frame = render(plane, camera(96, 72), outputs="all")
    covered = frame.alpha > 0.5
    assert covered.mean() > 0.95
    np.testing.assert_allclose(frame.depth[covered], 3.0, rtol=1e-5)
    np.testing.assert_array_equal(frame.median_depth[covered], np.float32(3.0))


def test_alpha_max_is_a_parameter() -> None:
    from spacedg.render.gaussians import Gaussians

    one = Gaussians([[0, 0, 2.0]], [[1.0, 0, 0, 0]], [[0.2, 0.2, 0.2]], [1.0], np.zeros((1, 1, 3)))
    for alpha_max in (0.5, 0.99):
        frame = render(one, camera(32, 24), settings=RasterSettings(alpha_max=alpha_max))
        assert frame.alpha.max() == pytest.approx(alpha_max, abs=1e-6)


def test_each_output_specialisation_has_its_own_disk_cache() -> None:
    """numba names an on-disk cache by qualified name: the eight specialisations (and their serial twins)
    must not share one index, or processes compiling different ones at once could mix them up."""
    kernels = [raster_cpu._make_composite(c, d, i) for c in (True, False) for d in (True, False) for i in (True, False)]
    names = {k.py_func.__qualname__ for k in kernels}
    assert len(names) == 8
    assert len({k.serial.py_func.__qualname__ for k in kernels} | names) == 16


@pytest.mark.parametrize(("seed", "width", "height"), [(4220, 45, 37), (4221, 33, 17), (4222, 70, 50)])
def test_a_composite_is_the_crop_of_the_same_camera_on_a_larger_canvas(seed: int, width: int, height: int) -> None:
    """A view whose last tile row and column reach past the image, covered by an opaque cloud of Gaussians centred
    inside it (its pixels saturate, alpha above 0.99; the pixels past its edge see only the cloud's fringe). On a
    canvas padded to whole tiles and more (right and bottom: the same pixel grid and tiles), cropped, every output
    is the view's bytes (the torch compositor's the same to float32 rounding: its batches sum in their own order).
    Widened on every side by 5 or 13 px, as motion blur's keyframe canvases are (the principal point moves, the tiles
    shift): the same to float32 rounding, the median depths and ids exactly, on both compositors. Gaussians centred up
    to 2 px past the edges reach in. Nothing past an image's edge reaches it but what reaches it on the larger canvas."""
    from spacedg.render.camera import Camera

    rng = np.random.default_rng(seed)
    cam = camera(width, height)
    n = width * height
    z = rng.uniform(3.0, 4.0, n)
    # pixel positions inside the image and up to 2 px past its edges (footprints reaching in from outside), well within
    # the projection's Jacobian limits (1.3 × the half-field of view from the principal point), which depend on the image's size
    u, v = rng.uniform(-2.0, width + 2.0, n), rng.uniform(-2.0, height + 2.0, n)
    cloud = random_gaussians(n, rng, opacity=(0.7, 1.0))
    means = np.stack([(u - cam.cx) / cam.fx * z, (v - cam.cy) / cam.fy * z, z], 1)
    scales = rng.uniform(1.5, 4.0, (n, 3)) * (z / cam.fx)[:, None]  # 1.5–4 px on screen
    gaussians = Gaussians(means, cloud.quats, scales, cloud.opacities, cloud.sh, cloud.instance_ids)
    padded = Camera(cam.fx, cam.fy, cam.cx, cam.cy, (width + 15) // 16 * 16 + 16, (height + 15) // 16 * 16 + 16, cam.cam_to_world)
    (small_cpu, small_torch), (big_cpu, big_torch) = (_both_composites(gaussians, view) for view in (cam, padded))
    assert small_cpu["alpha"].min() > 0.99  # the image is covered (its pixels saturate) …
    assert big_cpu["alpha"][height:, :].min() < 0.5 and big_cpu["alpha"][:, width:].min() < 0.5  # … the padding does not
    for name in _OUTPUTS:
        assert small_cpu[name].tobytes() == np.ascontiguousarray(big_cpu[name][:height, :width]).tobytes(), name
        # the torch path's colour and depth sums are batched matrix products over as many tiles as fit a batch, whose
        # summation order follows the batch: the same to float32 rounding (its own bytes depend on the canvas)
        np.testing.assert_allclose(small_torch[name], big_torch[name][:height, :width], rtol=1e-6, atol=1e-7, err_msg=name)
        np.testing.assert_allclose(small_torch[name], small_cpu[name], rtol=1e-5, atol=1e-5, err_msg=name)
    for margin in (5, 13):
        got, got_torch = _both_composites(gaussians, cam.widened(margin))
        for result, reference in ((got, small_cpu), (got_torch, small_torch)):
            crop = {name: result[name][margin:margin + height, margin:margin + width] for name in _OUTPUTS}
            # the projection rounds a moved principal point's positions anew (measured: within 1.2e-6)
            for name in ("rgb", "alpha", "depth"):
                np.testing.assert_allclose(crop[name], reference[name], rtol=1e-5, atol=1e-5, err_msg=name)
            for name in ("median_depth", "instance_ids"):
                np.testing.assert_array_equal(crop[name], reference[name], err_msg=name)


def _both_composites(gaussians: Gaussians, view) -> tuple[dict, dict]:
    """Every output of ``gaussians`` seen by ``view``, from the compiled compositor and the torch one (numpy)."""
    ids = gaussians.instance_ids
    packed, rects = project_cpu.project_gaussians(gaussians, view, SETTINGS)
    compiled = raster_cpu.rasterize(packed, rects, ids, view.width, view.height, SETTINGS.alpha_max, True, True, True, True)
    proj = as_projected(packed, rects)
    offsets, gauss = raster_torch.bin_tiles(proj, view.width, view.height, tight=True)
    torch_path = raster_torch.composite(proj, offsets, gauss, torch.from_numpy(ids.copy()), view.width, view.height,
                                        SETTINGS.alpha_max, True, True, True, chunk=16)
    return compiled, {k: v.numpy() for k, v in torch_path.items()}
