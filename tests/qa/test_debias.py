"""Bench-level blind pruning (spacedg.qa.debias) on synthetic item tables with a planted bias."""

from __future__ import annotations

import math
from collections import Counter

import numpy as np
import pytest

from spacedg.errors import ParameterError
from spacedg.plugins.qa_record import QARecord
from spacedg.plugins.specs import AnswerType, TaskGroup
from spacedg.qa.debias import HALF_SPLITS, MAX_ALLOWED, balanced_pick, debias, format_debias, noise_band, spread_targets
from spacedg.qa.debias_gbm import BoostedChoice
from spacedg.qa.debias_probe import probe, repeat_seeds, scene_folds, shown_chance, stable_hash

DIRECTIONS = ("left", "right", "forward", "back")
LABELS = ("chair", "lamp", "table", "cup")


def _direction(scene: str, k: int, truth: str, rng: np.random.Generator) -> QARecord:
    """A direction MCQ whose four options are shuffled; the truth is ``truth``."""
    label = LABELS[int(rng.integers(len(LABELS)))]
    order = [DIRECTIONS[i] for i in rng.permutation(4)]
    return QARecord(
        id=f"{scene}/camera_object_relative_direction/bbox_center_direction/{k:012x}", scene_id=scene,
        question_type="camera_object_relative_direction", sub_question_type="bbox_center_direction",
        task_group=TaskGroup.CAMERA_CENTRIC, answer_type=AnswerType.MCQ, views=(f"v{k}",),
        question=f"Where is the {label} relative to the camera?", options=tuple(f"{'ABCD'[i]}. {t}" for i, t in enumerate(order)),
        answer="ABCD"[order.index(truth)], geometry={"label": label, "refs": []},
    )


def _existence(scene: str, k: int, answer: str, rng: np.random.Generator) -> QARecord:
    label = LABELS[int(rng.integers(len(LABELS)))]
    return QARecord(
        id=f"{scene}/object_existence_estimation/existence/{k:012x}", scene_id=scene, question_type="object_existence_estimation",
        sub_question_type="existence", task_group=TaskGroup.OBJECT_CENTRIC, answer_type=AnswerType.YN, views=(f"v{k}",),
        question=f"Is there a {label} visible in this image?", options=(), answer=answer, geometry={"label": label, "refs": []},
    )


def _distance(scene: str, k: int, rng: np.random.Generator) -> QARecord:
    return QARecord(
        id=f"{scene}/camera_object_distance/single/{k:012x}", scene_id=scene, question_type="camera_object_distance",
        sub_question_type="single", task_group=TaskGroup.CAMERA_CENTRIC, answer_type=AnswerType.NA, views=(f"v{k}",),
        question="How far is the chair from the camera, in metres?", options=(), answer=float(rng.uniform(1, 4)),
        geometry={"label": "chair", "refs": []},
    )


def _table(scenes: int = 6, per_scene: int = 40, planted: float = 0.7, seed: int = 0) -> list[QARecord]:
    """Per scene: ``per_scene`` direction MCQs whose truth is "forward" with probability ``planted``
    (else uniform), ``per_scene`` balanced yes/no questions, and 4 metric ones."""
    rng = np.random.default_rng(seed)
    out = []
    for s in range(scenes):
        scene = f"room-{s}"
        for k in range(per_scene):
            truth = "forward" if rng.random() < planted else DIRECTIONS[int(rng.integers(4))]
            out.append(_direction(scene, k, truth, rng))
            out.append(_existence(scene, 1000 + k, "yes" if k % 2 else "no", rng))
        out.extend(_distance(scene, 2000 + k, rng) for k in range(4))
    return out


KEY = ("camera_object_relative_direction", "bbox_center_direction")
YN_KEY = ("object_existence_estimation", "existence")
TARGETS = {KEY: 75, YN_KEY: 75, ("camera_object_distance", "single"): 10}


@pytest.fixture(scope="module")
def planted() -> tuple[list[QARecord], object]:
    """Five scenes of 30 + 30 + 4 records, "forward" planted in 70 % of the directions, pruned to half (the targets)."""
    records = _table(scenes=5, per_scene=30)
    return records, debias(records, TARGETS, learned=False, repeats=1)


def test_a_planted_bias_is_pruned_to_the_bound_and_balance_is_kept(planted) -> None:
    records, result = planted
    before = result.before.row(KEY)
    assert before is not None and before.chance == pytest.approx(25.0) and before.excess > 20  # the plant is found
    allowed = {(r["question_type"], r["sub_question_type"]): r["allowed"] for r in result.to_dict()["after"]["rows"]}
    band = 100 * math.sqrt(0.25 * 0.75 / result.after.row(KEY).n)
    assert allowed[KEY] == pytest.approx(min(max(3.0, band), MAX_ALLOWED))  # the noise band at its n, never past 4 points
    assert result.folds == 5  # leave one scene out: one fold per scene
    assert result.within and all(r.excess <= allowed[r.key] for r in result.after.rows) and result.after.overall["excess"] <= 2.0
    kept = Counter((r.question_type, r.sub_question_type) for r in result.kept)
    assert kept[("camera_object_distance", "single")] == 10  # metric records: trimmed to their target only
    assert 0.8 * 75 <= kept[YN_KEY] <= 75  # the unbiased sub type keeps (about) its target (n = 75: noise is chased a little)
    assert math.ceil(0.5 * 75) <= kept[KEY] <= 75  # the biased one: pruned, never below the floor (half its target)
    assert result.removed[f"{KEY[0]}/{KEY[1]}"] == 150 - kept[KEY]
    truths = Counter(r.answer for r in result.kept if r.answer_type is AnswerType.YN)
    assert abs(truths["yes"] - truths["no"]) <= 0.2 * sum(truths.values())  # yes/no stays balanced
    letters = Counter(r.answer for r in result.kept if r.answer_type is AnswerType.MCQ)
    before = Counter(r.answer for r in records if r.answer_type is AnswerType.MCQ)
    assert max(letters.values()) - min(letters.values()) <= max(before.values()) - min(before.values())  # removal is letter-balanced
    kept_ids = {r.id for r in result.kept}
    assert [r.id for r in result.kept] == [r.id for r in records if r.id in kept_ids]  # input order
    assert f"{KEY[0]}/{KEY[1]}" in result.eligible and set(result.pruned) <= set(result.eligible)
    text = format_debias(result)
    assert "round 1 (blind models over the bound)" in text and "within the bounds" in text


def test_pruning_is_deterministic_and_leaves_an_unbiased_table_alone() -> None:
    table = _table(scenes=4, per_scene=16, planted=0.0, seed=4)
    one, two = debias(table, learned=False, seed=3, repeats=1), debias(list(table), learned=False, seed=3, repeats=1)
    assert [r.id for r in one.kept] == [r.id for r in two.kept] and one.rounds == two.rounds
    assert one.removed.get(f"{KEY[0]}/{KEY[1]}", 0) <= 0.25 * 64  # unbiased: at most noise is chased
    assert set(one.pruned) <= set(one.eligible)  # only what was over its band before pruning is pruned


def test_chance_is_over_the_options_shown_and_folds_are_whole_scenes() -> None:
    rng = np.random.default_rng(0)
    record = _direction("room-0", 0, "forward", rng)
    assert shown_chance(record, {}) == 0.25 and shown_chance(_existence("room-0", 1, "no", rng), {}) == 0.5
    folds = scene_folds([f"room-{i}" for i in range(7)] * 3, 3, seed=0)
    assert sorted(s for f in folds for s in f) == [f"room-{i}" for i in range(7)] and len(folds) == 3
    assert scene_folds(["a", "b"], 5, seed=0) == scene_folds(["b", "a"], 5, seed=0) and len(scene_folds(["a", "b"], 5, 0)) == 2
    assert probe([record]).rows == []  # one scene: nothing held out


def test_boosted_trees_learn_a_planted_option_and_targets_spread() -> None:
    records = _table(scenes=2, per_scene=60, planted=0.8, seed=5)
    mcq = [r for r in records if r.answer_type is AnswerType.MCQ]
    model = BoostedChoice(mcq[:60], frozenset({"where", "is", "the", "relative", "to", "camera"}))
    answers, truth = model.predict_many(mcq[60:])
    assert np.mean([a == r.answer for a, r in zip(answers, mcq[60:])]) > 0.6 and np.all((truth >= 0) & (truth <= 1))
    assert spread_targets({("a", "x"): 10, ("b", "y"): 5}, 6) == {("a", "x"): 4, ("b", "y"): 2}
    assert spread_targets({("a", "x"): 3}, 6) == {("a", "x"): 3}


@pytest.mark.parametrize("kwargs", [{"bound": -1.0}, {"overall_bound": "2"}, {"folds": 1}, {"max_rounds": -1}, {"floor": 2.0},
                                    {"repeats": 0}, {"noise_z": -1.0}, {"noise_z": True}])
def test_bad_arguments_are_named(kwargs) -> None:
    name = next(iter(kwargs))
    with pytest.raises(ParameterError, match=name):
        debias(_table(scenes=2, per_scene=2), **kwargs)


def test_qa_audit_debias_prints_before_after_and_rounds(tmp_path, capsys) -> None:
    from spacedg.cli import main

    for record in _table(scenes=3, per_scene=16, planted=0.9, seed=6):
        with open(tmp_path / f"{record.scene_id}.qa.jsonl", "a", encoding="utf-8") as f:
            f.write(record.to_json() + "\n")
    assert main(["qa", "audit", str(tmp_path), "--no-learned", "--debias"]) == 0
    text = capsys.readouterr().out
    assert "Blind pruning" in text and "round 1 (blind models over the bound)" in text and "| bbox_center_direction |" in text


def test_removal_takes_from_the_most_common_answer_first() -> None:
    from dataclasses import replace

    rng = np.random.default_rng(1)
    records = [replace(_direction("room-0", k, "forward", rng), answer=letter) for k, letter in enumerate("AAAAAABBBCCD")]
    rank = {r.id: (i * 7) % 12 for i, r in enumerate(records)}  # a "solvability" order that mixes the letters
    gone = balanced_pick(records, 4, lambda r: rank[r.id])
    left = Counter(r.answer for r in records if r.id not in gone)
    assert left["A"] + left["B"] == 5 and left["C"] == 2 and left["D"] == 1 and max(left.values()) == 3
    a_ranks = sorted(rank[r.id] for r in records if r.answer == "A")
    assert {rank[r.id] for r in records if r.id in gone and r.answer == "A"} >= set(a_ranks[:2])  # most solvable first within a letter
    assert balanced_pick(records, 99, lambda r: rank[r.id]) == {r.id for r in records}


def test_repeats_average_the_probes_of_their_fold_seeds() -> None:
    table = [r for r in _table(scenes=4, per_scene=6, planted=0.5, seed=7) if r.answer_type is not AnswerType.NA]
    seeds = repeat_seeds(5, 2)
    assert seeds[0] == 5 and len(set(seeds)) == 2 and repeat_seeds(5, 2) == seeds
    one, two = (probe(table, folds=2, seed=s, learned=False) for s in seeds)
    both = probe(table, folds=2, seed=5, learned=False, repeats=2)
    for r in table:
        for name, value in both.correct[r.id].items():
            assert value == pytest.approx((one.correct[r.id][name] + two.correct[r.id][name]) / 2)
    row = both.row(KEY)
    assert row is not None and noise_band(row, 1.0) == pytest.approx(100 * math.sqrt(0.25 * 0.75 / row.n))


def test_half_splits_average_in_probes_on_half_as_many_folds() -> None:
    table = [r for r in _table(scenes=4, per_scene=6, planted=0.5, seed=7) if r.answer_type is not AnswerType.NA]
    loso = probe(table, folds=4, seed=5, learned=False)
    halves = [probe(table, folds=2, seed=s, learned=False) for s in repeat_seeds(stable_hash(5, "half") % (2**31), 2)]
    mixed = probe(table, folds=4, seed=5, learned=False, half_splits=2)
    for r in table:
        for name, value in mixed.correct[r.id].items():
            assert value == pytest.approx((loso.correct[r.id][name] + sum(h.correct[r.id][name] for h in halves)) / 3)
    # the pruning uses them from 4 scenes when it leaves one scene out, and says so
    result = debias(table, learned=False)
    assert result.half_splits == HALF_SPLITS and result.to_dict()["half_splits"] == HALF_SPLITS
    assert f"and {HALF_SPLITS} splits into half as many folds" in format_debias(result)
    assert debias([r for r in table if r.scene_id in {"room-0", "room-1", "room-2"}], learned=False).half_splits == 0


def test_a_probe_refits_only_the_question_types_that_changed() -> None:
    table = [r for r in _table(scenes=4, per_scene=8, planted=0.6, seed=8) if r.answer_type is not AnswerType.NA]
    full = probe(table, folds=3, seed=2, learned=False)
    fewer = [r for r in table if not (r.question_type == KEY[0] and r.id.endswith(("1", "5")))]
    again = probe(fewer, folds=3, seed=2, learned=False)
    reused = probe(fewer, folds=3, seed=2, learned=False, reuse=full, changed={KEY[0]})
    assert reused.correct == again.correct and reused.rows == again.rows and reused.truth_probability == again.truth_probability


def test_count_chance_is_one_over_the_answer_bins() -> None:
    from spacedg.qa.audit import answer_class, count_chances

    def count(k: int, n: int) -> QARecord:
        return QARecord(
            id=f"room-0/object_counting/count/{k:012x}", scene_id="room-0", question_type="object_counting", sub_question_type="count",
            task_group=TaskGroup.OBJECT_CENTRIC, answer_type=AnswerType.COUNT, views=(f"v{k}",), question="How many chairs are visible?",
            options=(), answer=n, geometry={"label": "chair", "refs": []},
        )

    records = [count(k, n) for k, n in enumerate((0, 1, 2, 3, 6, 0))]
    assert [answer_class(r) for r in records] == ["0", "1", "2+", "2+", "2+", "0"]
    assert count_chances(records) == {"object_counting": pytest.approx(1 / 3)}  # bins 0, 1, 2+: not 1 / five counts
    assert shown_chance(records[0], count_chances(records)) == pytest.approx(1 / 3)


def test_removal_keeps_every_cells_roles_balanced() -> None:
    from dataclasses import replace

    from spacedg.qa.debias import balance_class

    rng = np.random.default_rng(2)
    records = []
    for k, (cell, role, letter) in enumerate([(c, r, "ABCD"[(i + j) % 4]) for i, c in enumerate("ab") for j, r in enumerate("xyxyxy")]):
        base = _direction("room-0", k, "forward", rng)
        records.append(replace(base, answer=letter, geometry={**base.geometry, "selection": {"subject": f"o{k}", "cell": cell, "role": role}}))
    gone = balanced_pick(records, 8, lambda r: r.id)
    left = Counter(balance_class(r) for r in records if r.id not in gone)
    assert sorted(left.values()) == [1, 1, 1, 1] and set(left) == {"a|x", "a|y", "b|x", "b|y"}


def _count(scene: str, k: int, count: int, cell: str = "label:chair|template:0") -> QARecord:
    """A counting record of bin role ``0`` / ``1`` / ``2+`` in one cell, as the selection deals them."""
    role = "0" if count == 0 else "1" if count == 1 else "2+"
    return QARecord(
        id=f"{scene}/object_counting/count/{k:012x}", scene_id=scene, question_type="object_counting", sub_question_type="count",
        task_group=TaskGroup.OBJECT_CENTRIC, answer_type=AnswerType.COUNT, views=(f"v{k}",),
        question="How many chairs are visible in this image?", options=(), answer=count,
        geometry={"label": "chair", "refs": [], "selection": {"subject": f"view:v{k}|label:chair", "cell": cell,
                                                              "role": role, "roles": ["0", "1", "2+"]}},
    )


def test_trimming_keeps_the_highest_counts_of_the_two_plus_bin() -> None:
    """A ``2+`` bin of twos and a few fives to sevens, trimmed by half: the twos go first (the
    selection asks the highest counts first; a random trim lost every count above four on 12 rooms)."""
    records = []
    for s in range(4):
        counts = [0] * 6 + [1] * 6 + [2] * 4 + [s + 4, 7]
        records += [_count(f"room-{s}", 10 * s + k, c) for k, c in enumerate(counts)]
    target = {("object_counting", "count"): len(records) // 2}
    kept = debias(records, target, learned=False, max_rounds=1).kept
    got = Counter(int(r.answer) for r in kept)
    assert sum(got.values()) == len(records) // 2 and got[0] == got[1] == got[2] + got[4] + got[5] + got[6] + got[7] + got[3]
    assert got[7] == 5 and got[4] == got[5] == got[6] == 1 and got[2] < 16  # every high count kept, twos trimmed


def test_trimming_counts_keeps_their_bins_balanced() -> None:
    """Cells (label and wording) of whole rounds but unequal sizes, trimmed together: the bins stay
    balanced pooled (ties between classes go to the role with most records left), not only per cell."""
    records, k = [], 0
    for cell in range(9):
        for _ in range(1 + cell % 4):
            for count in (0, 1, 2 + cell % 3):
                scene = f"room-{k % 5}"
                records.append(_count(scene, k, count, cell=f"label:l{cell}|template:0"))
                k += 1
    for target in (30, 41, 52):
        kept = debias(records, {("object_counting", "count"): target}, learned=False, max_rounds=1).kept
        bins = Counter(min(int(r.answer), 2) for r in kept)
        assert sum(bins.values()) == target and max(bins.values()) - min(bins.values()) <= 1, (target, bins)
    assert "counting answers kept: 0: " in format_debias(debias(records, {("object_counting", "count"): 30}, learned=False, max_rounds=1))
