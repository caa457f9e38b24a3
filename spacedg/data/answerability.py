"""Answerability: can the objects a question names still be seen in its (degraded) images?

A bench item whose named objects cannot be seen measures priors, not robustness. For each
object a question names, in the view where the question says to find it, this module measures
the contrast of its pixels against their surround in the **displayed** image (the item's 8-bit
sRGB image decoded to linear light ``Y``: its relative luminance, and each of its three colour
channels) and calls the object *discernible* when, in the luminance or in one channel, both hold:

1. **Weber contrast** ``C = |Y_o − Y_s| / (Y_s + f)`` is at least :data:`WEBER_THRESHOLD`
   (2 %). ``Y_o`` is the mean luminance of the object's pixels within a band of width ``w``
   inside its outline, ``Y_s`` the mean over a ring of width ``w`` outside it (display luminance,
   white = 1; ``w = max(2, 0.28·√n)`` px for an object of ``n`` pixels: the ring of a disc then
   has about the disc's area). 2 % is the classic Weber fraction of photopic vision and the
   contrast threshold that defines the meteorological visibility in Koschmieder's law (the
   haze plugin's ``ln(1/0.02) = 3.912``), so a hazed object is discernible exactly when it lies
   inside the visibility distance the haze model itself states. ``f`` = :data:`VIEWING_FLARE`
   (1 % of white): the veiling flare of the sRGB reference viewing environment (IEC 61966-2-1),
   light the screen reflects whatever the image shows, so a step between two near-black codes
   is not a large contrast (one 8-bit code at black is 2.4 % with it, not infinite).
2. **Contrast against noise** (Rose's criterion): ``|Y_o − Y_s| / (σ·√(1/n_o + 1/n_s))`` is at
   least :data:`ROSE_K` (5), ``σ`` the image's pixel noise (Immerkær's Laplacian estimate on the
   luminance; texture inflates it, so the test errs towards "not discernible"), ``n_o``, ``n_s``
   the pixels averaged. A step buried in sensor noise is not seen however large its mean.

Colour: a red teapot in front of a grey veil of the same luminance is plainly seen; eyes detect
an isoluminant colour step at lower cone contrast than a luminance step, so holding each linear
channel (a stand-in for the cone classes) to the same 2 % is conservative. The record keeps the
signal the object stood out in.

Where the object is: the instance-id map of a render with the item's own lens (distortion moves
objects) but without its blur (defocus and motion blur spread an object's light, not its
place): the object is where it is; the question is whether its light still stands out there.
Objects named: ``refs`` of the geometry block (each in its view), the counted objects of a
counting question, the visible members of an existence question's label (any one of them
suffices). Questions that name no visible object (camera motion, "is there a …?" answered no)
have nothing to check: they count as answerable and the shares leave them out (``groups == 0``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from spacedg.errors import InvalidDataError, ParameterError

if TYPE_CHECKING:
    from spacedg.data.pipeline import PipelineOptions
    from spacedg.plugins.qa_record import QARecord
    from spacedg.scene.model import Scene

__all__ = [
    "ROSE_K",
    "VIEWING_FLARE",
    "WEBER_THRESHOLD",
    "ItemAnswerability",
    "ObjectContrast",
    "answerability_table",
    "condition_of",
    "groups_answerability",
    "item_answerability",
    "named_objects",
    "noise_sigma",
    "object_contrast",
    "object_id_maps",
    "share_by_condition",
]

#: Weber contrast an object needs against its surround (2 %: Weber fraction; Koschmieder's visibility threshold).
WEBER_THRESHOLD = 0.02
#: Veiling flare of the display, fraction of white (IEC 61966-2-1 reference viewing environment: 1 %).
VIEWING_FLARE = 0.01
#: Rose's criterion: the mean step must be this many noise standard deviations of the difference of means.
ROSE_K = 5.0
#: Band / ring width per √(object pixels) (a disc's ring of this width has about the disc's area).
SURROUND_RATIO = 0.28
_MIN_BAND_PX = 2
_CACHE_ITEMS = 64  # id-map sets an object_id_maps cache keeps
_LUMA = np.array([0.2126, 0.7152, 0.0722], dtype=np.float64)  # Rec. 709 / sRGB relative luminance
_SIGNAL_NAMES = ("luminance", "red", "green", "blue")
_DECODE: np.ndarray | None = None


@dataclass(frozen=True)
class ObjectContrast:
    """One named object in one view of one item.

    Attributes:
        id: instance id. view: the view name. pixels: the object's pixels in the id map.
        weber: Weber contrast with the viewing flare (>= 0). snr: the step over its noise (Rose).
        discernible: ``weber >= WEBER_THRESHOLD and snr >= ROSE_K`` (False for an object of no pixels).
        signal: where the object stands out most: ``"luminance"``, or a colour channel (``"red"``, …).
    """

    id: int
    view: str
    pixels: int
    weber: float
    snr: float
    discernible: bool
    signal: str = "luminance"

    def to_dict(self) -> dict[str, Any]:
        return {"id": self.id, "view": self.view, "pixels": self.pixels, "weber": round(self.weber, 5),
                "snr": round(min(self.snr, 1e6), 2), "signal": self.signal, "discernible": self.discernible}


@dataclass(frozen=True)
class ItemAnswerability:
    """Whether every object an item's question names is discernible in the item's images.

    Attributes:
        answerable: every group of named objects has a discernible member (True when none is named).
        objects: one :class:`ObjectContrast` per named object and view.
        groups: how many requirements there were (a counted object, a ref, an existence label).
    """

    answerable: bool
    objects: tuple[ObjectContrast, ...]
    groups: int

    def to_dict(self) -> dict[str, Any]:
        return {"answerable": self.answerable, "groups": self.groups, "objects": [o.to_dict() for o in self.objects]}


def named_objects(record: QARecord) -> list[tuple[str, tuple[int, ...]]]:
    """The objects ``record``'s question names, as ``(view, ids)`` groups: each group is satisfied
    when any of its ids is discernible in that view (one id per group, except an existence label)."""
    geometry = record.geometry or {}
    refs = geometry.get("refs") or []
    if refs:
        return [(str(ref["view"]), (int(ref["id"]),)) for ref in refs]
    view = geometry.get("view")
    if view is None:
        return []
    if "counted" in geometry:
        return [(str(view), (int(entry["id"]),)) for entry in geometry["counted"]]
    visible = tuple(int(e["id"]) for e in geometry.get("instances", ()) if e.get("class") == "visible")
    return [(str(view), visible)] if visible else []


def _decode_table() -> np.ndarray:
    """Linear light of the 256 8-bit sRGB codes (the exact decode, as a lookup table), float32."""
    from spacedg.render.colour_cpu import decode_srgb

    global _DECODE
    if _DECODE is None:
        _DECODE = np.asarray(decode_srgb(np.arange(256, dtype=np.float32) / np.float32(255.0)), dtype=np.float32)
    return _DECODE


def _signals(image: np.ndarray) -> np.ndarray:
    """(H, W, 4) float32: relative display luminance (white = 1) and the three linear channels of a
    uint8 (H, W, 3) sRGB image (the signals whose contrast :func:`object_contrast` measures)."""
    linear = _decode_table()[np.asarray(image, dtype=np.uint8)]
    return np.concatenate([(linear @ _LUMA.astype(np.float32))[:, :, None], linear], axis=2)


def noise_sigma(luma: np.ndarray) -> float:
    """Immerkær's (1996) pixel-noise estimate: ``√(π/2)/(6(W−2)(H−2)) Σ |L * N|``, ``N`` the 3×3
    difference-of-Laplacians kernel (blind to planes and ramps). 0 for images under 3×3."""
    import cv2

    h, w = luma.shape
    if h < 3 or w < 3:
        return 0.0
    kernel = np.array([[1, -2, 1], [-2, 4, -2], [1, -2, 1]], dtype=np.float64)
    response = cv2.filter2D(np.asarray(luma, dtype=np.float32), cv2.CV_32F, kernel.astype(np.float32))[1:-1, 1:-1]
    return float(np.sqrt(np.pi / 2.0) * np.abs(response).sum(dtype=np.float64) / (6.0 * (w - 2) * (h - 2)))


def _regions(mask: np.ndarray, valid: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """``(band, ring)``: the object's pixels within ``w`` of its outline and the pixels within ``w``
    outside it (``w = max(2, 0.28·√n)``), the ring limited to ``valid``."""
    import cv2

    width = max(_MIN_BAND_PX, SURROUND_RATIO * np.sqrt(mask.sum()))
    u8 = mask.astype(np.uint8)
    band = mask & (cv2.distanceTransform(u8, cv2.DIST_L2, 3) <= width)
    ring = ~mask & (cv2.distanceTransform(1 - u8, cv2.DIST_L2, 3) <= width)
    if valid is not None:
        ring &= np.asarray(valid, dtype=bool)
    return band, ring


def object_contrast(
    signal: np.ndarray, mask: np.ndarray, sigma: float, valid: np.ndarray | None = None,
    regions: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[float, float, int]:
    """``(weber, snr, pixels)`` of the object ``mask`` in one (H, W) signal (luminance or a linear
    channel, white = 1) whose pixel noise is ``sigma`` (module docstring).

    ``valid`` (optional) excludes pixels from the surround (outside a fisheye's image circle);
    ``regions`` the ``(band, ring)`` of ``mask`` when already computed. An empty mask, or one
    with no surround, gives ``(0, 0, pixels)``.
    """
    mask = np.asarray(mask, dtype=bool)
    n = int(mask.sum())
    if n == 0:
        return 0.0, 0.0, 0
    band, ring = _regions(mask, valid) if regions is None else regions
    n_o, n_s = int(band.sum()), int(ring.sum())
    if n_o == 0 or n_s == 0:
        return 0.0, 0.0, n
    y_o, y_s = float(signal[band].mean(dtype=np.float64)), float(signal[ring].mean(dtype=np.float64))
    step = abs(y_o - y_s)
    spread = max(sigma, 1e-12) * np.sqrt(1.0 / n_o + 1.0 / n_s)
    return float(step / (y_s + VIEWING_FLARE)), float(step / spread), n


def _window(mask: np.ndarray, pixels: int) -> tuple[slice, slice]:
    """The bounding box of ``mask`` grown by its ring width (+2 px), clipped to the image."""
    margin = int(np.ceil(max(_MIN_BAND_PX, SURROUND_RATIO * np.sqrt(pixels)))) + 2
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    h, w = mask.shape
    return (slice(max(0, rows[0] - margin), min(h, rows[-1] + margin + 1)),
            slice(max(0, cols[0] - margin), min(w, cols[-1] + margin + 1)))


def _best_signal(signals: np.ndarray, sigmas: Sequence[float], mask: np.ndarray, valid: np.ndarray) -> tuple[float, float, int, str]:
    """The signal (luminance, red, green, blue) in which the object stands out most: ``(weber, snr,
    pixels, name)`` of the one with the largest ``min(weber / WEBER_THRESHOLD, snr / ROSE_K)``."""
    best = (0.0, 0.0, int(mask.sum()), "luminance")
    if best[2] == 0:
        return best
    window = _window(mask, best[2])  # the object and its ring: every measure is local
    mask, valid, signals = mask[window], valid[window], signals[window]
    score, regions = -1.0, _regions(mask, valid)
    for k, name in enumerate(_SIGNAL_NAMES):
        weber, snr, pixels = object_contrast(signals[:, :, k], mask, sigmas[k], valid, regions)
        if min(weber / WEBER_THRESHOLD, snr / ROSE_K) > score:
            score, best = min(weber / WEBER_THRESHOLD, snr / ROSE_K), (weber, snr, pixels, name)
    return best


def object_id_maps(
    scene: Scene, views: Sequence[str], provenance: Sequence[Mapping[str, Any]], options: PipelineOptions,
    cache: dict[Any, list[np.ndarray]] | None = None,
) -> list[np.ndarray]:
    """Instance-id maps (int32 (H, W), -1 = no instance, -2 = outside a fisheye's image circle) of
    ``views`` as the item's images frame them: the item's raster degradations (``provenance``)
    applied to the request, then its blur (defocus, motion) removed, rendered at
    ``options.image_size``. ``cache`` (a dict the caller keeps) shares the maps between items that
    frame the views alike (a bench question's clean and post-render variants: one render)."""
    import pickle

    from spacedg.data.chain import ResolvedDegradation
    from spacedg.plugins.specs import Stage
    from spacedg.render.request import RenderRequest

    steps = [ResolvedDegradation.from_provenance(entry) for entry in provenance]
    raster = sorted((s for s in steps if s.spec.stage is Stage.RASTER), key=lambda s: s.spec.sort_key)
    requests = []
    for index, name in enumerate(views):
        camera = scene.camera(name)
        if options.image_size is not None:
            camera = camera.fitted(*options.image_size)
        request = RenderRequest(camera, outputs=frozenset({"instance_ids"}))
        for step in raster:
            request = step.spec.apply(request, step.params, step.view_rng(index))
        requests.append(replace(request, defocus=None, motion=None))
    key = (scene.id, len(scene.gaussians), pickle.dumps([r.camera for r in requests]))
    if cache is not None and key in cache:
        return cache[key]
    maps = []
    for request in requests:
        frame = request.render(scene.gaussians, backend=options.backend, device=options.device, settings=options.settings)
        ids = np.asarray(frame.instance_ids, dtype=np.int32)
        if frame.valid is not None:
            ids = np.where(frame.valid, ids, np.int32(-2))  # outside the image circle: not surround either
        maps.append(ids)
    if cache is not None:
        if len(cache) >= _CACHE_ITEMS:
            cache.pop(next(iter(cache)))
        cache[key] = maps
    return maps


def item_answerability(
    record: QARecord, images: np.ndarray, id_maps: Sequence[np.ndarray], views: Sequence[str] | None = None,
) -> ItemAnswerability:
    """Answerability of one item: ``images`` uint8 (V, H, W, 3) sRGB (view order of ``record.views``
    unless ``views`` is given), ``id_maps`` the matching instance-id maps (:func:`object_id_maps`)."""
    views = tuple(record.views if views is None else views)
    groups = named_objects(record)
    missing = sorted({view for view, _ in groups} - set(views))
    if missing:
        raise InvalidDataError(f"record {record.id}: names objects in view(s) {missing}, not among its views {list(views)}")
    return groups_answerability(groups, images, id_maps, views)


def groups_answerability(
    groups: Sequence[tuple[str, Sequence[int]]], images: np.ndarray, id_maps: Sequence[np.ndarray], views: Sequence[str],
) -> ItemAnswerability:
    """:func:`item_answerability` for explicit ``(view, ids)`` groups (:func:`named_objects`' form)."""
    views = tuple(views)
    images = np.asarray(images)
    if images.ndim != 4 or images.shape[0] != len(views) or images.shape[-1] != 3 or len(id_maps) != len(views):
        raise ParameterError(
            f"item_answerability: need uint8 (V, H, W, 3) images and V id maps for the {len(views)} view(s) {list(views)}, "
            f"got images {images.shape} and {len(id_maps)} id map(s)"
        )
    decoded: dict[int, tuple[np.ndarray, list[float]]] = {}
    objects: list[ObjectContrast] = []
    answerable = True
    for view, ids in groups:
        if view not in views:
            raise ParameterError(f"item_answerability: a named object is in view {view!r}, not one of the images' views {list(views)}")
        v = views.index(view)
        if id_maps[v].shape != images.shape[1:3]:
            raise ParameterError(f"item_answerability: id map {id_maps[v].shape} does not match image {images.shape[1:3]} of view {view!r}")
        if v not in decoded:
            signals = _signals(images[v])
            decoded[v] = (signals, [noise_sigma(signals[:, :, k]) for k in range(signals.shape[2])])
        signals, sigmas = decoded[v]
        found = False
        for i in ids:
            weber, snr, pixels, signal = _best_signal(signals, sigmas, id_maps[v] == i, id_maps[v] >= -1)
            ok = bool(pixels > 0 and weber >= WEBER_THRESHOLD and snr >= ROSE_K)
            objects.append(ObjectContrast(int(i), view, pixels, weber, snr, ok, signal))
            found |= ok
        answerable &= found
    return ItemAnswerability(answerable, tuple(objects), len(groups))


def condition_of(degradation_type: str, provenance: Sequence[Mapping[str, Any]]) -> tuple[str, str]:
    """``(degradation_type, severity)`` of an item: the preset of the degradation the type names, else
    (a mixture) ``"bench"`` if its primary is there, else the first preset; ``"-"`` for clean or
    explicit parameters."""
    presets = {str(e["name"]): str(e["preset"]) for e in provenance if e.get("preset") is not None}
    if degradation_type in presets:
        return degradation_type, presets[degradation_type]
    if "bench" in presets.values():
        return degradation_type, "bench"
    return degradation_type, next(iter(presets.values()), "-")


def share_by_condition(rows: Sequence[Mapping[str, Any]]) -> dict[str, dict[str, dict[str, float]]]:
    """``degradation → severity → {items, with_objects, answerable, share}`` over per-item rows
    (``degradation_type``, ``severity``, ``answerable``, ``groups``). ``share`` is the answerable
    fraction of the items whose question names at least one visible object (1.0 when there is none)."""
    out: dict[str, dict[str, dict[str, float]]] = {}
    for row in rows:
        cell = out.setdefault(str(row["degradation_type"]), {}).setdefault(str(row["severity"]), {"items": 0, "with_objects": 0, "answerable": 0})
        cell["items"] += 1
        if row["groups"]:
            cell["with_objects"] += 1
            cell["answerable"] += int(bool(row["answerable"]))
    for by_severity in out.values():
        for cell in by_severity.values():
            cell["share"] = cell["answerable"] / cell["with_objects"] if cell["with_objects"] else 1.0
    return out


def answerability_table(shares: Mapping[str, Mapping[str, Mapping[str, float]]]) -> str:
    """A Markdown table of :func:`share_by_condition`: degradation rows × severity columns,
    each cell ``share (answerable/with_objects)``."""
    order = ["-", "1", "2", "3", "4", "5", "bench"]
    columns = sorted({s for row in shares.values() for s in row}, key=lambda s: (order.index(s) if s in order else len(order), s))
    lines = ["| degradation | " + " | ".join("clean" if c == "-" else c for c in columns) + " |", "|---|" + "---:|" * len(columns)]
    for name in sorted(shares, key=lambda d: (d != "ori", d)):
        cells = []
        for c in columns:
            cell = shares[name].get(c)
            cells.append("" if cell is None else f"{100 * cell['share']:.0f} % ({int(cell['answerable'])}/{int(cell['with_objects'])})")
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)
