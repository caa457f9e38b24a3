"""Shared question geometry (spacedg.plugins.questions.geometry) and view sampling rules."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.qa_scenes import CLEAR, PARTLY, build, camera, obj
from spacedg.plugins.questions.view_sampling import (
    ViewPair,
    OBJECT_PAIRS,
    TRANSLATION_PAIRS,
    PairRules,
    VisibilityIndex,
    description_clash,
    sample_pairs,
    split_across_views,
)
from spacedg.errors import InvalidDataError, ParameterError
from spacedg.plugins.questions.geometry import (
    CAMERA_MOTION_WORDS,
    COMPASS_SECTORS,
    RELPOS_SECTORS,
    build_mcq,
    dominant_parts,
    euler_yaw_pitch_roll,
    flipped_labels,
    ground_angle,
    parts_label,
    relative_rotation,
    relative_translation,
    vertical_dominates,
)


def _rot(yaw: float, pitch: float, roll: float) -> np.ndarray:
    a, b, c = np.radians([yaw, pitch, roll])
    ry = np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])
    rx = np.array([[1, 0, 0], [0, math.cos(b), -math.sin(b)], [0, math.sin(b), math.cos(b)]])
    rz = np.array([[math.cos(c), -math.sin(c), 0], [math.sin(c), math.cos(c), 0], [0, 0, 1]])
    return ry @ rx @ rz


@pytest.mark.parametrize("angles", [(30, 0, 0), (-12, 40, 3), (170, -60, -100), (0, 0, 45)])
def test_euler_round_trip(angles):
    assert np.allclose(euler_yaw_pitch_roll(_rot(*angles)), angles, atol=1e-9)


def test_camera_motion_words_follow_opencv_axes():
    a = camera((0, 0, 1.5), yaw_deg=0)  # looks along +x; its right is -y
    assert parts_label(dominant_parts(relative_translation(a, camera((0, -1, 1.5)))), CAMERA_MOTION_WORDS) == "right"
    assert parts_label(dominant_parts(relative_translation(a, camera((0, 0, 2.5)))), CAMERA_MOTION_WORDS) == "up"
    assert parts_label(dominant_parts(relative_translation(a, camera((1, 0.3, 1.5)))), CAMERA_MOTION_WORDS) == "forward"
    yaw, pitch, roll = euler_yaw_pitch_roll(relative_rotation(a, camera((0, 0, 1.5), yaw_deg=-20)))
    assert yaw == pytest.approx(20) and abs(pitch) < 1e-9 and abs(roll) < 1e-9  # turning right


def test_dominant_parts_rule_and_cap():
    assert dominant_parts([1.0, 0.5, 0.0]) == [(0, 1)]  # 0.5 < 0.5774
    assert dominant_parts([1.0, -0.6, 0.0]) == [(0, 1), (1, -1)]
    assert dominant_parts([1.0, 0.9, -0.95]) == [(0, 1), (2, -1)]  # at most two parts
    assert dominant_parts([0.0, 0.0, 0.0]) == []
    assert flipped_labels([(0, 1), (2, 1)], CAMERA_MOTION_WORDS) == ["left-forward", "right-backward", "left-backward"]


def test_sectors_and_boundary_guard():
    assert RELPOS_SECTORS.classify(0).index == 0 and RELPOS_SECTORS.classify(90).index == 2
    hit = RELPOS_SECTORS.classify(21.0)  # 1.5° before the front / front-right boundary
    assert RELPOS_SECTORS.labels[hit.index] == "front" and RELPOS_SECTORS.labels[hit.neighbour] == "front-right"
    for seed in range(20):
        assert "front-right" not in RELPOS_SECTORS.distractors(hit, np.random.default_rng(seed))
    far = RELPOS_SECTORS.classify(5.0)
    assert any("front-right" in RELPOS_SECTORS.distractors(far, np.random.default_rng(s)) for s in range(20))
    # compass by the 0.5774 rule: cardinal within ±30°
    assert [COMPASS_SECTORS.labels[COMPASS_SECTORS.classify(a).index] for a in (29.9, 30.1, 59.9, 60.1, 330.1, 329.9)] == [
        "north", "northeast", "northeast", "east", "north", "northwest"]


def _plain_classify(sectors, angle):
    """:meth:`Sectors.classify` written out without its memoised bounds (the reference)."""
    a, n = float(angle) % 360.0, len(sectors.labels)
    for k in range(n):
        lo, hi = sectors.starts[k] % 360.0, sectors.starts[(k + 1) % n] % 360.0
        if (lo <= a < hi) if lo < hi else (a >= lo or a < hi):
            to_lo, to_hi = (a - lo) % 360.0, (hi - a) % 360.0
            return (k, to_lo, (k - 1) % n) if to_lo <= to_hi else (k, to_hi, (k + 1) % n)
    raise AssertionError


@pytest.mark.parametrize("sectors", [RELPOS_SECTORS, COMPASS_SECTORS])
def test_sectors_memoised_bounds_and_pools_equal_the_plain_rules(sectors):
    angles = np.random.default_rng(5).uniform(-720.0, 720.0, 400).tolist()
    angles += [s + d for s in sectors.starts for d in (-1e-9, 0.0, 1e-9, 2.999, 3.0)] + [360.0, -0.0, 1e300]
    for i, angle in enumerate(angles):
        hit = sectors.classify(angle)
        assert (hit.index, hit.boundary_distance_deg, hit.neighbour) == _plain_classify(sectors, angle)
        # distractors: the other labels (the near-boundary neighbour out within the guard) in one permutation's order
        banned = {hit.index} | ({hit.neighbour} if hit.boundary_distance_deg < 3.0 else set())
        pool = [label for k, label in enumerate(sectors.labels) if k not in banned]
        expected = [pool[j] for j in np.random.default_rng(i).permutation(len(pool)).tolist()]
        assert sectors.distractors(hit, np.random.default_rng(i)) == expected


def test_ground_angle_uses_up_not_a_world_axis():
    up = np.array([0.0, 0.0, 1.0])
    assert ground_angle([1, 0, 0], [0, -1, 0], up) == pytest.approx(90.0)  # right of +x with z up
    assert ground_angle([1, 0, 5], [1, 0, -3], up) == pytest.approx(0.0)  # vertical parts ignored
    # same geometry with y up: the answer follows the scene's up
    assert ground_angle([1, 0, 0], [0, 0, 1], np.array([0.0, 1.0, 0.0])) == pytest.approx(90.0)
    assert vertical_dominates([0.1, 0, 1.0], up) and not vertical_dominates([1.0, 0, 1.0], up)
    with pytest.raises(InvalidDataError, match="vertical"):
        ground_angle([0, 0, 1], [1, 0, 0], up)


def test_build_mcq_letter_uniform_and_truth_unique():
    letters = []
    rng = np.random.default_rng(3)
    for _ in range(402):
        options, letter = build_mcq("right", ["left", "up", "down", "left"], rng)
        assert options[("ABCD".index(letter))][3:] == "right"
        assert sum(o[3:] == "right" for o in options) == 1
        letters.append(letter)
    counts = [letters.count(k) for k in "ABCD"]
    assert max(counts) - min(counts) <= 1  # dealt from shuffled blocks of four: exact balance
    assert letters[:4] != letters[4:8] or letters[4:8] != letters[8:12]  # but not a fixed cycle
    other = [build_mcq("right", ["left", "up", "down"], np.random.default_rng(3))[1] for _ in range(3)]
    assert len(set(other)) == 1  # a fresh generator with the same seed deals the same letter
    with pytest.raises(InvalidDataError, match="3 distractors"):
        build_mcq("right", ["left", "right"], np.random.default_rng(0))


# ------------------------------------------------------------------ view sampling
def _pairs_scene(covis: np.ndarray):
    views = {"v0": camera((0, 0, 1.5)), "v1": camera((0, -0.5, 1.5)), "v2": camera((0, -0.1, 1.5)), "v3": camera((0, 0, 1.5), yaw_deg=40)}
    return build([obj(1, "chair", (2, 0, 0.4))], views, covisibility=covis)


def test_sample_pairs_thresholds_round_robin_and_seed():
    covis = np.full((4, 4), 0.6, np.float32)
    covis[0, 1] = 0.2  # asymmetric: min(0.2, 0.6) = 0.2 fails > 0.25
    np.fill_diagonal(covis, 1)
    scene = _pairs_scene(covis)
    pairs = sample_pairs(scene, TRANSLATION_PAIRS, np.random.default_rng(0))
    keys = {frozenset((p.a, p.b)) for p in pairs}
    assert frozenset(("v0", "v1")) not in keys  # covisibility (min-symmetrised) too low
    assert frozenset(("v0", "v2")) not in keys  # 0.1 m baseline
    assert frozenset(("v1", "v2")) in keys and all(p.translation_m >= 0.35 for p in pairs)
    rot = sample_pairs(scene, PairRules(min_rotation_deg=15), np.random.default_rng(0))
    assert {frozenset((p.a, p.b)) for p in rot} == {frozenset(("v3", v)) for v in ("v0", "v1", "v2")}
    again = sample_pairs(scene, OBJECT_PAIRS, np.random.default_rng(5))
    assert again == sample_pairs(scene, OBJECT_PAIRS, np.random.default_rng(5))
    # round robin: no anchor repeats before every anchor had its first pair
    anchors = [p.a for p in again]
    first_repeat = next((i for i, a in enumerate(anchors) if a in anchors[:i]), len(anchors))
    assert len(set(anchors[:first_repeat])) == len(set(anchors))


def _sample_pairs_reference(scene, rules, rng):
    """``sample_pairs`` as written before its eligible pairs were memoised (stop 39): the draws and the order to match."""
    cov = scene.covisibility
    names = [n for n in cov.names if n in scene.views]
    idx = np.array([cov.index(n) for n in names], dtype=np.int64)
    sym = np.minimum(cov.matrix, cov.matrix.T)[np.ix_(idx, idx)].astype(np.float64)
    poses = np.stack([np.asarray(scene.views[n].cam_to_world, dtype=np.float64) for n in names])
    rot, centre = poses[:, :3, :3], poses[:, :3, 3]
    i, j = np.triu_indices(len(names), k=1)
    score = sym[i, j]
    baseline = np.linalg.norm(centre[j] - centre[i], axis=1)
    angle = np.degrees(np.arccos(np.clip((np.einsum("nij,nij->n", rot[i], rot[j]) - 1.0) / 2.0, -1.0, 1.0)))
    keep = ((score > rules.min_covisibility) & (score <= rules.max_covisibility)
            & (baseline >= rules.min_translation_m) & (angle >= rules.min_rotation_deg))
    i, j, score, baseline, angle = i[keep], j[keep], score[keep], baseline[keep], angle[keep]
    order = rng.permutation(len(i))
    flips = rng.random(len(i)) < 0.5
    seen_count, ranked = {}, []
    for pos, k in enumerate(order):
        a, b = (j[k], i[k]) if flips[k] else (i[k], j[k])
        rank = seen_count.get(int(a), 0)
        seen_count[int(a)] = rank + 1
        ranked.append((rank, pos, ViewPair(names[a], names[b], round(float(score[k]), 6), round(float(baseline[k]), 6),
                                           round(float(angle[k]), 6))))
    ranked.sort(key=lambda item: (item[0], item[1]))
    return [pair for _, _, pair in ranked]


def test_sample_pairs_equals_the_unmemoised_sampler_and_follows_the_scene():
    """The eligible pairs are memoised per covisibility, rules and cameras: over seeds, rules and two
    calls (a fresh computation, then a memo hit) the pairs and draws equal the plain sampler's, the
    generator is left in the same state, and a scene with another covisibility, or a camera replaced
    in place, gets its own pairs."""
    from spacedg.plugins.questions import view_sampling

    covis = np.full((4, 4), 0.6, np.float32)
    np.fill_diagonal(covis, 1)
    scene = _pairs_scene(covis)
    view_sampling._ELIGIBLE.clear()
    for rules in (OBJECT_PAIRS, TRANSLATION_PAIRS, PairRules(min_rotation_deg=15)):
        for seed in range(4):
            for _ in range(2):  # the first call computes, the second hits the memo
                ours, theirs = np.random.default_rng(seed), np.random.default_rng(seed)
                assert sample_pairs(scene, rules, ours) == _sample_pairs_reference(scene, rules, theirs)
                assert ours.random() == theirs.random()
    low = covis.copy()
    low[0, :] = low[:, 0] = 0.01  # v0 shares nothing now
    np.fill_diagonal(low, 1)
    other = _pairs_scene(low)
    assert sample_pairs(other, OBJECT_PAIRS, np.random.default_rng(3)) == _sample_pairs_reference(other, OBJECT_PAIRS, np.random.default_rng(3))
    assert all("v0" not in (p.a, p.b) for p in sample_pairs(other, OBJECT_PAIRS, np.random.default_rng(3)))
    moved = dict(scene.views)
    scene.views["v1"] = camera((5.0, 5.0, 1.5))  # the same views dict, edited in place
    try:
        assert sample_pairs(scene, TRANSLATION_PAIRS, np.random.default_rng(1)) == \
            _sample_pairs_reference(scene, TRANSLATION_PAIRS, np.random.default_rng(1))
    finally:
        scene.views.clear()
        scene.views.update(moved)


def test_sample_pairs_orders_many_views_as_the_plain_sampler():
    """The vectorised ranking (each anchor's k-th pair in round k, drawn order within a round) equals
    the plain loop's on 30 views with random covisibility, positions and headings, over seeds and rules."""
    rng = np.random.default_rng(11)
    n = 30
    covis = rng.uniform(0.0, 1.0, (n, n)).astype(np.float32)
    np.fill_diagonal(covis, 1)
    views = {f"v{k}": camera((float(x), float(y), 1.5), yaw_deg=float(yaw))
             for k, (x, y, yaw) in enumerate(zip(rng.uniform(-3, 3, n), rng.uniform(-3, 3, n), rng.uniform(-180, 180, n)))}
    scene = build([obj(1, "chair", (2, 0, 0.4))], views, covisibility=covis)
    for rules in (OBJECT_PAIRS, TRANSLATION_PAIRS, PairRules(min_rotation_deg=15), PairRules(min_covisibility=0.9)):
        for seed in range(6):
            ours, theirs = np.random.default_rng(seed), np.random.default_rng(seed)
            pairs = sample_pairs(scene, rules, ours)
            assert pairs == _sample_pairs_reference(scene, rules, theirs) and pairs
            assert ours.random() == theirs.random()


def test_sample_pairs_needs_covisibility():
    scene = _pairs_scene(np.eye(4)).with_covisibility(None)
    with pytest.raises(InvalidDataError, match="with_covisibility"):
        sample_pairs(scene, OBJECT_PAIRS, np.random.default_rng(0))
    with pytest.raises(ParameterError):
        PairRules(min_covisibility=0.5, max_covisibility=0.4)


def test_three_object_rule_and_description_clash():
    views = {"a": camera((0, 0, 1.5)), "b": camera((0, -1, 1.5))}
    insts = [obj(1, "chair", (2, 0, 0.4), description="red chair"), obj(2, "chair", (2, 1, 0.4), description="red chair"),
             obj(3, "table", (3, 0, 0.4)), obj(4, "chair", (2, -1, 0.4), description="blue chair")]
    vis = {"a": {1: CLEAR, 3: CLEAR, 4: CLEAR}, "b": {2: CLEAR, 3: CLEAR, 1: PARTLY}}
    scene = build(insts, views, vis)
    index = VisibilityIndex(scene)
    assert index.visible["a"] == (1, 3, 4) and index.seen["b"] == (1, 2, 3)
    assert split_across_views(index, "a", "b", (1, 2, 4))  # 2 only in b; 4 only in a
    assert not split_across_views(index, "a", "b", (1, 3, 4))  # all three in a
    assert not split_across_views(index, "a", "b", (1, 2, 3))  # all three seen in b (1 partly)
    assert description_clash(index, "b", scene.instance(2))  # 1 is seen in b with the same description
    assert not description_clash(index, "a", scene.instance(1))  # 4 differs ("blue chair")


def test_the_triplet_prefilters_are_the_three_object_rule(qa_room_dirs) -> None:
    """For objects referable in image A or B (the proxy and relative-position streams' candidates),
    "one is seen only in A and one only in B" is exactly :func:`split_across_views`: the proxy stream's
    inline prefilter (``only_a`` / ``only_b``) is this predicate, so neither stream asks the rule again;
    and the relative-position triplets are all and only the ordered triplets that obey it."""
    import itertools

    from spacedg.plugins.questions import camera_object_relative_direction as rel
    from spacedg.plugins.questions.records import referable_ids
    from spacedg.plugins.questions.view_sampling import OBJECT_DIRECTION_PAIRS, VisibilityIndex, sample_pairs, split_across_views
    from spacedg.scene.io import load_scene
    from tests.room_qa import prepare_room

    folder = qa_room_dirs[0]
    scene = prepare_room(load_scene(folder), folder / "cache")
    index = VisibilityIndex(scene)
    checked = 0
    for pair in sample_pairs(scene, OBJECT_DIRECTION_PAIRS, np.random.default_rng(0))[:12]:
        ids = sorted(set(referable_ids(index, pair.a)) | set(referable_ids(index, pair.b)))
        seen_a, seen_b = index.seen_set(pair.a), index.seen_set(pair.b)
        obeying = set()
        for tri in itertools.permutations(ids, 3):
            only_a, only_b = [i not in seen_b for i in tri], [i not in seen_a for i in tri]
            assert (any(only_a) and any(only_b)) == split_across_views(index, pair.a, pair.b, tri)
            if any(only_a) and any(only_b):
                obeying.add(tri)
            checked += 1
        ref_view, triplets = rel._relpos_candidates(index, pair)
        assert sorted(ref_view) == ids and set(triplets) == obeying and len(triplets) == len(obeying)
    assert checked > 1000



def test_vector_length_is_numpys_norm_bit_for_bit() -> None:
    """``vector_length`` (the per-candidate lengths) equals ``float(np.linalg.norm(v))`` exactly:
    random vectors over many scales, zeros, subnormals, huge values, and strided views."""
    from spacedg.plugins.questions.geometry import vector_length

    rng = np.random.default_rng(5)
    vectors = [v for v in rng.standard_normal((3000, 3)) * 10.0 ** rng.integers(-8, 9, size=(3000, 1))]
    vectors += [np.zeros(3), np.array([5e-324, 0.0, -5e-324]), np.array([1e154, -1e154, 3e153]), np.array([np.inf, 1.0, 0.0])]
    matrix = rng.standard_normal((4, 4))
    vectors += [matrix[:3, k] for k in range(4)] + [matrix[k, ::2] for k in range(4)]  # non-contiguous columns and steps
    vectors += [matrix, matrix.T, np.array([2**40, 2**40]), np.array([3, 4], dtype=np.float32), np.array([True, True]), [3.0, 4.0]]  # others: numpy's own norm
    with np.errstate(over="ignore"):  # 1e154² overflows to inf in both
        for v in vectors:
            assert vector_length(v) == float(np.linalg.norm(v))


def test_round_robin_takes_one_item_per_stream_in_turn() -> None:
    """Streams take turns, an exhausted one drops out, and any iterable (a list too) is iterated once."""
    from spacedg.plugins.questions.records import round_robin

    assert list(round_robin([[1, 2], iter([3]), (x for x in [4, 5, 6]), []])) == [1, 3, 4, 2, 5, 6]
    started = []

    def stream(k):
        started.append(k)
        yield k

    merged = round_robin(stream(k) for k in range(3))
    assert started == [] and next(merged) == 0 and started == [0]  # started lazily


def test_camera_inside_shortcut_agrees_with_the_box_test() -> None:
    """``bounding_sphere``'s "surely outside" never rejects a point ``OrientedBox.contains`` accepts: random
    boxes (rotations exact, rounded to 6 and 7 decimals, skewed by up to 2e-6: what OrientedBox accepts),
    points on and near their faces and corners, inside, outside and far away."""
    from spacedg.plugins.questions.records import _farther, bounding_sphere
    from spacedg.scene.box import OrientedBox

    rng = np.random.default_rng(17)
    accepted = shortcut = 0
    for k in range(400):
        q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
        rotation = [q, np.round(q, 6), np.round(q, 7), q + rng.uniform(-2e-6, 2e-6, (3, 3))][k % 4]
        box = OrientedBox(rng.uniform(-5, 5, 3), rng.uniform(0.01, 3, 3), rotation)
        sphere = bounding_sphere(box)
        assert sphere is not None
        signs = rng.choice([-1.0, 1.0], (200, 3))
        local = signs * box.extents / 2.0 * rng.choice([0.0, 0.5, 1.0 - 1e-12, 1.0, 1.0 + 1e-12, 1.5, 20.0], (200, 3))
        points = box.center + local @ np.asarray(rotation).T
        inside = box.contains(points)
        accepted += int(inside.sum())
        for point, hit in zip(points, inside):
            if _farther(tuple(point.tolist()), sphere):
                shortcut += 1
                assert not hit
    assert accepted > 1000 and shortcut > 1000
