"""Degradation chains, one grammar: :class:`Chain` parses, names, expands, resolves and records them.

A **chain** is the degradations one sample goes through. Written as text, items are joined by
``+``; each item is a degradation name, ``name:preset`` (``"haze:3"``, ``"haze:bench"``) or the
name of a mixture recipe (``"night_capture"``, no preset)::

    "clean"  ""                       no degradation (``degradation_type`` "ori")
    "haze"   "haze:3+low_res"         one item, two items
    "night_capture"                   a mixture: low_light at the default preset, motion_blur and
                                      low_res at the mixture preset (severity "2")

In Python an item may also be a mapping ``{"name", "preset", "params"}`` (explicit parameters; the
others are sampled from the preset), a :class:`DegradationChoice`, ``(name, params)`` or
``(name, preset)``, and a chain a list of items.

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
  reproduces its bytes.

Seeds: each degradation of a chain draws its parameters from ``derive_seed(sample_seed, name)``, so
one degradation draws the same parameters in every chain of a sample.

Scene depth: presets whose metre ranges scale with the scene (``ParamRange(per_depth=True)``:
defocus focus distance, motion-blur path, haze reference distance) are resolved at the sample's
scene depth (``resolve(..., scene_depth=D)``, D in metres: the pipeline measures it,
:func:`~spacedg.data.pipeline.sample_scene_depth`); the provenance then holds the resolved
absolute metres and ``scene_depth_m``, so it still reproduces the bytes without measuring
anything. :meth:`Chain.scales_with_depth` says whether a chain needs D.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
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
    "ResolvedDegradation",
    "parse_chain",
    "resolve_chain",
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


@dataclass(frozen=True)
class DegradationChoice:
    """One item of a chain as a user asks for it.

    Attributes:
        name: a registered degradation name, or (before :meth:`Chain.choices`) a mixture name.
        preset: preset to sample parameters from (``None`` = the chain's default preset).
        params: explicit parameter values; parameters not given are sampled from the preset.
    """

    name: str
    preset: str | None = None
    params: Mapping[str, float] | None = None

    @property
    def is_mixture(self) -> bool:
        return self.name in MIXTURES

    def text(self) -> str:
        """``name`` or ``name:preset``; explicit parameters are shown as ``name(key=value, …)``
        (display only: text cannot carry parameters)."""
        out = self.name if self.preset is None else f"{self.name}:{self.preset}"
        if self.params:
            out += "(" + ", ".join(f"{k}={v}" for k, v in self.params.items()) + ")"
        return out


@dataclass(frozen=True)
class ResolvedDegradation:
    """A degradation with concrete parameters and its seed (what provenance records)."""

    spec: DegradationSpec
    params: Mapping[str, int | float]
    seed: int
    preset: str | None
    scene_depth: float | None = None

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
        scaled to the sample's scene depth), JSON-serialisable."""
        out = {"name": self.name, "params": dict(self.params), "seed": self.seed, "preset": self.preset}
        if self.scene_depth is not None:
            out["scene_depth_m"] = self.scene_depth
        return out


# ------------------------------------------------------------------ parsing
def _item_from_mapping(item: Mapping[str, Any]) -> DegradationChoice:
    unknown = sorted(set(item) - {"name", "preset", "params"})
    if unknown or "name" not in item:
        raise ParameterError(
            f"a degradation given as a mapping needs 'name' and may have 'preset' and 'params'; got keys {sorted(item)}"
        )
    preset = item.get("preset")
    return DegradationChoice(str(item["name"]), None if preset is None else str(preset), item.get("params"))


def _item_from_text(text: str) -> DegradationChoice:
    name, _, preset = text.strip().partition(":")
    name, preset = name.strip(), preset.strip()
    if name in MIXTURES and preset:
        raise ParameterError(
            f"mixture {name!r} takes no preset ({text.strip()!r}); its primary uses the default preset and the others "
            "the mixture preset"
        )
    return DegradationChoice(name, preset or None)


def _items(value: Any) -> tuple[DegradationChoice, ...]:
    if value is None:
        return ()
    if isinstance(value, Chain):
        return value.items
    if isinstance(value, str):
        if value.strip() in ("", "clean"):
            return ()
        return tuple(_item_from_text(part) for part in value.split("+"))
    if isinstance(value, DegradationChoice):
        return (value,)
    if isinstance(value, Mapping):
        return (_item_from_mapping(value),)
    if isinstance(value, tuple) and len(value) == 2 and isinstance(value[0], str) and isinstance(value[1], (Mapping, str, int)):
        name, extra = value
        return (DegradationChoice(name, params=extra) if isinstance(extra, Mapping) else DegradationChoice(name, str(extra)),)
    if isinstance(value, Iterable):
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


@dataclass(frozen=True)
class Chain:
    """One degradation chain (see the module docstring). Build it with :meth:`parse`.

    Attributes:
        items: the items as written (a mixture is one item until :meth:`choices` expands it).
    """

    items: tuple[DegradationChoice, ...] = ()

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
    ) -> tuple[ResolvedDegradation, ...]:
        """Concrete parameters for each degradation, drawn from ``derive_seed(seed, name)``, sorted
        into the physical order; depth-relative ranges scaled to ``scene_depth`` metres (``None``:
        the reference depth, the ranges as written).

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
            params = spec.sample_params(preset, np.random.default_rng(deg_seed), scene_depth if scaled else None)
            if choice.params:
                params.update(spec.validate_params(choice.params, partial=True))
                if set(choice.params) == set(spec.param_map):
                    preset = None  # every value explicit: no preset involved
            depth = float(scene_depth) if scaled else None  # type: ignore[arg-type]
            resolved.append(ResolvedDegradation(spec, spec.validate_params(params), deg_seed, preset, depth))
        return tuple(sorted(resolved, key=lambda r: r.spec.sort_key))

    def provenance(
        self, seed: int, default_preset: str = "bench", mixture_preset: str = "2", scene_depth: float | None = None,
    ) -> list[dict[str, Any]]:
        """What a sample under this chain records: ``[{name, params, seed, preset}, …]`` in pipeline order."""
        return [step.provenance() for step in self.resolve(seed, default_preset, mixture_preset, scene_depth)]

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
