"""Issue 29 item 4: a fisheye lens and defocus together, on degenerate cameras (seeded fuzz).

Every render is finite and in range, the compiled and torch backends agree on alpha within
:data:`ALPHA_TOLERANCE`, and a ``degrade()`` chain of ``distortion`` with a large ``defocus``
either keeps its image or raises :class:`~spacedg.render.coverage.CoverageLostError` naming the
blur and the lens (never a black image without an error).
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from spacedg.data.pipeline import PipelineOptions, degrade
from spacedg.errors import SpaceDGError
from spacedg.plugins.degradations import distortion
from spacedg.render import Defocus, RasterSettings, render
from spacedg.render.coverage import CoverageLostError
from spacedg.render.gaussians import Gaussians
from spacedg.render.request import RenderRequest
from tests.fuzz_cases import _param, check_frame, random_camera, tiny_scene

#: Largest |alpha_cpu − alpha_torch| over the fuzz (measured: 2.2e-5 over 900 cases, float32
#: compositing in different orders). Gaussians of aspect ratio ~1e20 (a 1e20 m needle 1 cm wide)
#: are left out: their 2D determinant is below float64's cancellation noise in either backend.
ALPHA_TOLERANCE = 1e-4


def _scene(rng: np.random.Generator) -> Gaussians:
    n = int(rng.integers(20, 80))
    quats = rng.normal(size=(n, 4))
    quats /= np.linalg.norm(quats, axis=1, keepdims=True)
    return Gaussians.from_colors(
        rng.normal(0, 1.5, (n, 3)) + [0, 0, 3], quats, np.exp(rng.uniform(np.log(0.01), np.log(0.5), (n, 3))),
        rng.uniform(0.05, 1.0, n), rng.uniform(0, 1, (n, 3)),
    )


def test_fisheye_with_defocus_on_degenerate_cameras_backends_agree(monkeypatch) -> None:
    """Degenerate cameras under distortion and defocus: every frame finite and in range (the compiled path with its
    per-tile sampling of widely blurred tiles too), and the two backends' coverage the same with it turned off."""
    from spacedg.render import defocus as model

    rng = np.random.default_rng(29)
    rendered = 0
    for _ in range(24):
        gauss, cam = _scene(rng), random_camera(rng)  # sizes 1–64 px, focal 1e-3 … 1e6 px, principal point off the frame
        params = {p.name: _param(p, rng) for p in distortion.SPEC.params}  # hard limits included
        settings = RasterSettings(alpha_max=float(rng.choice([0.5, 0.99, 0.999999])), antialiased=bool(rng.random() < 0.3),
                                  defocus_extent=None if rng.random() < 0.2 else 2.5)
        blur = Defocus(aperture=float(rng.choice([15.0, 50.0, 200.0, 1000.0])), focus=float(rng.choice([1e-6, 0.01, 1.0, 3.0, 1e4])))
        try:
            lensed = distortion.distort(RenderRequest(cam), **params).camera
        except SpaceDGError:
            continue
        sampled = render(gauss, lensed, defocus=blur, outputs="all", backend="cpu", settings=settings)
        with monkeypatch.context() as patch:
            patch.setattr(model, "TILE_SAMPLE_MIN_COC", 0.0)
            cpu = render(gauss, lensed, defocus=blur, outputs="all", backend="cpu", settings=settings)
        torch = render(gauss, lensed, defocus=blur, outputs="all", backend="torch", settings=settings)
        for frame in (sampled, cpu, torch):
            check_frame(frame)
        assert np.abs(cpu.alpha - torch.alpha).max() <= ALPHA_TOLERANCE, (cam, params, blur)
        rendered += int(cpu.alpha.any())
    assert rendered >= 8


@pytest.fixture(scope="module")
def tiny():
    return tiny_scene()


def test_distortion_with_large_defocus_keeps_the_image_or_names_the_cause(tiny) -> None:
    rng = np.random.default_rng(600)
    view = sorted(tiny.views)[0]
    outcomes = {"kept": 0, "refused": 0}
    for seed in range(10):
        params = {p.name: _param(p, rng) for p in distortion.SPEC.params}
        chain = [{"name": "distortion", "params": params},
                 {"name": "defocus", "params": {"aperture": float(rng.choice([50.0, 200.0])), "depth": float(rng.uniform(0.5, 8.0))}}]
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("error")  # no silent NaN either
                images = degrade(tiny, [view], chain, seed=seed, options=PipelineOptions(image_size=(64, 48))).images
        except CoverageLostError as err:
            assert "circle of confusion" in str(err) and "sharp render" in str(err)
            outcomes["refused"] += 1
            continue
        assert images.max() > 0, chain  # a kept image is never black
        outcomes["kept"] += 1
    assert outcomes["kept"] >= 3


def test_a_tiny_image_circle_under_a_large_blur_is_refused_with_its_cause(tiny) -> None:
    view = sorted(tiny.views)[0]
    chain = [{"name": "distortion", "params": {"k1": 0.0, "k2": 0.0, "k3": 0.0, "k4": 0.0, "max_theta": 0.05}},
             {"name": "defocus", "params": {"aperture": 200.0, "depth": 7.5}}]
    with pytest.raises(CoverageLostError, match=r"circle of confusion of up to 600 px.*image circle \(max θ 0.05 rad\)"):
        degrade(tiny, [view], chain, options=PipelineOptions(image_size=(64, 48)))
    sharp = degrade(tiny, [view], chain[:1], options=PipelineOptions(image_size=(64, 48)))
    assert sharp.images.max() > 0 and 0.0 < sharp.captured_share <= 1.0


def test_render_command_names_the_blur_not_a_frame_mismatch(tiny, tmp_path, capsys) -> None:
    from spacedg.cli import main
    from spacedg.scene.io import save_scene

    save_scene(tiny, tmp_path / "s")
    png = tmp_path / "v.png"
    argv = ["render", str(tmp_path / "s"), "--view", sorted(tiny.views)[0], "--out", str(png), "--fisheye", "0,0,0,0,0.2"]
    assert main(argv + ["--defocus", "1000,7.5"]) == 2
    err = capsys.readouterr().err
    assert "circle of confusion" in err and "frame mismatch" not in err and not png.exists()
    assert main(argv) == 0 and png.exists()  # the lens alone renders


@pytest.mark.parametrize("seed, max_theta", [(4106, 1.2), (4107, 1.2), (4108, 0.3)])
def test_a_fisheye_frame_zeroes_exactly_the_pixels_outside_its_image_circle(seed: int, max_theta: float) -> None:
    """``frame_from_images`` zeroes (ids: −1) exactly the pixels its lens does not image, through the image
    circle's cached flat indices on contiguous images and the mask on strided ones or where most of the frame is
    outside (``max_theta`` 0.3): every output, NaN and −0.0 inputs included, equals the boolean-mask assignment."""
    from spacedg.render.camera import Camera, FisheyeLens
    from spacedg.render.composite import frame_from_images, lens_valid_mask

    rng = np.random.default_rng(seed)
    height, width = 37, 53
    camera = Camera(20.0, 22.0, 26.0, 18.5, width, height, np.eye(4), fisheye=FisheyeLens(-0.2, 2e-4, 1e-4, 0.0, max_theta))
    valid = lens_valid_mask(camera)
    assert valid is not None and 0 < valid.sum() < valid.size
    assert (valid.mean() < 0.5) == (max_theta < 1.0)
    for strided in (False, True):
        images = {
            "rgb": rng.standard_normal((height, width, 3)).astype(np.float32),
            "alpha": rng.random((height, width)).astype(np.float32),
            "depth": rng.random((height, width)).astype(np.float32),
            "median_depth": rng.random((height, width)).astype(np.float32),
            "instance_ids": rng.integers(-1, 9, (height, width)).astype(np.int32),
        }
        images["rgb"][0, 0] = np.nan
        images["alpha"][-1, -1] = -0.0
        if strided:  # channel-last views of wider arrays: not C-contiguous
            images["rgb"] = np.concatenate([images["rgb"], images["rgb"]], axis=2)[..., ::2]
            assert not images["rgb"].flags.c_contiguous
        expected = {name: image.copy() for name, image in images.items()}
        for name, image in expected.items():
            image[~valid] = -1 if name == "instance_ids" else 0.0
        frame = frame_from_images(images, camera, frozenset(images))
        for name, image in expected.items():
            assert getattr(frame, name).tobytes() == image.tobytes(), (name, strided)
