"""Counts and answer balance of question records, and the blind baseline.

- :func:`count_table`: records per (question_type, sub_question_type) and answer type.
- :func:`answer_balance`: share of each correct letter A–D over 4-option MCQ records (A–C over
  3-option ones) and of yes/no over YN records, in percent.
- :func:`blind_baseline`: leave-one-scene-out "always answer the most frequent answer of this
  sub type" accuracy on MCQ and YN records, against chance (25 % / 50 %). Two priors are
  measured: the most frequent **letter** (what a blind model can output) and the most
  frequent **option text** (a blind model that reads the options and picks the one that was
  most often right in the training scenes: catches text bias such as "forward" dominating).
  The full blind stress test (per-label priors, option-text priors, a learned text model) is
  :func:`spacedg.qa.audit.blind_audit`.
- :func:`record_subject` / :func:`repeat_rate`: what a record asks about (read from its
  geometry, the same for every index version) and the share of records that re-ask a subject
  already asked in the same scene and sub type.
- :func:`ambiguities`: records a person could not answer as stated: a label-only question
  (counting, existence "no") while the view shows a related label or an object showing the
  label unannotated (:mod:`spacedg.scene.lexicon`; needs the scenes' visibility), a size
  comparison whose difference is visible but not decidable (between "about the same" and a
  clear difference), and a rotation answer naming a component under 5° in the gravity-aware
  reading.
"""

from __future__ import annotations

from collections import Counter, defaultdict
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np

from spacedg.plugins.answers import MCQ_LETTERS
from spacedg.plugins.qa_record import QARecord
from spacedg.plugins.questions.camera_rotation import MIN_ROTATION_DEG
from spacedg.plugins.questions.geometry import gravity_rotation
from spacedg.plugins.questions.object_size_comparison import thresholds_for
from spacedg.plugins.specs import AnswerType
from spacedg.render.camera import Camera
from spacedg.scene.lexicon import default_lexicon
from spacedg.scene.visibility_classes import VisibilityClass, classify

__all__ = ["count_table", "answer_balance", "blind_baseline", "format_table", "option_text", "record_subject", "repeat_rate", "ambiguities"]


def count_table(records: Iterable[QARecord]) -> list[dict[str, Any]]:
    """One row per (question_type, sub_question_type): ``n`` and the answer type."""
    counts: Counter[tuple[str, str, str]] = Counter(
        (r.question_type, r.sub_question_type, r.answer_type.value) for r in records
    )
    return [
        {"question_type": q, "sub_question_type": s, "answer_type": a, "n": n}
        for (q, s, a), n in sorted(counts.items())
    ]


def answer_balance(records: Iterable[QARecord]) -> dict[str, Any]:
    """``{"mcq_n", "letters": {A: %, ...}, "mcq3_n", "letters3": {A: %, B: %, C: %}, "yn_n", "yes_pct"}``:
    the correct letters of the 4-option MCQs (``letters``, uniform = 25 %) and of the 3-option
    ones (size comparisons; ``letters3``, uniform = 33.3 %) apart."""
    letters: Counter[str] = Counter()
    letters3: Counter[str] = Counter()
    yes = no = 0
    for r in records:
        if r.answer_type is AnswerType.MCQ:
            (letters3 if len(r.options) == 3 else letters)[str(r.answer)] += 1
        elif r.answer_type is AnswerType.YN:
            yes += r.answer == "yes"
            no += r.answer == "no"
    mcq, mcq3 = sum(letters.values()), sum(letters3.values())
    return {
        "mcq_n": mcq,
        "letters": {k: (100.0 * letters[k] / mcq if mcq else 0.0) for k in MCQ_LETTERS},
        "mcq3_n": mcq3,
        "letters3": {k: (100.0 * letters3[k] / mcq3 if mcq3 else 0.0) for k in MCQ_LETTERS[:3]},
        "yn_n": yes + no,
        "yes_pct": 100.0 * yes / (yes + no) if yes + no else 0.0,
    }


def option_text(record: QARecord, letter: str) -> str:
    """The text of option ``letter`` (``""`` when missing)."""
    for line in record.options:
        if line.startswith(f"{letter}. "):
            return line[3:]
    return ""


def blind_baseline(records_by_scene: Mapping[str, Sequence[QARecord]]) -> list[dict[str, Any]]:
    """Leave-one-scene-out majority baselines per (question_type, sub_question_type), MCQ and YN.

    For each held-out scene, the priors are counted on the other scenes: the most frequent
    answer (letter or yes/no) and, for MCQ, the most frequent correct option text. On the held-out
    scene the letter prior answers that letter; the text prior picks the option whose text has the
    highest training count (ties → the first option). Rows give ``n``, ``chance`` and both
    accuracies in percent; a final row ``ALL`` pools every record.
    """
    keys = sorted({(r.question_type, r.sub_question_type) for rs in records_by_scene.values() for r in rs
                   if r.answer_type in (AnswerType.MCQ, AnswerType.YN)})
    hits: dict[tuple[str, str], list[int]] = defaultdict(lambda: [0, 0, 0])  # n, letter hits, text hits
    chance: dict[tuple[str, str], float] = {}
    for held in records_by_scene:
        answer_prior: dict[tuple[str, str], Counter[str]] = defaultdict(Counter)
        text_prior: dict[tuple[str, str], Counter[str]] = defaultdict(Counter)
        for scene, rs in records_by_scene.items():
            if scene == held:
                continue
            for r in rs:
                k = (r.question_type, r.sub_question_type)
                answer_prior[k][str(r.answer)] += 1
                if r.answer_type is AnswerType.MCQ:
                    text_prior[k][option_text(r, str(r.answer))] += 1
        for r in records_by_scene[held]:
            k = (r.question_type, r.sub_question_type)
            if k not in keys:
                continue
            chance[k] = 100.0 / len(r.options) if r.answer_type is AnswerType.MCQ else 50.0
            row = hits[k]
            row[0] += 1
            guess = answer_prior[k].most_common(1)[0][0] if answer_prior[k] else ("A" if r.answer_type is AnswerType.MCQ else "yes")
            row[1] += guess == str(r.answer)
            if r.answer_type is AnswerType.MCQ:
                texts = [(option_text(r, letter), letter) for letter in MCQ_LETTERS[:len(r.options)]]
                best = max(texts, key=lambda tl: text_prior[k][tl[0]])[1]
                row[2] += best == str(r.answer)
            else:
                row[2] += guess == str(r.answer)
    rows = []
    total = [0, 0, 0]
    total_chance = 0.0
    for k in keys:
        n, h_letter, h_text = hits[k]
        if n == 0:
            continue
        rows.append({"question_type": k[0], "sub_question_type": k[1], "n": n, "chance": chance[k],
                     "letter_prior": 100.0 * h_letter / n, "text_prior": 100.0 * h_text / n})
        total = [total[0] + n, total[1] + h_letter, total[2] + h_text]
        total_chance += chance[k] * n
    if total[0]:
        rows.append({"question_type": "ALL", "sub_question_type": "", "n": total[0], "chance": total_chance / total[0],
                     "letter_prior": 100.0 * total[1] / total[0], "text_prior": 100.0 * total[2] / total[0]})
    return rows


def format_table(rows: Sequence[Mapping[str, Any]], columns: Sequence[str] | None = None) -> str:
    """A Markdown table of ``rows`` (floats with one decimal)."""
    if not rows:
        return "(no rows)"
    cols = list(columns or rows[0].keys())
    def cell(v: Any) -> str:
        return f"{v:.1f}" if isinstance(v, float) else str(v)
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    lines += ["| " + " | ".join(cell(r.get(c, "")) for c in cols) + " |" for r in rows]
    return "\n".join(lines)


# ------------------------------------------------------------------ repeats
def _ids(g: Mapping[str, Any]) -> list[int]:
    return [int(r["id"]) for r in g.get("refs") or [] if "id" in r]


def record_subject(record: QARecord) -> str:
    """What ``record`` asks about, read from its geometry block the same way for every index
    version (the built-ins' ``selection`` subjects are this key or stricter): the object (size estimation), the
    unordered object pair (inter-object distance, size comparison), the measuring view and the
    object (camera-object distance and ``bbox_center_direction``), the view and the unordered
    pair (single-view direction), the ordered objects (three-object and compass questions), the
    unordered view pair (camera motion), the view and the label (counting, existence); other
    families: the views and the named objects."""
    g = record.geometry
    q, sub, views, ids = record.question_type, record.sub_question_type, record.views, _ids(g)
    if q == "object_bounding_size_estimation" and ids:
        return f"object:{ids[0]}"
    if q in ("inter_object_distance", "object_size_comparison") and ids:
        return f"{sub}|objects:" + "|".join(map(str, sorted(ids)))
    if (q == "camera_object_distance_estimation" or sub == "bbox_center_direction") and ids:
        return f"view:{views[-1]}|object:{ids[0]}"
    if q == "camera_object_relative_direction" and sub == "single_view":
        return f"view:{views[0]}|objects:" + "|".join(map(str, sorted(ids)))
    if q in ("camera_translation", "camera_rotation"):
        return "views:" + "|".join(sorted(views))
    if q in ("object_counting", "object_existence_estimation"):
        return f"view:{views[0]}|label:{str(g.get('label_key', g.get('label', ''))).lower()}"
    if ids:
        return "objects:" + "|".join(map(str, ids))
    return "views:" + "|".join(views)


def repeat_rate(records_by_scene: Mapping[str, Sequence[QARecord]]) -> list[dict[str, Any]]:
    """Per (question_type, sub_question_type): ``n``, ``repeats`` (records whose subject was
    already asked in the same scene and sub type: camera-motion families count a view pair,
    label-only families a view and label) and ``repeat_pct``; a final ``ALL`` row."""
    rows: dict[tuple[str, str], list[int]] = defaultdict(lambda: [0, 0])
    for rs in records_by_scene.values():
        seen: set[tuple[str, str, str]] = set()
        for r in rs:
            key = (r.question_type, r.sub_question_type, record_subject(r))
            row = rows[(r.question_type, r.sub_question_type)]
            row[0] += 1
            row[1] += key in seen
            seen.add(key)
    out = [{"question_type": q, "sub_question_type": s, "n": n, "repeats": k, "repeat_pct": 100.0 * k / n}
           for (q, s), (n, k) in sorted(rows.items()) if n]
    total = sum(r["n"] for r in out)
    if total:
        reps = sum(r["repeats"] for r in out)
        out.append({"question_type": "ALL", "sub_question_type": "", "n": total, "repeats": reps, "repeat_pct": 100.0 * reps / total})
    return out


# ------------------------------------------------------------------ ambiguities
def _size_ambiguous(record: QARecord) -> bool:
    g = record.geometry
    values = g.get("values")
    if not values or len(values) != 2:
        return False

    same, different = thresholds_for(str(g.get("quantity", "longest_side")), values)
    delta = abs(round(float(values[0]) - float(values[1]), 9))
    truth = g.get("truth")
    return same <= delta < different or (delta < same and truth != "same") or (delta >= different and truth == "same")


def _rotation_imperceptible(record: QARecord) -> bool:
    g = record.geometry
    try:
        poses = [np.asarray(g["cam_to_world_a"], dtype=np.float64), np.asarray(g["cam_to_world_b"], dtype=np.float64)]
    except KeyError:
        return False
    cams = [Camera(1.0, 1.0, 1.0, 1.0, 2, 2, p) for p in poses]
    yaw, pitch, roll = gravity_rotation(cams[0], cams[1], np.asarray(g.get("up", [0, 0, 1]), dtype=np.float64))
    angles = {"yaw": yaw, "pitch": pitch, "roll": roll}
    axes = g.get("axes") or []
    named = axes[:1] if g.get("mode") == "single" else axes[:2]
    return any(abs(angles.get(a, 0.0)) < MIN_ROTATION_DEG for a in named)


def ambiguities(records: Iterable[QARecord], scenes: Mapping[str, Any] | None = None) -> dict[str, int]:
    """Counts of records a person could not answer as stated (module docstring):
    ``label_related`` (needs ``scenes``: scene id → :class:`~spacedg.scene.model.Scene` with
    visibility; the view shows a related label or an object that shows the label unannotated,
    books on a bookshelf counted apart as ``label_shown_unannotated``), ``size_undecidable``,
    ``rotation_imperceptible``; ``checked_label_only`` says how many label-only records were
    checked against a scene."""

    lexicon = default_lexicon()
    out = {"label_related": 0, "label_shown_unannotated": 0, "size_undecidable": 0, "rotation_imperceptible": 0, "checked_label_only": 0}
    for r in records:
        if r.question_type == "object_size_comparison":
            out["size_undecidable"] += _size_ambiguous(r)
        elif r.question_type == "camera_rotation":
            out["rotation_imperceptible"] += _rotation_imperceptible(r)
        elif r.question_type in ("object_counting", "object_existence_estimation") and scenes and r.scene_id in scenes:
            if r.question_type == "object_existence_estimation" and r.answer == "yes":
                continue  # "yes" stands whatever else is in view
            scene = scenes[r.scene_id]
            view = r.views[0]
            label = str(r.geometry.get("label", ""))
            cam = scene.views[view]
            seen = [inst for inst in scene.instances
                    if classify(inst.visibility.get(view), image_area=cam.width * cam.height) is not VisibilityClass.HIDDEN]
            out["checked_label_only"] += 1
            if any(lexicon.related(label, inst.label) for inst in seen):
                out["label_related"] += 1
            elif any(lexicon.confuses(label, inst.label) for inst in seen):
                out["label_shown_unannotated"] += 1
    return out
