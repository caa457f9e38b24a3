"""Independent recomputation: every answer re-derived from its record's ``geometry`` block.

The code here shares nothing with the families or ``spacedg.plugins.questions.geometry``: its
own relative poses, dominant-axis words, Euler angles, ground-plane angles, sectors and
visibility rule. It runs on >= 500 records of four synthetic rooms (random world frames, so
``up`` is not always z) and asserts 100 % agreement, that the geometry block matches the scene
(poses and boxes), that the truth is never among the distractors, and the near-boundary rule.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest


LETTERS = "ABCD"


@pytest.fixture(scope="module")
def scenes_and_records(room_records):
    """The four session rooms and their records (every family, 15 per sub type, seed 7),
    generated once per session and shared with test_families.py."""
    return room_records


# ------------------------------------------------------------- own geometry
def _pose(m):
    m = np.asarray(m, dtype=float)
    return m[:3, :3], m[:3, 3]


def _in_cam(pose, point):
    rot, centre = _pose(pose)
    return rot.T @ (np.asarray(point, float) - centre)


def _words(vec, names, ratio=0.5774):
    """names[axis] = (negative word, positive word); largest first, second if >= ratio * first."""
    mags = [abs(v) for v in vec]
    order = sorted(range(3), key=lambda k: (-mags[k], k))
    first = order[0]
    out = [names[first][int(vec[first] > 0)]]
    if mags[order[1]] >= ratio * mags[first]:
        out.append(names[order[1]][int(vec[order[1]] > 0)])
    return out


CAM_WORDS = (("left", "right"), ("up", "down"), ("backward", "forward"))
BODY_WORDS = (("Left", "Right"), ("Up", "Down"), ("Back", "Front"))


def _flat(v, up):
    v = np.asarray(v, float)
    return v - (v @ up) * up


def _heading(forward, v, up):
    """Clockwise-from-above angle of v from forward, degrees [0, 360)."""
    f = _flat(forward, up)
    f = f / np.linalg.norm(f)
    r = np.cross(f, up)
    w = _flat(v, up)
    return math.degrees(math.atan2(w @ r, w @ f)) % 360


RELPOS = ["front", "front-right", "right", "back-right", "back", "back-left", "left", "front-left"]
COMPASS = ["north", "northeast", "east", "southeast", "south", "southwest", "west", "northwest"]
COMPASS_EDGES = [30, 60, 120, 150, 210, 240, 300, 330]


def _relpos(angle):
    k = int(((angle + 22.5) % 360) // 45)
    edges = [(22.5 + 45 * j) % 360 for j in range(8)]
    return RELPOS[k], min(min(abs(angle - e), 360 - abs(angle - e)) for e in edges)


def _compass(angle):
    n, e = math.cos(math.radians(angle)), math.sin(math.radians(angle))
    ns = "north" if n > 0 else "south"
    ew = "east" if e > 0 else "west"
    if abs(e) < 0.5774 * abs(n):
        label = ns
    elif abs(n) < 0.5774 * abs(e):
        label = ew
    else:
        label = ns + ew
    return label, min(min(abs(angle - b), 360 - abs(angle - b)) for b in COMPASS_EDGES)


def _truth_text(record):
    return record.options[LETTERS.index(record.answer)][3:]


def _phrase(obj):
    d = " ".join(obj["description"].split()).rstrip(".")
    label = obj["label"].replace("_", " ")
    if not d:
        return label
    return d if label.lower() in d.lower() else f"{d} ({label})"


def _top(obj, up):
    rot = np.asarray(obj["rotation"], float)
    half = np.asarray(obj["extents"], float) / 2
    corners = [np.asarray(obj["center"], float) + rot @ (half * np.array(s)) for s in
               [(a, b, c) for a in (-1, 1) for b in (-1, 1) for c in (-1, 1)]]
    return max(c @ up for c in corners)


def _cameras(g, record):
    if "cameras" in g:
        return [g["cameras"][v] for v in record.views]
    return [g["cam_to_world_a"], g["cam_to_world_b"]][: len(record.views)]


# ------------------------------------------------------------- per family
def _check(record):  # noqa: C901 - one branch per family, on purpose
    g = record.geometry
    q, sub = record.question_type, record.sub_question_type
    up = np.asarray(g.get("up", [0, 0, 1]), float)
    if q == "camera_translation":
        (ra, ta), (_, tb) = _pose(g["cam_to_world_a"]), _pose(g["cam_to_world_b"])
        d = ra.T @ (tb - ta)
        dist = float(np.linalg.norm(d))
        if sub == "main_dir":
            assert _truth_text(record) == "-".join(_words(d, CAM_WORDS))
        elif sub == "distance_exact":
            assert record.answer == pytest.approx(dist, abs=6e-4)
        else:
            threshold = float(re.search(r"exceeds ([0-9.]+) meters", record.question).group(1))
            assert record.answer == ("yes" if dist > threshold else "no")
            # the factor threshold / distance is snapped out of (0.85, 1.15); the question shows 2 decimals
            assert abs(threshold / dist - 1) >= 0.15 - 0.0051 / dist or threshold == 0.05
    elif q == "camera_rotation":
        # the gravity-aware reading: heading, elevation and bank of each camera, differenced
        (ra, _), (rb, _) = _pose(g["cam_to_world_a"]), _pose(g["cam_to_world_b"])

        def attitude(rot):
            right, fwd = rot[:, 0], rot[:, 2]
            flat = _flat(fwd, up)
            level = np.cross(fwd, up) / np.linalg.norm(np.cross(fwd, up))
            bank = math.degrees(math.atan2(right @ np.cross(fwd, level), right @ level))
            return flat / np.linalg.norm(flat), math.degrees(math.asin(np.clip(fwd @ up, -1, 1))), bank

        (fa, ea, ba), (fb, eb, bb) = attitude(ra), attitude(rb)
        assert abs(ea) <= 60 and abs(eb) <= 60
        yaw = math.degrees(math.atan2(fb @ np.cross(fa, up), fb @ fa))
        pitch = eb - ea
        roll = (bb - ba + 180) % 360 - 180
        angles = {"yaw": yaw, "pitch": pitch, "roll": roll}
        words = {"yaw": ("turn left", "turn right"), "pitch": ("tilt down", "tilt up"), "roll": ("counterclockwise roll", "clockwise roll")}
        axes, mode = sub.rsplit("_", 1)
        named = axes.split("+")
        if mode == "single":  # a single names its two text axes in the order yaw, pitch, roll; the larger is asked
            assert named == [a for a in ("yaw", "pitch", "roll") if a in named]
            ax1, ax2 = sorted(named, key=lambda k: -abs(angles[k]))
        else:
            ax1, ax2 = named
        a1, a2 = abs(angles[ax1]), abs(angles[ax2])
        ranked = sorted(angles, key=lambda k: -abs(angles[k]))
        assert a1 >= 5 and [ax1, ax2] == ranked[:2] and abs(pitch) <= 60
        ratio = a2 / a1
        truth = _truth_text(record)
        if mode == "single":
            assert a2 < 5 or ratio <= 0.4 + 1e-6
            assert truth == words[ax1][int(angles[ax1] > 0)]
        else:
            assert ratio >= 0.6 - 1e-6
            for ax in (ax1, ax2):
                assert words[ax][int(angles[ax] > 0)] in truth and words[ax][int(angles[ax] <= 0)] not in truth.split(" and ")
    elif q == "camera_object_distance_estimation":
        cams = _cameras(g, record)
        centre = np.asarray(g["objects"][0]["center"], float)
        assert record.answer == pytest.approx(float(np.linalg.norm(centre - _pose(cams[-1])[1])), abs=6e-4)
    elif q == "camera_object_relative_direction":
        cams = _cameras(g, record)
        objs = g["objects"]
        if sub == "single_view":
            v = _in_cam(cams[0], objs[1]["center"]) - _in_cam(cams[0], objs[0]["center"])
            assert _truth_text(record) == "-".join(_words(v, BODY_WORDS))
        elif sub == "bbox_center_direction":
            v = _in_cam(cams[1], objs[0]["center"])
            assert _truth_text(record) == "-".join(_words(v, BODY_WORDS))
        else:
            a, b, c = (np.asarray(o["center"], float) for o in objs)
            angle = _heading(b - a, c - a, up)
            label, edge = _relpos(angle)
            assert _truth_text(record) == label
            assert np.linalg.norm(_flat(b - a, up)) >= 0.25 and abs((c - a) @ up) < 1.2 * np.linalg.norm(_flat(c - a, up))
            if edge < 3:
                k = RELPOS.index(label)
                side = RELPOS[(k + 1) % 8] if ((angle + 22.5) % 45) > 22.5 else RELPOS[(k - 1) % 8]
                assert side not in [o[3:] for o in record.options]
    elif q == "inter_object_distance":
        c1, c2 = (np.asarray(o["center"], float) for o in g["objects"][:2])
        assert record.answer == pytest.approx(float(np.linalg.norm(c1 - c2)), abs=6e-4)
    elif q in ("cross_view_cardinal_direction", "object_proxy_cardinal_direction"):
        _check_compass(record, g, up)
    elif q == "object_size_comparison":
        o1, o2 = g["objects"]
        if sub == "longest_side_compare":
            v1, v2 = max(o1["extents"]), max(o2["extents"])
        else:
            v1, v2 = _top(o1, up), _top(o2, up)
        if sub == "longest_side_compare":
            same, different = max(0.05, 0.1 * max(v1, v2)), max(0.1, 0.2 * max(v1, v2))
        else:
            same, different = 0.05, 0.15
        assert not same + 1e-9 <= abs(v1 - v2) < different - 1e-9  # the grey zone is never asked
        expected = "about the same" if abs(v1 - v2) < same else _phrase(o1 if v1 > v2 else o2)
        assert _truth_text(record) == expected
    elif q == "object_bounding_size_estimation":
        assert list(record.answer) == [round(v, 2) for v in sorted(g["object"]["extents"])]
    elif q == "object_existence_estimation":
        th = g["thresholds"]
        clear = [i["visible_pixels"] >= th["min_pixels"] and i["visible_fraction"] >= th["min_fraction"] for i in _vis_list(g["instances"])]
        pixels = [i["visible_pixels"] for i in _vis_list(g["instances"])]
        assert record.answer == ("yes" if any(clear) else "no")
        if record.answer == "no":
            assert not any(pixels)
    elif q == "object_counting":
        th = g["thresholds"]
        assert all(c["visible_pixels"] >= th["min_pixels"] and c["visible_fraction"] >= th["min_fraction"] for c in g["counted"])
        assert all(n["visible_pixels"] in (0, None) for n in g["not_counted"])
        assert record.answer == len(g["counted"])
    else:  # pragma: no cover
        raise AssertionError(f"no recomputation for {q}")


def _vis_list(instances):
    return [i.get("visibility", i) for i in instances]


def _check_compass(record, g, up):
    assumed = re.search(r" is (north|east|south|west)\. What is", record.question).group(1)
    objs = [np.asarray(o["center"], float) for o in g["objects"]]
    if record.question_type == "cross_view_cardinal_direction":
        cams = _cameras(g, record)
        ref, query = objs[0] - _pose(cams[0])[1], objs[1] - _pose(cams[1])[1]
    else:  # A relative to B defines the frame; C relative to B is asked
        ref, query = objs[0] - objs[1], objs[2] - objs[1]
    for v in (ref, query):
        horizontal = np.linalg.norm(_flat(v, up))
        assert horizontal >= 0.25 and abs(v @ up) < 1.2 * horizontal
    angle = (_heading(ref, query, up) + {"north": 0, "east": 90, "south": 180, "west": 270}[assumed]) % 360
    label, edge = _compass(angle)
    assert _truth_text(record) == label
    if edge < 3:  # the neighbour across the near boundary is no distractor
        nearest = min(COMPASS_EDGES, key=lambda b: min(abs(angle - b), 360 - abs(angle - b)))
        across = _compass((nearest + (3.5 if _compass(nearest - 3.5)[0] == label else -3.5)) % 360)[0]
        assert across not in [o[3:] for o in record.options]


def _matches_scene(record, scene):
    g = record.geometry
    if "cameras" in g:
        for view, pose in g["cameras"].items():
            assert np.allclose(pose, scene.views[view].cam_to_world)
    for key, view in (("cam_to_world_a", 0), ("cam_to_world_b", 1)):
        if key in g:
            assert np.allclose(g[key], scene.views[record.views[view]].cam_to_world)
    objs = list(g.get("objects", [])) + ([g["object"]] if "object" in g else [])
    for o in objs:
        box = scene.instance(o["id"]).box
        assert np.allclose(o["center"], box.center) and np.allclose(o["extents"], box.extents)
    assert np.allclose(g.get("up", scene.up), scene.up)


def recomputes(record, scene):
    """Every check of one record (raises when one fails): its geometry matches the scene, the truth
    is offered once, and the answer re-derives. ``benchmarks/qa_speed.py`` runs it too."""
    _matches_scene(record, scene)
    if record.options:
        texts = [o[3:] for o in record.options]
        assert texts.count(_truth_text(record)) == 1  # truth never among the distractors
    _check(record)


def test_every_answer_recomputes(scenes_and_records):
    total = 0
    per_type: dict[str, int] = {}
    for scene, records in scenes_and_records:
        for record in records:
            recomputes(record, scene)
            per_type[record.question_type] = per_type.get(record.question_type, 0) + 1
            total += 1
    assert total >= 500, total
    assert len(per_type) == 11, per_type


def test_near_boundary_cases_are_exercised(scenes_and_records):
    """The sector-boundary rule above is not vacuous: some records lie within 3° of a boundary."""
    near = 0
    for _, records in scenes_and_records:
        for r in records:
            if r.sub_question_type in ("relpos_A_facing_B", "assumed_direction", "proxy_frame"):
                g = r.geometry
                dist = g.get("boundary_distance_deg", g.get("sector", {}).get("boundary_distance_deg") if isinstance(g.get("sector"), dict) else None)
                near += dist is not None and dist < 3
    assert near >= 1


def test_index_selection_is_debiased(scenes_and_records):
    """Per scene: no subject asked twice per sub type; every balanced cell holds whole rounds
    (each of its roles equally often); the correct letters of each MCQ sub type are uniform to
    within one block of four (three for the 3-option size comparisons)."""
    from collections import Counter, defaultdict

    from spacedg.qa.stats import record_subject

    for _, records in scenes_and_records:
        subjects = Counter((r.sub_question_type, record_subject(r)) for r in records)
        assert max(subjects.values()) == 1
        cells: dict[tuple[str, str], Counter] = defaultdict(Counter)
        roles: dict[tuple[str, str], list] = {}
        letters: dict[str, Counter] = defaultdict(Counter)
        for r in records:
            sel = r.geometry["selection"]
            if "cell" in sel:
                cells[(r.question_type, sel["cell"])][sel["role"]] += 1
                roles[(r.question_type, sel["cell"])] = sel["roles"]
            if r.answer_type.value == "MCQ":
                letters[(r.sub_question_type, len(r.options))][r.answer] += 1
        for key, counts in cells.items():
            # whole rounds: every role of the cell (or, for option-set cells, the ones the scene offers) equally often
            assert set(counts) <= set(roles[key]) and len(counts) >= 2 and len(set(counts.values())) == 1, (key, counts)
        for (sub, n), counts in letters.items():  # the letters shown: A–D, or A–C for a size comparison's three options
            assert max(counts.get(k, 0) for k in LETTERS[:n]) - min(counts.get(k, 0) for k in LETTERS[:n]) <= 1, (sub, counts)
