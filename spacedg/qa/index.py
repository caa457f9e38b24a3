"""Question index files: their names, their cache keys, reading and writing them.

A scene's question index is ``<out>/<scene id>.qa.jsonl`` (one :class:`QARecord` per line,
families in name order) with ``<out>/<scene id>.qa.meta.json`` (key, config, counts, timings),
both written atomically; ``out`` defaults to the scene folder itself. How the records are made
is :mod:`spacedg.qa.build`.

**Full index and selection indexes** (:func:`index_paths`). The *full* index
``<scene id>.qa.jsonl`` holds every registered family (``QABuildConfig.families`` empty): it is
what :class:`~spacedg.data.dataset.SpaceDGDataset` reads by default and what a bench export
without pruning reads (a pruned bench reads its candidates, ``<scene id>.qa-pooled.jsonl``,
:attr:`QABuildConfig.file_mode`; a train export ``<scene id>.qa-train.jsonl``). A build restricted to some families (``families=("a", "b")``, ``spacedg qa build
--families a,b``) writes a *selection index* beside it, ``<scene id>.qa.a+b.jsonl`` with
``<scene id>.qa.a+b.meta.json`` (names sorted and joined by ``+``; a selection longer than
:data:`MAX_SELECTION_CHARS` characters is named ``families-<12 hex of its SHA-1>``), and never
touches the full index. Records are seeded per (scene, family), so a selection index holds
exactly the records that family selection has in the full index built with the same settings:
writing it apart loses nothing, while replacing or merging into the full index would leave one
file whose meta key no longer describes its content. A dataset built with
``qa_config=QABuildConfig(families=...)`` reads (and builds) that selection's index.

An index is **reused** when its meta file's key matches (:func:`index_key`): the key hashes the
index version, the build config, the SHA-256 of ``scene.json`` (views, poses, instances) and the
selected families with the distributions and versions that provide them and the SHA-256 of each
family's module source (and the judge's name). Any change rebuilds it; ``force=True`` always does.
"""

from __future__ import annotations

import hashlib
import importlib.util
import json
from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from spacedg.errors import FileFormatError, ParameterError
from spacedg.files import atomic_write_bytes
from spacedg.plugins import get_question_family, list_question_families
from spacedg.plugins.qa_record import QARecord
from spacedg.plugins.specs import NAME_PATTERN
from spacedg.scene.io import load_scene
from spacedg.scene.lexicon import default_lexicon
from spacedg.qa.gc_pause import collector_paused

__all__ = [
    "MODES", "FILE_MODES", "QA_INDEX_VERSION", "QABuildConfig", "SceneQA", "selected_families", "MAX_SELECTION_CHARS", "selection_name",
    "index_paths", "config_index_paths", "scene_json_path", "index_key", "module_files_digest", "read_meta", "is_current", "index_is_current", "read_index", "write_index",
]

#: Bump when the index layout or the build procedure changes (part of the key).
#: 3: debiased selection (subjects once per sub type, whole rounds per cell), lexicon in the key.
#: 4: pools count distinct subjects (:data:`~spacedg.qa.build.ALTERNATES` records each); rounds
#: balance the selection entries' ``features`` across roles; distractors of sector-label MCQs dealt evenly.
#: 5: selection modes (:mod:`spacedg.qa.modes`: strict ``bench``, dense ``train``); no twins; counts beyond 2.
#: 6: single-axis rotation sub types named by their text axes; counting counts an instance with a quarter of it
#: showing; compass angles within 0.01° of a sector boundary not asked.
#: 7: the pool refuses a valid candidate before its family draws for it (:func:`~spacedg.plugins.candidates.admitted`,
#: ``PASSED_OVER`` in its turn): the same rules and scan, but a refused candidate's random draws are never taken,
#: so later candidates draw other numbers.
QA_INDEX_VERSION = 7

#: The selection modes (:mod:`spacedg.qa.modes`): strict ``bench``, dense ``train``.
MODES: tuple[str, ...] = ("bench", "train")
#: The index files a scene folder may hold, as :func:`index_paths` modes, in the order readers
#: prefer them: the bench, a pruned bench's candidates (:attr:`QABuildConfig.file_mode`), the train selection.
FILE_MODES: tuple[str, ...] = ("bench", "pooled", "train")

#: A family selection whose ``+``-joined names are longer than this is named by its hash.
MAX_SELECTION_CHARS = 100


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
            answer balancing (1 = no balancing: the first ``per_sub_type`` in seeded order). 40
            by default. 20 generates 20–28 % faster, but a sub type whose rounds wait on a rare
            answer loses records: on 8 built-in rooms ``yaw+pitch_single`` kept 128 records
            instead of 152 and ``bbox_center_direction`` 80 instead of 88 (issue 31's note).
        visibility_size: reduced render size (width, height) px for instance visibility: a bounding box,
            each view rendered at its own aspect inside it (16:9 views at 160×90).
        covisibility_size: reduced render size (width, height) px for covisibility (a bounding box, likewise).
        mode: ``"bench"`` (strict: an object or pair asked at most once per sub type and scene,
            whatever the views) or ``"train"`` (dense: each object from many views,
            :data:`~spacedg.qa.modes.TRAIN_QUOTA_FACTOR` × ``per_sub_type`` per sub type); a
            train index has files of its own (:func:`index_paths`). See :mod:`spacedg.qa.modes`.
        partial_rounds: also take partial rounds of the cells' roles where whole rounds leave a
            sub type room (:func:`~spacedg.qa.selection.select_records`): the candidates of a bench
            whose roles are balanced across its scenes afterwards
            (:func:`~spacedg.qa.cell_balance.balance_cells`; ``spacedg export --split bench`` with
            the blind pruning). Such an index is not balanced on its own and has files of its own
            (``<id>.qa-pooled.jsonl``, :attr:`file_mode`); off by default.
    """

    seed: int = 0
    families: tuple[str, ...] = ()
    per_sub_type: int = 25
    max_scan: int = 20_000
    pool_factor: int = 40
    visibility_size: tuple[int, int] = (160, 120)
    covisibility_size: tuple[int, int] = (80, 60)
    mode: str = "bench"
    partial_rounds: bool = False

    def __post_init__(self) -> None:
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise ParameterError(f"QABuildConfig: seed must be an integer >= 0, got {self.seed!r}")
        for name in ("per_sub_type", "max_scan", "pool_factor"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ParameterError(f"QABuildConfig: {name} must be a positive integer, got {value!r}")
        if isinstance(self.families, str):
            raise ParameterError(f"QABuildConfig: families must be a sequence of family names, not one string ({self.families!r})")
        if self.mode not in MODES:
            raise ParameterError(f"QABuildConfig: mode must be one of {list(MODES)}, got {self.mode!r}")
        if not isinstance(self.partial_rounds, bool):
            raise ParameterError(f"QABuildConfig: partial_rounds must be True or False, got {self.partial_rounds!r}")
        if self.partial_rounds and self.mode != "bench":
            raise ParameterError("QABuildConfig: partial_rounds is for the candidates of a pooled bench (mode 'bench'), "
                                 f"not mode {self.mode!r}")
        object.__setattr__(self, "families", tuple(sorted(set(self.families))))
        object.__setattr__(self, "visibility_size", tuple(self.visibility_size))
        object.__setattr__(self, "covisibility_size", tuple(self.covisibility_size))

    @property
    def file_mode(self) -> str:
        """The index files' mode part (:func:`index_paths`): ``"pooled"`` for a bench's candidates
        with partial rounds (``<id>.qa-pooled.jsonl``: not balanced on its own, so never read as the
        strict bench index ``<id>.qa.jsonl``), else :attr:`mode`."""
        return "pooled" if self.partial_rounds else self.mode

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready fields (tuples as lists): what the meta file and the key record."""
        out = asdict(self)
        out["families"] = list(self.families)
        out["visibility_size"] = list(self.visibility_size)
        out["covisibility_size"] = list(self.covisibility_size)
        if not self.partial_rounds:
            del out["partial_rounds"]  # recorded only when on: the keys of every index built without it stay as they were
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> QABuildConfig:
        """The config :meth:`to_dict` wrote (lists back to tuples)."""
        return cls(**{"mode": "bench", **data, "families": tuple(data["families"]), "visibility_size": tuple(data["visibility_size"]),
                      "covisibility_size": tuple(data["covisibility_size"])})


@dataclass
class SceneQA:
    """The result of indexing one scene: its records, the index file, and whether it was reused."""

    scene_id: str
    path: Path
    records: list[QARecord]
    reused: bool
    seconds: dict[str, float] = field(default_factory=dict)
    dropped: dict[str, int] = field(default_factory=dict)

    def counts(self) -> dict[str, int]:
        """Records per question type, by name."""
        return dict(sorted(Counter(r.question_type for r in self.records).items()))


def selected_families(names: Sequence[str]) -> list[Any]:
    """The question families named (sorted, distinct), or every registered one when ``names`` is empty."""
    if not names:
        return list_question_families()
    return [get_question_family(n) for n in sorted(set(names))]


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


def index_paths(scene_id: str, out_dir: str | Path, families: Sequence[str] = (), mode: str = "bench") -> tuple[Path, Path]:
    """``(<out>/<id>.qa.jsonl, <out>/<id>.qa.meta.json)``: the full index; with ``families``, the
    selection index ``(<out>/<id>.qa.<selection>.jsonl, <out>/<id>.qa.<selection>.meta.json)``
    (:func:`selection_name`; see the module docstring). ``mode="train"`` (the dense training
    selection, :mod:`spacedg.qa.modes`): ``<id>.qa-train…`` instead of ``<id>.qa…``; ``"pooled"``
    (a bench's candidates with partial rounds, :attr:`QABuildConfig.file_mode`): ``<id>.qa-pooled…``."""
    out = Path(out_dir)
    selection = selection_name(families)
    head = f"{scene_id}.qa" if mode == "bench" else f"{scene_id}.qa-{mode}"
    stem = head if not selection else f"{head}.{selection}"
    return out / f"{stem}.jsonl", out / f"{stem}.meta.json"


def config_index_paths(scene_id: str, out_dir: str | Path, config: QABuildConfig) -> tuple[Path, Path]:
    """:func:`index_paths` of the index ``config`` builds (its families and :attr:`~QABuildConfig.file_mode`)."""
    return index_paths(scene_id, out_dir, config.families, config.file_mode)


def scene_json_path(scene_dir: str | Path) -> Path:
    """The ``scene.json`` of a native scene folder (or the file itself when given one)."""
    scene_dir = Path(scene_dir)
    return scene_dir / "scene.json" if scene_dir.is_dir() else scene_dir


def index_key(scene_json: Path, config: QABuildConfig, families: Iterable[Any], judge: Any) -> str:
    """The cache key of an index (see the module docstring): SHA-256 hex."""
    digest = hashlib.sha256()
    digest.update(scene_json.read_bytes())
    fams = []
    for fam in families:
        origin = fam.origin
        fams.append([fam.name, getattr(origin, "distribution", None), getattr(origin, "version", None), _module_digest(fam),
                     bool(getattr(fam, "metric_only", False)), bool(getattr(fam, "plain_rounds", False))])

    judge_name = None if judge is None else getattr(judge, "__name__", type(judge).__name__)
    head = {
        "version": QA_INDEX_VERSION, "config": config.to_dict(), "families": fams, "judge": judge_name,
        "lexicon": default_lexicon().digest(),
    }
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
    return module_files_digest(dict.fromkeys(getattr(part, "__module__", None) for part in parts))


def module_files_digest(modules: Iterable[str | None]) -> str | None:
    """SHA-256 of the source files of ``modules`` (names; ``None`` and modules without a file skipped): one
    file, the SHA-256 of its bytes; several, the SHA-256 of their files' digests in that order; ``None`` when
    none has a file. Read from disk, so nothing is imported."""
    files = []
    for module in filter(None, modules):
        spec = importlib.util.find_spec(module)
        if spec is not None and spec.origin and Path(spec.origin).is_file():
            files.append(hashlib.sha256(Path(spec.origin).read_bytes()))
    if len(files) < 2:
        return files[0].hexdigest() if files else None
    return hashlib.sha256(b"".join(f.digest() for f in files)).hexdigest()


def read_meta(path: Path) -> dict[str, Any] | None:
    """The meta file's mapping, or ``None`` when it is missing or not a JSON object."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def is_current(jsonl: Path, meta_path: Path, key: str) -> bool:
    """Whether the index ``jsonl`` exists and its meta file records ``key``."""
    meta = read_meta(meta_path)
    return meta is not None and meta.get("key") == key and jsonl.is_file()


def index_is_current(scene_dir: str | Path, config: QABuildConfig = QABuildConfig(), out_dir: str | Path | None = None) -> bool:
    """Whether ``build_scene_index(scene_dir, config, out_dir=out_dir)`` would reuse its index
    (reads ``scene.json`` and the meta file only: nothing is rendered)."""

    scene_json = scene_json_path(scene_dir)
    scene_id = load_scene(Path(scene_dir)).id
    jsonl, meta_path = config_index_paths(scene_id, out_dir if out_dir is not None else scene_json.parent, config)
    return is_current(jsonl, meta_path, index_key(scene_json, config, selected_families(config.families), None))


def read_index(path: str | Path) -> list[QARecord]:
    """Records of a ``*.qa.jsonl`` file; :class:`FileFormatError` naming the file and line on bad input."""
    path = Path(path)
    records = []
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except OSError as err:
        raise FileFormatError(f"{path}: cannot read the question index ({err.strerror})") from err
    with collector_paused():  # thousands of records kept alive: the cyclic collector would re-scan them all (a quarter of the time)
        for number, line in enumerate(lines, 1):
            if not line.strip():
                continue
            try:
                records.append(QARecord.from_json(line))
            except Exception as err:  # noqa: BLE001 - report which line is bad
                raise FileFormatError(f"{path}:{number}: not a question record ({err}); rebuild with `spacedg qa build`") from err
    return records


def write_index(jsonl: Path, meta_path: Path, records: Sequence[QARecord], meta: dict[str, Any]) -> None:
    """Write ``records`` (one JSON line each) to ``jsonl``, then ``meta`` (indented JSON) to
    ``meta_path``, each atomically; the meta file last, so a key never describes a missing index."""
    body = "".join(r.to_json() + "\n" for r in records).encode("utf-8")
    jsonl.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(jsonl, body)
    atomic_write_bytes(meta_path, (json.dumps(meta, indent=2) + "\n").encode("utf-8"))
