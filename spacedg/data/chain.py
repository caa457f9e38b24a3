"""Degradation chains, one grammar: :class:`Chain` parses, names, expands, resolves and records them.

A **chain** is the degradations one sample goes through. Written as text, items are joined by
``+``; each item is a degradation name, ``name:preset`` (``"haze:3"``, ``"haze:bench"``) or the
name of a mixture recipe (``"night_capture"``, no preset)::

    "clean"  ""                       no degradation (``degradation_type`` "ori")
    "haze"   "haze:3+low_res"         one item, two items
    "night_capture"                   a mixture: low_light at the default preset, motion_blur and
                                      low_res at the mixture preset (severity "2")

An item may carry explicit parameters (the others are sampled from the preset): in Python a
mapping ``{"name", "preset", "params"}``, a :class:`DegradationChoice`, ``(name, params)`` or
``(name, preset)``; as text ``name(key=value, …)`` or ``name:preset(key=value, …)``
(``"haze:bench(density=3.5)"``; values as Python writes numbers, ``repr``, so they read back
exactly). A chain is one item, ``+``-joined items, or a list of these. Every chain has exactly
one canonical text (:attr:`Chain.text`) and ``Chain.parse(chain.text) == chain`` for every chain.

A :class:`Chain` is a frozen, hashable, picklable value: it is what travels from the dataset to
DataLoader workers and the pipeline. Text is for display and the command line only; nothing
downstream parses it again.

What a chain is used for, each in exactly one place:

- :meth:`Chain.parse` reads any of the forms above (unknown keys and malformed items fail here);
- :attr:`Chain.name` is the ``degradation_type`` column: ``"ori"`` for clean, else the item names
  without presets joined by ``+`` (a mixture keeps its recipe name);
- :attr:`Chain.text` is the canonical text (``"haze:3+low_res"``), :meth:`Chain.with_severity`
  gives items written without a preset a severity (mixtures keep their recipe);
- :meth:`Chain.choices` expands mixtures into :class:`DegradationChoice` objects;
- :meth:`Chain.resolve` draws concrete parameters from a seed, in the physical order
  (raster → linear → display, then each stage's ``order``), as :class:`ResolvedDegradation` objects;
- :meth:`Chain.provenance` is what a sample records: ``[{name, params, seed, preset}, …]``, which
  reproduces its bytes (:meth:`ResolvedDegradation.from_provenance` reads an entry back;
  :func:`spacedg.data.pipeline.replay` renders it).

Seeds: each degradation of a chain draws its parameters from ``derive_seed(sample_seed, name)``, so
one degradation draws the same parameters in every chain of a sample.

Scene depth: presets whose metre ranges scale with the scene (``ParamRange(per_depth=True)``:
defocus focus distance, motion-blur path, haze reference distance) are resolved at the sample's
scene depth (``resolve(..., scene_depth=D)``, D in metres: the pipeline measures it,
:func:`~spacedg.data.pipeline.sample_scene_depth`); the provenance then holds the resolved
absolute metres and ``scene_depth_m``, so it still reproduces the bytes without measuring
anything. :meth:`Chain.scales_with_depth` says whether a chain needs D.

Image size: presets whose pixel lengths are stated at the reference image size
(``ParamRange(per_size=True)``, :data:`~spacedg.plugins.specs.REFERENCE_IMAGE_SIZE`, a 1752 × 1168
ScanNet++ DSLR frame: the in-drop blur of water droplets, the sensor's photosite pitch) are
resolved at the output size (``resolve(..., image_size=(W, H))``,
:func:`~spacedg.plugins.specs.image_scale`); the provenance then holds the pixels used and
``image_size``. Explicit parameters are never scaled (they are the pixels used).
"""

from __future__ import annotations

import math
import numbers
import re
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from spacedg.errors import ParameterError, UnknownPluginError
from spacedg.plugins.registry import get_degradation
from spacedg.plugins.specs import DegradationSpec, suggest
from spacedg.seeding import derive_seed

__all__ = [
    "CLEAN",
    "BENCH_DEGRADATIONS",
    "MIXTURES",
    "SEVERITIES",
    "Chain",
    "DegradationChoice",
    "Mixture",
    "Params",
    "ResolvedDegradation",
    "parse_chain",
    "resolve_chain",
    "split_chains",
]

#: ``degradation_type`` of a clean sample (the VLMEvalKit / SpaceDG convention).
CLEAN = "ori"

#: The nine degradations of SpaceDG-Bench, in the paper's table order.
BENCH_DEGRADATIONS: tuple[str, ...] = (
    "defocus", "distortion", "haze", "jpeg_compression", "low_light",
    "low_res", "motion_blur", "over_exposure", "water_droplets",
)

#: Presets a chain item can be given with :meth:`Chain.with_severity` (plus ``"random"`` in the dataset).
SEVERITIES: tuple[str, ...] = ("bench", "1", "2", "3", "4", "5")


@dataclass(frozen=True)
class Mixture:
    """A real-world inspired mixture recipe: one primary degradation, milder auxiliaries."""

    primary: str
    auxiliaries: tuple[str, ...]
    description: str


#: The paper's six mixture recipes (Table "mixed-degradation settings"); primary first.
MIXTURES: Mapping[str, Mixture] = {
    "night_capture": Mixture("low_light", ("motion_blur", "low_res"), "LL + MB + LR"),
    "hazy_long_range": Mixture("haze", ("low_res", "motion_blur"), "HZ + LR + MB"),
    "wet_lens_motion": Mixture("water_droplets", ("motion_blur", "low_light"), "WD + MB + LL"),
    "backlit_dynamics": Mixture("over_exposure", ("motion_blur",), "OE + MB"),
    "motion_defocus": Mixture("motion_blur", ("defocus", "low_res"), "MB + DF + LR"),
    "compressed_portrait": Mixture("defocus", ("jpeg_compression",), "DF + JPEG"),
}


#: What a degradation name, a preset name and a parameter key look like in a chain.
_TOKEN = r"[A-Za-z0-9_][A-Za-z0-9_.-]*"
_TOKEN_RE = re.compile(_TOKEN)


class Params(Mapping[str, "int | float"]):
    """Explicit parameter values of a chain item: a read-only, hashable, picklable mapping
    ``name → int | float`` (insertion order kept for display; equal to a ``dict`` with the same items)."""

    __slots__ = ("_items",)

    def __init__(self, values: Mapping[str, Any]) -> None:
        if not isinstance(values, Mapping):
            raise ParameterError(f"a degradation's params must be a mapping name → number, got {type(values).__name__}: {values!r}")
        self._items = tuple((_param_key(k), _param_value(k, v)) for k, v in values.items())

    def __getitem__(self, key: str) -> int | float:
        for name, value in self._items:
            if name == key:
                return value
        raise KeyError(key)

    def __iter__(self) -> Iterator[str]:
        return (name for name, _ in self._items)

    def __len__(self) -> int:
        return len(self._items)

    def __hash__(self) -> int:
        return hash(frozenset(self._items))

    def __repr__(self) -> str:
        return f"Params({dict(self._items)!r})"

    def __reduce__(self) -> tuple[Any, ...]:
        return Params, (dict(self._items),)

    def text(self) -> str:
        """``key=value, …`` with each value's ``repr`` (reads back exactly)."""
        return ", ".join(f"{k}={v!r}" for k, v in self._items)


def _param_key(key: object) -> str:
    if not isinstance(key, str) or not _TOKEN_RE.fullmatch(key):
        raise ParameterError(f"a degradation parameter name must be a name such as 'density', got {key!r}")
    return key


def _param_value(key: str, value: object) -> int | float:
    """``value`` as a plain ``int`` or finite ``float`` (numpy numbers too; bools refused)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ParameterError(f"degradation parameter {key!r} must be a finite number, got {value!r}")
    number: int | float = int(value) if isinstance(value, numbers.Integral) else float(value)
    if not math.isfinite(number):
        raise ParameterError(f"degradation parameter {key!r} must be a finite number, got {value!r}")
    return number


def _explain_params(name: str, params: object) -> None:
    """Raise the registered degradation ``name``'s own error about ``params`` (an unknown parameter
    named as such, with the parameters it takes) when it has one; return when ``name`` is not a
    registered degradation or its check passes (the caller then raises its generic error)."""
    if not isinstance(params, Mapping) or not all(isinstance(k, str) for k in params):
        return
    try:
        spec = get_degradation(name)
    except UnknownPluginError:
        return
    spec.validate_params(params, partial=True)


@dataclass(frozen=True)
class DegradationChoice:
    """One item of a chain as a user asks for it (frozen, hashable, picklable).

    Attributes:
        name: a registered degradation name, or (before :meth:`Chain.choices`) a mixture name.
        preset: preset to sample parameters from (``None`` = the chain's default preset).
        params: explicit parameter values (:class:`Params`, ``None`` for none); parameters not
            given are sampled from the preset. A mixture takes neither a preset nor params.
    """

    name: str
    preset: str | None = None
    params: Mapping[str, float] | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not _TOKEN_RE.fullmatch(self.name):
            raise ParameterError(f"a degradation name must be a name such as 'haze' or 'night_capture', got {self.name!r}")
        preset = self.preset
        if isinstance(preset, int) and not isinstance(preset, bool):
            preset = str(preset)
        if preset is not None and (not isinstance(preset, str) or not _TOKEN_RE.fullmatch(preset)):
            raise ParameterError(f"degradation {self.name!r}: a preset must be a name such as 'bench' or '3', got {self.preset!r}")
        try:
            params = None if self.params is None or len(self.params) == 0 else Params(self.params)  # type: ignore[arg-type]
        except ParameterError:
            _explain_params(self.name, self.params)
            raise
        object.__setattr__(self, "preset", preset)
        object.__setattr__(self, "params", params)
        if self.name in MIXTURES and (preset is not None or params is not None):
            raise ParameterError(
                f"mixture {self.name!r} takes no preset or params ({self.text()!r}); its primary uses the default preset "
                "and the others the mixture preset"
            )

    @property
    def is_mixture(self) -> bool:
        return self.name in MIXTURES

    def text(self) -> str:
        """``name``, ``name:preset``, and explicit parameters as ``name:preset(key=value, …)``
        (``Chain.parse`` reads it back to an equal item)."""
        out = self.name if self.preset is None else f"{self.name}:{self.preset}"
        if self.params:
            out += f"({self.params.text()})" if isinstance(self.params, Params) else f"({Params(self.params).text()})"
        return out


@dataclass(frozen=True)
class ResolvedDegradation:
    """A degradation with concrete parameters and its seed (what provenance records)."""

    spec: DegradationSpec
    params: Mapping[str, int | float]
    seed: int
    preset: str | None
    scene_depth: float | None = None
    image_size: tuple[int, int] | None = None

    @property
    def name(self) -> str:
        return self.spec.name

    def view_rng(self, view_index: int) -> np.random.Generator:
        """The generator ``apply`` gets for view ``view_index`` of the sample."""
        return np.random.default_rng([self.seed, view_index])

    def key(self) -> tuple[Any, ...]:
        """Hashable identity (name, parameters, seed): equal keys render and apply identically."""
        return (self.name, tuple(sorted(self.params.items())), self.seed)

    def provenance(self) -> dict[str, Any]:
        """``{name, params, seed, preset}`` (plus ``scene_depth_m`` when the preset's metres were
        scaled to the sample's scene depth, ``image_size`` ``[W, H]`` when its pixels were scaled
        to the output size), JSON-serialisable."""
        out = {"name": self.name, "params": dict(self.params), "seed": self.seed, "preset": self.preset}
        if self.scene_depth is not None:
            out["scene_depth_m"] = self.scene_depth
        if self.image_size is not None:
            out["image_size"] = [int(v) for v in self.image_size]
        return out

    @classmethod
    def from_provenance(cls, entry: Mapping[str, Any]) -> ResolvedDegradation:
        """The degradation one provenance entry (:meth:`provenance`) records: its name, every
        parameter, its seed, preset and scene depth, checked; applying it gives the same bytes."""
        if not isinstance(entry, Mapping) or not {"name", "params", "seed"} <= set(entry) or set(entry) - _PROVENANCE_KEYS:
            raise ParameterError(
                f"a provenance entry is a mapping with 'name', 'params', 'seed' (and optionally 'preset', 'scene_depth_m', 'image_size'), "
                f"got {entry!r}"
            )
        spec = _lookup(str(entry["name"]))
        seed = entry["seed"]
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise ParameterError(f"provenance of {spec.name!r}: seed must be an integer >= 0, got {seed!r}")
        depth = entry.get("scene_depth_m")
        if depth is not None and not (isinstance(depth, (int, float)) and math.isfinite(depth) and depth > 0):
            raise ParameterError(f"provenance of {spec.name!r}: scene_depth_m must be a positive number of metres, got {depth!r}")
        size = entry.get("image_size")
        if size is not None and not (isinstance(size, (list, tuple)) and len(size) == 2 and all(
                isinstance(v, int) and not isinstance(v, bool) and v >= 1 for v in size)):
            raise ParameterError(f"provenance of {spec.name!r}: image_size must be [width, height] in whole pixels >= 1, got {size!r}")
        preset = entry.get("preset")
        return cls(spec, spec.validate_params(entry["params"]), int(seed), None if preset is None else str(preset),
                   None if depth is None else float(depth), None if size is None else (int(size[0]), int(size[1])))


_PROVENANCE_KEYS = frozenset({"name", "params", "seed", "preset", "scene_depth_m", "image_size"})


# ------------------------------------------------------------------ parsing
_ITEM_RE = re.compile(rf"\s*(?P<name>{_TOKEN})\s*(?::\s*(?P<preset>{_TOKEN})?\s*)?(?:\((?P<params>[^()]*)\)\s*)?")
_INT_RE = re.compile(r"[+-]?\d+")


def split_chains(text: str, sep: str = ",") -> list[str]:
    """``text`` split at ``sep`` outside parentheses (``"haze(a=1, b=2),low_res"`` → two chains):
    how a comma-separated list of chains on the command line is read."""
    parts, depth, start = [], 0, 0
    for i, char in enumerate(text):
        depth += (char == "(") - (char == ")")
        if depth < 0:
            break
        if char == sep and depth == 0:
            parts.append(text[start:i])
            start = i + 1
    if depth != 0:
        raise ParameterError(f"unbalanced parentheses in degradation chain(s) {text!r}")
    return [*parts, text[start:]]


def _item_from_mapping(item: Mapping[str, Any]) -> DegradationChoice:
    unknown = sorted(set(item) - {"name", "preset", "params"})
    if unknown or "name" not in item:
        raise ParameterError(
            f"a degradation given as a mapping needs 'name' and may have 'preset' and 'params'; got keys {sorted(item)}"
        )
    preset = item.get("preset")
    return DegradationChoice(item["name"], None if preset is None else str(preset), item.get("params"))


def _params_from_text(text: str, item: str) -> dict[str, int | float]:
    out: dict[str, int | float] = {}
    for part in filter(None, (p.strip() for p in text.split(","))):
        key, eq, value = (x.strip() for x in part.partition("="))
        if not eq or key in out:
            raise ParameterError(f"degradation {item!r}: parameters are written key=value, each once (e.g. 'haze(density=3.5)'), got {part!r}")
        try:
            out[key] = int(value) if _INT_RE.fullmatch(value) else float(value)
        except ValueError:
            raise ParameterError(f"degradation {item!r}: parameter {key!r} must be a number, got {value!r}") from None
    return out


def _item_from_text(text: str) -> DegradationChoice:
    match = _ITEM_RE.fullmatch(text)
    if match is None:
        raise ParameterError(
            f"cannot read a degradation from {text.strip()!r}: write name, name:preset or name:preset(key=value, …), "
            "e.g. 'haze', 'haze:3', 'haze:bench(density=3.5)'"
        )
    params = match["params"]
    return DegradationChoice(match["name"], match["preset"], None if params is None else _params_from_text(params, text.strip()))


def _items(value: Any) -> tuple[DegradationChoice, ...]:
    if value is None:
        return ()
    if isinstance(value, Chain):
        return value.items
    if isinstance(value, str):
        if value.strip() in ("", "clean"):
            return ()
        return tuple(_item_from_text(part) for part in split_chains(value, "+"))
    if isinstance(value, DegradationChoice):
        return (value,)
    if isinstance(value, Mapping):
        return (_item_from_mapping(value),)
    if isinstance(value, tuple) and len(value) == 2 and isinstance(value[0], str) and isinstance(value[1], (Mapping, str, int)):
        name, extra = value
        return (DegradationChoice(name, params=extra) if isinstance(extra, Mapping) else DegradationChoice(name, str(extra)),)
    if isinstance(value, Iterable) and not isinstance(value, (bytes, bytearray)):
        return tuple(item for part in value for item in _items(part))
    raise ParameterError(
        f"cannot read a degradation from {value!r}; give a name ('haze', 'haze:3'), a mixture "
        f"({', '.join(MIXTURES)}), a mapping {{'name', 'preset', 'params'}} or a list of these"
    )


def _lookup(name: str) -> DegradationSpec:
    try:
        return get_degradation(name)
    except UnknownPluginError as err:
        close = suggest(name, list(MIXTURES))
        hint = f" Mixtures: {', '.join(MIXTURES)}." if not close else f" Did you mean the mixture {close[0]!r}?"
        raise UnknownPluginError(f"{err}{hint}") from None


# ------------------------------------------------------------------ the chain
def _reads_depth(spec: DegradationSpec, preset: str, choice: DegradationChoice) -> bool:
    """Whether ``preset`` of ``spec`` has a depth-relative range that ``choice`` does not set explicitly."""
    explicit = choice.params or {}
    return any(r.per_depth and name not in explicit for name, r in spec.presets.get(preset, {}).items())


def _reads_size(spec: DegradationSpec, preset: str, choice: DegradationChoice) -> bool:
    """Whether ``preset`` of ``spec`` has a pixel range stated at the reference size that ``choice`` does not set explicitly."""
    explicit = choice.params or {}
    return any(r.per_size and name not in explicit for name, r in spec.presets.get(preset, {}).items())


@dataclass(frozen=True)
class Chain:
    """One degradation chain (see the module docstring). Build it with :meth:`parse`.

    Attributes:
        items: the items as written (a mixture is one item until :meth:`choices` expands it).
    """

    items: tuple[DegradationChoice, ...] = ()

    def __post_init__(self) -> None:
        items = tuple(self.items)
        if not all(isinstance(item, DegradationChoice) for item in items):
            raise ParameterError(f"Chain(items) takes DegradationChoice objects (use Chain.parse for other forms), got {self.items!r}")
        object.__setattr__(self, "items", items)

    @classmethod
    def parse(cls, value: Any) -> Chain:
        """A :class:`Chain` from any accepted form (see the module docstring); a chain is returned as is."""
        return value if isinstance(value, Chain) else cls(_items(value))

    @property
    def is_clean(self) -> bool:
        return not self.items

    @property
    def name(self) -> str:
        """The ``degradation_type``: ``"ori"`` for clean, else item names joined by ``+``
        (``"haze:3+low_res"`` → ``"haze+low_res"``; ``"night_capture"`` stays)."""
        return CLEAN if self.is_clean else "+".join(item.name for item in self.items)

    @property
    def text(self) -> str:
        """Canonical text: ``"clean"`` or the items joined by ``+`` (``"haze:3+low_res"``)."""
        return "clean" if self.is_clean else "+".join(item.text() for item in self.items)

    def __str__(self) -> str:
        return self.text

    def with_severity(self, severity: str) -> Chain:
        """Every item written without a preset gets ``severity``; mixtures keep their recipe."""
        severity = str(severity)
        return Chain(tuple(
            item if item.preset is not None or item.is_mixture else DegradationChoice(item.name, severity, item.params)
            for item in self.items
        ))

    def choices(self, mixture_preset: str = "2") -> tuple[DegradationChoice, ...]:
        """The items with mixtures expanded: the primary at the default preset, the auxiliaries at
        ``mixture_preset``."""
        out: list[DegradationChoice] = []
        for item in self.items:
            if item.is_mixture:
                recipe = MIXTURES[item.name]
                out += [DegradationChoice(recipe.primary), *(DegradationChoice(a, mixture_preset) for a in recipe.auxiliaries)]
            else:
                out.append(item)
        return tuple(out)

    def scales_with_depth(self, default_preset: str = "bench", mixture_preset: str = "2") -> bool:
        """Whether resolving this chain reads the scene depth (a preset with a ``per_depth`` range
        whose parameters are not all given explicitly)."""
        return any(_reads_depth(_lookup(c.name), c.preset or default_preset, c) for c in self.choices(mixture_preset))

    def resolve(
        self, seed: int, default_preset: str = "bench", mixture_preset: str = "2", scene_depth: float | None = None,
        image_size: tuple[int, int] | None = None,
    ) -> tuple[ResolvedDegradation, ...]:
        """Concrete parameters for each degradation, drawn from ``derive_seed(seed, name)``, sorted
        into the physical order; depth-relative ranges scaled to ``scene_depth`` metres (``None``:
        the reference depth, the ranges as written), pixel ranges to the output's
        ``image_size = (width, height)`` (``None``: the reference size, the ranges as written).

        Raises :class:`ParameterError` (or :class:`UnknownPluginError`) for an unknown name, unknown
        preset, unknown parameter, a value outside its hard limits, or one degradation twice.
        """
        if scene_depth is not None and not (isinstance(scene_depth, (int, float, np.floating, np.integer)) and math.isfinite(scene_depth) and scene_depth > 0):
            raise ParameterError(f"scene_depth must be a finite positive number of metres, got {scene_depth!r}")
        resolved: list[ResolvedDegradation] = []
        seen: set[str] = set()
        for choice in self.choices(mixture_preset):
            spec = _lookup(choice.name)
            if spec.name in seen:
                raise ParameterError(
                    f"degradation {spec.name!r} appears twice in one chain; a chain applies each degradation once "
                    "(a mixture already includes its auxiliaries)"
                )
            seen.add(spec.name)
            deg_seed = derive_seed(seed, spec.name)
            preset = choice.preset or default_preset
            if preset not in spec.presets:
                spec.sample_params(preset, np.random.default_rng(deg_seed))  # the unknown-preset error
            scaled = scene_depth is not None and _reads_depth(spec, preset, choice)
            sized = image_size is not None and _reads_size(spec, preset, choice)
            params = spec.sample_params(preset, np.random.default_rng(deg_seed), scene_depth if scaled else None,
                                        tuple(image_size) if sized else None)  # type: ignore[arg-type]
            if choice.params:
                params.update(spec.validate_params(dict(choice.params), partial=True))
                if set(choice.params) == set(spec.param_map):
                    preset = None  # every value explicit: no preset involved
            depth = float(scene_depth) if scaled else None  # type: ignore[arg-type]
            size = (int(image_size[0]), int(image_size[1])) if sized else None  # type: ignore[index]
            resolved.append(ResolvedDegradation(spec, spec.validate_params(params), deg_seed, preset, depth, size))
        return tuple(sorted(resolved, key=lambda r: r.spec.sort_key))

    def provenance(
        self, seed: int, default_preset: str = "bench", mixture_preset: str = "2", scene_depth: float | None = None,
        image_size: tuple[int, int] | None = None,
    ) -> list[dict[str, Any]]:
        """What a sample under this chain records: ``[{name, params, seed, preset}, …]`` in pipeline order."""
        return [step.provenance() for step in self.resolve(seed, default_preset, mixture_preset, scene_depth, image_size)]

    def check(self, severities: Iterable[str | None] = (None,)) -> Chain:
        """Resolve once per severity (``None``: as written) so unknown names, presets and repeats
        fail now with suggestions; returns ``self``."""
        for level in severities:
            (self if level is None else self.with_severity(level)).resolve(0)
        return self


def parse_chain(chain: Any, mixture_preset: str = "2") -> tuple[DegradationChoice, ...]:
    """``Chain.parse(chain).choices(mixture_preset)``: one chain as degradation choices, mixtures expanded."""
    return Chain.parse(chain).choices(mixture_preset)


def resolve_chain(
    chain: Any, seed: int, default_preset: str = "bench", mixture_preset: str = "2"
) -> tuple[ResolvedDegradation, ...]:
    """``Chain.parse(chain).resolve(...)``: concrete, sorted degradations of one chain."""
    return Chain.parse(chain).resolve(seed, default_preset, mixture_preset)
