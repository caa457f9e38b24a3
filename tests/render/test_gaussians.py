"""Gaussians container: validation messages, SH evaluation and rotation, derivations."""

from __future__ import annotations

import numpy as np
import pytest

from spacedg.errors import InvalidDataError
from spacedg.render.gaussians import (
    SH_C0,
    Gaussians,
    eval_sh,
    quat_from_matrix,
    quat_to_matrix,
    sh_basis,
)


def _random(n: int, rng: np.random.Generator, degree: int = 0, ids: bool = False) -> dict:
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return dict(
        means=rng.normal(size=(n, 3)),
        quats=q,
        scales=rng.uniform(0.01, 0.1, (n, 3)),
        opacities=rng.uniform(0, 1, n),
        sh=rng.normal(size=(n, (degree + 1) ** 2, 3)) * 0.3,
        instance_ids=rng.integers(-1, 3, n) if ids else None,
    )


def test_valid_gaussians_are_float32_and_read_only(rng):
    g = Gaussians(**_random(20, rng, degree=2, ids=True))
    assert len(g) == 20 and g.sh_degree == 2
    assert g.means.dtype == np.float32 and g.instance_ids.dtype == np.int32
    with pytest.raises(ValueError):
        g.means[0, 0] = 1.0


@pytest.mark.parametrize(
    "field, mutate, expected",
    [
        ("means", lambda d: d["means"].__setitem__((3, 1), np.nan), r"'means': 1 of 10 entries hold NaN or Inf \(first at index 3"),
        ("scales", lambda d: d["scales"].__setitem__((5, 0), np.inf), r"'scales': 1 of 10 entries hold NaN or Inf \(first at index 5"),
        ("quats", lambda d: d["quats"].__setitem__(slice(2, 4), 0.0), r"'quats': 2 of 10 quaternions are zero \(first at index 2\)"),
        ("quats", lambda d: d["quats"].__setitem__(7, [1.0, 1.0, 0.0, 0.0]), r"'quats': 1 of 10 quaternions are not unit \(first at index 7"),
        ("scales", lambda d: d["scales"].__setitem__((4, 2), -0.1), r"'scales': 1 of 10 entries outside \[0, inf\] \(first at index 4"),
        ("opacities", lambda d: d["opacities"].__setitem__(slice(0, 3), 1.5), r"'opacities': 3 of 10 entries outside \[0, 1\]"),
        ("instance_ids", lambda d: d.__setitem__("instance_ids", np.full(10, -2)), r"'instance_ids': 10 of 10 entries outside \[-1, inf\]"),
    ],
)
def test_validation_names_field_count_and_index(rng, field, mutate, expected):
    data = _random(10, rng)
    mutate(data)
    with pytest.raises(InvalidDataError, match=expected) as info:
        Gaussians(**data, source="room.ply")
    assert str(info.value).startswith("room.ply: ")


def test_mismatched_lengths_and_bad_sh_count(rng):
    data = _random(10, rng)
    data["opacities"] = data["opacities"][:9]
    with pytest.raises(InvalidDataError, match=r"mismatched lengths \(means=10, quats=10, scales=10, opacities=9, sh=10\)"):
        Gaussians(**data)
    data = _random(10, rng)
    data["sh"] = np.zeros((10, 5, 3))
    with pytest.raises(InvalidDataError, match="5 SH coefficients per channel"):
        Gaussians(**data)
    data = _random(10, rng)
    data["means"] = np.zeros((10, 2))
    with pytest.raises(InvalidDataError, match=r"'means': expected shape \(N, 3\), got \(10, 2\)"):
        Gaussians(**data)


def test_degree0_colour_and_from_colors(rng):
    colors = rng.uniform(0, 1, (5, 3))
    d = _random(5, rng)
    g = Gaussians.from_colors(d["means"], d["quats"], d["scales"], d["opacities"], colors)
    np.testing.assert_allclose(g.base_colors(), colors, atol=1e-6)
    np.testing.assert_allclose(eval_sh(g.sh, np.zeros((5, 3))), colors, atol=1e-6)


def test_sh_basis_is_orthonormal_on_the_sphere():
    # Monte Carlo with many points: ∫ Y_i Y_j dω = δ_ij (times 4π normalisation of the real SH)
    rng = np.random.default_rng(0)
    d = rng.normal(size=(400_000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    basis = sh_basis(3, d)
    gram = basis.T @ basis * (4 * np.pi / len(d))
    np.testing.assert_allclose(gram, np.eye(16), atol=0.02)
    assert basis[0, 0] == pytest.approx(SH_C0)


def test_transform_rotates_positions_covariances_and_view_dependent_colour(rng):
    g = Gaussians(**_random(40, rng, degree=3))
    q = np.array([0.3, -0.5, 0.7, 0.4]) / np.linalg.norm([0.3, -0.5, 0.7, 0.4])
    rot = quat_to_matrix(q[None])[0]
    np.testing.assert_allclose(quat_from_matrix(rot), q, atol=1e-12)
    t = np.array([1.0, -2.0, 0.5])
    g2 = g.transformed(rot, t, scale=2.0)
    np.testing.assert_allclose(g2.means, 2 * g.means @ rot.T + t, atol=1e-5)
    cov = lambda gg: (lambda m: m @ m.transpose(0, 2, 1))(quat_to_matrix(gg.quats.astype(np.float64)) * gg.scales[:, None, :])
    np.testing.assert_allclose(cov(g2), 4 * rot @ cov(g) @ rot.T, atol=1e-6)
    cam = np.array([0.2, 0.1, -3.0])
    d1 = g.means - cam
    d1 /= np.linalg.norm(d1, axis=1, keepdims=True)
    d2 = g2.means - (2 * rot @ cam + t)
    d2 /= np.linalg.norm(d2, axis=1, keepdims=True)
    np.testing.assert_allclose(eval_sh(g2.sh, d2), eval_sh(g.sh, d1), atol=1e-5)


def test_transform_rejects_reflections_and_bad_scale(rng):
    g = Gaussians(**_random(3, rng))
    with pytest.raises(InvalidDataError, match="reflection"):
        g.transformed(np.diag([1.0, 1.0, -1.0]))
    with pytest.raises(InvalidDataError, match="positive finite"):
        g.transformed(scale=0.0)


def test_concat_pads_sh_and_instance_ids(rng):
    a = Gaussians(**_random(3, rng, degree=0))
    b = Gaussians(**_random(2, rng, degree=2, ids=True))
    c = Gaussians.concat([a, b])
    assert len(c) == 5 and c.sh_degree == 2
    np.testing.assert_array_equal(c.instance_ids[:3], [-1, -1, -1])
    np.testing.assert_array_equal(c.sh[:3, 1:], 0.0)
    np.testing.assert_array_equal(c.sh[:3, 0], a.sh[:, 0])
    with pytest.raises(InvalidDataError, match="cannot lower SH degree"):
        b.with_sh_degree(1)
    assert len(a.subset(np.array([True, False, True]))) == 2
