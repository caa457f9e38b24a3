"""Bench-level blind pruning: remove what text-only models learn from a pooled bench, iteratively.

A room has too few records per sub type to tell a small bias from noise; a bench pools many.
:func:`debias` probes the pooled records k-fold by scene with every blind predictor
(:func:`spacedg.qa.debias_probe.probe`: the stress test's five plus boosted trees, chance = 1 /
options shown) and, round after round, removes items the blind models solve, until

- every MCQ / YN / COUNT sub type's best blind accuracy is within ``chance + allowed`` (:func:`row_bound`:
  ``bound``, 3 points, or the sub type's noise band where wider, never past :data:`MAX_ALLOWED`, 4), and
- the pooled figure (each sub type's best predictor) is within ``chance + overall_bound`` (2 points),

then trims every sub type to its target size (``targets``: what the bench would hold without
pruning; the caller oversamples candidates so that the pruned bench keeps that size).

**A round.** For an eligible sub type over its allowed excess (best ``a``, chance ``c``, aim ``t = 0``: chance itself, since
the probe that picks the records also scores them, and a probe with other folds finds part of
the bias again (measured on 8 held-out rooms: +2.5 in the pruning's folds, +8.0 leave-one-scene-out
when aiming at ``bound − 1``); when no
sub type is over but the pooled figure is, the sub types above ``overall_bound − 1`` aim at
``overall_bound − 1.5``), it removes ``x = ⌈n (a − c − t) / (1 − c − t)⌉`` records (at least one,
at most a quarter of the sub type, never below ``floor`` × its target): the number that brings the
best predictor to the aim if it stayed as fitted. They are taken in order of blind solvability:
records the sub type's best predictor solves first, then by how many predictors solve them, the
boosted model's probability of the truth, and a seeded hash (so the result is a pure function of
the records and ``seed``). Then everything is probed again (the predictors refit on what remains)
and the next round starts. **Trimming**: once no sub type is over, sub types above their target
lose their surplus in a seeded random order, answer-balanced (not the most solvable first: removing
many of those plants the opposite bias, which the next probe learns; counts lose their lowest
first within a bin), and the probe runs again (an
eligible sub type pushed over its allowed excess goes back to pruning). Only the question types
that lost records are refitted (the predictors are fitted per question type). At most ``max_rounds`` rounds.

**Only what was there is pruned.** The sub types pruned for their own figure are those over their
allowed excess in the probe of the candidates (``eligible``; the pooled rule above may still take
from any sub type while the pooled figure is over), and those over it right after the trim, in
the question types the trim refitted (the trimmed bench is what a checker probes: on 8 unseen
rooms a trim from 352 to 191 records left `relpos_A_facing_B` at + 3.3, + 6.9 under a
four-fold check; pruning 9 more brought it to + 3.0); a sub type within it otherwise is never pruned later, even
if a refit after other sub types' removals pushes its figure over (measured on 12 rooms: two
rotation sub types at chance + 0.0 and + 0.8 before were chased by refit noise from 132 to 70
records, which *planted* a bias: + 14.1 and − 12.3 under an independent leave-one-scene-out probe).
**Folds.** The probe leaves one scene out (:data:`MAX_PROBE_FOLDS` folds at most: a bench of more
scenes is dealt into that many), as a blind model trained on the bench's other scenes would be
and as an outside checker probes. Five folds were used before: a per-label prior needs most
scenes to train on, and on 12 rooms the five-fold probe read `bbox_center_direction` at + 3.3
(within its band, so never pruned) where leave-one-scene-out read + 8.3.
``repeats`` fold seeds are averaged where the folds group several scenes (3 by default; 1
when every fold is one scene, since every seed then deals the same folds); a leave-one-scene-out
probe of 4 scenes or more averages in :data:`HALF_SPLITS` probes on half as many folds too (other
fold seeds), so the records pruned are those blind models solve whatever the split: pruned by
leave-one-scene-out alone, 4 unseen rooms kept `relpos_A_facing_B` at + 3.0 there but + 6.0 on
average over ten 2-fold splits. A sub type's allowed excess is ``max(bound, noise_z σ)``, σ a uniform guess's binomial
deviation at its n, but never more than :data:`MAX_ALLOWED` (4 points, one under the chance + 5 a
bench must meet): a sub type of 50 three-option records (σ 6.7) was left at + 5.8.
Removal is answer-balanced (:func:`balanced_pick`), so the letters, yes/no and count bins stay
as balanced as the selection dealt them.

**Every predictor decides, the letter one included.** Where a sub type shows its options in a
fixed order, an option-text bias is a letter bias, so the letter predictor must count. (Leaving it
out was measured on 4 rooms of an unseen seed: three sub types ended at chance + 5.5 to + 6.3 by
the letter predictor alone. Keeping it chases noise on small sub types: on 12 rooms a rotation
sub type of 131 records was pruned to 75.)

**Balance.** Records are removed whole: in a bench every record is asked under clean and under
every degradation, so the degradation balance is untouched. Sub types are pruned on their own
figures and trimmed to their targets, so their shares stay those of the unpruned bench except
where a sub type needed more pruning than the oversampling allowed (its shortfall is reported).
Metric records (NA, SIZE_LIST) are not probed; they are only trimmed to their targets (seeded order).
"""

from __future__ import annotations

import math
from collections import Counter, defaultdict
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from spacedg.errors import ParameterError
from spacedg.plugins.qa_record import QARecord
from spacedg.plugins.questions.object_counting import bin_floor
from spacedg.plugins.specs import AnswerType
from spacedg.qa.audit import answer_class, count_chances
from spacedg.qa.cell_balance import balance_cells
from spacedg.qa.mode_stats import count_distribution, format_counts
from spacedg.qa.debias_probe import (
    DISCRETE, PROBES, Probe, SubTypeBlind, blind_rows, probe, stable_hash,
)

__all__ = ["DEFAULT_BOUND", "DEFAULT_OVERALL_BOUND", "HALF_SPLITS", "MAX_ALLOWED", "MAX_PROBE_FOLDS", "OVERSAMPLE", "DebiasResult", "debias",
           "debias_pooled", "format_debias", "spread_targets"]

#: A sub type's best blind accuracy may exceed chance by this many points.
DEFAULT_BOUND = 3.0
#: The pooled best-per-sub-type accuracy may exceed chance by this many points.
DEFAULT_OVERALL_BOUND = 2.0
#: Fold seeds every probe of the pruning averages over when its folds group several scenes (a record
#: one split happens to solve weighs less); leaving one scene out, every seed deals the same folds: 1.
DEFAULT_REPEATS = 3
#: The probe's folds: one per scene up to this many scenes, this many beyond.
MAX_PROBE_FOLDS = 12
#: Probes on half as many folds (other fold seeds) the pruning's probe averages in beside its
#: leave-one-scene-out one (:func:`~spacedg.qa.debias_probe.probe` ``half_splits``), from 4 scenes.
HALF_SPLITS = 2
#: A sub type's allowed excess never exceeds this many points (the bar is chance + 5).
MAX_ALLOWED = 4.0
#: Below this many records a sub type's blind accuracy moves by 3+ points per record: the summary names such sub types.
MIN_MEASURABLE = 30
#: A sub type is pruned only above ``max(bound, noise_z × σ)``, σ a uniform guess's binomial deviation at its n.
DEFAULT_NOISE_Z = 1.0
#: The predictors whose figures decide the pruning (module docstring).
DECIDING: tuple[str, ...] = PROBES
_PRUNE = "blind models over the bound"
_TRIM = "trim to target size"
#: Candidates per target record a debiased bench export builds (``--per-sub-type`` × this).
OVERSAMPLE = 2


@dataclass
class DebiasResult:
    """:func:`debias`'s outcome: the records kept (input order), the probe before and after, and
    per round the records removed per sub type (``"question_type/sub_question_type" → n``) and why."""

    kept: list[QARecord]
    before: Probe
    after: Probe
    rounds: list[dict[str, Any]] = field(default_factory=list)
    targets: dict[tuple[str, str], int] = field(default_factory=dict)
    bound: float = DEFAULT_BOUND
    overall_bound: float = DEFAULT_OVERALL_BOUND
    noise_z: float = 0.0
    repeats: int = 1
    folds: int = 0
    half_splits: int = 0
    eligible: list[str] = field(default_factory=list)
    #: Records removed per sub type before the probe to balance the cells' roles across scenes
    #: (:func:`~spacedg.qa.cell_balance.balance_cells`; empty where the caller did not balance).
    balanced: dict[str, int] = field(default_factory=dict)

    @property
    def removed(self) -> dict[str, int]:
        """Records removed per sub type over every round (pruned and trimmed)."""
        return self._removed(None)

    @property
    def pruned(self) -> dict[str, int]:
        """Records removed per sub type because blind models solved them (not trimming)."""
        return self._removed(_PRUNE)

    def _removed(self, why: str | None) -> dict[str, int]:
        total: Counter[str] = Counter()
        for r in self.rounds:
            if why is None or r["why"] == why:
                total.update(r["removed"])
        return dict(sorted(total.items()))

    @property
    def within(self) -> bool:
        """Whether the final probe meets both bounds."""
        return not any(over_bound(r, self.bound, self.noise_z, 1e-9) for r in self.after.rows) and self.after.overall.get("excess", 0.0) <= self.overall_bound + 1e-9

    def to_dict(self) -> dict[str, Any]:
        def table(p: Probe) -> dict[str, Any]:
            rows = [{**r.to_dict(), "allowed": row_bound(r, self.bound, self.noise_z)} for r in p.rows]
            return {"rows": rows, "overall": p.overall}

        return {
            "bound": self.bound, "overall_bound": self.overall_bound, "noise_z": self.noise_z, "repeats": self.repeats, "folds": self.folds, "half_splits": self.half_splits, "max_allowed": MAX_ALLOWED,
            "within": self.within, "kept": len(self.kept), "eligible": self.eligible,
            "before": table(self.before), "after": table(self.after), "rounds": self.rounds, "removed": self.removed,
            "pruned": self.pruned, "balanced": self.balanced,
            "targets": {f"{q}/{s}": n for (q, s), n in sorted(self.targets.items())},
        }


def spread_targets(counts: Mapping[tuple[str, str], int], total: int) -> dict[tuple[str, str], int]:
    """``total`` records shared over sub types in proportion to ``counts`` (largest remainders; ties by key)."""
    whole = sum(counts.values())
    if whole <= total:
        return dict(counts)
    exact = {k: c * total / whole for k, c in counts.items()}
    out = {k: math.floor(v) for k, v in exact.items()}
    for k in sorted(exact, key=lambda k: (-(exact[k] - out[k]), k))[: total - sum(out.values())]:
        out[k] += 1
    return out


def _solvable_key(pr: Probe, best: str, seed: int) -> Callable[[QARecord], tuple[Any, ...]]:
    """Sort key: most blind-solvable first (module docstring)."""
    def key(r: QARecord) -> tuple[Any, ...]:
        hits = pr.correct.get(r.id, {})
        return (-hits.get(best, 0.0), -sum(hits.get(p, 0.0) for p in PROBES), -pr.truth_probability.get(r.id, 0.0),
                stable_hash(seed, "prune", r.id))
    return key


def _cell_role(record: QARecord) -> tuple[str | None, str]:
    """A record's selection ``(cell, role)`` (the answer text or count bin the selection balanced
    per cell), else ``(None, answer class)`` (:func:`~spacedg.qa.audit.answer_class`)."""
    entry = record.geometry.get("selection") if isinstance(record.geometry, Mapping) else None
    if isinstance(entry, Mapping) and entry.get("cell") is not None and entry.get("role") is not None:
        return str(entry["cell"]), str(entry["role"])
    return None, answer_class(record)


def balance_class(record: QARecord) -> str:
    """What a record's removal is balanced over: its selection ``cell`` and ``role`` (each cell's
    roles are balanced, by whole rounds per scene or across scenes by
    :func:`~spacedg.qa.cell_balance.balance_cells`: e.g. each compass label per assumed direction), else
    its :func:`~spacedg.qa.audit.answer_class` (letter, yes/no, count bin)."""
    return _class_name(*_cell_role(record))


def _class_name(cell: str | None, role: str) -> str:
    return role if cell is None else f"{cell}|{role}"


def balanced_pick(records: Sequence[QARecord], x: int, rank: Callable[[QARecord], Any]) -> set[str]:
    """The ids of ``x`` of ``records`` taken **balanced**: each pick comes from the
    :func:`balance_class` (cell and role) with the most records left (ties: the class whose role
    has the most records left over all cells, so the roles stay balanced pooled too, not only
    within each cell; then the class whose best record ranks first), and within it from the answer (:func:`~spacedg.qa.audit.answer_class`:
    letter, yes/no, count bin) with the most records left, in ``rank`` order. Removing them keeps
    the roles of every cell and the letters as balanced as the selection dealt them (or makes
    them more so), so pruning and trimming never plant an answer-text or letter bias of their own
    (a letter-only balance was measured to leave a compass sub type's answer texts uneven: + 7.6
    by the option-text prior after trimming 256 records to 141). Pruning and trimming both pick
    this way; when pruning, the pooled-role tie-break ranks before blind solvability among
    classes of equal size."""
    classes: dict[str, list[QARecord]] = defaultdict(list)
    role_of: dict[str, str] = {}
    roles: Counter[str] = Counter()
    for r in sorted(records, key=rank):
        cell, role = _cell_role(r)
        cls = _class_name(cell, role)  # = balance_class(r)
        classes[cls].append(r)
        role_of[cls] = role
        roles[role] += 1
    letters = Counter(answer_class(r) for r in records)
    taken: set[str] = set()
    for _ in range(min(x, len(records))):
        cls = min((c for c in classes if classes[c]), key=lambda c: (-len(classes[c]), -roles[role_of[c]], rank(classes[c][0]), c))
        queue = classes[cls]
        pick = min(range(len(queue)), key=lambda i: (-letters[answer_class(queue[i])], i))
        r = queue.pop(pick)
        letters[answer_class(r)] -= 1
        roles[role_of[cls]] -= 1
        taken.add(r.id)
    return taken


def noise_band(row: SubTypeBlind, z: float) -> float:
    """``z`` binomial standard deviations of a uniform guess's accuracy at the row's ``n``, in points:
    how far chance alone moves a sub type's figure (a row of 75 four-option MCQs: 5.0 at ``z = 1``)."""
    c = row.chance / 100.0
    return z * 100.0 * math.sqrt(max(c * (1.0 - c), 0.0) / max(row.n, 1))


def row_bound(row: SubTypeBlind, bound: float, noise_z: float) -> float:
    """The excess a sub type may keep: ``bound``, or its :func:`noise_band` where that is wider
    (pruning inside the band removes what the fitted predictors hit by luck, not a bias), but
    never more than :data:`MAX_ALLOWED` where that is over ``bound`` (a bench must keep every sub type within chance + 5)."""
    return max(bound, min(noise_band(row, noise_z), MAX_ALLOWED))


def over_bound(row: SubTypeBlind, bound: float, noise_z: float, tol: float = 0.0) -> bool:
    """Whether the sub type's excess is over its :func:`row_bound` (by more than ``tol`` points)."""
    return row.excess > row_bound(row, bound, noise_z) + tol


def _over(pr: Probe, bound: float, noise_z: float, question_types: Collection[str] | None = None) -> set[tuple[str, str]]:
    """The sub types over their allowed excess in ``pr`` (of ``question_types`` only, when given)."""
    return {row.key for row in pr.rows
            if (question_types is None or row.key[0] in question_types) and over_bound(row, bound, noise_z)}


def _aims(pr: Probe, bound: float, overall_bound: float, noise_z: float = 0.0,
          eligible: Collection[tuple[str, str]] | None = None) -> dict[tuple[str, str], float]:
    """The excess each sub type is pruned towards this round: the ``eligible`` sub types over
    their :func:`row_bound` aim at chance (0); only when none is, and the pooled figure is over
    ``overall_bound``, those above ``overall_bound − 1`` aim at ``overall_bound − 1.5``."""
    over = {row.key: 0.0 for row in pr.rows
            if over_bound(row, bound, noise_z) and (eligible is None or row.key in eligible)}
    if over or pr.overall.get("excess", 0.0) <= overall_bound:
        return over
    return {row.key: overall_bound - 1.5 for row in pr.rows if row.excess > overall_bound - 1.0}


def _to_remove(row: SubTypeBlind, aim: float) -> int:
    a, c, t = row.best_score / 100.0, row.chance / 100.0, aim / 100.0
    x = math.ceil(row.n * (a - c - t) / max(1e-6, 1.0 - c - t))
    return max(1, min(x, row.n // 4 or 1))


def _prune_round(by_key: dict[tuple[str, str], list[QARecord]], pr: Probe, floors: Mapping[tuple[str, str], int],
                 bound: float, overall_bound: float, seed: int, noise_z: float,
                 eligible: Collection[tuple[str, str]]) -> dict[str, int]:
    """Remove this round's records from ``by_key`` in place; returns ``"q/s" → removed``."""
    removed: dict[str, int] = {}
    aims = _aims(pr, bound, overall_bound, noise_z, eligible)
    for row in pr.rows:
        aim = aims.get(row.key)
        rs = by_key.get(row.key, [])
        room = len(rs) - floors.get(row.key, 0)
        if aim is None or room <= 0:
            continue
        x = min(_to_remove(row, aim), room)
        gone = balanced_pick(rs, x, _solvable_key(pr, row.best, seed))
        by_key[row.key] = [r for r in rs if r.id not in gone]
        removed[f"{row.key[0]}/{row.key[1]}"] = x
    return removed


def _trim_round(by_key: dict[tuple[str, str], list[QARecord]], targets: Mapping[tuple[str, str], int], seed: int) -> dict[str, int]:
    """Trim every sub type above its target to it, in a seeded order (a random subsample keeps the
    answer distribution: trimming the most solvable first would plant the opposite bias); returns
    ``"q/s" → removed``."""
    removed: dict[str, int] = {}
    for key, rs in by_key.items():
        surplus = len(rs) - targets.get(key, len(rs))
        if surplus > 0:
            gone = balanced_pick(rs, surplus, lambda r: (_trim_first(r), stable_hash(seed, "trim", r.id), r.id))
            by_key[key] = [r for r in rs if r.id not in gone]
            removed[f"{key[0]}/{key[1]}"] = surplus
    return removed


def _trim_first(record: QARecord) -> int:
    """Trimming order before the seeded one: a COUNT record's count above the lowest of its bin
    (the ``2+`` bin loses its twos before its sixes, as the selection asks the highest counts
    first; a random trim kept none of the few views that show five to seven), 0 for any other
    record. Relative to the bin, so the ``0`` and ``1`` classes and any ``2+`` class holding a two
    rank alike and their ties are broken by the pooled role count and the seeded hash (the
    absolute count made the ``0`` bin lose every tie: bins 33 / 50 / 54 of 137 on 6 rooms)."""
    if record.answer_type is not AnswerType.COUNT:
        return 0
    count = int(record.answer)  # type: ignore[arg-type]
    return count - bin_floor(count)


def _deciding(pr: Probe, by_key: Mapping[tuple[str, str], list[QARecord]], counts: Mapping[str, float]) -> Probe:
    """``pr`` with its rows and pooled figures over the :data:`DECIDING` predictors."""
    rows, overall = blind_rows([r for rs in by_key.values() for r in rs], pr.correct, counts, DECIDING)
    return Probe(pr.correct, pr.truth_probability, rows, overall)


def _trim_metric(records: Sequence[QARecord], targets: Mapping[tuple[str, str], int], seed: int) -> set[str]:
    """The ids of the metric ``records`` kept: per sub type its target (all without one), in a seeded order."""
    by_key: dict[tuple[str, str], list[QARecord]] = defaultdict(list)
    for r in records:
        by_key[(r.question_type, r.sub_question_type)].append(r)
    kept: set[str] = set()
    for key, rs in by_key.items():
        ordered = sorted(rs, key=lambda r: (stable_hash(seed, "trim", r.id), r.id))
        kept.update(r.id for r in ordered[: targets.get(key, len(rs))])
    return kept


def _check(bound: float, overall_bound: float, folds: int, max_rounds: int, floor: float, repeats: int, noise_z: float) -> None:
    for name, value in (("bound", bound), ("overall_bound", overall_bound)):
        if not isinstance(value, (int, float)) or isinstance(value, bool) or not 0.0 <= value <= 100.0:
            raise ParameterError(f"debias: {name} must be a number of points in [0, 100], got {value!r}")
    for name, value, low in (("folds", folds, 2), ("max_rounds", max_rounds, 0)):
        if isinstance(value, bool) or not isinstance(value, int) or value < low:
            raise ParameterError(f"debias: {name} must be an integer >= {low}, got {value!r}")
    if not isinstance(floor, (int, float)) or isinstance(floor, bool) or not 0.0 <= floor <= 1.0:
        raise ParameterError(f"debias: floor must be a share in [0, 1], got {floor!r}")
    if isinstance(repeats, bool) or not isinstance(repeats, int) or repeats < 1:
        raise ParameterError(f"debias: repeats must be an integer >= 1, got {repeats!r}")
    if isinstance(noise_z, bool) or not isinstance(noise_z, (int, float)) or not 0.0 <= noise_z <= 5.0:
        raise ParameterError(f"debias: noise_z must be a number of standard deviations in [0, 5], got {noise_z!r}")


def debias(
    records: Sequence[QARecord], targets: Mapping[tuple[str, str], int] | None = None, *, bound: float = DEFAULT_BOUND,
    overall_bound: float = DEFAULT_OVERALL_BOUND, folds: int | None = None, seed: int = 0, max_rounds: int = 20,
    floor: float = 0.5, learned: bool = True, repeats: int | None = None, noise_z: float = DEFAULT_NOISE_Z,
    half_splits: int | None = None,
) -> DebiasResult:
    """Prune ``records`` (a pooled bench) until no blind model beats chance by more than the bounds (module docstring).

    Args:
        records: question records of many scenes (metric ones are only trimmed to their targets, in a seeded order).
        targets: records wanted per ``(question_type, sub_question_type)``; default: as many as given.
        bound / overall_bound: points over chance allowed per sub type / pooled.
        folds: scene folds of the probe (``None``: one per scene, at most :data:`MAX_PROBE_FOLDS`).
            seed: the folds and the order of equals.
        max_rounds: probe-and-prune rounds at most. floor: never prune a sub type below this share of its target.
        learned: include the logistic model in the probe.
        repeats: fold seeds each probe averages over (:func:`~spacedg.qa.debias_probe.probe`; ``None``:
            1 when every fold is one scene, else :data:`DEFAULT_REPEATS`).
        noise_z: a sub type is pruned only above its noise band too (:func:`row_bound`); 0: ``bound`` alone.
        half_splits: probes on half as many folds averaged into each probe (``None``: :data:`HALF_SPLITS`
            when the folds leave one scene out of 4 or more, else 0).
    """
    scenes = len({r.scene_id for r in records})
    if folds is None:
        folds = max(2, min(scenes, MAX_PROBE_FOLDS))
    if repeats is None:
        repeats = 1 if folds >= scenes else DEFAULT_REPEATS
    _check(bound, overall_bound, folds, max_rounds, floor, repeats, noise_z)
    if half_splits is None:
        half_splits = HALF_SPLITS if folds >= scenes >= 4 else 0
    options = {"folds": folds, "seed": seed, "learned": learned, "repeats": repeats, "half_splits": half_splits}
    discrete = [r for r in records if r.answer_type in DISCRETE]
    by_key: dict[tuple[str, str], list[QARecord]] = defaultdict(list)
    for r in discrete:
        by_key[(r.question_type, r.sub_question_type)].append(r)
    metric = _trim_metric([r for r in records if r.answer_type not in DISCRETE], targets or {}, seed)
    targets = {k: int(targets.get(k, len(v))) if targets else len(v) for k, v in by_key.items()}
    floors = {k: math.ceil(floor * t) for k, t in targets.items()}
    counts = count_chances(discrete)
    current = before = probe(discrete, counts=counts, **options)
    deciding = _deciding(before, by_key, counts)
    eligible = _over(deciding, bound, noise_z)
    rounds: list[dict[str, Any]] = []
    for number in range(1, max_rounds + 1):
        removed = _prune_round(by_key, deciding, floors, bound, overall_bound, seed, noise_z, eligible)
        why = _PRUNE
        if not removed:
            removed, why = _trim_round(by_key, targets, seed), _TRIM
        if not removed:
            break
        rounds.append({"round": number, "why": why, "removed": removed, "total": sum(removed.values())})
        changed = {name.split("/", 1)[0] for name in removed}
        current = probe([r for rs in by_key.values() for r in rs], counts=counts, reuse=current, changed=changed, **options)
        deciding = _deciding(current, by_key, counts)
        if why == _TRIM:  # what the trim pushed over its allowed excess (its own records or its question type's refit) is pruned too
            eligible |= _over(deciding, bound, noise_z, changed)
    keep = {r.id for rs in by_key.values() for r in rs} | metric
    kept = [r for r in records if r.id in keep]
    return DebiasResult(kept, before, current, rounds, targets, float(bound), float(overall_bound), float(noise_z), repeats, folds, half_splits,
                        sorted(f"{q}/{t}" for q, t in eligible))


def debias_pooled(records: Sequence[QARecord], targets_for: Callable[[list[QARecord]], Mapping[tuple[str, str], int]] | None = None,
                  *, seed: int = 0, **options: Any) -> DebiasResult:
    """A bench's candidates (partial rounds, ``<id>.qa-pooled.jsonl``) pruned: every cell's roles balanced
    across the scenes first (:func:`~spacedg.qa.cell_balance.balance_cells`, reported in
    :attr:`DebiasResult.balanced`), then :func:`debias` with ``targets_for(the balanced records)``
    (``None``: no trim to a size) and ``options``."""
    balanced = balance_cells(records, seed)
    result = debias(balanced.kept, targets_for(balanced.kept) if targets_for is not None else None, seed=seed, **options)
    result.balanced = balanced.removed
    return result


def format_debias(result: DebiasResult) -> str:
    """Before/after per sub type (n, best blind, chance, excess, target, records pruned as blind-solved and
    trimmed to the target) and the records removed per round, as Markdown."""
    lines = [
        f"Blind pruning ({result.folds} folds by scene, mean over {result.repeats} fold seed(s)"
        f"{f' and {result.half_splits} splits into half as many folds' if result.half_splits else ''}; chance = 1 / options shown; bound: sub type "
        f"<= chance + min(max({result.bound:g}, {result.noise_z:g} sigma of chance at its n), {MAX_ALLOWED:g}) = 'allowed', overall <= chance + {result.overall_bound:g})",
        "| question_type | sub_question_type | type | n before | best before | n after | best after | chance | excess before | excess after "
        "| allowed | target | pruned | trimmed |",
        "|---|---|---|---:|---|---:|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    removed, pruned = result.removed, result.pruned
    for row in result.before.rows:
        after = result.after.row(row.key)
        name = f"{row.key[0]}/{row.key[1]}"
        a_n, a_best, a_excess = (after.n, f"{after.best} {after.best_score:.1f}", f"{after.excess:+.1f}") if after else (0, "", "")
        allowed = f"{row_bound(after or row, result.bound, result.noise_z):.1f}"
        lines.append(f"| {row.question_type} | {row.sub_question_type} | {row.answer_type} | {row.n} | {row.best} {row.best_score:.1f} | "
                     f"{a_n} | {a_best} | {row.chance:.1f} | {row.excess:+.1f} | {a_excess} | {allowed} | {result.targets.get(row.key, row.n)} | "
                     f"{pruned.get(name, 0)} | {removed.get(name, 0) - pruned.get(name, 0)} |")
    b, a = result.before.overall, result.after.overall
    if b.get("n"):
        lines.append(f"| ALL (MCQ+YN+COUNT) | | | {int(b['n'])} | {b['best']:.1f} | {int(a.get('n', 0))} | {a.get('best', 0.0):.1f} | "
                     f"{b['chance']:.1f} / {a.get('chance', 0.0):.1f} | {b['excess']:+.1f} | {a.get('excess', 0.0):+.1f} | {result.overall_bound:g} | "
                     f"{sum(result.targets.values())} | {sum(pruned.values())} | {sum(removed.values()) - sum(pruned.values())} |")
    if result.balanced:
        parts = ", ".join(f"{k} {v}" for k, v in result.balanced.items())
        lines.append(f"before the probe, roles balanced per cell across scenes: removed {sum(result.balanced.values())}: {parts}")
    for r in result.rounds:
        parts = ", ".join(f"{k} {v}" for k, v in sorted(r["removed"].items()))
        lines.append(f"round {r['round']} ({r['why']}): removed {r['total']}: {parts}")
    lines.append(f"pruned for blind bias (over their allowed excess before pruning, or pushed over it by the trim): {', '.join(result.eligible) or 'none'}")
    counts = count_distribution(result.kept)
    if counts:
        lines.append(f"counting answers kept: {format_counts(counts)}")
    over = [f"{r.question_type}/{r.sub_question_type}" for r in result.after.rows if over_bound(r, result.bound, result.noise_z, 1e-9)]
    lines.append("within the bounds" if result.within else f"NOT within the bounds after the last round: {', '.join(over) or 'pooled'} "
                 "(pruning stops at half a sub type's target: too few candidates there; and a sub type within its band "
                 "before pruning is not pruned: its excess is noise of the refit predictors)")
    few = [f"{r.sub_question_type} (n {r.n}, one record = {100 / r.n:.0f} points)" for r in result.after.rows if r.n < MIN_MEASURABLE]
    if few:
        lines.append(f"too few records to measure a blind bias to a few points (n < {MIN_MEASURABLE}; add scenes): {', '.join(few)}")
    return "\n".join(lines)
