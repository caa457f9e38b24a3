"""Per-scene question index: every family's records for a scene, built from a seed, stored as JSONL.

Building one scene (:func:`build_scene_index`):

1. load the scene folder; attach per-view instance visibility and the view covisibility
   matrix, both cached in ``<scene>/cache/`` (``*.visibility.npz``, ``*.covisibility.npz``);
2. for every selected family (sorted by name), run ``family.generate(scene, rng)`` with
   ``rng = default_rng(derive_seed(seed, scene_id, family))``: the records are seeded per
   (scene, family), so adding a family never changes another family's records;
3. pool up to ``pool_factor × per_sub_type`` candidates per ``sub_question_type`` (no more
   than ``max_scan`` per family) and take ``per_sub_type`` of them round-robin over the correct
   answers (option text, yes/no, count), so a blind model cannot profit from one answer being
   common where the scene offers alternatives; an optional judge
   (:class:`~spacedg.data.judge.DescriptionJudge`) drops records whose descriptions it finds
   ambiguous (asked only about records being taken);
4. write ``<out>/<scene id>.qa.jsonl`` (one :class:`QARecord` per line, families in name
   order) and ``<out>/<scene id>.qa.meta.json`` (key, config, counts, timings) atomically.
   ``out`` defaults to the scene folder itself.

**Full index and selection indexes** (:func:`index_paths`). The *full* index
``<scene id>.qa.jsonl`` holds every registered family (``QABuildConfig.families`` empty): it is
what :class:`~spacedg.data.dataset.SpaceDGDataset` reads by default, what exports and the review
page find. A build restricted to some families (``families=("a", "b")``, ``spacedg qa build
--families a,b``) writes a *selection index* beside it, ``<scene id>.qa.a+b.jsonl`` with
``<scene id>.qa.a+b.meta.json`` (names sorted and joined by ``+``; a selection longer than
:data:`MAX_SELECTION_CHARS` characters is named ``families-<12 hex of its SHA-1>``), and never
touches the full index. Records are seeded per (scene, family), so a selection index holds
exactly the records that family selection has in the full index built with the same settings:
writing it apart loses nothing, while replacing or merging into the full index would leave one
file whose meta key no longer describes its content. A dataset built with
``qa_config=QABuildConfig(families=...)`` reads (and builds) that selection's index.

An index is **reused** when its meta file's key matches: the key hashes the index version,
the build config, the SHA-256 of ``scene.json`` (views, poses, instances) and the selected
families with the distributions and versions that provide them and the SHA-256 of each
family's module source (and the judge's name). Any
change rebuilds it; ``force=True`` always does.
"""

from __future__ import annotations

import hashlib
import importlib.util
import json
import time
from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from spacedg.plugins.guard import plugin_call
from spacedg.plugins.qa_record import QARecord
from spacedg.scene.model import Scene
from spacedg.errors import FileFormatError, ParameterError
from spacedg.plugins.specs import NAME_PATTERN, AnswerType

__all__ = [
    "QA_INDEX_VERSION", "QABuildConfig", "SceneQA", "prepare_scene", "generate_records",
    "MAX_SELECTION_CHARS", "selection_name", "index_paths", "build_scene_index", "read_index", "truth_key", "index_is_current", "ensure_indexes",
]

#: Bump when the index layout or the build procedure changes (part of the key).
QA_INDEX_VERSION = 2


@dataclass(frozen=True)
class QABuildConfig:
    """How a scene's question index is built.

    Attributes:
        seed: master seed; each (scene, family) draws from ``derive_seed(seed, scene, family)``.
        families: family names to run (empty = every registered family, the *full* index);
            stored sorted and without repeats. A non-empty selection has an index file of its
            own (:func:`index_paths`).
        per_sub_type: at most this many records per ``sub_question_type`` and family.
        max_scan: at most this many candidates examined per family.
        pool_factor: candidates pooled per sub type, as a multiple of ``per_sub_type``, for
            answer balancing (1 = no balancing: the first ``per_sub_type`` in seeded order).
        visibility_size: reduced render size (width, height) px for instance visibility.
        covisibility_size: reduced render size (width, height) px for covisibility.
    """

    seed: int = 0
    families: tuple[str, ...] = ()
    per_sub_type: int = 25
    max_scan: int = 20_000
    pool_factor: int = 8
    visibility_size: tuple[int, int] = (160, 120)
    covisibility_size: tuple[int, int] = (80, 60)

    def __post_init__(self) -> None:
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise ParameterError(f"QABuildConfig: seed must be an integer >= 0, got {self.seed!r}")
        for name in ("per_sub_type", "max_scan", "pool_factor"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ParameterError(f"QABuildConfig: {name} must be a positive integer, got {value!r}")
        if isinstance(self.families, str):
            raise ParameterError(f"QABuildConfig: families must be a sequence of family names, not one string ({self.families!r})")
        object.__setattr__(self, "families", tuple(sorted(set(self.families))))
        object.__setattr__(self, "visibility_size", tuple(self.visibility_size))
        object.__setattr__(self, "covisibility_size", tuple(self.covisibility_size))

    def to_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["families"] = list(self.families)
        out["visibility_size"] = list(self.visibility_size)
        out["covisibility_size"] = list(self.covisibility_size)
        return out


@dataclass
class SceneQA:
    """The result of indexing one scene."""

    scene_id: str
    path: Path
    records: list[QARecord]
    reused: bool
    seconds: dict[str, float] = field(default_factory=dict)
    dropped: dict[str, int] = field(default_factory=dict)

    def counts(self) -> dict[str, int]:
        return dict(sorted(Counter(r.question_type for r in self.records).items()))


# ------------------------------------------------------------------ building
def _families(names: Sequence[str]) -> list[Any]:
    from spacedg.plugins import get_question_family, list_question_families

    if not names:
        return list_question_families()
    return [get_question_family(n) for n in sorted(set(names))]


def prepare_scene(
    scene: Scene,
    cache_dir: str | Path | None,
    config: QABuildConfig = QABuildConfig(),
    *,
    backend: str = "auto",
    progress: bool = True,
    timings: dict[str, float] | None = None,
) -> Scene:
    """``scene`` with visibility and covisibility attached (cached under ``cache_dir`` if given).

    First the scene's frame is checked (a scene whose cameras see nothing is refused, naming the
    cause) and Gaussians without instance ids get them by box containment (with a warning)."""
    from spacedg.scene.covisibility import with_covisibility
    from spacedg.scene.frame_check import require_frame
    from spacedg.scene.labelling import ensure_instance_ids
    from spacedg.scene.visibility import compute_visibility, load_or_compute_visibility, with_visibility

    require_frame(scene, backend=backend)
    scene = ensure_instance_ids(scene)
    t0 = time.perf_counter()
    if cache_dir is None:
        table = compute_visibility(scene, image_size=config.visibility_size, backend=backend, progress=progress)
    else:
        table = load_or_compute_visibility(scene, cache_dir, image_size=config.visibility_size, backend=backend, progress=progress)
    scene = with_visibility(scene, table)
    t1 = time.perf_counter()
    scene = with_covisibility(scene, cache_dir, image_size=config.covisibility_size, backend=backend, progress=progress)
    if timings is not None:
        timings["visibility_s"] = t1 - t0
        timings["covisibility_s"] = time.perf_counter() - t1
    return scene


def truth_key(record: QARecord) -> str | None:
    """What answer balancing groups by: the correct option's text (MCQ), the answer (YN, COUNT),
    or ``None`` for metric answers (NA, SIZE_LIST), which are not balanced."""
    if record.answer_type is AnswerType.MCQ:
        letter = str(record.answer)
        return next((o[3:] for o in record.options if o.startswith(letter + ". ")), letter)
    if record.answer_type in (AnswerType.YN, AnswerType.COUNT):
        return str(record.answer)
    return None


def _select_balanced(pool: list[QARecord], cap: int, keep: Any) -> list[QARecord]:
    """Up to ``cap`` records of one sub type, round-robin over truth buckets (first-seen order).

    Each bucket is consumed in generation order; ``keep(record)`` (the judge) is asked only for
    records about to be taken. The result is returned in generation order.
    """
    buckets: dict[str | None, list[int]] = {}
    for i, record in enumerate(pool):
        buckets.setdefault(truth_key(record), []).append(i)
    queues = [list(reversed(ix)) for ix in buckets.values()]
    taken: list[int] = []
    while len(taken) < cap and any(queues):
        for queue in queues:
            while queue and len(taken) < cap:
                i = queue.pop()
                if keep(pool[i]):
                    taken.append(i)
                    break
    return [pool[i] for i in sorted(taken)]


def generate_records(
    scene: Scene,
    config: QABuildConfig = QABuildConfig(),
    *,
    judge: Any = None,
    dropped: dict[str, int] | None = None,
) -> list[QARecord]:
    """Records of every selected family for a prepared scene (see the module docstring).

    Per family, candidates are pooled (up to ``pool_factor × per_sub_type`` per sub type,
    ``max_scan`` in all); then each sub type takes ``per_sub_type`` records round-robin over
    its truth buckets (:func:`truth_key`: the correct option's text, the yes/no or count
    answer), so no single answer dominates where the candidates allow; metric answers are
    taken in generation order.

    ``judge``: a callable ``judge(image, label, description) -> "KEEP"/"DROP"`` or a
    :class:`~spacedg.data.judge.DescriptionJudge`, asked only about records being taken;
    ``dropped`` receives per-family counts of records the judge removed.
    """
    from spacedg.data.judge import DescriptionJudge
    from spacedg.seeding import derive_seed

    if judge is not None and not isinstance(judge, DescriptionJudge):
        judge = DescriptionJudge(scene, judge)
    out: list[QARecord] = []
    want = config.per_sub_type * config.pool_factor
    for family in _families(config.families):
        rng = np.random.default_rng(derive_seed(config.seed, scene.id, family.name))
        pools: dict[str, list[QARecord]] = {}
        with plugin_call("question family", family, "generate"):
            for scanned, record in enumerate(family.generate(scene, rng)):
                if scanned >= config.max_scan:
                    break
                pool = pools.setdefault(record.sub_question_type, [])
                if len(pool) < want:
                    pool.append(record)
                elif all(len(pools.get(s, ())) >= want for s in family.sub_question_types):
                    break

        def keep(record: QARecord, family_name: str = family.name) -> bool:
            if judge is None or judge.keep(record):
                return True
            if dropped is not None:
                dropped[family_name] = dropped.get(family_name, 0) + 1
            return False

        for sub in family.sub_question_types:
            out.extend(_select_balanced(pools.get(sub, []), config.per_sub_type, keep))
    return out


#: A family selection whose ``+``-joined names are longer than this is named by its hash.
MAX_SELECTION_CHARS = 100


def selection_name(families: Sequence[str]) -> str:
    """The file-name part of a family selection: ``""`` for the full index (no selection), else
    the sorted distinct names joined by ``+`` (``"object_counting+camera_rotation"`` order-free),
    or ``families-<first 12 hex of the SHA-1 of that text>`` when it exceeds :data:`MAX_SELECTION_CHARS`."""
    names = sorted(set(families))
    for name in names:
        if not isinstance(name, str) or not NAME_PATTERN.match(name):
            raise ParameterError(f"family selection: {name!r} is not a family name (^[a-z][a-z0-9_]*$); see `spacedg plugins`")
    text = "+".join(names)
    if len(text) > MAX_SELECTION_CHARS:
        return "families-" + hashlib.sha1(text.encode("utf-8")).hexdigest()[:12]
    return text


def index_paths(scene_id: str, out_dir: str | Path, families: Sequence[str] = ()) -> tuple[Path, Path]:
    """``(<out>/<id>.qa.jsonl, <out>/<id>.qa.meta.json)``: the full index; with ``families``, the
    selection index ``(<out>/<id>.qa.<selection>.jsonl, <out>/<id>.qa.<selection>.meta.json)``
    (:func:`selection_name`; see the module docstring)."""
    out = Path(out_dir)
    selection = selection_name(families)
    stem = f"{scene_id}.qa" if not selection else f"{scene_id}.qa.{selection}"
    return out / f"{stem}.jsonl", out / f"{stem}.meta.json"


def _index_key(scene_json: Path, config: QABuildConfig, families: Iterable[Any], judge: Any) -> str:
    digest = hashlib.sha256()
    digest.update(scene_json.read_bytes())
    fams = []
    for fam in families:
        origin = fam.origin
        fams.append([fam.name, getattr(origin, "distribution", None), getattr(origin, "version", None), _module_digest(fam)])
    judge_name = None if judge is None else getattr(judge, "__name__", type(judge).__name__)
    head = {"version": QA_INDEX_VERSION, "config": config.to_dict(), "families": fams, "judge": judge_name}
    digest.update(json.dumps(head, sort_keys=True).encode())
    return digest.hexdigest()


def _module_digest(family: Any) -> str | None:
    """SHA-256 of the source of the modules that make the family's records (so editing a family
    rebuilds indexes even without a version bump): the module of its raw ``generate`` and, when
    that is a ``functools.partial`` (what a family factory such as
    :func:`~spacedg.plugins.questions.pairs.pair_family` stores), of the functions bound into it
    (a pair family's stream). One module: the SHA-256 of its file; several: the SHA-256 of their
    files' digests in that order. ``None`` when none has a file."""
    raw = getattr(family.generate, "__wrapped__", family.generate)
    func = getattr(raw, "func", None)  # functools.partial
    parts = [raw] if func is None else [func, *(p for p in (*raw.args, *raw.keywords.values()) if callable(p))]
    modules = dict.fromkeys(getattr(part, "__module__", None) for part in parts)
    files = []
    for module in filter(None, modules):
        spec = importlib.util.find_spec(module)
        if spec is not None and spec.origin and Path(spec.origin).is_file():
            files.append(hashlib.sha256(Path(spec.origin).read_bytes()))
    if len(files) < 2:
        return files[0].hexdigest() if files else None
    return hashlib.sha256(b"".join(f.digest() for f in files)).hexdigest()


def _read_meta(path: Path) -> dict[str, Any] | None:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def build_scene_index(
    scene_dir: str | Path,
    config: QABuildConfig = QABuildConfig(),
    *,
    out_dir: str | Path | None = None,
    judge: Any = None,
    force: bool = False,
    backend: str = "auto",
    progress: bool = True,
) -> SceneQA:
    """Build (or reuse) the question index of one native scene folder (see the module docstring):
    the full index, or with ``config.families`` the selection index beside it (:func:`index_paths`)."""
    from spacedg.scene.io import load_scene
    from spacedg.files import atomic_write_bytes

    scene_dir = Path(scene_dir)
    scene = load_scene(scene_dir)
    scene_json = scene_dir / "scene.json" if scene_dir.is_dir() else scene_dir
    key = _index_key(scene_json, config, _families(config.families), judge)
    jsonl, meta_path = index_paths(scene.id, out_dir if out_dir is not None else scene_json.parent, config.families)
    if not force and _is_current(jsonl, meta_path, key):
        meta = _read_meta(meta_path) or {}
        return SceneQA(scene.id, jsonl, read_index(jsonl), reused=True, seconds=dict(meta.get("seconds", {})))
    timings: dict[str, float] = {}
    prepared = prepare_scene(scene, scene_json.parent / "cache", config, backend=backend, progress=progress, timings=timings)
    dropped: dict[str, int] = {}
    t0 = time.perf_counter()
    records = generate_records(prepared, config, judge=judge, dropped=dropped)
    timings["generate_s"] = time.perf_counter() - t0
    body = "".join(r.to_json() + "\n" for r in records).encode("utf-8")
    jsonl.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(jsonl, body)
    meta = {
        "format": "spacedg-qa-index", "version": QA_INDEX_VERSION, "key": key, "scene_id": scene.id,
        "config": config.to_dict(), "records": len(records),
        "counts": dict(sorted(Counter(r.question_type for r in records).items())),
        "dropped_by_judge": dropped, "seconds": {k: round(v, 4) for k, v in timings.items()},
    }
    atomic_write_bytes(meta_path, (json.dumps(meta, indent=2) + "\n").encode("utf-8"))
    return SceneQA(scene.id, jsonl, records, reused=False, seconds=timings, dropped=dropped)


def _is_current(jsonl: Path, meta_path: Path, key: str) -> bool:
    meta = _read_meta(meta_path)
    return meta is not None and meta.get("key") == key and jsonl.is_file()


def index_is_current(scene_dir: str | Path, config: QABuildConfig = QABuildConfig(), out_dir: str | Path | None = None) -> bool:
    """Whether ``build_scene_index(scene_dir, config, out_dir=out_dir)`` would reuse its index
    (reads ``scene.json`` and the meta file only: nothing is rendered)."""
    from spacedg.scene.io import load_scene

    scene_dir = Path(scene_dir)
    scene_json = scene_dir / "scene.json" if scene_dir.is_dir() else scene_dir
    scene_id = load_scene(scene_dir).id
    jsonl, meta_path = index_paths(scene_id, out_dir if out_dir is not None else scene_json.parent, config.families)
    return _is_current(jsonl, meta_path, _index_key(scene_json, config, _families(config.families), None))


def read_index(path: str | Path) -> list[QARecord]:
    """Records of a ``*.qa.jsonl`` file; :class:`FileFormatError` naming the file and line on bad input."""
    path = Path(path)
    records = []
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except OSError as err:
        raise FileFormatError(f"{path}: cannot read the question index ({err.strerror})") from err
    for number, line in enumerate(lines, 1):
        if not line.strip():
            continue
        try:
            records.append(QARecord.from_json(line))
        except Exception as err:  # noqa: BLE001 - report which line is bad
            raise FileFormatError(f"{path}:{number}: not a question record ({err}); rebuild with `spacedg qa build`") from err
    return records


# --------------------------------------------------------- many scenes, isolated
def _build_indexes(payload: dict[str, Any]) -> dict[str, str]:
    """Child side of :func:`ensure_indexes`: build the indexes of ``payload["dirs"]``; returns
    ``folder → error message`` for the scenes that failed."""
    from tqdm import tqdm

    from spacedg.errors import SpaceDGError

    config = payload["config"]
    cfg = QABuildConfig(**{**config, "families": tuple(config["families"]), "visibility_size": tuple(config["visibility_size"]),
                           "covisibility_size": tuple(config["covisibility_size"])})
    failed: dict[str, str] = {}
    for folder in tqdm(payload["dirs"], desc="question indexes (first use)", unit="scene"):
        try:
            build_scene_index(folder, cfg, progress=False)
        except (SpaceDGError, OSError, ValueError) as err:
            failed[folder] = str(err)
    return failed


def ensure_indexes(dirs: Sequence[Path], config: QABuildConfig) -> dict[str, str]:
    """Build the question index of each scene folder whose index is missing or stale, **in a
    separate Python process** (:func:`~spacedg.scene.store.run_isolated`: the caller never starts
    numba or CUDA threads before a DataLoader forks its workers); returns ``folder → error`` for
    scenes that could not be read or indexed."""
    from spacedg.errors import SpaceDGError
    from spacedg.scene.store import run_isolated

    failed: dict[str, str] = {}
    stale = []
    for d in dirs:
        try:
            if not index_is_current(d, config):
                stale.append(str(d))
        except (SpaceDGError, OSError, ValueError) as err:
            failed[str(d)] = str(err)
    if stale:
        failed.update(run_isolated("spacedg.data.qa_index:_build_indexes", {"dirs": stale, "config": config.to_dict()}))
    return failed
