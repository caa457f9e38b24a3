"""Bench-level blind pruning (issue 30 item 1): what blind models get on a pooled bench, with and without it.

Builds the bench records exactly as ``spacedg export --split bench --all-bench`` does before it
renders (so no image is rendered here):

- **plain**: ``--no-debias``: the indexes at ``--per-sub-type`` (read from ``--plain``; without
  ``--plain`` the table's "plain" columns are the oversampled candidates before pruning);
- **debiased**: the default: indexes at ``OVERSAMPLE × --per-sub-type`` with partial rounds (``<id>.qa-pooled.jsonl``,
  built in ``--candidates``: the same folders as ``--plain`` or copies), pruned by
  :func:`spacedg.data.bench_debias.debias_dataset`.

Both are then probed by two checks with the same predictors: leave-one-scene-out (what an outside
checker trained on the bench's other scenes measures; up to 12 scenes these are the pruning's own
folds) and half as many folds of whole scenes on another fold seed (folds the pruning never saw);
chance = 1 / options shown. Prints the table per sub type (n, best blind, chance, excess, before and after), the
records each round removed, the answer balance (letters, yes/no, counts) before and after, and
writes ``--json``.

    .venv/bin/python benchmarks/debias_bench.py --plain rooms100 rooms200 --candidates cand100 cand200
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from spacedg.data.bench_debias import OVERSAMPLE, debias_dataset  # noqa: E402
from spacedg.data.dataset import SpaceDGDataset  # noqa: E402
from spacedg.qa.debias import MAX_PROBE_FOLDS, format_debias  # noqa: E402
from spacedg.qa.debias_probe import probe  # noqa: E402
from spacedg.qa.index import QABuildConfig  # noqa: E402


def _bench(scenes: list[Path], per_sub_type: int, seed: int, partial_rounds: bool = False) -> SpaceDGDataset:
    return SpaceDGDataset("bench", scenes=scenes, split_fractions=(0.0, 1.0), seed=seed,
                          qa_config=QABuildConfig(seed=seed, per_sub_type=per_sub_type, partial_rounds=partial_rounds))


def _half_check_kind(records, check: tuple[int, int], result, seed: int) -> str:
    """Whether the half-folds check deals the scenes as one of the pruning's own half splits (then it is in-sample)."""
    from spacedg.qa.debias_probe import half_split_plans, scene_folds

    scene_ids = [r.scene_id for r in records]
    def split(folds: int, fold_seed: int) -> set[frozenset[str]]:
        return {frozenset(group) for group in scene_folds(scene_ids, folds, fold_seed)}
    own = [split(*plan) for plan in half_split_plans(scene_ids, seed, result.half_splits)]
    return "the same split as one the pruning averaged in: in-sample" if split(*check) in own else "folds the pruning never used"


def _table(plain, debiased, removed) -> str:
    lines = ["| sub type | type | n plain | best plain | chance | excess plain | n debiased | best debiased | excess debiased | pruned |",
             "|---|---|---:|---|---:|---:|---:|---|---:|---:|"]
    for row in plain.rows:
        after = debiased.row(row.key)
        name = f"{row.key[0]}/{row.key[1]}"
        cells = (after.n, f"{after.best} {after.best_score:.1f}", f"{after.excess:+.1f}") if after else (0, "", "")
        lines.append(f"| {name} | {row.answer_type} | {row.n} | {row.best} {row.best_score:.1f} | {row.chance:.1f} | {row.excess:+.1f} | "
                     f"{cells[0]} | {cells[1]} | {cells[2]} | {removed.get(name, 0)} |")
    p, d = plain.overall, debiased.overall
    lines.append(f"| ALL (MCQ+YN+COUNT) | | {int(p['n'])} | {p['best']:.1f} | {p['chance']:.1f} / {d['chance']:.1f} | {p['excess']:+.1f} | "
                 f"{int(d['n'])} | {d['best']:.1f} | {d['excess']:+.1f} | {sum(removed.values())} |")
    return "\n".join(lines)


def _shares(records) -> dict:
    """Per discrete sub type: n and the largest minus the smallest answer share (letters, yes/no, counts), percent."""
    from collections import Counter, defaultdict

    from spacedg.qa.debias_probe import DISCRETE

    groups = defaultdict(Counter)
    for r in records:
        if r.answer_type in DISCRETE:
            groups[(r.question_type, r.sub_question_type)][str(r.answer)] += 1
    return {k: (sum(c.values()), c) for k, c in sorted(groups.items())}


def _balance(before, after) -> str:
    """Answer balance before and after: per sub type the answers' counts (letters, yes/no, counts)."""
    lines = ["Answer balance (counts per correct answer; before -> after):"]
    b, a = _shares(before), _shares(after)
    for key, (n, counts) in b.items():
        n2, c2 = a.get(key, (0, {}))
        fmt = lambda c: " ".join(f"{k}:{c[k]}" for k in sorted(c))  # noqa: E731
        lines.append(f"  {key[0]}/{key[1]}: n {n} [{fmt(counts)}] -> n {n2} [{fmt(c2)}]")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--plain", type=Path, nargs="+", default=None,
                        help="scene folders (or folders of them): indexes at --per-sub-type (default: no plain bench, debiased only)")
    parser.add_argument("--candidates", type=Path, nargs="+", required=True,
                        help="folders of the same scenes (or --plain's): oversampled indexes with partial rounds (<id>.qa-pooled.jsonl)")
    parser.add_argument("--per-sub-type", type=int, default=25)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--check-seed", type=int, default=1, help="fold seed of the independent check")
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    cand = _bench(args.candidates, args.per_sub_type * OVERSAMPLE, args.seed, partial_rounds=True)
    plain = _bench(args.plain, args.per_sub_type, args.seed) if args.plain else None
    scenes = len(cand.scene_dirs)
    before_records = list(plain.records if plain else cand.records)
    checks = {"loso": (scenes, args.check_seed)}
    if scenes >= 4:  # half as many folds on a fold seed of its own (with 2-3 scenes two folds are nearly leave-one-out)
        checks["half"] = (scenes // 2, args.check_seed + 6)
    before_checks = {name: probe(before_records, folds=f, seed=sd) for name, (f, sd) in checks.items()}
    started = time.perf_counter()
    result = debias_dataset(cand, args.per_sub_type, None, args.seed)
    seconds = time.perf_counter() - started
    print(f"{scenes} scenes; plain bench {len(plain.records) if plain else '-'} records; candidates {len(result.before.correct)} discrete "
          f"-> debiased bench {len(cand.records)} records ({seconds:.0f} s, {len(result.rounds)} rounds)\n")
    print(format_debias(result) + "\n")
    after_checks = {name: probe(cand.records, folds=f, seed=sd) for name, (f, sd) in checks.items()}
    same = f" (the pruning's own folds: it leaves one scene out up to {MAX_PROBE_FOLDS} scenes)" if scenes <= MAX_PROBE_FOLDS else ""
    titles = {"loso": f"Check: leave-one-scene-out, fold seed {args.check_seed}{same}"}
    if "half" in checks:
        titles["half"] = f"Check: {checks['half'][0]} folds of whole scenes, fold seed {checks['half'][1]} ({_half_check_kind(cand.records, checks['half'], result, args.seed)})"
    for name in checks:
        print(f"{titles[name]}; chance = 1 / options shown; 'plain' = {'the --no-debias bench' if plain else 'the candidates before pruning'}; "
              "pruned: removed as blind-solved, trimming not counted:")
        print(_table(before_checks[name], after_checks[name], result.pruned) + "\n")
    print(_balance(plain.records if plain else before_records, cand.records))
    if args.json:
        out = {"scenes": sorted(cand.scene_dirs), "debias": result.to_dict()}
        for name in checks:
            out[f"check_{name}_plain"] = [r.to_dict() for r in before_checks[name].rows]
            out[f"check_{name}_plain_overall"] = before_checks[name].overall
            out[f"check_{name}_debiased"] = [r.to_dict() for r in after_checks[name].rows]
            out[f"check_{name}_debiased_overall"] = after_checks[name].overall
        args.json.write_text(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
