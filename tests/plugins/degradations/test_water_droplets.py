"""Built-in ``water_droplets`` degradation (linear stage, lens drops)."""

from __future__ import annotations

import cv2
import numba
import numpy as np
import pytest

from spacedg.errors import InvalidDataError, ParameterError
from spacedg.plugins import Category, Stage
from spacedg.plugins.degradations.water_droplets import (
    RIM_DARKENING,
    SPEC,
    SPECULAR_INTENSITY,
    droplet_field,
    fresnel_ratio,
    refracted_view,
    refraction_reach,
    water_droplets,
)
from spacedg.render.colour import linear_to_srgb

BENCH = {"scale": 3.0, "radius": 0.6, "strength": 0.4, "blur_sigma": 2.2, "blur_kernel": 9}


def _textured(height: int = 96, width: int = 128) -> np.ndarray:
    """Linear-light test image: gradients, a checkerboard, a sinusoid and an HDR 'window' (4.0)."""
    y, x = np.mgrid[0:height, 0:width].astype(np.float32)
    base = np.stack([x / width, y / height, 0.5 + 0.4 * np.sin(x / 5.0) * np.cos(y / 7.0)], axis=-1)
    image = 0.6 * base * np.where(((x // 12 + y // 12) % 2 == 0)[..., None], 0.3, 1.0)
    image[5:20, 70:100] = 4.0
    return image.astype(np.float32)


def _apply(image: np.ndarray, seed: int = 0, **changes: float) -> np.ndarray:
    return SPEC.apply(image, {}, {**BENCH, **changes}, np.random.default_rng(seed))


def _encode(linear: np.ndarray) -> np.ndarray:
    return np.round(255.0 * linear_to_srgb(np.clip(linear.astype(np.float64), 0.0, 1.0)))


def test_spec_declaration() -> None:
    assert SPEC.name == "water_droplets" and SPEC.stage is Stage.LINEAR and SPEC.category is Category.METEOROLOGICAL
    assert SPEC.order == 20.0 and SPEC.needs == frozenset()
    params = SPEC.param_map
    assert list(params) == ["scale", "radius", "strength", "blur_sigma", "blur_kernel"]
    assert {n: (p.unit, p.low, p.high) for n, p in params.items()} == {
        "scale": ("1/image", 0.0, 100.0),
        "radius": ("1", 0.0, 1.0),
        "strength": ("1", 0.0, 5.0),
        "blur_sigma": ("px", 0.0, 20.0),
        "blur_kernel": ("px", 1, 51),
    }
    assert params["blur_kernel"].integer
    bench = {k: r.to_list() for k, r in SPEC.presets["bench"].items()}
    assert bench == {"scale": [2.5, 4.0], "radius": [0.25, 0.75], "strength": [0.3, 0.5], "blur_sigma": [2.0, 2.5], "blur_kernel": [9, 9]}
    for preset in SPEC.preset_names:  # an integer range would draw even kernels
        kernel = SPEC.presets[preset]["blur_kernel"]
        assert kernel.fixed and kernel.low % 2 == 1, preset


@pytest.mark.parametrize("changes", [{"radius": 0.0}, {"scale": 0.0}, {"radius": 0.0, "strength": 5.0, "blur_sigma": 20.0}])
def test_no_drops_is_bit_exact_identity(changes: dict[str, float]) -> None:
    image = _textured()
    out = _apply(image, **changes)
    assert out.tobytes() == image.tobytes() and out is not image


def test_outside_drops_untouched_inside_changed() -> None:
    image = _textured()
    out = _apply(image, seed=4)
    alpha = droplet_field(image.shape[:2], BENCH["scale"], BENCH["radius"], BENCH["strength"], np.random.default_rng(4)).alpha
    outside = alpha == 0.0
    assert 0.05 < 1.0 - outside.mean() < 0.8, "the bench field should cover part of the image"
    assert out[outside].tobytes() == image[outside].tobytes()
    assert np.abs(out - image).max(axis=-1)[alpha > 0.5].mean() > 0.01


def test_same_seed_same_bytes_different_seed_differs() -> None:
    image = _textured()
    assert _apply(image, seed=7).tobytes() == _apply(image.copy(), seed=7).tobytes()
    assert _apply(image, seed=7).tobytes() != _apply(image, seed=8).tobytes()


def test_thread_count_does_not_change_bytes() -> None:
    image = _textured(120, 160)
    before = numba.get_num_threads()
    try:
        results = []
        for threads in (1, numba.config.NUMBA_NUM_THREADS):
            numba.set_num_threads(threads)
            results.append(_apply(image, seed=3, scale=6.0).tobytes())
    finally:
        numba.set_num_threads(before)
    assert results[0] == results[1]


@pytest.mark.parametrize("value", [0.0, 0.37, 1.0, 5.0])
def test_constant_image_stays_constant_plus_highlight(value: float) -> None:
    # Refraction and blur of a constant field are constant; only the Phong highlight adds light.
    image = np.full((80, 112, 3), value, np.float32)
    params = {**BENCH, "radius": 0.9, "strength": 1.7}
    plain = water_droplets(image, **params, rng=np.random.default_rng(2), specular=0.0, rim=0.0)
    np.testing.assert_allclose(plain, value, rtol=1e-6, atol=1e-7)
    lit = water_droplets(image, **params, rng=np.random.default_rng(2))
    field = droplet_field(image.shape[:2], params["scale"], params["radius"], params["strength"], np.random.default_rng(2))
    assert field.highlight.max() > 0.5, "some highlight should be near its peak"
    through = 1.0 - field.alpha * RIM_DARKENING * (1.0 - field.transmission)  # Fresnel-dark rims, nothing lost outside drops
    assert through.min() < 0.97 and np.all(through[field.alpha == 0] == 1.0)
    expected = value * through[..., None] + SPECULAR_INTENSITY * field.highlight[..., None]
    np.testing.assert_allclose(lit, np.broadcast_to(expected, image.shape), rtol=1e-5, atol=1e-6)


def test_refraction_flips_and_minifies() -> None:
    # A drop of radius r shows the scene at c − (strength·F/r − 1)(p − c) (F = the longer side, 96 px; r ≤ 21 px):
    # over a horizontal ramp the ramp inside a drop runs backwards (flipped), steeper than outside
    # (minified), exactly as the remap coordinates say. Blur, highlight and rim loss off.
    y, x = np.mgrid[0:64, 0:96].astype(np.float32)
    image = np.repeat((x / 64.0)[..., None], 3, axis=-1)
    field = droplet_field((64, 96), 1.5, 1.0, 0.4, np.random.default_rng(0))
    out = water_droplets(image, 1.5, 1.0, 0.4, 0.0, 1, np.random.default_rng(0), specular=0.0, rim=0.0)[..., 0]
    core = field.alpha == 1.0
    pairs = core[:, 1:] & core[:, :-1] & (np.abs(np.diff(field.height, axis=1)) < 2.0)
    # the square each pixel averages (its spread, where the drop minifies) stays inside the frame
    lo, hi = field.map_x - 0.5 * np.maximum(field.spread, 1.0), field.map_x + 0.5 * np.maximum(field.spread, 1.0)
    pairs &= (lo[:, 1:] > 0) & (hi[:, :-1] < 95) & (hi[:, 1:] < 95) & (lo[:, :-1] > 0)
    steps = np.diff(field.map_x, axis=1)  # source px per image px: 1 − strength·F/r, constant across one drop
    inside = pairs[:, 1:] & pairs[:, :-1] & (np.abs(np.diff(steps, axis=1)) < 1e-3)  # two steps alike: not a drop's edge
    step = steps[:, 1:][inside]
    assert inside.sum() > 200 and np.all(step < 0.0) and np.median(step) < -1.0, "every drop flips, most minify"
    # a magnifying pixel samples the ramp bilinearly (exact); a minifying one averages its square of the
    # pixel staircase, which follows the ramp once the square spans a few pixels (not near 1 px)
    clear = inside & ((field.spread[:, 1:-1] <= 1.0) | (field.spread[:, 1:-1] >= 4.0))
    assert clear.sum() > 200
    np.testing.assert_allclose(np.diff(out, axis=1)[:, 1:][clear] * 64.0, steps[:, 1:][clear], atol=0.05)
    assert refraction_reach((64, 96), 0.4) == pytest.approx(0.4 * 96)
    plain = water_droplets(image, 1.5, 1.0, 0.0, 0.0, 1, np.random.default_rng(0), specular=0.0, rim=0.0)
    np.testing.assert_allclose(plain, image, atol=1e-6)  # strength 0: the scene behind, undeviated


def _refracted_background(image: np.ndarray, params: dict, seed: int) -> tuple[object, np.ndarray]:
    """The drop field and what the scene behind carries through it, lossless: ``(1 − α) I + α blur(refracted(I))``."""
    field = droplet_field(image.shape[:2], params["scale"], params["radius"], params["strength"], np.random.default_rng(seed))
    seen = refracted_view(image, field)
    k, sigma = params["blur_kernel"], params["blur_sigma"]
    if k > 1 and sigma > 0:
        seen = cv2.GaussianBlur(seen, (k, k), sigma, borderType=cv2.BORDER_REFLECT)
    alpha = field.alpha[..., None]
    return field, (1.0 - alpha) * image + alpha * seen


@pytest.mark.parametrize("preset", ["bench", "1", "3", "5"])
def test_drops_over_black_stay_dark_but_their_highlight(preset: str) -> None:
    params = SPEC.sample_params(preset, np.random.default_rng(5))
    out = water_droplets(np.zeros((72, 128, 3), np.float32), **params, rng=np.random.default_rng(5))
    field = droplet_field((72, 128), params["scale"], params["radius"], params["strength"], np.random.default_rng(5))
    lit = SPECULAR_INTENSITY * field.highlight
    assert np.all(out[lit == 0.0] == 0.0) and (field.alpha > 0).mean() > 0.02
    np.testing.assert_allclose(out, np.repeat(lit[..., None], 3, axis=-1), atol=1e-7)  # the highlight is all the light


@pytest.mark.parametrize("preset", ["bench", "1", "3", "5"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_drop_light_is_the_refracted_background(preset: str, seed: int) -> None:
    # Outside the highlights a drop carries the light of the refracted background it shows, less
    # the Fresnel loss of its surface (98.3 % averaged over a drop): within 2 %, and never more.
    image = _textured()
    params = SPEC.sample_params(preset, np.random.default_rng(seed))
    out = water_droplets(image, **params, rng=np.random.default_rng(seed))
    field, behind = _refracted_background(image, params, seed)
    unlit = (field.alpha > 0) & (SPECULAR_INTENSITY * field.highlight < 1e-4)
    ratio = out[unlit].sum() / behind[unlit].sum()
    assert 0.98 <= ratio <= 1.0, ratio
    gain = out - behind - SPECULAR_INTENSITY * field.highlight[..., None]
    assert gain.max() <= 1e-5 * float(behind.max()) + 1e-7  # no pixel gains light but its highlight
    lossless = water_droplets(image, **params, rng=np.random.default_rng(seed), specular=0.0, rim=0.0)
    np.testing.assert_allclose(lossless, behind, rtol=1e-5, atol=1e-6)


def test_fresnel_ratio_limits() -> None:
    assert fresnel_ratio(1.0, 1.333) == pytest.approx(1.0)
    assert fresnel_ratio(0.0, 1.333) == pytest.approx(0.0, abs=1e-12)
    assert fresnel_ratio(0.5, 1.0) == pytest.approx(1.0)  # no interface, no loss
    cos = np.linspace(0.0, 1.0, 101)
    assert np.all(np.diff(fresnel_ratio(cos, 1.333)) > 0)  # darker towards grazing incidence


@pytest.mark.parametrize(
    "changes",
    [
        {"scale": 0.0},
        {"scale": 100.0},
        {"scale": 0.01, "strength": 5.0},
        {"radius": 1.0, "strength": 5.0},
        {"strength": 0.0},
        {"blur_kernel": 1},
        {"blur_kernel": 51, "blur_sigma": 20.0},
        {"blur_kernel": 51, "blur_sigma": 0.01},
        {"blur_sigma": 0.0},
    ],
)
@pytest.mark.parametrize("fill", [None, 0.0, 1e30])
def test_extremes_finite_shape_dtype(changes: dict[str, float], fill: float | None) -> None:
    image = _textured(48, 64) if fill is None else np.full((48, 64, 3), fill, np.float32)
    out = _apply(image, seed=1, **changes)
    assert out.dtype == np.float32 and out.shape == image.shape and np.isfinite(out).all()
    encoded = _encode(out)
    assert encoded.min() >= 0 and encoded.max() <= 255


def test_hdr_survives_and_tiny_images() -> None:
    image = np.full((40, 40, 3), 50.0, np.float32)
    out = water_droplets(image, 2.0, 1.0, 0.5, 2.0, 9, np.random.default_rng(0), specular=0.0, rim=0.0)
    np.testing.assert_allclose(out, 50.0, rtol=1e-6)  # no clipping of real light above 1
    for shape in ((1, 1, 3), (1, 7, 3), (5, 1, 3)):
        tiny = _apply(np.full(shape, 0.5, np.float32), scale=100.0, radius=1.0)
        assert tiny.shape == shape and np.isfinite(tiny).all()


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_input_rejected(bad: float) -> None:
    image = _textured(16, 16)
    image[3, 5, 1] = bad
    with pytest.raises(InvalidDataError, match=r"1 non-finite value\(s\).*\(3, 5, 1\)"):
        _apply(image)


def test_distance_rises_with_severity() -> None:
    image = _textured(120, 160)
    clean = _encode(image)
    distances = []
    for level in ("1", "2", "3", "4", "5"):
        per_seed = []
        for seed in range(4):
            params = SPEC.sample_params(level, np.random.default_rng(seed))
            per_seed.append(np.mean(np.abs(_encode(SPEC.apply(image, {}, params, np.random.default_rng(seed))) - clean)))
        distances.append(float(np.mean(per_seed)))
    assert all(a < b for a, b in zip(distances, distances[1:])), distances


@pytest.mark.parametrize(
    ("changes", "pattern"),
    [
        ({"blur_kernel": 8}, r"'blur_kernel' = 8 must be odd.*use 7 or 9"),
        ({"blur_kernel": 52}, r"outside its hard limits \[1, 51\]"),
        ({"blur_kernel": 7.5}, "must be an integer"),
        ({"scale": -1.0}, r"outside its hard limits \[0, 100\]"),
        ({"radius": 1.5}, r"outside its hard limits \[0, 1\]"),
        ({"strength": 6.0}, r"outside its hard limits \[0, 5\]"),
        ({"blur_sigma": 21.0}, r"outside its hard limits \[0, 20\]"),
        ({"blur_sigma": float("nan")}, "must be a finite number"),
        ({"radiu": 0.5}, "Did you mean 'radius'"),
    ],
)
def test_bad_params_rejected(changes: dict[str, float], pattern: str) -> None:
    with pytest.raises(ParameterError, match=pattern):
        _apply(_textured(16, 16), **changes)


def test_extreme_aspect_ratio_at_high_scale_rejected() -> None:
    with pytest.raises(ParameterError, match="lower scale or use a less elongated image"):
        _apply(np.zeros((1, 30000, 3), np.float32), scale=100.0)
    with pytest.raises(ParameterError, match="specular must be a finite number >= 0"):
        water_droplets(_textured(16, 16), **BENCH, rng=np.random.default_rng(0), specular=-1.0)


def test_missing_param_and_bad_inputs_rejected() -> None:
    with pytest.raises(ParameterError, match=r"missing parameter\(s\) \['blur_kernel'\]"):
        SPEC.apply(_textured(16, 16), {}, {k: v for k, v in BENCH.items() if k != "blur_kernel"}, np.random.default_rng(0))
    with pytest.raises(InvalidDataError, match="float32"):
        _apply(_textured(16, 16).astype(np.float64))
    with pytest.raises(InvalidDataError, match="numpy.random.Generator"):
        SPEC.apply(_textured(16, 16), {}, BENCH, 0)  # type: ignore[arg-type]


def test_input_not_modified() -> None:
    image = _textured()
    before = image.copy()
    _apply(image, seed=2, strength=3.0)
    assert image.tobytes() == before.tobytes()
    strided = _textured(96, 256)[:, ::2]  # non-contiguous view
    assert _apply(strided).shape == strided.shape


def test_a_minifying_drop_shows_the_mean_of_what_it_spans() -> None:
    """A drop that minifies k× shows, at each pixel, the mean of the k × k source pixels it spans (a lens
    integrates; a point sample would alias). Over a 1-px checkerboard every pixel whose square spans
    ≥ 4 × 4 source pixels reads within 0.1 of the board's mean; a point sample reads 0 or 1."""
    y, x = np.mgrid[0:72, 0:128]
    board = np.repeat(((x + y) % 2).astype(np.float32)[..., None], 3, axis=-1)
    field = droplet_field(board.shape[:2], 3.0, 0.5, 0.4, np.random.default_rng(3))
    seen = refracted_view(board, field)
    wide = field.spread >= 4.0
    assert wide.sum() > 100
    assert np.abs(seen[wide] - 0.5).max() < 0.1
    point = cv2.remap(board, field.map_x, field.map_y, cv2.INTER_NEAREST, borderMode=cv2.BORDER_REFLECT)
    assert np.abs(point[wide] - 0.5).min() > 0.4
    # over a constant scene the mean is the constant (exact, edges and reflections included)
    flat = refracted_view(np.full_like(board, 0.3), field)
    np.testing.assert_allclose(flat, 0.3, rtol=1e-5)


def test_the_summed_area_table_is_numpys_cumulative_sums_bit_for_bit() -> None:
    """The minifying drops' summed-area table (rows in parallel, then each row plus the one above) is
    ``cumsum(cumsum(padded, columns), rows)`` bit for bit, with a zero first row and column, and the
    channels' extremes it reads in the same pass are the frame's."""
    from spacedg.plugins.degradations.common import reflect_index
    from spacedg.plugins.degradations.water_droplets import _padded_sat
    from spacedg.render import kernel_cache

    rng = np.random.default_rng(46)
    for h, w, pad in [(1, 1, 1), (7, 5, 3), (48, 64, 17), (30, 20, 45)]:
        rgb = (rng.random((h, w, 3)) * rng.choice([1.0, 1e6]) - 0.2).astype(np.float32)
        rows, cols = reflect_index(h, pad), reflect_index(w, pad)
        lo, hi = np.empty(3), np.empty(3)
        sat = _padded_sat(kernel_cache.read_only(rgb), rows, cols, lo, hi)  # read-only, as the drops pass it: one signature
        expected = np.zeros((rows.size + 1, cols.size + 1, 3))
        expected[1:, 1:] = np.cumsum(np.cumsum(rgb[rows][:, cols].astype(np.float64), axis=1), axis=0)
        assert sat.tobytes() == expected.tobytes()
        assert lo.tolist() == rgb.reshape(-1, 3).min(axis=0).tolist() and hi.tolist() == rgb.reshape(-1, 3).max(axis=0).tolist()


def _field_by_pixel(shape: tuple[int, int], drops: tuple[np.ndarray, ...], reach: float) -> dict[str, np.ndarray]:
    """The drop field pixel by pixel in numpy float64, as the module docstring states it: each pixel
    ``(j + ½, i + ½)`` looks at its own cell of every layer (``min(⌊x / cell⌋, columns − 1)``), the
    highest drop holding it (``d² < r²``; a tie keeps the earlier layer) gives its values."""
    from spacedg.plugins.degradations.water_droplets import EDGE_WIDTH, LIGHT_DIRECTION, SHININESS_LOG2, WATER_INDEX

    cells, n_cols, n_rows, offsets, centre_x, centre_y, drop_r = drops
    height, width = shape
    names = ("alpha", "height", "highlight", "map_x", "map_y", "transmission", "spread")
    out = {name: np.empty(shape, np.float32) for name in names}
    lx, ly, lz = LIGHT_DIRECTION
    for i in range(height):
        y = i + 0.5
        for j in range(width):
            x = j + 0.5
            best = None
            for layer in range(cells.shape[0]):
                row = min(int(y * (1.0 / cells[layer, 1])), n_rows[layer] - 1)
                k = offsets[layer] + row * n_cols[layer] + min(int(x * (1.0 / cells[layer, 0])), n_cols[layer] - 1)
                r, dx, dy = drop_r[k], x - centre_x[k], y - centre_y[k]
                d2 = dx * dx + dy * dy
                if d2 < r * r and (best is None or np.sqrt(r * r - d2) > best[0]):
                    best = (np.sqrt(r * r - d2), dx, dy, r)
            if best is None:
                values = (0.0, 0.0, 0.0, j, i, 1.0, 0.0)
            else:
                h, dx, dy, r = best
                nx, ny, nz = dx / r, dy / r, h / r
                t = min((1.0 - np.sqrt(nx * nx + ny * ny)) / EDGE_WIDTH, 1.0)
                a = t * t * (3.0 - 2.0 * t)
                spec = max(2.0 * (nx * lx + ny * ly + nz * lz) * nz - lz, 0.0)
                for _ in range(SHININESS_LOG2):
                    spec *= spec
                values = (a, h, a * spec, x - reach * nx - 0.5, y - reach * ny - 0.5, fresnel_ratio(nz, WATER_INDEX), abs(1.0 - reach / r))
            for name, value in zip(names, values):
                out[name][i, j] = value
    return out


@pytest.mark.parametrize("seed", [4101, 4102, 4103, 4104])
def test_the_field_drawn_drop_by_drop_is_the_pixel_by_pixel_rule(seed: int) -> None:
    """The compiled field walks each row drop by drop (the pixels of a cell within a pixel of its disk); it
    gives the values of the pixel-by-pixel rule bit for bit: largest drops (radius 1, touching their
    cells' sides), overlapping layers, cells narrower than a few pixels, a 3:2-snapped non-exact aspect."""
    from spacedg.plugins.degradations.water_droplets import _draw_drops

    rng = np.random.default_rng(seed)
    shape = [(37, 53), (40, 60), (29, 31), (12, 90)][seed % 4]
    scale = float(rng.choice([1.0, 2.7, 6.0, 11.0]))
    radius = float(rng.choice([1.0, float(rng.uniform(0.2, 1.0))]))
    strength = float(rng.uniform(0.0, 2.0))
    field = droplet_field(shape, scale, radius, strength, np.random.default_rng(seed))
    expected = _field_by_pixel(shape, _draw_drops(shape, scale, radius, np.random.default_rng(seed)), refraction_reach(shape, strength))
    assert (field.alpha > 0).any()
    for name, values in expected.items():
        assert getattr(field, name).tobytes() == values.tobytes(), name


@pytest.mark.parametrize("radius, centre, row", [
    (1e20, 0.0, 0.0), (1e20, -3e19, -3e19), (1e160, 5.0, 5.0), (3.0, 1e30, 1e30), (3.0, 1e30, 0.5), (3.0, -1e30, 1.5),
    (2.0, 1e19, 0.5), (0.7, 2.5, 2.5),
])
def test_the_field_kernel_walks_huge_and_far_drops_safely(radius: float, centre: float, row: float) -> None:
    """A drop whose chord lies beyond the int64 range, whose radius squared overflows, or whose centre is far
    along the row it crosses (``row``: its centre's y): the kernel clamps the chord's pixels as floats (an
    int64 overflow there read far out of bounds) and gives the pixel-by-pixel rule's values."""
    from spacedg.plugins.degradations.water_droplets import (
        EDGE_WIDTH, LIGHT_DIRECTION, SHININESS_LOG2, WATER_INDEX, DropletField, _field_kernel,
    )

    shape = (2, 4)
    cell = max(10.0 * radius, 10.0)
    drops = (np.array([[cell, cell]]), np.array([1]), np.array([1]), np.array([0]), np.array([centre]), np.array([row]), np.array([radius]))
    field = DropletField(*(np.full(shape, np.nan, np.float32) for _ in range(7)))
    with np.errstate(all="ignore"):
        _field_kernel(*shape, *drops, 2.0, WATER_INDEX, np.asarray(LIGHT_DIRECTION, np.float64), SHININESS_LOG2, EDGE_WIDTH,
                      field.alpha, field.height, field.highlight, field.map_x, field.map_y, field.transmission, field.spread)
        expected = _field_by_pixel(shape, drops, 2.0)
    for name, values in expected.items():
        assert getattr(field, name).tobytes() == values.tobytes(), name
