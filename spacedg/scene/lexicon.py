"""The label lexicon: which labels a person may take for one another, and what objects show
without being annotated.

Label-only questions (counting, existence) ask about a *label*, and a viewer answers with
what the word covers: "Is there a chair?" is "yes" to most people beside an armchair, "Is
there a monitor?" is debatable beside a TV, and "How many books?" beside a full bookshelf
has no good answer when the books are drawn as part of the shelf. So those families consult
this lexicon and skip a view that shows an instance of a **related** label, or an instance
that **shows** the label unannotated (questions never claim what a person sees is absent).

Relations (labels compare case-, space- and underscore-insensitively, :func:`label_key`):

``synonyms``
    groups of labels for one kind of thing (``tv`` / ``television``, ``sofa`` / ``couch``).
``kinds``
    label → broader labels it is a kind of (``armchair`` → ``chair``, ``desk`` → ``table``);
    transitive (``armchair`` → ``chair`` → ``seat``).
``related``
    pairs a person may reasonably confuse though neither is a kind of the other
    (``stool`` / ``chair``, ``monitor`` / ``tv``, ``cabinet`` / ``wardrobe``).
``shows``
    label → labels an instance of it usually displays **without** their own annotation
    (``bookshelf`` → ``book``: the rows of books belong to the shelf's instance).
``sizes``
    label → ``[longest side, top above the floor]`` in metres of a typical instance: the
    world knowledge a blind model has ("a sofa is longer than a cup"). Size-comparison
    questions balance their answers against it (:meth:`Lexicon.typical_size`).

:meth:`Lexicon.related` is true for two different labels that are synonyms, one a kind of
the other (either way, transitively), listed as ``related``, or with the same head noun
(``lamp`` / ``floor lamp``, the rule the families used before the lexicon). It is symmetric.
:meth:`Lexicon.shown_by` gives the labels whose instances show a label (with the label's
relatives).

Extending it for a real-scene vocabulary: a JSON file with any of the five keys, e.g.
``{"kinds": {"office chair": ["chair"]}, "related": [["ottoman", "stool"]], "shows":
{"kitchen counter": ["bottle"]}, "sizes": {"ottoman": [0.6, 0.45]}}``, merged over the built-in one by
:meth:`Lexicon.merged` / :func:`load_lexicon`, or named in the environment variable
``SPACEDG_LEXICON`` (paths separated by ``os.pathsep``), which :func:`default_lexicon` reads.
:meth:`Lexicon.digest` identifies a lexicon's content (the question index hashes it into its
key, so editing the lexicon rebuilds indexes).
"""

from __future__ import annotations

import functools
import hashlib
import json
import math
import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from spacedg.errors import FileFormatError
from spacedg.scene.language import label_text

__all__ = ["BUILTIN", "LEXICON_ENV", "Lexicon", "default_lexicon", "head_noun", "label_key", "load_lexicon"]

#: Environment variable naming extra lexicon JSON files (``os.pathsep``-separated).
LEXICON_ENV = "SPACEDG_LEXICON"


def label_key(label: str) -> str:
    """Labels compare case-, space- and underscore-insensitively (``"Coffee_table"`` = ``"coffee table"``)."""
    if type(label) is not str:
        return label_text(label).lower()
    key = _LABEL_KEYS.get(label)
    if key is None:
        if len(_LABEL_KEYS) >= 65_536:
            _LABEL_KEYS.clear()
        key = _LABEL_KEYS[label] = label_text(label).lower()
    return key


#: label → :func:`label_key` (every candidate compares labels; bounded).
_LABEL_KEYS: dict[str, str] = {}


def head_noun(label: str) -> str:
    """The noun a label names: its last word, or the word before " of " (``"floor lamp"`` → ``"lamp"``,
    ``"pair of shoes"`` → ``"pair"``)."""
    words = label_key(label).partition(" of ")[0].split()
    return words[-1] if words else ""


@dataclass(frozen=True)
class Lexicon:
    """Label relations (see the module docstring). Build with :meth:`from_dict`; immutable."""

    synonyms: tuple[frozenset[str], ...] = ()
    kinds: Mapping[str, frozenset[str]] = field(default_factory=dict)
    related_pairs: frozenset[frozenset[str]] = frozenset()
    shows: Mapping[str, frozenset[str]] = field(default_factory=dict)
    sizes: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    _memo: dict[Any, Any] = field(default_factory=dict, init=False, repr=False, compare=False)

    # ------------------------------------------------------------ building
    @classmethod
    def from_dict(cls, data: Mapping[str, Any], where: str = "lexicon") -> Lexicon:
        """A lexicon from ``{"synonyms": [[...]], "kinds": {label: [...]}, "related": [[a, b]], "shows": {label: [...]},
        "sizes": {label: [longest m, top m]}}``."""
        unknown = sorted(set(data) - {"synonyms", "kinds", "related", "shows", "sizes"})
        if unknown:
            raise FileFormatError(f"{where}: unknown key(s) {unknown}; a lexicon has 'synonyms', 'kinds', 'related', 'shows', 'sizes'")

        def words(value: Any, what: str) -> list[str]:
            if not isinstance(value, (list, tuple)) or not all(isinstance(v, str) and v.strip() for v in value):
                raise FileFormatError(f"{where}: {what} must be a list of non-empty label strings, got {value!r}")
            return [label_key(v) for v in value]

        def mapping(value: Any, what: str) -> dict[str, frozenset[str]]:
            if not isinstance(value, Mapping):
                raise FileFormatError(f"{where}: '{what}' must map a label to a list of labels, got {type(value).__name__}")
            return {label_key(k): frozenset(words(v, f"'{what}'[{k!r}]")) for k, v in value.items()}

        groups = data.get("synonyms", [])
        if not isinstance(groups, (list, tuple)):
            raise FileFormatError(f"{where}: 'synonyms' must be a list of label lists")
        pairs = data.get("related", [])
        if not isinstance(pairs, (list, tuple)):
            raise FileFormatError(f"{where}: 'related' must be a list of [label, label] pairs")
        related = []
        for pair in pairs:
            got = words(pair, "each 'related' entry")
            if len(got) != 2:
                raise FileFormatError(f"{where}: each 'related' entry is a pair [label, label], got {pair!r}")
            related.append(frozenset(got))
        sizes_in = data.get("sizes", {})
        if not isinstance(sizes_in, Mapping):
            raise FileFormatError(f"{where}: 'sizes' must map a label to [longest side m, top m]")
        sizes: dict[str, tuple[float, float]] = {}
        for k, v in sizes_in.items():
            ok = isinstance(v, (list, tuple)) and len(v) == 2 and all(
                isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) and x >= 0 for x in v
            )
            if not ok:
                raise FileFormatError(f"{where}: 'sizes'[{k!r}] must be [longest side m, top above the floor m], got {v!r}")
            sizes[label_key(k)] = (float(v[0]), float(v[1]))
        return cls(
            synonyms=tuple(frozenset(words(g, "each 'synonyms' group")) for g in groups),
            kinds=mapping(data.get("kinds", {}), "kinds"),
            related_pairs=frozenset(related),
            shows=mapping(data.get("shows", {}), "shows"),
            sizes=sizes,
        )

    def to_dict(self) -> dict[str, Any]:
        """The JSON form :meth:`from_dict` reads (sorted, so equal lexicons give equal text)."""
        return {
            "synonyms": sorted(sorted(g) for g in self.synonyms),
            "kinds": {k: sorted(v) for k, v in sorted(self.kinds.items())},
            "related": sorted(sorted(p) for p in self.related_pairs),
            "shows": {k: sorted(v) for k, v in sorted(self.shows.items())},
            "sizes": {k: list(v) for k, v in sorted(self.sizes.items())},
        }

    def merged(self, other: Lexicon) -> Lexicon:
        """This lexicon with ``other``'s relations added (nothing is removed)."""
        kinds = {k: set(v) for k, v in self.kinds.items()}
        for k, v in other.kinds.items():
            kinds.setdefault(k, set()).update(v)
        shows = {k: set(v) for k, v in self.shows.items()}
        for k, v in other.shows.items():
            shows.setdefault(k, set()).update(v)
        return Lexicon(
            synonyms=self.synonyms + other.synonyms,
            kinds={k: frozenset(v) for k, v in kinds.items()},
            related_pairs=self.related_pairs | other.related_pairs,
            shows={k: frozenset(v) for k, v in shows.items()},
            sizes={**self.sizes, **other.sizes},
        )

    def digest(self) -> str:
        """SHA-256 of :meth:`to_dict` (identifies the content)."""
        return hashlib.sha256(json.dumps(self.to_dict(), sort_keys=True).encode()).hexdigest()

    # ------------------------------------------------------------ queries
    def _synonyms_of(self, key: str) -> set[str]:
        out = {key}
        for group in self.synonyms:
            if key in group:
                out |= group
        return out

    def broader(self, label: str) -> frozenset[str]:
        """Every label ``label`` is a kind of (transitively, through synonyms), without itself."""
        return self._closure(label_key(label))

    def _closure(self, key: str) -> frozenset[str]:
        memo = ("closure", key)
        if memo in self._memo:
            return self._memo[memo]
        seen: set[str] = set()
        todo = list(self._synonyms_of(key))
        while todo:
            k = todo.pop()
            for parent in self.kinds.get(k, ()):
                for p in self._synonyms_of(parent):
                    if p not in seen:
                        seen.add(p)
                        todo.append(p)
        out = self._memo[memo] = frozenset(seen - self._synonyms_of(key))
        return out

    def related(self, a: str, b: str) -> bool:
        """True for two **different** labels a person may take for one another (module docstring)."""
        memo = ("related", a, b)
        if memo not in self._memo:
            self._memo[memo] = self._related(label_key(a), label_key(b))
        return self._memo[memo]

    def _related(self, ka: str, kb: str) -> bool:
        if ka == kb or not ka or not kb:
            return False
        if head_noun(ka) == head_noun(kb):
            return True
        if kb in self._synonyms_of(ka):
            return True
        if kb in self._closure(ka) or ka in self._closure(kb):
            return True
        sa, sb = self._synonyms_of(ka), self._synonyms_of(kb)
        return any(frozenset((x, y)) in self.related_pairs for x in sa for y in sb)

    def typical_size(self, label: str) -> tuple[float, float] | None:
        """``(longest side, top above the floor)`` metres of a typical ``label`` (or a synonym), else ``None``."""
        for key in sorted(self._synonyms_of(label_key(label))):
            if key in self.sizes:
                return self.sizes[key]
        return None

    def shown_by(self, label: str) -> frozenset[str]:
        """Labels whose instances show ``label`` (or a label related to it, or one it is a kind of) unannotated."""
        key = label_key(label)
        out = set()
        for container, shown in self.shows.items():
            for s in shown:
                if s == key or self.related(s, key):
                    out.add(container)
        return frozenset(out)

    def confuses(self, asked: str, seen: str) -> bool:
        """Whether a view showing an instance labelled ``seen`` makes a label-only question about
        ``asked`` ambiguous: the labels are related, or ``seen`` shows ``asked`` unannotated
        (memoised per pair of labels, like :meth:`related`: a scene asks it for every object of every view)."""
        memo = ("confuses", asked, seen)
        hit = self._memo.get(memo)
        if hit is None:
            hit = self._memo[memo] = self._confuses(asked, seen)
        return hit

    def _confuses(self, asked: str, seen: str) -> bool:
        if self.related(asked, seen):
            return True
        containers = self.shown_by(asked)
        key = label_key(seen)
        return bool(containers & (self._synonyms_of(key) | self.broader(key)))


#: The built-in lexicon: the synthetic rooms' catalogue and common indoor (ScanNet-style) labels.
BUILTIN = Lexicon.from_dict({
    "synonyms": [
        ["tv", "television", "tv screen"],
        ["sofa", "couch"],
        ["trash can", "trash bin", "garbage can", "garbage bin", "wastebasket", "waste bin", "dustbin"],
        ["bookshelf", "bookcase", "book shelf"],
        ["monitor", "computer monitor", "computer screen", "display"],
        ["cup", "mug"],
        ["plant", "potted plant", "houseplant"],
        ["box", "storage box", "cardboard box"],
        ["nightstand", "night stand", "bedside table"],
        ["refrigerator", "fridge"],
    ],
    "kinds": {
        "armchair": ["chair"], "office chair": ["chair"], "dining chair": ["chair"], "swivel chair": ["chair"],
        "chair": ["seat"], "stool": ["seat"], "sofa": ["seat"], "bench": ["seat"], "ottoman": ["seat"],
        "desk": ["table"], "coffee table": ["table"], "side table": ["table"], "dining table": ["table"],
        "end table": ["table"], "nightstand": ["table"],
        "floor lamp": ["lamp"], "table lamp": ["lamp"], "desk lamp": ["lamp"],
        "small plant": ["plant"],
        "tv": ["screen"], "monitor": ["screen"],
        "wardrobe": ["cabinet"], "kitchen cabinet": ["cabinet"], "file cabinet": ["cabinet"],
        "bookshelf": ["shelf"],
        "suitcase": ["luggage", "bag"], "backpack": ["bag"],
    },
    "related": [
        ["stool", "chair"], ["monitor", "tv"], ["armchair", "sofa"], ["bookshelf", "cabinet"],
        ["cabinet", "nightstand"], ["vase", "cup"], ["bowl", "cup"], ["box", "suitcase"], ["box", "trash can"],
    ],
    "shows": {
        "bookshelf": ["book"], "shelf": ["book"],
    },
    # [longest side, top above the floor], metres: the synthetic catalogue's mean instance (objects on
    # tables counted at a 0.75 m top; "plant" mixes floor plants and small plants on tables: 37 plants of
    # 28 built-in rooms measure 0.41 m median, 0.53 m mean, so 0.5, not the 0.73 a mixture of the two
    # builders' nominal sizes gave, which put most plant pairs in the wrong prior cell: a blind model
    # that learned plants' sizes solved 55 % of them, 31 % of the others) and common indoor labels
    "sizes": {
        "table": [1.4, 0.75], "coffee table": [1.0, 0.42], "desk": [1.25, 0.74], "chair": [0.9, 0.9], "stool": [0.6, 0.6],
        "sofa": [1.95, 0.82], "armchair": [0.9, 0.82], "bed": [2.05, 1.05], "wardrobe": [2.0, 2.0], "bookshelf": [1.55, 1.55],
        "cabinet": [1.2, 0.75], "tv": [1.05, 1.45], "monitor": [0.6, 1.2], "floor lamp": [1.6, 1.6], "lamp": [0.45, 1.2],
        "plant": [0.5, 0.98], "small plant": [0.35, 1.1], "box": [0.45, 0.28], "trash can": [0.4, 0.4], "ball": [0.23, 0.23],
        "suitcase": [0.7, 0.7], "vase": [0.3, 1.05], "cup": [0.12, 0.85], "bowl": [0.22, 0.82], "book": [0.26, 0.79],
        "door": [2.05, 2.05], "window": [1.3, 2.0], "refrigerator": [1.8, 1.8], "sink": [0.6, 0.9], "toilet": [0.7, 0.75],
        "bathtub": [1.65, 0.55], "pillow": [0.6, 0.6], "backpack": [0.45, 0.45], "nightstand": [0.5, 0.55],
        "keyboard": [0.45, 0.77], "laptop": [0.35, 0.78], "bottle": [0.25, 0.95], "picture": [0.6, 1.7], "mirror": [0.9, 1.7],
        "whiteboard": [1.5, 1.9], "curtain": [2.0, 2.3], "radiator": [1.0, 0.7], "printer": [0.45, 0.95],
        "microwave": [0.5, 1.2], "shelf": [1.2, 1.5], "kitchen cabinet": [1.2, 0.9], "office chair": [1.0, 1.0],
        "bag": [0.45, 0.4], "shoes": [0.3, 0.12], "clock": [0.3, 2.0], "towel": [0.7, 1.0], "telephone": [0.2, 0.77],
    },
})


def load_lexicon(path: str | Path, base: Lexicon | None = None) -> Lexicon:
    """``base`` (default :data:`BUILTIN`) merged with the lexicon JSON file at ``path``."""
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except OSError as err:
        raise FileFormatError(f"{path}: cannot read the lexicon ({err.strerror})") from err
    except ValueError as err:
        raise FileFormatError(f"{path}: not JSON ({err}); a lexicon is {{'synonyms', 'kinds', 'related', 'shows'}}") from err
    if not isinstance(data, Mapping):
        raise FileFormatError(f"{path}: a lexicon file holds one JSON object")
    return (BUILTIN if base is None else base).merged(Lexicon.from_dict(data, str(path)))


def _from_env(value: str) -> Lexicon:
    lexicon = BUILTIN
    for part in filter(None, value.split(os.pathsep)):
        lexicon = load_lexicon(part, lexicon)
    return lexicon


@functools.lru_cache(maxsize=8)
def _cached(value: str) -> Lexicon:
    return _from_env(value)


def default_lexicon() -> Lexicon:
    """:data:`BUILTIN` merged with the files named in ``SPACEDG_LEXICON`` (read on every call, cached per value)."""
    return _cached(os.environ.get(LEXICON_ENV, ""))


def related_labels(lexicon: Lexicon, label: str, labels: Iterable[str]) -> list[str]:
    """The members of ``labels`` that make a question about ``label`` ambiguous (:meth:`Lexicon.confuses`)."""
    return [other for other in labels if lexicon.confuses(label, other)]


__all__ += ["related_labels"]

