"""Seeded fuzz: ≥ 1000 degenerate scenes, lenses and requests; no output may be NaN or Inf."""

from __future__ import annotations

import numpy as np

from spacedg.render import Defocus, MotionBlur, RasterSettings, render
from spacedg.render.camera import Camera, FisheyeLens
from spacedg.render.gaussians import Gaussians

SCALES = np.array([0.0, 1e-9, 1e-6, 1e-3, 0.05, 1.0, 1e2, 1e4])
OPACITIES = np.array([0.0, 1e-7, 1.0 / 255.0, 0.5, 1.0])


def degenerate_scene(rng: np.random.Generator) -> Gaussians:
    n = int(rng.integers(1, 9))
    kind = rng.integers(0, 7, n)
    means = rng.normal(0, 1, (n, 3)) + [0, 0, 3]
    means[kind == 0] = [0.0, 0.0, 0.0]  # at the camera centre
    means[kind == 1, 2] = 0.01  # on the near plane
    means[kind == 2, 2] = -rng.uniform(0, 5, (kind == 2).sum())  # behind the camera
    means[kind == 3] *= 1e6  # very far
    means[kind == 4] = [0.0, 0.0, 1e-4]  # inside the near plane, on the axis
    means[kind == 5, 2] = 0.0101  # just past the near plane, off axis: huge Jacobian
    quats = rng.normal(size=(n, 4))
    quats /= np.linalg.norm(quats, axis=1, keepdims=True)
    scales = rng.choice(SCALES, (n, 3))
    opacities = rng.choice(OPACITIES, n)
    degree = int(rng.integers(0, 4))
    sh = rng.normal(0, 1, (n, (degree + 1) ** 2, 3)) * rng.choice([0.0, 1.0, 1e3], (n, 1, 1))
    return Gaussians(means, quats, scales, opacities, sh, rng.integers(-1, 3, n).astype(np.int32))


def degenerate_camera(rng: np.random.Generator) -> Camera:
    lens = None
    if rng.random() < 0.4:
        lens = FisheyeLens(*rng.choice([-0.24, 0.0, 1e-4, 0.5, -1.0], 4), max_theta=float(rng.choice([0.3, 1.5, 3.0])))
    f = float(rng.choice([1e-2, 20.0, 1e4]))
    return Camera(f, f, 12.0, 8.0, 24, 16, np.eye(4), lens)


def request(rng: np.random.Generator) -> dict:
    kw: dict = {"outputs": "all", "settings": RasterSettings(alpha_max=float(rng.choice([0.5, 0.99, 0.999999])), antialiased=bool(rng.random() < 0.5))}
    if rng.random() < 0.3:
        kw["defocus"] = Defocus(aperture=float(rng.choice([1e-6, 10.0, 1e4])), focus=float(rng.choice([1e-6, 1.0, 1e6])))
    if rng.random() < 0.05:
        kw["motion"] = MotionBlur(translation=tuple(rng.normal(0, 1e3, 3)), rotation=(0.0, 3.0, 0.0), sub_steps=3)
    return kw


def check(frame) -> None:
    for name in ("rgb", "alpha", "depth", "median_depth"):
        image = getattr(frame, name)
        assert np.isfinite(image).all(), name
    assert (frame.alpha >= 0).all() and (frame.alpha <= 1).all()
    assert (frame.rgb >= 0).all() and (frame.depth >= 0).all()
    assert (frame.instance_ids >= -1).all()


def test_fuzz_compiled_path_on_1200_degenerate_scenes() -> None:
    rng = np.random.default_rng(20261121)
    drawn = 0
    for _ in range(1200):
        frame = render(degenerate_scene(rng), degenerate_camera(rng), backend="cpu", **request(rng))
        check(frame)
        drawn += int(frame.alpha.any())
    assert drawn > 100  # the fuzz does reach the compositor, not only the culling


def test_fuzz_torch_path_on_150_degenerate_scenes() -> None:
    rng = np.random.default_rng(7)
    for _ in range(150):
        check(render(degenerate_scene(rng), degenerate_camera(rng), backend="torch", **request(rng)))


def test_camera_inside_a_huge_gaussian_stays_finite() -> None:
    g = Gaussians([[0.0, 0.0, 0.5]], [[1.0, 0, 0, 0]], [[1e4, 1e4, 1e4]], [1.0], np.ones((1, 1, 3)))
    for backend in ("cpu", "torch"):
        frame = render(g, Camera(20.0, 20.0, 12.0, 8.0, 24, 16, np.eye(4)), outputs="all", backend=backend)
        check(frame)
        assert frame.alpha.min() > 0.9  # it fills the view
