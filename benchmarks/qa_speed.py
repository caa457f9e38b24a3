"""Question generation before/after: time of ``qa build``'s generation stage and byte identity.

Prints numbers only (never part of the test run).

    .venv/bin/python benchmarks/qa_speed.py --base /tmp/qa-base            # 4 demo rooms + 4 rooms of seed 20
    .venv/bin/python benchmarks/qa_speed.py --base /tmp/qa-base --rooms DIR [DIR ...] --no-profile
    .venv/bin/python benchmarks/qa_speed.py --base /tmp/qa-41e7ace --same-as /tmp/qa-456f964 --rooms DIR ... --mode train

Issue 31's measurement: ``--base`` a checkout of 41e7ace (before issue 31's work), ``--same-as``
one of 456f964 (the indexes this code must equal byte for byte: main before the light
candidates; 41e7ace's indexes differ on purpose, version 4). ``--mode train`` times the dense
train selection (``<id>.qa-train.jsonl``).

When the new indexes differ from ``--same-as``'s (a change of the order of draws, e.g. the pool's
gate of index version 7), the run shows the **equivalence** instead: per sub type the records
of both (counts, the most common answer's share, the independent re-derivation of every answer
by ``tests/plugins/questions/test_recompute.py``'s checker) and the blind audit's excess over
chance (:func:`~spacedg.qa.audit.blind_audit`, leave one scene out over every room timed), side by side.

``--base`` is a checkout of the reference code (``git worktree add /tmp/qa-base 41e7ace``). The
rooms are the built-in synthetic rooms (``spacedg scenes synth``: seeds 0–3, the demo rooms, and
``--other-seed`` … +3), generated once into ``--work`` (default ``/tmp/qa-speed``) unless given
with ``--rooms``. Both checkouts build every room's index (:func:`~spacedg.qa.build.build_scene_index`, default
settings, one process, ``NUMBA_NUM_THREADS=1``) in their own interpreter (``PYTHONPATH``),
alternately ``--repeats`` times (default 3: base, new, new, base, …), with the visibility and
covisibility caches in place (``_rooms`` fills them with a first ``qa build``), so what differs is
question generation. Each round's ratio is printed as it ends; the tables take each room's fastest
run per side (the same generation of a room varied by up to 50 % between runs on a shared
2-core machine, a few-second run most). Per room: records, the CPU seconds
(``time.process_time``) and wall seconds of each build, their ratios, and whether the two
``<scene>.qa.jsonl`` files have the same SHA-256. Then the new code's
generation of one room under cProfile (``NUMBA_NUM_THREADS=1``): the top functions by own time.
"""

from __future__ import annotations

import argparse
import cProfile
import hashlib
import io
import json
import os
import pstats
import subprocess
import sys
import time
from collections.abc import Iterable
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]


def _env(code: Path) -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": str(code), "NUMBA_NUM_THREADS": "1"}


def _spacedg(code: Path, *args: str) -> None:
    """``spacedg ARGS`` with ``code`` first on the path (its own interpreter)."""
    subprocess.run([sys.executable, "-m", "spacedg", *args], env=_env(code), check=True, stdout=subprocess.DEVNULL, cwd=code)


def _rooms(work: Path, seed: int, n: int, code: Path) -> list[Path]:
    out = work / f"seed{seed}"
    if not out.is_dir():
        _spacedg(code, "scenes", "synth", "--n", str(n), "--out", str(out), "--seed", str(seed))
        _spacedg(code, "qa", "build", str(out), "--out", str(work / f"cache{seed}"), "--jobs", "1")  # the caches
    return sorted(p for p in out.iterdir() if (p / "scene.json").is_file())


#: Run in the checkout's own interpreter: build each room's index (``--force``; visibility and
#: covisibility from the rooms' caches, filled by an earlier build) and print scene id →
#: [records, wall s, CPU s of its generation (``generate_records``)].
_CHILD = """
import json, sys, time
import spacedg, spacedg.qa.build as build
print("imported", spacedg.__file__, file=sys.stderr)
from spacedg.qa.index import QABuildConfig, selected_families
selected_families(None)  # the plugin registry, loaded once before timing
plain, spent = build.generate_records, []

def timed(*args, **kwargs):
    w, c = time.perf_counter(), time.process_time()
    records = plain(*args, **kwargs)
    spent.append((time.perf_counter() - w, time.process_time() - c))
    return records

build.generate_records = timed  # what build_scene_index calls: generation only, not the visibility
out = {}
for room in sys.argv[3:]:
    config = QABuildConfig() if sys.argv[2] == "bench" else QABuildConfig(mode=sys.argv[2])  # older checkouts: no mode
    qa = build.build_scene_index(room, config, out_dir=sys.argv[1], force=True, progress=False)
    out[qa.scene_id] = [len(qa.records), *spent.pop()]
print(json.dumps(out))
"""


def _build(code: Path, rooms: list[Path], out: Path, mode: str = "bench") -> dict[str, tuple[int, float, float, str]]:
    """scene id → (records, wall s, CPU s, sha256 of ``<scene>.qa.jsonl`` or ``.qa-train.jsonl``) of
    building every room's index with ``code``."""
    done = subprocess.run(
        [sys.executable, "-c", _CHILD, str(out), mode, *map(str, rooms)], env=_env(code), capture_output=True, text=True,
        cwd=code,  # ``-c`` puts the working directory first on sys.path: it must be the checkout timed
    )
    if done.returncode != 0:
        raise SystemExit(f"{code}: the build failed\n{done.stderr[-3000:]}")
    if f"imported {Path(code).resolve() / 'spacedg'}" not in done.stderr:
        raise SystemExit(f"{code}: the child did not import this checkout's spacedg\n{done.stderr[-2000:]}")
    result = {}
    for scene, (n, wall, cpu) in json.loads(done.stdout.strip().splitlines()[-1]).items():
        result[scene] = (n, wall, cpu, hashlib.sha256(_index_file(out, scene, mode).read_bytes()).hexdigest())
    return result


def _alternated(base_code: Path, rooms: list[Path], work: Path, group: int, mode: str, repeats: int) -> tuple[dict, dict]:
    """Build every room with ``base_code`` and with this checkout, alternately, ``repeats`` times
    (base, new, new, base, …: a slow spell or a drift of the machine hits both sides); returns each
    side's per-room :func:`_build` result with the **fastest** wall and the fastest CPU time of its
    runs (each its own minimum, possibly of different runs: a loaded machine only ever adds time,
    and a run of a few seconds is hit hardest). Prints each round's ratio of the sums, so the
    spread is visible. Every run of a side must give the same index bytes."""
    runs: dict[str, list[dict]] = {"base": [], "new": []}
    sides = {"base": (base_code, work / f"base{group}"), "new": (HERE, work / f"new{group}")}
    for rep in range(repeats):
        for side in ("base", "new") if rep % 2 == 0 else ("new", "base"):  # base, new, new, base, …
            code, out = sides[side]
            runs[side].append(_build(code, rooms, out, mode))
        if repeats > 1:
            cpu = [sum(r[2] for r in runs[side][-1].values()) for side in ("base", "new")]
            print(f"  round {rep + 1}/{repeats}: base {cpu[0]:.2f} s, new {cpu[1]:.2f} s of CPU: {cpu[0] / cpu[1]:.1f}x", flush=True)
    fastest = []
    for side, results in runs.items():
        merged = {}
        for scene, (n, _, _, sha) in results[0].items():
            if any(r[scene][3] != sha for r in results):
                raise SystemExit(f"{side}: {scene}'s index differs between runs of the same code")
            merged[scene] = (n, min(r[scene][1] for r in results), min(r[scene][2] for r in results), sha)
        fastest.append(merged)
    return fastest[0], fastest[1]


def _compare(label: str, base: dict, new: dict, reference: dict | None = None) -> tuple[float, float, bool]:
    """Print the per-room table (``identical``: the new index equals ``reference``'s, default
    ``base``'s, byte for byte); returns (base CPU s, new CPU s, every index identical)."""
    what = "identical" if reference is None else "same as --same-as"
    print(f"\n{label}\n{'scene':<14}{'records':>8}{'base CPU s':>11}{'new CPU s':>10}{'ratio':>7}"
          f"{'base wall s':>12}{'new wall s':>11}{'ratio':>7}  {what}")
    tb = tn = wb = wn = 0.0
    same_all = True
    for scene in sorted(base):
        (nb, wall_b, cpu_b, _), (nn, wall_n, cpu_n, hn) = base[scene], new[scene]
        ref = (reference or base)[scene]
        same = ref[3] == hn and ref[0] == nn
        same_all &= same
        tb, tn, wb, wn = tb + cpu_b, tn + cpu_n, wb + wall_b, wn + wall_n
        print(f"{scene:<14}{nb:>8}{cpu_b:>11.2f}{cpu_n:>10.2f}{cpu_b / cpu_n:>6.1f}x"
              f"{wall_b:>12.2f}{wall_n:>11.2f}{wall_b / wall_n:>6.1f}x  {'yes' if same else 'NO'}")
    print(f"{'all':<14}{'':>8}{tb:>11.2f}{tn:>10.2f}{tb / tn:>6.1f}x{wb:>12.2f}{wn:>11.2f}{wb / wn:>6.1f}x  {'yes' if same_all else 'NO'}")
    return tb, tn, same_all


def _index_records(out: Path, scene_ids: Iterable[str], mode: str) -> dict[str, list]:
    """scene id → the records of its index in ``out`` (built by :func:`_build`)."""
    from spacedg.qa.index import read_index

    return {scene_id: read_index(_index_file(out, scene_id, mode)) for scene_id in scene_ids}


def _index_file(out: Path, scene_id: str, mode: str) -> Path:
    """The index file :func:`_build` writes for ``scene_id`` in ``mode``."""
    from spacedg.qa.index import index_paths

    return index_paths(scene_id, out, mode=mode)[0]


def _rederive(records_by_scene: dict[str, list], scenes: dict[str, object]) -> int:
    """Answers the tests' independent checker (``tests/plugins/questions/test_recompute.py``, which
    shares no code with the families) disagrees with, or fails on: 0 when every answer re-derives."""
    if str(HERE) not in sys.path:
        sys.path.append(str(HERE))  # the checker lives with the tests
    from tests.plugins.questions import test_recompute as checker

    bad = 0
    for scene_id, records in records_by_scene.items():
        for record in records:
            try:
                checker.recomputes(record, scenes[scene_id])
            except Exception:  # noqa: BLE001 - any failure of the check is a disagreement, counted
                bad += 1
    return bad


def _top_share(records: list) -> str:
    """The most common answer's share of a discrete sub type, as ``"north 14 %"``: the correct
    option's text for MCQ (its letter is dealt evenly anyway), yes/no, counts; '' for metric answers."""
    from collections import Counter

    from spacedg.plugins.specs import AnswerType
    from spacedg.qa.audit_text import truth_text

    if not records or records[0].answer_type not in (AnswerType.MCQ, AnswerType.YN, AnswerType.COUNT):
        return ""
    answer, n = Counter(map(truth_text, records)).most_common(1)[0]
    return f"{answer[:10]} {100 * n / len(records):.0f} %"


def _equivalence(reference: dict[str, list], new: dict[str, list], rooms: list[Path]) -> None:
    """Print the two index sets side by side per sub type (module docstring)."""
    from spacedg.qa.audit import blind_audit
    from spacedg.scene.io import load_scene

    scenes = {scene.id: scene for scene in map(load_scene, rooms)}

    def by_sub(records_by_scene: dict[str, list]) -> dict[tuple[str, str], list]:
        out: dict[tuple[str, str], list] = {}
        for records in records_by_scene.values():
            for r in records:
                out.setdefault((r.question_type, r.sub_question_type), []).append(r)
        return out

    subs_ref, subs_new = by_sub(reference), by_sub(new)
    reports = [blind_audit(x) for x in (reference, new)]
    audits = [{(row.question_type, row.sub_question_type): row for row in report.rows} for report in reports]
    bad_ref, bad_new = _rederive(reference, scenes), _rederive(new, scenes)
    print(f"\nequivalence over {len(new)} rooms (--same-as vs this checkout): re-derivation disagreements {bad_ref} / {bad_new}; "
          "blind excess = best text-only predictor over chance, leave one scene out (points)")
    print(f"{'question_type/sub_question_type':<58}{'records':>13}{'most common answer':>36}{'blind excess':>16}")
    for key in sorted(set(subs_ref) | set(subs_new)):
        a, b = subs_ref.get(key, []), subs_new.get(key, [])
        ex = [getattr(audit.get(key), "excess", None) for audit in audits]
        excess = " / ".join("" if e is None else f"{e:+.1f}" for e in ex) if any(e is not None for e in ex) else ""
        top_a, top_b = _top_share(a), _top_share(b)
        shares = f"{top_a} / {top_b}" if top_a or top_b else ""
        print(f"{'/'.join(key):<58}{f'{len(a)} / {len(b)}':>13}{shares:>36}{excess:>16}")
    overall = [report.overall.get("excess") for report in reports]
    print(f"{'ALL (MCQ+YN+COUNT)':<58}{f'{sum(map(len, subs_ref.values()))} / {sum(map(len, subs_new.values()))}':>13}{'':>36}"
          f"{' / '.join('' if e is None else f'{e:+.1f}' for e in overall):>16}")


def _family_split(scene, mode: str) -> None:
    """The new code's generation of one prepared scene, per family: candidates pooled, records
    kept and CPU seconds (pooling, selection and building together; a second generation in this
    process, so the per-process caches are warm)."""
    import spacedg.qa.build as build
    from spacedg.qa.index import QABuildConfig

    plain_pool, plain_family = build._pool, build._family_records
    rows: dict[str, list] = {}

    def pool(family, *args, **kwargs):
        pooled = plain_pool(family, *args, **kwargs)
        rows.setdefault(family.name, [0, 0, 0.0])[0] = len(pooled)
        return pooled

    def family_records(family, *args, **kwargs):
        t = time.process_time()
        records = plain_family(family, *args, **kwargs)
        row = rows.setdefault(family.name, [0, 0, 0.0])
        row[1], row[2] = len(records), time.process_time() - t
        return records

    build._pool, build._family_records = pool, family_records
    try:
        t = time.process_time()
        build.generate_records(scene, QABuildConfig(mode=mode))
        total = time.process_time() - t
    finally:
        build._pool, build._family_records = plain_pool, plain_family
    print(f"\ngeneration of {scene.id} per family (CPU s, no profiler; pooled = candidates the selection reads)")
    print(f"{'family':<36}{'pooled':>8}{'kept':>6}{'CPU s':>8}{'share':>7}")
    for name, (pooled, kept, spent) in sorted(rows.items(), key=lambda kv: -kv[1][2]):
        print(f"{name:<36}{pooled:>8}{kept:>6}{spent:>8.3f}{100 * spent / total:>6.0f}%")
    print(f"{'all (with the pass over families)':<36}{sum(r[0] for r in rows.values()):>8}{sum(r[1] for r in rows.values()):>6}{total:>8.3f}")


def _profile(room: Path, top: int, mode: str = "bench") -> None:
    """The new code's generation of ``room`` under cProfile (top functions by own time), then again per family (:func:`_family_split`)."""
    from spacedg.qa.build import generate_records, prepare_scene
    from spacedg.qa.index import QABuildConfig
    from spacedg.scene.io import load_scene

    scene = prepare_scene(load_scene(room), room / "cache", QABuildConfig(mode=mode), progress=False)
    profile = cProfile.Profile()
    t0 = time.perf_counter()
    profile.enable()
    records = generate_records(scene, QABuildConfig(mode=mode))
    profile.disable()
    print(f"\nprofile of {room.name}: {len(records)} records in {time.perf_counter() - t0:.2f} s under cProfile")
    text = io.StringIO()
    pstats.Stats(profile, stream=text).sort_stats("tottime").print_stats(top)
    print("\n".join(line for line in text.getvalue().splitlines() if line.strip())[-6000:])
    _family_split(scene, mode)  # after the profile, so the profile is a first (cold-cache) generation


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--base", type=Path, required=True, help="checkout of the reference code")
    parser.add_argument("--same-as", type=Path, default=None,
                        help="checkout whose indexes the new ones must equal byte for byte (default: --base), e.g. the "
                        "branch this one merged when its outputs changed on purpose; timed too")
    parser.add_argument("--work", type=Path, default=Path("/tmp/qa-speed"))
    parser.add_argument("--rooms", type=Path, nargs="*", help="room folders (default: generate the demo rooms and --other-seed rooms)")
    parser.add_argument("--other-seed", type=int, default=20)
    parser.add_argument("--n", type=int, default=4, help="rooms per seed")
    parser.add_argument("--mode", choices=("bench", "train"), default="bench", help="the selection timed (qa build --mode)")
    parser.add_argument("--repeats", type=int, default=3,
                        help="builds per side, alternating base and new; the tables take each room's fastest (default 3)")
    parser.add_argument("--no-profile", action="store_true")
    parser.add_argument("--top", type=int, default=20)
    args = parser.parse_args()
    if args.repeats < 1:
        parser.error(f"--repeats must be at least 1, got {args.repeats}")
    groups = {"given rooms": args.rooms} if args.rooms else {
        "demo rooms (seeds 0-3)": _rooms(args.work, 0, args.n, HERE),
        f"rooms of seed {args.other_seed}": _rooms(args.work, args.other_seed, args.n, HERE),
    }
    totals = [0.0, 0.0]
    pairs: list[tuple[dict, dict]] = []
    for i, (label, rooms) in enumerate(groups.items()):
        base, new = _alternated(args.base, rooms, args.work, i, args.mode, args.repeats)
        if args.same_as is not None:
            same = _build(args.same_as, rooms, args.work / f"same{i}", args.mode)
            _compare(f"{label}: --same-as {args.same_as} (reference of the identity) vs this checkout", same, new)
            if any(same[scene][3] != new[scene][3] for scene in new):
                pairs.append((_index_records(args.work / f"same{i}", same, args.mode), _index_records(args.work / f"new{i}", new, args.mode)))
        tb, tn, _ = _compare(f"{label}: --base {args.base} vs this checkout", base, new, same if args.same_as else None)
        totals[0] += tb
        totals[1] += tn
    print(f"\ngeneration CPU, every room: base {totals[0]:.1f} s, new {totals[1]:.1f} s: {totals[0] / totals[1]:.1f}x faster")
    if pairs:
        all_rooms = [room for rooms in groups.values() for room in rooms]
        _equivalence({k: v for ref, _ in pairs for k, v in ref.items()}, {k: v for _, new in pairs for k, v in new.items()}, all_rooms)
    if not args.no_profile:
        _profile(next(iter(groups.values()))[0], args.top, args.mode)


if __name__ == "__main__":
    main()
