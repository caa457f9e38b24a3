"""What a degradation plugin declares (:class:`DegradationSpec`), and the names every plugin shares.

A **degradation** is described by a :class:`DegradationSpec`: its name, :class:`Category`,
:class:`Stage`, parameters (:class:`ParamSpec`, with units and hard limits), presets
(``"bench"`` = the paper's parameter table, ``"1"`` … ``"5"`` = severity, mild → harsh),
what it needs from the render, and its ``apply`` callable. The enums a question record uses
(:class:`AnswerType`, :class:`TaskGroup`) and the name patterns live here too; a **question
family** is declared by :class:`~spacedg.plugins.question_family.QuestionFamily`.

Stage contracts (what ``apply`` receives and returns)
-----------------------------------------------------

The pipeline runs one physical camera: raster-stage degradations change the render itself →
linear HDR light (unclamped) → linear-stage degradations → clip → sRGB encode → display-stage
degradations. Within a stage, degradations run in increasing :attr:`DegradationSpec.order`
(the physical position of the effect, see :data:`ORDER_GUIDE`), whatever order a user lists
them in. Every ``apply`` is deterministic given ``(input, params, rng)``: it draws randomness
only from ``rng`` (a :class:`numpy.random.Generator`), never from global state.

``Stage.RASTER`` — :class:`RasterApply`
    ``apply(request, params, rng) -> request``: receives the view's
    :class:`spacedg.render.request.RenderRequest` (camera and lens, defocus, motion, outputs)
    and returns an edited copy (``dataclasses.replace``); it never sees pixels. It is typed
    loosely (``Any``) here so this module does not import the renderer.
``Stage.LINEAR`` — :class:`LinearApply`
    ``apply(rgb, aux, params, rng) -> rgb``: ``rgb`` is linear-light HDR float32 (H, W, 3),
    **unclamped** (values above 1 are real light); ``aux`` maps the render outputs the spec
    declared in ``needs`` (e.g. ``"depth"``: (H, W) float32 metres, expected z along the optical
    axis; ``"alpha"``: (H, W) float32; ``"instance_ids"``: (H, W) int32, -1 = none) to arrays.
    When some degradation of the sample needs depth, the pipeline also passes
    ``aux["far_depth"]``: the sample's far surface depth in metres (99th percentile of covered
    depths, maximum over the sample's views), for models normalised by depth.
    Returns float32 (H, W, 3); the input must not be modified in place.
``Stage.DISPLAY`` — :class:`DisplayApply`
    ``apply(image, params, rng) -> image``: ``image`` is the encoded 8-bit sRGB picture,
    uint8 (H, W, 3), RGB channel order. Returns uint8 of the same shape. A display stage
    receives no render outputs, so its ``needs`` must be empty.

Device implementations (optional, :attr:`DegradationSpec.apply_torch`)
----------------------------------------------------------------------

A linear or display degradation may also give ``apply_torch`` with the same signature on torch
tensors on the render's device (linear: ``rgb`` float32 (H, W, 3), ``aux`` tensors plus the
``far_depth`` float; display: uint8 (H, W, 3)), the same ``params`` and the same numpy ``rng``
(it draws the same numbers from it; noise fields may be drawn on the device from a key taken
from ``rng``). The pipeline uses it when it degrades on a torch device
(:mod:`spacedg.data.pipeline`); a degradation without one runs its numpy ``apply`` there, the
image copied to the host and back. Its tolerance against ``apply`` is the plugin's to state.

Parameters and presets
----------------------

``params`` given to ``apply`` is the dict returned by :meth:`DegradationSpec.validate_params`
(every declared parameter present, integers as ``int``, others as ``float``). A preset maps
every parameter to a :class:`ParamRange`; ``low == high`` fixes the value. Severity presets
``"1"`` … ``"5"`` must be monotone (mild → harsh) in each parameter that declares
``harsher="higher"`` or ``harsher="lower"``.
"""

from __future__ import annotations

import difflib
import math
import re
from collections.abc import Callable, Iterable, Mapping
from dataclasses import asdict, dataclass, field
from enum import StrEnum
from typing import TYPE_CHECKING, Any, Literal, Protocol, TypeVar

import numpy as np

from spacedg.errors import ParameterError, PluginError

if TYPE_CHECKING:  # pragma: no cover - typing only
    from spacedg.plugins.origin import PluginOrigin

__all__ = [
    "NAME_PATTERN",
    "SUB_TYPE_PATTERN",
    "SEVERITY_PRESETS",
    "REQUIRED_PRESETS",
    "RENDER_OUTPUTS",
    "ORDER_GUIDE",
    "ParamSpec",
    "ParamRange",
    "REFERENCE_DEPTH_M",
    "REFERENCE_IMAGE_SIZE",
    "image_scale",
    "scale_pixels",
    "Category",
    "Stage",
    "AnswerType",
    "TaskGroup",
    "RasterApply",
    "LinearApply",
    "DisplayApply",
    "DegradationSpec",
    "enum_member",
    "suggest",
]

E = TypeVar("E", bound=StrEnum)

#: Names of degradations, question families, parameters and sub question types.
NAME_PATTERN = re.compile(r"^[a-z][a-z0-9_]*$")
#: ``sub_question_type`` values: like names, plus ``+`` (camera rotation's ``"yaw+pitch_dual"``).
SUB_TYPE_PATTERN = re.compile(r"^[a-z][A-Za-z0-9_+]*$")
_PRESET_PATTERN = re.compile(r"^[a-z0-9][a-z0-9_]*$")

#: Severity presets, mild → harsh.
SEVERITY_PRESETS: tuple[str, ...] = ("1", "2", "3", "4", "5")
#: Presets every degradation declares: the paper's table (or, for degradations the paper does
#: not cover, a representative harsh setting) and the five severities.
REQUIRED_PRESETS: tuple[str, ...] = ("bench", *SEVERITY_PRESETS)

#: Render outputs a degradation may ask for in ``needs`` (anything else is computed only
#: when some degradation asks for it).
RENDER_OUTPUTS: frozenset[str] = frozenset({"depth", "median_depth", "alpha", "instance_ids"})

#: Conventional :attr:`DegradationSpec.order` values (the physical position within a stage);
#: third-party degradations pick a value between these.
ORDER_GUIDE: Mapping[str, float] = {
    # raster
    "distortion": 10.0,
    "defocus": 20.0,
    "motion_blur": 30.0,
    # linear: atmosphere → front glass → lens → sensor gain → sensor noise
    "haze": 10.0,
    "water_droplets": 20.0,
    "vignetting": 25.0,
    "low_light": 30.0,
    "over_exposure": 30.0,
    # display
    "low_res": 10.0,
    "jpeg_compression": 20.0,
}


def suggest(name: str, choices: Iterable[str], n: int = 3) -> list[str]:
    """Up to ``n`` names from ``choices`` close to ``name`` (difflib, cutoff 0.6)."""
    return difflib.get_close_matches(str(name), list(choices), n=n, cutoff=0.6)


def _did_you_mean(name: str, choices: Iterable[str]) -> str:
    close = suggest(name, choices)
    return f" Did you mean {', '.join(repr(c) for c in close)}?" if close else ""


def _check_name(value: object, what: str) -> str:
    if not isinstance(value, str) or not NAME_PATTERN.match(value):
        raise PluginError(
            f"{what} {value!r} is not a valid name: use lower-case letters, digits and '_', "
            "starting with a letter (pattern ^[a-z][a-z0-9_]*$)"
        )
    return value


def _is_number(value: object) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))


# ------------------------------------------------------------------ enums
class Category(StrEnum):
    """The paper's four degradation categories."""

    OPTICAL_DYNAMIC = "optical_dynamic"
    METEOROLOGICAL = "meteorological"
    PHOTOMETRIC = "photometric"
    DIGITAL = "digital"


class Stage(StrEnum):
    """Where in the image formation a degradation acts (see the module docstring)."""

    RASTER = "raster"
    LINEAR = "linear"
    DISPLAY = "display"

    @property
    def rank(self) -> int:
        """Pipeline position: raster 0, linear 1, display 2."""
        return {"raster": 0, "linear": 1, "display": 2}[self.value]


class AnswerType(StrEnum):
    """How an answer is represented and scored (see ``spacedg.plugins.qa_record``)."""

    MCQ = "MCQ"
    YN = "YN"
    NA = "NA"
    COUNT = "COUNT"
    SIZE_LIST = "SIZE_LIST"


class TaskGroup(StrEnum):
    """The paper's three task groups."""

    CAMERA_CENTRIC = "camera_centric"
    CAMERA_OBJECT = "camera_object"
    OBJECT_CENTRIC = "object_centric"


def enum_member(enum_cls: type[E], value: object) -> E | None:
    """``value`` as a member of ``enum_cls`` (a member, or a member's value), or ``None`` if it is neither."""
    if isinstance(value, enum_cls):
        return value
    try:
        return enum_cls(value)
    except ValueError:
        return None


def _enum(enum_cls: type[StrEnum], value: object, what: str) -> Any:
    member = enum_member(enum_cls, value)
    if member is None:
        allowed = [m.value for m in enum_cls]
        raise PluginError(f"{what} {value!r} is not one of: {', '.join(allowed)}.{_did_you_mean(str(value), allowed)}")
    return member


# ------------------------------------------------------------- protocols
class RasterApply(Protocol):
    """``apply(options, params, rng) -> options`` for raster-stage degradations."""

    def __call__(self, options: Any, params: Mapping[str, Any], rng: np.random.Generator) -> Any: ...


class LinearApply(Protocol):
    """``apply(rgb_linear_f32_HxWx3, aux, params, rng) -> rgb_linear_f32_HxWx3`` for linear-stage degradations."""

    def __call__(
        self,
        rgb: np.ndarray,
        aux: Mapping[str, np.ndarray],
        params: Mapping[str, Any],
        rng: np.random.Generator,
    ) -> np.ndarray: ...


class DisplayApply(Protocol):
    """``apply(image_uint8_HxWx3_RGB, params, rng) -> uint8 image of the same shape`` for display-stage degradations."""

    def __call__(self, image: np.ndarray, params: Mapping[str, Any], rng: np.random.Generator) -> np.ndarray: ...


# ------------------------------------------------------------ parameters
@dataclass(frozen=True)
class ParamSpec:
    """One parameter of a degradation.

    Attributes:
        name: parameter name (the paper's name where it has one).
        unit: unit string: ``"px"`` (pixels at the rendered resolution), ``"m"``, ``"1/m"``,
            ``"rad"``, ``"s"``, ``"1"`` (dimensionless), …
        description: what the parameter does, in one or two sentences.
        low, high: hard limits, inclusive; ``None`` = unbounded on that side. Values outside
            are rejected, never clamped.
        integer: the parameter takes integer values only.
        harsher: ``"higher"`` if larger values degrade more, ``"lower"`` if smaller values do,
            ``None`` if neither (structural parameters such as a sub-step count). Used to check
            that the severity presets are monotone.
        recorded_default: for a parameter added after callers and samples were written: the
            value a params mapping (or provenance entry) without it stands for, the behaviour
            before it existed; ``None`` = it must be given.
    """

    name: str
    unit: str
    description: str
    low: float | None = None
    high: float | None = None
    integer: bool = False
    harsher: Literal["higher", "lower"] | None = None
    recorded_default: float | None = None

    def __post_init__(self) -> None:
        _check_name(self.name, "parameter name")
        if not isinstance(self.unit, str) or not self.unit.strip():
            raise PluginError(f"parameter {self.name!r}: unit must be a non-empty string such as 'px', 'm', 'rad' or '1'")
        if not isinstance(self.description, str):
            raise PluginError(f"parameter {self.name!r}: description must be a string")
        for side in ("low", "high"):
            value = getattr(self, side)
            if value is None:
                continue
            if not _is_number(value) or not math.isfinite(float(value)):
                raise PluginError(f"parameter {self.name!r}: hard limit {side} must be a finite number or None, got {value!r}")
            if self.integer and float(value) != int(value):
                raise PluginError(f"parameter {self.name!r} is integer, but its hard limit {side} is {value!r}")
            object.__setattr__(self, side, int(value) if self.integer else float(value))
        if self.low is not None and self.high is not None and self.low > self.high:
            raise PluginError(f"parameter {self.name!r}: hard limits low={self.low} > high={self.high}")
        if self.harsher not in (None, "higher", "lower"):
            raise PluginError(f"parameter {self.name!r}: harsher must be 'higher', 'lower' or None, got {self.harsher!r}")

    def limits_text(self) -> str:
        lo = "-inf" if self.low is None else f"{self.low:g}"
        hi = "inf" if self.high is None else f"{self.high:g}"
        return f"[{lo}, {hi}]"

    def check(self, value: object, where: str) -> int | float:
        """Return ``value`` as ``int`` / ``float`` or raise :class:`ParameterError`."""
        if not _is_number(value) or not math.isfinite(float(value)):  # type: ignore[arg-type]
            raise ParameterError(f"{where}: parameter {self.name!r} must be a finite number ({self.unit}), got {value!r}")
        number = float(value)  # type: ignore[arg-type]
        if self.integer:
            if number != int(number):
                raise ParameterError(f"{where}: parameter {self.name!r} must be an integer, got {value!r}")
            number = int(number)
        if (self.low is not None and number < self.low) or (self.high is not None and number > self.high):
            raise ParameterError(
                f"{where}: parameter {self.name!r} = {value!r} is outside its hard limits {self.limits_text()} "
                f"({self.unit}); pick a value inside them"
            )
        return number

    def to_dict(self) -> dict[str, Any]:
        """Every field, in declaration order (plain JSON types; ``recorded_default`` only when set)."""
        out = asdict(self)
        if self.recorded_default is None:
            del out["recorded_default"]
        return out


#: The scene depth (metres) at which a preset's depth-relative ranges (``ParamRange(per_depth=True)``)
#: are stated: the median surface depth of a frame of a ScanNet++-style room (indoor RGB-D sets
#: such as ScanNet and NYUv2 put the median of their depth maps at 2–3 m; the built-in rooms
#: measure 2.9–3.5 m). At this depth the ``bench`` presets are the paper's table verbatim.
REFERENCE_DEPTH_M = 2.5


#: The image size ``(width, height)`` in pixels at which a preset's pixel ranges
#: (``ParamRange(per_size=True)``) are stated: a ScanNet++ DSLR frame as published (the
#: undistorted and resized DSLR images of ScanNet++ are 1752 × 1168, 3:2, principal point at
#: (876, 584)), the frames the paper's bench was rendered from. At this size the ``bench``
#: presets are the paper's table verbatim.
REFERENCE_IMAGE_SIZE: tuple[int, int] = (1752, 1168)


def image_scale(width: int, height: int) -> float:
    """How many times larger an image of ``width × height`` pixels is than the reference
    (:data:`REFERENCE_IMAGE_SIZE`): the ratio of the shorter sides, ``min(W, H) / 1168``.

    The one place pixel lengths are scaled with the image (a length in pixels at the reference
    becomes ``length · image_scale`` pixels). The shorter side is used because it is what the
    drop field of ``water_droplets`` counts its cells across, so blur and drops keep their
    proportion at every aspect ratio; at the reference's 3:2 it equals the width ratio.
    """
    w, h = int(width), int(height)
    if w < 1 or h < 1:
        raise ParameterError(f"image_scale: the image size must be at least 1 × 1 pixels, got {width!r} × {height!r}")
    return min(w, h) / float(min(REFERENCE_IMAGE_SIZE))


def scale_pixels(value: float, scale: float, integer: bool = False, power: int = 1) -> int | float:
    """A length of ``value`` pixels at the reference size, at an image ``scale`` times larger
    (:func:`image_scale`): ``value · scale``. With ``power = -1`` a fraction of the image whose
    result is stated in reference pixels (low_res's size factor: the reduced image keeps its
    pixel count): ``value / scale``. An integer is a window size: an odd window stays odd (its
    half-width ``(value - 1) / 2`` is scaled and rounded, so a kernel keeps a centre pixel;
    never below 1), an even one is rounded (never below 1)."""
    if power == -1:
        return float(value) / float(scale)
    if not integer:
        return float(value) * float(scale)
    value = int(value)
    if value % 2 == 1:
        return 2 * int(round((value - 1) / 2 * scale)) + 1
    return max(1, int(round(value * scale)))


@dataclass(frozen=True)
class ParamRange:
    """A closed interval ``[low, high]`` a preset samples a parameter from (``low == high``: fixed).

    ``per_depth=True``: the range is stated for a scene at :data:`REFERENCE_DEPTH_M` and scales
    with the sample's scene depth ``D`` (a focus distance, a camera path, a haze reference
    distance: metres that should follow the scene's size, so a tabletop and a room degrade
    alike); :meth:`DegradationSpec.sample_params` draws from the range, then multiplies by
    ``D / REFERENCE_DEPTH_M`` (clamped to the parameter's hard limits).

    ``per_size=True`` (= 1): a length in pixels (unit ``"px"``) stated at
    :data:`REFERENCE_IMAGE_SIZE` that scales with the output image (:func:`image_scale`,
    :func:`scale_pixels`), so one preset degrades a 1920 × 1080 and a 640 × 360 render of the
    same view alike. ``per_size=-1``: a fraction of the image (unit ``"1"``) whose result is a
    pixel count stated at the reference, so it scales inversely (low_res's ``scale``).
    """

    low: float
    high: float
    per_depth: bool = False
    per_size: int = 0

    def __post_init__(self) -> None:
        for side in ("low", "high"):
            value = getattr(self, side)
            if not _is_number(value) or not math.isfinite(float(value)):
                raise PluginError(f"ParamRange: {side} must be a finite number, got {value!r}")
            object.__setattr__(self, side, int(value) if isinstance(value, (int, np.integer)) else float(value))
        if self.low > self.high:
            raise PluginError(f"ParamRange: low={self.low} > high={self.high}; write the smaller bound first")

    @classmethod
    def of(cls, value: ParamRange | tuple[float, float] | list[float] | float) -> ParamRange:
        """Coerce ``(low, high)``, ``[low, high]`` or a single number (fixed) to a range."""
        if isinstance(value, ParamRange):
            return value
        if isinstance(value, (tuple, list)):
            if len(value) != 2:
                raise PluginError(f"ParamRange: expected (low, high), got {value!r}")
            return cls(value[0], value[1])
        if _is_number(value):
            return cls(value, value)  # type: ignore[arg-type]
        raise PluginError(f"ParamRange: expected a ParamRange, (low, high) or a number, got {value!r}")

    @property
    def fixed(self) -> bool:
        return self.low == self.high

    def sample(self, rng: np.random.Generator, integer: bool = False) -> int | float:
        """One uniform draw from ``[low, high]``; integers uniform over ``low..high`` inclusive.

        Always consumes exactly one ``rng.random()`` draw (also when fixed), so the stream of a
        preset does not shift when one of its ranges is fixed.
        """
        u = float(rng.random())
        if integer:
            lo, hi = math.ceil(self.low), math.floor(self.high)
            return int(min(hi, lo + math.floor(u * (hi - lo + 1))))
        if self.fixed:
            return float(self.low)
        return float(self.low + u * (self.high - self.low))

    def to_list(self) -> list[float]:
        return [self.low, self.high]

    def scaled(self, value: float, scene_depth: float | None) -> float:
        """``value`` drawn from this range, at ``scene_depth`` metres (module :data:`REFERENCE_DEPTH_M`)."""
        if not self.per_depth or scene_depth is None:
            return value
        return float(value) * (float(scene_depth) / REFERENCE_DEPTH_M)  # ratio first: exact at the reference

    def sized(self, value: int | float, image_size: tuple[int, int] | None, integer: bool = False) -> int | float:
        """``value`` drawn from this range, at an image of ``image_size = (width, height)`` pixels."""
        if not self.per_size or image_size is None:
            return value
        return scale_pixels(value, image_scale(*image_size), integer, -1 if self.per_size == -1 else 1)


# --------------------------------------------------------- degradations
@dataclass(frozen=True, eq=False)
class DegradationSpec:
    """Everything the engine needs to know about one degradation (see the module docstring).

    Attributes:
        name: unique name (``^[a-z][a-z0-9_]*$``), the paper's where it has one.
        category: one of :class:`Category`.
        stage: one of :class:`Stage`; fixes the ``apply`` contract.
        params: the parameters, in a fixed order.
        presets: preset name → {parameter name → :class:`ParamRange` (or ``(low, high)``, or a
            number)}; must contain :data:`REQUIRED_PRESETS`, name every parameter, stay within
            the hard limits, and be monotone over the severities.
        apply: the stage's callable (:class:`RasterApply`, :class:`LinearApply` or
            :class:`DisplayApply`).
        needs: render outputs ``apply`` reads (subset of :data:`RENDER_OUTPUTS`).
        description: the model in a few sentences, with units.
        order: physical position within the stage (see :data:`ORDER_GUIDE`); lower runs first.
        apply_torch: optional twin of ``apply`` on torch tensors (see "Device implementations"
            in the module docstring); ``None`` = the pipeline's device path runs ``apply`` on the host.
        origin: set by the registry: which plugin registered the spec.
    """

    name: str
    category: Category
    stage: Stage
    params: tuple[ParamSpec, ...]
    presets: Mapping[str, Mapping[str, ParamRange]]
    apply: Callable[..., Any]
    needs: frozenset[str] = frozenset()
    description: str = ""
    order: float = 50.0
    apply_torch: Callable[..., Any] | None = field(default=None, compare=False, repr=False)
    origin: PluginOrigin | None = field(default=None, compare=False, repr=False)

    def __post_init__(self) -> None:
        _check_name(self.name, "degradation name")
        where = f"degradation {self.name!r}"
        object.__setattr__(self, "category", _enum(Category, self.category, f"{where}: category"))
        object.__setattr__(self, "stage", _enum(Stage, self.stage, f"{where}: stage"))
        params = tuple(self.params)
        for p in params:
            if not isinstance(p, ParamSpec):
                raise PluginError(f"{where}: params must be ParamSpec objects, got {type(p).__name__}")
        names = [p.name for p in params]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise PluginError(f"{where}: parameter(s) {dup} declared more than once")
        object.__setattr__(self, "params", params)
        if not callable(self.apply):
            raise PluginError(f"{where}: apply must be callable, got {type(self.apply).__name__}")
        if self.apply_torch is not None and not callable(self.apply_torch):
            raise PluginError(f"{where}: apply_torch must be callable or None, got {type(self.apply_torch).__name__}")
        if self.apply_torch is not None and self.stage is Stage.RASTER:
            raise PluginError(f"{where}: a raster-stage degradation edits the render request; it has no apply_torch (the render itself runs on the device)")
        needs = frozenset(self.needs)
        unknown = sorted(needs - RENDER_OUTPUTS)
        if unknown:
            raise PluginError(
                f"{where}: needs {unknown} are not render outputs; choose from {sorted(RENDER_OUTPUTS)}"
            )
        if self.stage is Stage.DISPLAY and needs:
            raise PluginError(f"{where}: a display-stage degradation receives no render outputs, so needs must be empty (got {sorted(needs)})")
        object.__setattr__(self, "needs", needs)
        if not isinstance(self.description, str):
            raise PluginError(f"{where}: description must be a string")
        if not _is_number(self.order) or not math.isfinite(float(self.order)):
            raise PluginError(f"{where}: order must be a finite number, got {self.order!r}")
        object.__setattr__(self, "order", float(self.order))
        object.__setattr__(self, "presets", self._check_presets(where))

    def _check_presets(self, where: str) -> dict[str, dict[str, ParamRange]]:
        if not isinstance(self.presets, Mapping):
            raise PluginError(f"{where}: presets must be a mapping preset name → {{param: (low, high)}}")
        by_name = self.param_map
        out: dict[str, dict[str, ParamRange]] = {}
        for preset, ranges in self.presets.items():
            if not isinstance(preset, str) or not _PRESET_PATTERN.match(preset):
                raise PluginError(f"{where}: preset name {preset!r} must be lower-case letters, digits and '_'")
            if not isinstance(ranges, Mapping):
                raise PluginError(f"{where}: preset {preset!r} must map parameter names to ranges")
            unknown = [k for k in ranges if k not in by_name]
            if unknown:
                hint = _did_you_mean(unknown[0], by_name)
                raise PluginError(f"{where}: preset {preset!r} names unknown parameter(s) {unknown}; parameters are {list(by_name)}.{hint}")
            missing = [k for k in by_name if k not in ranges]
            if missing:
                raise PluginError(f"{where}: preset {preset!r} does not give a range for {missing}; every preset must name every parameter")
            converted: dict[str, ParamRange] = {}
            for pname, value in ranges.items():
                rng_ = ParamRange.of(value)
                spec = by_name[pname]
                for bound in (rng_.low, rng_.high):
                    try:
                        spec.check(bound, f"{where}: preset {preset!r}")
                    except ParameterError as err:
                        raise PluginError(str(err)) from None
                if rng_.per_depth and (spec.integer or spec.unit != "m"):
                    raise PluginError(f"{where}: preset {preset!r}: only a parameter in metres may scale with scene depth (per_depth), not {pname!r}")
                if rng_.per_size not in (0, 1, -1) or (rng_.per_size == 1 and spec.unit != "px") or (rng_.per_size == -1 and spec.unit != "1"):
                    raise PluginError(
                        f"{where}: preset {preset!r}: only a parameter in pixels may scale with the image size (per_size=True), "
                        f"and only a dimensionless fraction inversely (per_size=-1), not {pname!r} ({spec.unit}, per_size={rng_.per_size!r})"
                    )
                converted[pname] = (
                    ParamRange(int(rng_.low), int(rng_.high), per_size=rng_.per_size) if spec.integer
                    else ParamRange(float(rng_.low), float(rng_.high), rng_.per_depth, rng_.per_size)
                )
            out[preset] = converted
        missing_presets = [p for p in REQUIRED_PRESETS if p not in out]
        if missing_presets:
            raise PluginError(
                f"{where}: missing preset(s) {missing_presets}; declare 'bench' (the paper's table, or a representative "
                "harsh setting) and the severities '1' (mild) … '5' (harsh)"
            )
        for p in self.params:
            if p.harsher is None:
                continue
            sign = 1.0 if p.harsher == "higher" else -1.0
            for a, b in zip(SEVERITY_PRESETS, SEVERITY_PRESETS[1:]):
                ra, rb = out[a][p.name], out[b][p.name]
                if sign * (rb.low - ra.low) < 0 or sign * (rb.high - ra.high) < 0:
                    raise PluginError(
                        f"{where}: severity presets must get harsher from '1' to '5', but parameter {p.name!r} "
                        f"(harsher = {p.harsher}) goes from {ra.to_list()} at '{a}' to {rb.to_list()} at '{b}'"
                    )
        return out

    # ------------------------------------------------------------ queries
    @property
    def param_map(self) -> dict[str, ParamSpec]:
        """Parameter name → :class:`ParamSpec`, in declaration order."""
        return {p.name: p for p in self.params}

    @property
    def preset_names(self) -> list[str]:
        """Preset names: ``"bench"``, ``"1"`` … ``"5"``, then any others in declaration order."""
        rest = [p for p in self.presets if p not in REQUIRED_PRESETS]
        return [*REQUIRED_PRESETS, *rest]

    @property
    def sort_key(self) -> tuple[int, float, str]:
        """Pipeline order: (stage rank, order, name)."""
        return (self.stage.rank, self.order, self.name)

    def validate_params(self, params: Mapping[str, Any], *, partial: bool = False) -> dict[str, int | float]:
        """Check names and hard limits; return a new dict with ``int`` / ``float`` values.

        Raises :class:`ParameterError` for an unknown name (with close names suggested), a
        value that is not a finite number, a non-integer value for an integer parameter, a
        value outside the hard limits, or (unless ``partial``) a missing parameter. A missing
        parameter with a ``recorded_default`` (one added after callers and records were written)
        takes that value.
        """
        where = f"degradation {self.name!r}"
        if not isinstance(params, Mapping):
            raise ParameterError(f"{where}: params must be a mapping name → value, got {type(params).__name__}")
        by_name = self.param_map
        out: dict[str, int | float] = {}
        for key, value in params.items():
            if key not in by_name:
                raise ParameterError(
                    f"{where}: unknown parameter {key!r}.{_did_you_mean(str(key), by_name)} "
                    f"Parameters: {', '.join(f'{p.name} ({p.unit}, {p.limits_text()})' for p in self.params) or 'none'}"
                )
            out[key] = by_name[key].check(value, where)
        if not partial:
            out.update({k: v for k, v in self.recorded_defaults().items() if k not in out})
            missing = [k for k in by_name if k not in out]
            if missing:
                raise ParameterError(
                    f"{where}: missing parameter(s) {missing}; give every parameter, or start from "
                    f"sample_params(preset, rng) with a preset in {self.preset_names}"
                )
        return {p.name: out[p.name] for p in self.params if p.name in out}

    def scales_with_depth(self, preset: str) -> bool:
        """Whether ``preset`` has a depth-relative range (``ParamRange(per_depth=True)``)."""
        return any(r.per_depth for r in self.presets.get(str(preset), {}).values())

    def recorded_defaults(self) -> dict[str, int | float]:
        """``{name: recorded_default}`` of the parameters that have one (:class:`ParamSpec`), checked."""
        return {p.name: p.check(p.recorded_default, f"degradation {self.name!r}") for p in self.params if p.recorded_default is not None}

    def scales_with_size(self, preset: str) -> bool:
        """Whether ``preset`` has a pixel range stated at the reference size (``ParamRange(per_size=True)``)."""
        return any(r.per_size for r in self.presets.get(str(preset), {}).values())

    def sample_params(
        self, preset: str, rng: np.random.Generator, scene_depth: float | None = None, image_size: tuple[int, int] | None = None,
    ) -> dict[str, int | float]:
        """Draw one value per parameter from ``preset``, in declaration order, one draw each.

        ``scene_depth`` (metres, the sample's): depth-relative ranges are scaled by
        ``scene_depth / REFERENCE_DEPTH_M`` and clamped to the hard limits; ``None`` = the
        reference depth (the ranges as written). ``image_size`` (``(width, height)`` pixels of
        the output): pixel ranges stated at :data:`REFERENCE_IMAGE_SIZE` are scaled by
        :func:`image_scale` (:func:`scale_pixels`) and clamped; ``None`` = the reference size."""
        preset = str(preset)  # severities may be given as int
        if preset not in self.presets:
            raise ParameterError(
                f"degradation {self.name!r}: unknown preset {preset!r}.{_did_you_mean(preset, self.presets)} "
                f"Presets: {', '.join(self.preset_names)}"
            )
        if not isinstance(rng, np.random.Generator):
            raise ParameterError(f"degradation {self.name!r}: rng must be a numpy.random.Generator, got {type(rng).__name__}; use np.random.default_rng(seed)")
        ranges = self.presets[preset]
        if scene_depth is not None and not (_is_number(scene_depth) and math.isfinite(float(scene_depth)) and scene_depth > 0):
            raise ParameterError(f"degradation {self.name!r}: scene_depth must be a positive number of metres, got {scene_depth!r}")
        if image_size is not None and not (
            isinstance(image_size, (tuple, list)) and len(image_size) == 2
            and all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v >= 1 for v in image_size)
        ):
            raise ParameterError(f"degradation {self.name!r}: image_size must be (width, height) in whole pixels >= 1, got {image_size!r}")
        out: dict[str, int | float] = {}
        for p in self.params:
            value = ranges[p.name].sample(rng, integer=p.integer)
            scaled = (ranges[p.name].per_depth and scene_depth is not None) or (ranges[p.name].per_size and image_size is not None)
            if scaled:
                value = ranges[p.name].sized(ranges[p.name].scaled(value, scene_depth), image_size, p.integer)
                value = value if p.low is None else max(value, p.low)
                value = value if p.high is None else min(value, p.high)
            out[p.name] = value
        return out

    def describe(self) -> dict[str, Any]:
        """A JSON-serialisable description (what ``spacedg plugins --json`` prints)."""
        return {
            "name": self.name,
            "category": self.category.value,
            "stage": self.stage.value,
            "order": self.order,
            "needs": sorted(self.needs),
            "params": [p.to_dict() for p in self.params],
            "presets": {name: {k: r.to_list() for k, r in self.presets[name].items()} for name in self.preset_names},
            "description": self.description,
        }
