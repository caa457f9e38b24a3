"""Motion blur's keyframe path (:mod:`spacedg.render.motion_warp`): determinism, accuracy
against many sub-steps, and a continuous smear (no stroboscopic copies)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.render_helpers import camera, random_gaussians
from spacedg.render import MotionBlur, render
from spacedg.render.camera import look_at
from spacedg.render.colour import linear_to_srgb
from spacedg.render.gaussians import Gaussians
from spacedg.render.motion import MotionJob, render_motion_keyframes, render_motion_substeps


def psnr(image: np.ndarray, reference: np.ndarray) -> float:
    a = np.clip(linear_to_srgb(image.astype(np.float64)), 0, 1)
    b = np.clip(linear_to_srgb(reference.astype(np.float64)), 0, 1)
    return 10 * math.log10(1 / max(float(np.mean((a - b) ** 2)), 1e-30))


def textured_wall(seed: int = 0) -> Gaussians:
    """A dense opaque wall of random colours 3 m away, with a nearer box in front (parallax)."""
    rng = np.random.default_rng(seed)
    grid = np.stack(np.meshgrid(np.arange(-3.0, 3.0, 0.06), np.arange(-2.4, 2.4, 0.06)), -1).reshape(-1, 2)
    grid = grid + rng.uniform(-0.03, 0.03, grid.shape)  # irregular: a regular grid near the pixel pitch aliases
    wall = np.column_stack([grid, rng.uniform(2.8, 3.2, len(grid))])  # no depth ties (their order flips with the pose)
    box = np.column_stack([rng.uniform(-0.3, 0.3, 600), rng.uniform(-0.3, 0.3, 600), rng.uniform(1.5, 1.6, 600)])
    means = np.concatenate([wall, box])
    n = len(means)
    scales = np.concatenate([np.tile([0.05, 0.05, 1e-3], (len(wall), 1)), np.full((600, 3), 0.03)])
    colours = rng.uniform(0.0, 1.0, (n, 1, 3))
    return Gaussians(means, np.tile([1.0, 0, 0, 0], (n, 1)), scales, np.full(n, 0.95), colours)


MOTION = dict(translation=(0.3, 0.05, 0.0), rotation=(0.0, 0.1, 0.02))


def test_keyframe_path_is_deterministic_and_the_default_fast_path() -> None:
    g = random_gaussians(800, np.random.default_rng(1))
    cam = camera(64, 48)
    blur = MotionBlur(**MOTION, fast=True)
    a = render(g, cam, outputs="all", motion=blur)
    b = render(g, cam, outputs="all", motion=blur)
    assert "keyframes" in a.stats
    for name in ("rgb", "alpha", "depth", "median_depth", "instance_ids"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    sharp = render(g, cam, outputs="all")  # mid-exposure labels stay the ground truth
    np.testing.assert_array_equal(a.instance_ids, sharp.instance_ids)
    np.testing.assert_array_equal(a.median_depth, sharp.median_depth)
    assert np.isfinite(a.depth).all() and np.isfinite(a.rgb).all()


def test_keyframe_path_matches_many_sub_steps_on_a_textured_scene() -> None:
    """Two keyframes: ≥ 45 dB against 96 sub-steps on a tiny wall-and-box scene with parallax."""
    g = textured_wall()
    cam = camera(80, 60, focal=70.0)
    blur = MotionBlur(**MOTION, sub_steps=96)
    reference = render(g, cam, motion=blur)
    fast = render_motion_keyframes(MotionJob(g, cam, blur, frozenset({"rgb"})), keyframes=2)
    assert psnr(fast.rgb, reference.rgb) > 45.0
    # the sharp image is far from both: the test measures the blur, not a still frame
    assert psnr(render(g, cam).rgb, reference.rgb) < 30.0


def test_a_moving_point_leaves_a_continuous_smear_not_copies() -> None:
    """A small bright Gaussian swept 60 px sideways: the keyframe path's streak has no gaps,
    where 4 sub-steps leave 4 separate copies (the ghosting the keyframe path removes)."""
    g = Gaussians([[0.0, 0.0, 2.0]], [[1.0, 0, 0, 0]], [[0.003, 0.003, 0.003]], [0.9], np.full((1, 1, 3), 1.0))
    cam = camera(96, 32, focal=100.0)
    blur = MotionBlur(translation=(1.2, 0.0, 0.0), sub_steps=4, fast=True)  # 100 px/m · 1.2 m / 2 m = 60 px
    smear = render_motion_keyframes(MotionJob(g, cam, blur, frozenset({"rgb"})), keyframes=1)
    strobe = render_motion_substeps(MotionJob(g, cam, blur, frozenset({"rgb"})), fast=False)
    row_smear = smear.alpha[16, 25:71]  # the interior of the 48 → −12 px path through centre 48
    row_strobe = strobe.alpha[16, 25:71]
    assert row_smear.min() > 0.6 * row_smear.mean()  # flat streak
    assert row_strobe.min() < 0.05 * row_strobe.max()  # gaps between copies
    # same energy: the smear redistributes the point's alpha along its path
    np.testing.assert_allclose(smear.alpha.sum(), strobe.alpha.sum(), rtol=0.05)


def _bilinear(src: np.ndarray, x: float, y: float) -> np.ndarray:
    """Reference bilinear read at array-index coordinates (clamped like the kernels)."""
    hc, wc = src.shape[:2]
    x = min(max(x, 0.0), wc - 1.001)
    y = min(max(y, 0.0), hc - 1.001)
    x0, y0 = int(x), int(y)
    ax, ay = x - x0, y - y0
    return ((1 - ax) * (1 - ay) * src[y0, x0] + ax * (1 - ay) * src[y0, x0 + 1]
            + (1 - ax) * ay * src[y0 + 1, x0] + ax * ay * src[y0 + 1, x0 + 1])


def test_gather_and_doubling_match_a_python_path_average() -> None:
    """The compiled kernels against a plain loop: the mean of ``2^P · M`` bilinear reads along
    each pixel's path (a parabola through the pixel); pixels whose path crosses only empty
    canvas stay 0."""
    from spacedg.render import motion_warp

    rng = np.random.default_rng(5)
    hc, wc, margin = 30, 40, 5
    src = np.zeros((hc, wc, 4), np.float32)
    src[8:20, 10:30] = rng.uniform(0.1, 1.0, (12, 20, 4)).astype(np.float32)  # an object on empty canvas
    field = np.zeros((hc, wc, 4), np.float32)
    field[..., 0] = rng.uniform(-2, 2, (hc, wc))
    field[..., 1] = rng.uniform(-2, 2, (hc, wc))
    field[..., 2] = 9.0
    field[..., 3] = 3.0
    for passes in (0, 1):
        current = src.copy()
        for j in range(passes):
            out = np.empty_like(current)
            motion_warp.doubling_pass(current, field, np.float32(0.25 / 2**j), motion_warp.occupancy(current), out)
            current = out
        acc = np.zeros((hc - 2 * margin, wc - 2 * margin, 4), np.float32)
        motion_warp.gather(current, field, margin, 1.0 / 2**passes, 1.0, motion_warp.occupancy(current), acc)
        for i, j in [(0, 0), (5, 7), (10, 20), (19, 29), (12, 3)]:
            ci, cj = i + margin, j + margin
            c, d = field[ci, cj, :2].astype(np.float64), field[ci, cj, 2:].astype(np.float64)
            scale = 1.0 / 2**passes
            count = int(np.ceil(scale * np.hypot(*d)))
            times = 0.5 - 0.5 * scale + (np.arange(count) + 0.5) * scale / count
            # the parabola from A = P + c − d/2 through P (t = ½) to B = P + c + d/2
            points = [(cj + c[0] - d[0] / 2 + t * d[0] - 4 * t * (1 - t) * c[0],
                       ci + c[1] - d[1] / 2 + t * d[1] - 4 * t * (1 - t) * c[1]) for t in times]
            reference = src
            if passes:  # one pass, in plain Python: each texel the mean of two reads ±¼ of the segment apart
                e = 0.25 * field[0, 0, 2:]
                reference = np.array([[0.5 * (_bilinear(src, x - e[0], y - e[1]) + _bilinear(src, x + e[0], y + e[1]))
                                       for x in range(wc)] for y in range(hc)], np.float32)
            expected = np.mean([_bilinear(reference, x, y) for x, y in points], axis=0)
            np.testing.assert_allclose(acc[i, j], expected, atol=2e-5, err_msg=f"pixel {(i, j)}, {passes} passes")
        assert np.all(acc[0, 0] == 0.0)  # its segment stays over empty canvas
        assert acc.max() > 0.05


@pytest.mark.parametrize("seed", range(14))
def test_passes_over_their_regions_give_the_whole_canvas_bytes(seed: int) -> None:
    """Doubling passes restricted to :func:`~spacedg.render.motion_warp.pass_regions` (what a covered canvas
    takes) give the gather the bytes of passes over the whole canvas: each pass writes into a buffer of NaN, so
    a pixel it leaves out and a later pass or the gather reads would show. Fields with long paths, large centre
    offsets (the parabola's bend), one axis only, paths that leave the canvas, NaN and infinite values
    (sanitised), margins of 0 to 40 px, one to three passes, canvases of a few pixels, and (the last seeds) a
    path of thousands of pixels walked every 0.02–0.03 px, where the float32 sums of the sample times drift by
    pixels."""
    from spacedg.render import motion_warp

    rng = np.random.default_rng(2000 + seed)
    height, width = int(rng.integers(2, 40)), int(rng.integers(2, 50))
    margin = int(rng.integers(0, 41))
    spacing = 1.0
    if seed >= 12:  # a uniform path of 3000 px walked every 0.02-0.03 px (one pass): the times' sums drift
        height, width, margin, spacing = 2, 2, 760, (0.02, 0.03)[seed % 2]
    hc, wc = height + 2 * margin, width + 2 * margin
    src = rng.uniform(0.05, 1.0, (hc, wc, 4)).astype(np.float32)
    field = np.empty((hc, wc, 4), np.float32)
    reach = float(rng.choice([2.0, 20.0, 120.0]))
    field[..., :2] = rng.uniform(-1.0, 1.0, (hc, wc, 2)) * rng.choice([0.1, 3.0, 25.0])
    field[..., 2:] = rng.uniform(-1.0, 1.0, (hc, wc, 2)) * reach
    if seed % 3 == 1:
        field[..., 3] = 0.0  # a sideways pan
    if seed % 4 == 2 and seed < 12:
        field.reshape(-1)[rng.integers(0, field.size, 5)] = np.array([np.nan, np.inf, -np.inf, np.nan, np.inf], np.float32)
    if seed >= 12:
        field[...] = (0.0, 0.0, 3000.0, 0.0)
    extents = np.empty(4, np.float32)
    motion_warp.sanitise_field(field, np.float32(2 * (hc + wc)), extents)
    assert np.array_equal(extents, np.abs(field).reshape(-1, 4).max(axis=0))
    for passes in (1,) if seed >= 12 else (1, 2, 3):
        results = []
        for regions in (None, motion_warp.pass_regions((hc, wc), margin, (height, width), passes, extents, spacing)):
            current, spare = src.copy(), np.empty_like(src)
            for j in range(passes):
                spare.fill(np.nan)
                motion_warp.doubling_pass(current, field, np.float32(0.25 / 2**j), motion_warp.FULL, spare, None if regions is None else regions[j])
                current, spare = spare, current
            acc = np.zeros((height, width, 4), np.float32)
            motion_warp.gather(current, field, margin, 1.0 / 2**passes, spacing, motion_warp.FULL, acc)
            results.append(acc)
        assert np.isfinite(results[1]).all() and results[1].tobytes() == results[0].tobytes(), f"{passes} passes"
        assert all(r0 <= r1 and c0 <= c1 for r0, r1, c0, c1 in regions)
    with pytest.raises(ValueError, match="region"):
        motion_warp.doubling_pass(src, field, np.float32(0.25), motion_warp.FULL, np.empty_like(src), (0, hc + 1, 0, wc))
    line = np.ones((1, 5, 4), np.float32)  # one row of texels: no 2 × 2 block to read
    with pytest.raises(ValueError, match="at least 2 × 2"):
        motion_warp.doubling_pass(line, np.zeros((1, 5, 4), np.float32), np.float32(0.25), motion_warp.FULL, np.empty_like(line))
    with pytest.raises(ValueError, match="at least 2 × 2"):
        motion_warp.gather(line, np.zeros((1, 5, 4), np.float32), 0, 1.0, 1.0, motion_warp.FULL, np.zeros((1, 5, 4), np.float32))


def test_a_path_longer_than_a_chunk_is_walked_in_one_piece() -> None:
    """:func:`~spacedg.render.motion_warp.gather` places a path's samples in chunks of
    ``_PATH_CHUNK``: paths of one chunk less one sample, exactly one, one more, exactly two, two
    and one more, and of up to 4 chunks average the same reads as a plain loop over all of them,
    with and without the fifth (depth) channel."""
    from spacedg.render import motion_warp

    rng = np.random.default_rng(8)
    hc, wc, margin = 40, 260, 4
    for channels in (4, 5):
        src = rng.uniform(0.0, 1.0, (hc, wc, channels)).astype(np.float32)
        field = np.zeros((hc, wc, 4), np.float32)
        field[..., 0] = rng.uniform(-3, 3, (hc, wc))
        field[..., 1] = rng.uniform(-1, 1, (hc, wc))
        chunk = motion_warp._PATH_CHUNK
        edges = np.array([chunk - 1, chunk, chunk + 1, 2 * chunk, 2 * chunk + 1], np.float32) - np.float32(0.5)
        field[..., 2] = np.linspace(float(chunk), 250.0, wc, dtype=np.float32)[None, :]
        field[..., 2][:, margin : margin + edges.size] = edges  # counts ⌈d⌉ = 63, 64, 65, 128, 129 (d_v = 0)
        field[..., 3] = 5.0
        field[..., 3][:, margin : margin + edges.size] = 0.0
        acc = np.zeros((hc - 2 * margin, wc - 2 * margin, channels), np.float32)
        motion_warp.gather(src, field, margin, 1.0, 1.0, motion_warp.FULL, acc)
        for i, j in [(3, 0), (5, 1), (7, 2), (9, 3), (11, 4), (10, 60), (20, 130), (31, 251)]:
            ci, cj = i + margin, j + margin
            c, d = field[ci, cj, :2].astype(np.float64), field[ci, cj, 2:].astype(np.float64)
            count = int(np.ceil(np.hypot(*d)))
            assert count >= chunk - 1
            times = (np.arange(count) + 0.5) / count
            points = [(cj + c[0] - d[0] / 2 + t * d[0] - 4 * t * (1 - t) * c[0],
                       ci + c[1] - d[1] / 2 + t * d[1] - 4 * t * (1 - t) * c[1]) for t in times]
            expected = np.mean([_bilinear(src, x, y) for x, y in points], axis=0)
            np.testing.assert_allclose(acc[i, j], expected, atol=3e-5, err_msg=f"pixel {(i, j)}, {channels} channels")


def test_every_way_of_walking_a_path_gives_the_same_bits() -> None:
    """:func:`~spacedg.render.motion_warp.gather` walks a colour-only path of at most ``_FUSED_MAX`` samples in
    one loop, a longer one in chunks summed in a register, and a path with the depth channel in chunks summed
    in memory: the colour sums are the same float32 bits whichever it takes (paths of 1 to ~60 samples, two
    walked lengths), and the short ones average the reads a plain loop makes."""
    from spacedg.render import motion_warp

    rng = np.random.default_rng(21)
    hc, wc, margin = 48, 64, 6
    src = rng.uniform(0.0, 1.0, (hc, wc, 5)).astype(np.float32)
    field = np.zeros((hc, wc, 4), np.float32)
    field[..., 0] = rng.uniform(-1.5, 1.5, (hc, wc))
    field[..., 1] = rng.uniform(-1.5, 1.5, (hc, wc))
    field[..., 2] = rng.uniform(0.0, 60.0, (hc, wc))
    field[..., 3] = rng.uniform(-3.0, 3.0, (hc, wc))
    colour = np.ascontiguousarray(src[..., :4])
    walked = {}
    for length in (1.0, 0.25):
        four = np.zeros((hc - 2 * margin, wc - 2 * margin, 4), np.float32)
        five = np.zeros((hc - 2 * margin, wc - 2 * margin, 5), np.float32)
        motion_warp.gather(colour, field, margin, length, 1.0, motion_warp.FULL, four)
        motion_warp.gather(src, field, margin, length, 1.0, motion_warp.FULL, five)
        assert four.tobytes() == np.ascontiguousarray(five[..., :4]).tobytes(), f"length {length}"
        walked[length] = four
    counts = np.ceil(np.hypot(field[margin:-margin, margin:-margin, 2], field[margin:-margin, margin:-margin, 3]))
    assert (counts <= motion_warp._FUSED_MAX).sum() > 100 and (counts > 2 * motion_warp._FUSED_MAX).sum() > 100  # both walks
    for i, j in np.argwhere(counts <= motion_warp._FUSED_MAX)[:6]:
        ci, cj = i + margin, j + margin
        c, d = field[ci, cj, :2].astype(np.float64), field[ci, cj, 2:].astype(np.float64)
        count = max(1, int(np.ceil(np.hypot(*d))))
        times = (np.arange(count) + 0.5) / count
        points = [(cj + c[0] - d[0] / 2 + t * d[0] - 4 * t * (1 - t) * c[0], ci + c[1] - d[1] / 2 + t * d[1] - 4 * t * (1 - t) * c[1]) for t in times]
        expected = np.mean([_bilinear(colour, x, y) for x, y in points], axis=0)
        np.testing.assert_allclose(walked[1.0][i, j], expected, atol=2e-5, err_msg=f"pixel {(i, j)}")


def test_degenerate_inputs_stay_in_range() -> None:
    """Found by the long fuzz run: a 1 × 1 view and kilometres of motion used to read outside the
    keyframe canvas (alpha 1.8e25, rgb -2.3e13); paths are now bounded and tiny views take the
    sub-step path."""
    import numpy as np

    from tests.fuzz_cases import FAMILIES, case_render

    for seed in (2000769, 2001442, 2001359, 2002319):
        run = case_render(np.random.default_rng([FAMILIES.index("render"), seed]), None, None)  # type: ignore[arg-type]
        run()  # check_frame: finite, alpha in [0, 1], rgb >= 0


def test_keyframe_count_follows_contrast_across_moving_depth_edges() -> None:
    """The count comes from the predicted error (:mod:`spacedg.render.motion_error`): a sideways
    move past the box's depth edges asks for more keyframes than a turn with the same path; the
    same scene in one colour, or no motion, for one; the count rises with the measure, is the
    smallest whose prediction meets the target, has one keyframe per ``KEYFRAME_PATH_PX`` of the
    path at least, and is clamped."""
    from spacedg.render.motion_error import KEYFRAME_PATH_PX, MODEL_A, MODEL_B, MODEL_C, TARGET_DB, edge_parallax_contrast, keyframes_for
    from spacedg.render.settings import RasterSettings

    settings = RasterSettings()
    g = textured_wall()
    cam = camera(80, 60, focal=70.0)
    sideways = MotionBlur(translation=(0.6, 0.0, 0.0), rotation=(0.0, 0.0, 0.0))
    turn = MotionBlur(translation=(0.0, 0.0, 0.0), rotation=(0.0, 0.6 / 2.2, 0.0))  # about the same path on the wall
    moving, turning = edge_parallax_contrast(g, cam, sideways, settings), edge_parallax_contrast(g, cam, turn, settings)
    assert moving > 1e6 * turning  # a turn moves every depth alike: no parallax (rounding only)
    assert keyframes_for(moving, 20.0, 8) == 2 and keyframes_for(turning, 20.0, 8) == 1
    grey = Gaussians(g.means, g.quats, g.scales, g.opacities, np.full_like(g.sh, 0.3))  # edges without contrast
    assert edge_parallax_contrast(grey, cam, sideways, settings) < 1e-4 * moving
    still = edge_parallax_contrast(g, cam, MotionBlur(translation=(0.0, 0.0, 0.0), rotation=(0.0, 0.0, 0.0)), settings)
    assert still < 1e-12 and keyframes_for(still, 0.0, 8) == 1  # the pose round trip's rounding only

    def predicted(measure: float, count: int) -> float:
        return MODEL_A - MODEL_B * 10 * math.log10(measure) + MODEL_C * 10 * math.log10(count)

    counts = [keyframes_for(m, 10.0, 8) for m in np.geomspace(1e-5, 1.0, 60)]
    assert counts == sorted(counts) and counts[0] == 1 and counts[-1] == 8
    for measure in np.geomspace(1e-4, 0.1, 25):
        k = keyframes_for(measure, 0.0, 80)
        assert predicted(measure, k) >= TARGET_DB - 1e-9 and (k == 1 or predicted(measure, k - 1) < TARGET_DB)
    assert keyframes_for(0.0, 0.0, 8) == 1 and keyframes_for(math.inf, 0.0, 8) == keyframes_for(math.nan, 0.0, 8) == 8
    assert keyframes_for(1e6, 0.0, 3) == 3 and keyframes_for(1e6, 0.0, 0) == 1
    # at least one keyframe per KEYFRAME_PATH_PX of the longest path, whatever the edges
    assert [keyframes_for(0.0, KEYFRAME_PATH_PX * f, 8) for f in (0.5, 1.0, 1.01, 2.5, 7.99, 100.0)] == [1, 1, 2, 3, 8, 8]
    assert keyframes_for(0.0, math.nan, 8) == keyframes_for(0.0, math.inf, 8) == 8
    assert keyframes_for(1e-2, 3.5 * KEYFRAME_PATH_PX, 8) == max(4, keyframes_for(1e-2, 0.0, 8))
    frame = render_motion_keyframes(MotionJob(g, cam, MotionBlur(**MOTION, fast=True), frozenset({"rgb"})))
    assert frame.stats["edge_measure"] == edge_parallax_contrast(g, cam, MotionBlur(**MOTION, fast=True), settings)
    assert frame.stats["keyframes"] == keyframes_for(frame.stats["edge_measure"], frame.stats["displacement_px"], 8)
    wide = MotionBlur(translation=(1.5, 0.0, 0.0), rotation=(0.0, 0.0, 0.0), fast=True)  # the edges ask for more than the path
    frame = render_motion_keyframes(MotionJob(g, cam, wide, frozenset({"rgb"})))
    assert frame.stats["keyframes"] > keyframes_for(0.0, frame.stats["displacement_px"], 8)


def test_one_doubling_pass_per_doubling_of_the_path() -> None:
    """:func:`~spacedg.render.motion.doubling_passes`: none up to ``DOUBLING_FROM_PX``, then one per
    doubling of the interval's longest path, at most ``DOUBLING_PASSES``; none for a NaN path."""
    from spacedg.render.motion import DOUBLING_FROM_PX, DOUBLING_PASSES, doubling_passes

    factors = (0.0, 0.5, 1.0, 1.01, 1.99, 2.0, 2.01, 3.9, 4.0, 4.01)
    assert [doubling_passes(DOUBLING_FROM_PX * f) for f in factors] == [0, 0, 0, 1, 1, 1, 2, 2, 2, 3]
    assert doubling_passes(1e30) == doubling_passes(math.inf) == DOUBLING_PASSES == 3 and doubling_passes(math.nan) == 0


def test_the_edge_measure_stays_finite_and_bounded_on_degenerate_views() -> None:
    """A 2 × 2 view, an empty scene, a dolly through the wall (surfaces end behind the camera: no
    path there, as in the warp), a thousand kilometres of motion; and the measure is skipped where it cannot
    change the count (no translation, or the path alone asks for the most)."""
    from spacedg.render.motion_error import edge_parallax_contrast, keyframes_for
    from spacedg.render.motion_error_cpu import _apart, _seen
    from spacedg.render.settings import RasterSettings

    settings = RasterSettings()
    g = textured_wall()
    cam = camera(80, 60, focal=70.0)
    forward = np.array([1.0, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, -2.0])  # 2 m ahead of the view's camera
    far_point = _seen(forward, 0.1, 0.0, 3.0)  # the ray (0.1, 0, 1) at 3 m, against at 2.5 m and 1 m
    ahead_of_it = _apart(_seen(forward, 0.1, 0.0, 2.5), far_point, 70.0, 70.0)
    behind_it = _apart(_seen(forward, 0.1, 0.0, 1.0), far_point, 70.0, 70.0)
    assert ahead_of_it == pytest.approx(70.0 * (0.25 / 0.5 - 0.3 / 1.0)) and behind_it == 0.0
    dolly = MotionBlur(translation=(0.05, 0.0, 4.0), rotation=(0.0, 0.0, 0.0))
    through = edge_parallax_contrast(g, cam, dolly, settings)
    assert math.isfinite(through) and 0.0 < through <= 2.0 * (80 + 60)
    assert keyframes_for(through, 0.0, 8) < 8  # gaps of 5e7 px before points behind the camera had no path
    tiny = edge_parallax_contrast(g, camera(2, 2, focal=2.0), MotionBlur(**MOTION), settings)
    assert math.isfinite(tiny) and tiny >= 0.0
    empty = Gaussians(np.zeros((0, 3)), np.zeros((0, 4)), np.zeros((0, 3)), np.zeros(0), np.zeros((0, 1, 3)))
    assert edge_parallax_contrast(empty, cam, MotionBlur(**MOTION), settings) == 0.0
    wild = edge_parallax_contrast(g, cam, MotionBlur(translation=(1e6, 0.0, 0.0), rotation=(0.0, 0.0, 3.0)), settings)
    assert math.isfinite(wild) and 0.0 < wild <= 2.0 * (80 + 60)
    turn = render_motion_keyframes(MotionJob(g, cam, MotionBlur(translation=(0.0, 0.0, 0.0), rotation=(0.0, 0.2, 0.0), fast=True), frozenset({"rgb"})))
    assert "edge_measure" not in turn.stats and turn.stats["keyframes"] == keyframes_for(0.0, turn.stats["displacement_px"], 8)
    far = render_motion_keyframes(MotionJob(g, cam, MotionBlur(translation=(4.0, 0.0, 0.0), rotation=(0.0, 0.0, 0.0), sub_steps=2, fast=True), frozenset({"rgb"})))
    assert far.stats["displacement_px"] > 128.0 and far.stats["keyframes"] == 2 and "edge_measure" not in far.stats


def test_the_compiled_edge_measure_is_the_numpy_formula_bit_for_bit() -> None:
    """:func:`~spacedg.render.motion_error.edge_parallax_contrast` (its per-pair products compiled,
    :mod:`spacedg.render.motion_error_cpu`) equals the numpy formula it replaced, to the last bit: each pixel's
    ray at its own depth and at its right (lower) neighbour's seen from both ends of the exposure, the gap
    capped at the warp's reach, times the mean squared sRGB difference, summed in numpy; on a wall and box,
    at odd sizes, with dollies through the wall (points behind an end) and wild motions."""
    from spacedg.render.camera import exposure_poses
    from spacedg.render.composite import composite_view
    from spacedg.render.motion_error import COARSE_FACTOR, edge_parallax_contrast
    from spacedg.render.motion_warp import COVERED_ALPHA, fill_depth, relative_transform
    from spacedg.render.settings import RasterSettings

    def seen(m, x_ray, y_ray, depth):
        x, y = x_ray * depth, y_ray * depth
        ze = m[6] * x + m[7] * y + m[8] * depth + m[11]
        ahead = ze > 1e-6
        ze = np.where(ahead, ze, 1.0)
        return (m[0] * x + m[1] * y + m[2] * depth + m[9]) / ze, (m[3] * x + m[4] * y + m[5] * depth + m[10]) / ze, ahead

    def apart(u, v, ahead, other, fx, fy):
        return np.where(ahead & other[2], np.hypot(fx * (u - other[0]), fy * (v - other[1])), 0.0)

    def numpy_measure(g, cam, motion, settings):
        width, height = max(2, cam.width // COARSE_FACTOR), max(2, cam.height // COARSE_FACTOR)
        images, _ = composite_view(g, cam.resized(width, height), frozenset({"rgb", "depth"}), "cpu", None, settings, None)
        alpha, depth = images["alpha"], images["depth"]
        z = np.where((alpha > COVERED_ALPHA) & np.isfinite(depth), depth.astype(np.float64), fill_depth(alpha, depth))
        x_ray = ((np.arange(width) + 0.5) * (cam.width / width) - cam.cx) / cam.fx
        y_ray = ((np.arange(height) + 0.5) * (cam.height / height) - cam.cy) / cam.fy
        reach = 2.0 * (cam.width + cam.height)
        delta_h, delta_v = np.zeros((height, width - 1)), np.zeros((height - 1, width))
        with np.errstate(all="ignore"):
            for pose in exposure_poses(cam, np.array(motion.translation), np.array(motion.rotation), np.array([-0.5, 0.5])):
                m = relative_transform(cam.cam_to_world, pose)
                own = seen(m, x_ray[None, :], y_ray[:, None], z)
                gap_h = apart(own[0][:, :-1], own[1][:, :-1], own[2][:, :-1], seen(m, x_ray[None, :-1], y_ray[:, None], z[:, 1:]), cam.fx, cam.fy)
                gap_v = apart(own[0][:-1], own[1][:-1], own[2][:-1], seen(m, x_ray[None, :], y_ray[:-1, None], z[1:]), cam.fx, cam.fy)
                np.maximum(delta_h, np.minimum(gap_h, reach), out=delta_h)
                np.maximum(delta_v, np.minimum(gap_v, reach), out=delta_v)
            encoded = linear_to_srgb(np.clip(images["rgb"].astype(np.float64), 0.0, 1.0))
            total = float(np.sum(np.mean(np.diff(encoded, axis=1) ** 2, axis=2) * delta_h)
                          + np.sum(np.mean(np.diff(encoded, axis=0) ** 2, axis=2) * delta_v))
        value = total / (delta_h.size + delta_v.size)
        return value if math.isfinite(value) else math.inf

    settings = RasterSettings()
    g = textured_wall(3)
    motions = [MotionBlur(**MOTION), MotionBlur(translation=(0.05, 0.0, 4.0), rotation=(0.0, 0.0, 0.0)),
               MotionBlur(translation=(1e6, 0.0, 0.0), rotation=(0.0, 0.0, 3.0)), MotionBlur(translation=(-0.4, 0.3, -2.0), rotation=(0.2, -0.1, 0.05))]
    for cam in (camera(80, 60, focal=70.0), camera(97, 61, focal=55.0)):
        for motion in motions:
            assert edge_parallax_contrast(g, cam, motion, settings) == numpy_measure(g, cam, motion, settings)


def test_the_edge_measure_on_the_torch_backend_is_the_cpu_one() -> None:
    """The coarse render runs on the job's backend: torch's measure equals the compiled CPU one to
    float rounding, and both pick the same count."""
    import torch

    from spacedg.render.motion_error import edge_parallax_contrast, keyframes_for
    from spacedg.render.settings import RasterSettings

    g = textured_wall()
    cam = camera(80, 60, focal=70.0)
    for motion in (MotionBlur(**MOTION), MotionBlur(translation=(0.6, 0.0, 0.0), rotation=(0.0, 0.0, 0.0))):
        on_cpu = edge_parallax_contrast(g, cam, motion, RasterSettings())
        on_torch = edge_parallax_contrast(g, cam, motion, RasterSettings(), "torch", torch.device("cpu"))
        assert on_torch == pytest.approx(on_cpu, rel=1e-4)
        assert keyframes_for(on_torch, 20.0, 8) == keyframes_for(on_cpu, 20.0, 8)


def test_the_edge_measure_does_not_depend_on_the_image_size() -> None:
    """``S`` is the share of the image in error bands (module docstring): the same view at twice the
    size measures about the same (the band is twice as wide in pixels, over twice the edge length
    in an image four times larger)."""
    from spacedg.render.motion_error import edge_parallax_contrast
    from spacedg.render.settings import RasterSettings

    g = textured_wall()
    small = camera(80, 60, focal=70.0)
    sideways = MotionBlur(translation=(0.3, 0.0, 0.0), rotation=(0.0, 0.0, 0.0))
    a = edge_parallax_contrast(g, small, sideways, RasterSettings())
    b = edge_parallax_contrast(g, small.resized(160, 120), sideways, RasterSettings())
    assert 0.67 < b / a < 1.5, (a, b)


def test_keyframe_glue_kernels_equal_their_numpy_forms() -> None:
    """:func:`~spacedg.render.motion_warp.keyframe_source`, :func:`~spacedg.render.motion_warp.fill_depth` and
    :func:`~spacedg.render.motion_warp.sanitise_field` give the bytes of the numpy steps they replaced: alpha right at the float32 threshold, NaN,
    ±inf and values beyond the reach in the field, 4 and 5 channels, a strided input."""
    from spacedg.render import motion_warp

    rng = np.random.default_rng(31)
    h, w = 37, 53
    rgb = rng.uniform(0, 2, (h, w, 3)).astype(np.float32)
    alpha = rng.uniform(0, 1, (h, w)).astype(np.float32)
    alpha[::5, ::3] = np.float32(1e-3)  # exactly the float32 threshold: not covered (numpy compares in float32)
    alpha[1::7, ::4] = np.nextafter(np.float32(1e-3), np.float32(1))
    alpha[2::9] = 0.0
    depth = rng.uniform(0.1, 9, (h, w)).astype(np.float32)
    for channels in (4, 5):
        for image in (rgb, np.ascontiguousarray(rgb[:, ::-1])[:, ::-1]):  # contiguous, then a reversed (strided) view
            fill = float(np.sum(depth * alpha) / max(float(alpha.sum()), 1e-30))
            assert motion_warp.fill_depth(alpha, depth) == fill and motion_warp.fill_depth(np.zeros_like(alpha), depth) == 1.0
            want = np.empty((h, w, channels), np.float32)
            want[..., :3] = image
            want[..., 3] = alpha
            if channels == 5:
                want[..., 4] = depth * alpha
            want_geometry = np.where(alpha > 1e-3, depth, np.float32(fill)).astype(np.float32)
            src, geometry = np.empty_like(want), np.empty((h, w), np.float32)
            motion_warp.keyframe_source(image, alpha, depth, fill, src, geometry)
            assert src.tobytes() == want.tobytes() and geometry.tobytes() == want_geometry.tobytes()

    field = (rng.standard_normal((h, w, 4)) * 10.0 ** rng.integers(-3, 6, (h, w, 4))).astype(np.float32)
    field.reshape(-1)[rng.choice(field.size, 60, replace=False)] = rng.choice([np.nan, np.inf, -np.inf, 3e38, -3e38], 60)
    reach = np.float32(2 * (w + h))
    want = np.clip(np.nan_to_num(field.copy(), nan=0.0, posinf=0.0, neginf=0.0), -reach, reach)
    want_longest = float(np.sqrt(np.max(want[..., 2] ** 2 + want[..., 3] ** 2)))
    longest = motion_warp.sanitise_field(field, reach)
    assert field.tobytes() == want.tobytes()
    assert longest == want_longest and math.isfinite(longest)
    flat = np.zeros((3, 4, 4), np.float32)  # no motion at all: 0
    assert motion_warp.sanitise_field(flat, reach) == 0.0 and not flat.any()

    # nothing covered: every pixel's geometry is the fill depth (render_motion_keyframes passes 1.0 then)
    src, geometry = np.empty((h, w, 4), np.float32), np.empty((h, w), np.float32)
    motion_warp.keyframe_source(rgb, np.zeros((h, w), np.float32), depth, 1.0, src, geometry)
    assert (geometry == 1.0).all() and not src[..., 3].any()
    # shapes that do not match are refused (the kernels do not check bounds)
    with pytest.raises(ValueError, match="keyframe_source: shapes"):
        motion_warp.keyframe_source(rgb, alpha, depth[:-1], 1.0, src, geometry)
    with pytest.raises(ValueError, match="keyframe_source: shapes"):
        motion_warp.keyframe_source(rgb, alpha, depth, 1.0, np.empty((h, w, 3), np.float32), geometry)
    with pytest.raises(ValueError, match=r"sanitise_field: field must be \(H, W, 4\)"):
        motion_warp.sanitise_field(np.zeros((3, 4, 2), np.float32), reach)


def test_vector_taps_give_the_bits_of_the_scalar_sums() -> None:
    """The 4-lane taps of :func:`~spacedg.render.motion_warp.gather` and
    :func:`~spacedg.render.motion_warp.doubling_pass` compute, on every lane, the scalar sums the
    kernels wrote per channel before (same order, same fast-math flags, so the same FMA
    contractions): the same bits on random texels and weights, with and without accumulation;
    the kernels refuse canvases of other than 4 or 5 channels."""
    import numba

    from spacedg.render import motion_warp

    @numba.njit(fastmath=motion_warp._FASTMATH)
    def both_ways(flat, taps, weights, start, vector4, scalar4, vector8, scalar8):  # pragma: no cover - compiled
        for k in range(taps.shape[0]):
            t = taps[k]
            w = weights[k]
            at = np.uint64(4 * k)
            vector4[at : at + np.uint64(4)] = start[k]
            motion_warp._add_weighted_taps4(vector4, at, flat, (t[0], t[1], t[2], t[3]), (w[0], w[1], w[2], w[3]))
            motion_warp._weighted_taps4(vector8, at, flat, (t[0], t[1], t[2], t[3], t[4], t[5], t[6], t[7]),
                                        (w[0], w[1], w[2], w[3], w[4], w[5], w[6], w[7]))
            for c in range(4):
                q = np.uint64(c)
                acc = start[k, c]
                acc += w[0] * flat[t[0] + q] + w[1] * flat[t[1] + q] + w[2] * flat[t[2] + q] + w[3] * flat[t[3] + q]
                scalar4[at + q] = acc
                scalar8[at + q] = (w[0] * flat[t[0] + q] + w[1] * flat[t[1] + q] + w[2] * flat[t[2] + q] + w[3] * flat[t[3] + q]
                                   + w[4] * flat[t[4] + q] + w[5] * flat[t[5] + q] + w[6] * flat[t[6] + q] + w[7] * flat[t[7] + q])

    rng = np.random.default_rng(46)
    n = 20_000
    flat = (rng.standard_normal(4096) * 10.0 ** rng.integers(-3, 4, 4096)).astype(np.float32)
    taps = rng.integers(0, flat.size - 4, (n, 8)).astype(np.uint64)
    weights = rng.uniform(0, 1, (n, 8)).astype(np.float32)
    start = (rng.standard_normal((n, 4)) * 100).astype(np.float32)
    vector4, scalar4, vector8, scalar8 = (np.full(4 * n, np.nan, np.float32) for _ in range(4))
    both_ways(flat, taps, weights, start, vector4, scalar4, vector8, scalar8)
    assert vector4.tobytes() == scalar4.tobytes() and vector8.tobytes() == scalar8.tobytes()
    assert np.isfinite(vector8).all()

    three = np.zeros((8, 9, 3), np.float32)
    with pytest.raises(ValueError, match="4 or 5 channels"):
        motion_warp.gather(three, np.zeros((8, 9, 4), np.float32), 1, 1.0, 1.0, motion_warp.FULL, np.zeros((6, 7, 3), np.float32))
    with pytest.raises(ValueError, match="4 or 5 channels"):
        motion_warp.doubling_pass(three, np.zeros((8, 9, 4), np.float32), np.float32(0.25), motion_warp.FULL, np.empty_like(three))
