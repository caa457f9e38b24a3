"""Degraded images of one sample: plan the renders, run the degradation chains, encode.

Given a scene, the names of a sample's views, one or several **chains** of degradations and a
seed, :func:`degrade_variants` does the least work that produces every chain's images:

1. Each chain is resolved (:class:`~spacedg.data.chain.Chain`: names, name + preset, name +
   explicit parameters, or a mixture recipe) into
   :class:`~spacedg.data.chain.ResolvedDegradation` objects with concrete parameters drawn
   from a seed, sorted into the physical order (raster → linear → display, then each
   stage's ``order``) whatever order the user listed them in.
2. Chains with the same raster-stage degradations (same names, parameters and seeds) share one
   render per view; all raster degradations of a chain edit one
   :class:`~spacedg.render.request.RenderRequest`, so distortion + defocus + motion blur is a
   single (motion-blurred) render. A chain with no raster degradation uses the clean render.
   Depth is rendered only when a linear degradation of the group ``needs`` it.
3. Per chain and view: the linear chain on linear HDR light (unclamped), pixels outside a
   fisheye image circle set back to black, clip + exact 8-bit sRGB encode, then the display
   chain on the uint8 image.

Objects, not text. A chain arrives as a frozen :class:`~spacedg.data.chain.Chain` (a dataset item
as an :class:`ItemPlan`: record, chain, seed; :func:`degrade_plan`) and is used as is: text is
parsed only where a user wrote text. :func:`replay` renders a recorded provenance list (every
parameter and seed as recorded, nothing drawn again), which gives the sample's bytes.

Seeds. ``seed`` is the sample's seed. Each degradation of a chain gets
``derive_seed(seed, name)``, so a degradation draws the same parameters in every chain of the
sample. Its parameters are drawn from ``np.random.default_rng(deg_seed)`` (preset ranges, in
declaration order); its ``apply`` for view ``i`` gets ``np.random.default_rng([deg_seed, i])``.
The provenance ``{name, params, seed, preset}`` therefore reproduces the image exactly.

Scene depth. Presets whose metres scale with the scene (defocus focus distance, motion-blur
path, haze reference distance: ``ParamRange(per_depth=True)``) are resolved at the sample's
scene depth :func:`sample_scene_depth` (the median over its views of each view's median surface
depth, measured from the Gaussians without rendering, cached per view), so a tabletop and a room
degrade alike; at 2 m (:data:`~spacedg.plugins.specs.REFERENCE_DEPTH_M`, a ScanNet++ room) the
presets are the paper's numbers. The provenance records the resolved metres and
``scene_depth_m``: it reproduces the bytes without measuring anything.

Image size. Presets whose pixels are stated at the reference image size (1752 × 1168, a ScanNet++
DSLR frame: ``ParamRange(per_size=True)``) are resolved at the sample's output size, so a
1920 × 1080 render area-downsampled to 640 × 360 matches a 640 × 360 render
(``benchmarks/resolution.py``); the provenance records the pixels used and ``image_size``.

Mixtures. The six recipes of the paper (:data:`spacedg.data.chain.MIXTURES`) are available by
name: the primary degradation at the chain's default preset (``bench``) and the others at the
milder ``mixture_preset`` (severity ``"2"`` by default).

Device. With a non-CPU torch ``device`` (``PipelineOptions(device="cuda")``) the render and the
degradations stay on it: the linear chain, the lens mask, the exact 8-bit sRGB encode and the
display chain run on torch tensors (each degradation's ``apply_torch``,
:mod:`spacedg.plugins.degradations.device`, with the same parameters, seeds and ``rng`` draws as the
CPU path and the per-degradation tolerances stated there); only the uint8 images come back to the
host. A degradation without ``apply_torch`` (a third-party plugin, typically) runs its numpy
``apply`` on the host, its image copied off the device and back, with a warning naming it once per
process. ``degrade_on="device"`` forces this path (on the CPU when ``device`` is ``None``: what the
CPU tests exercise); ``"host"`` keeps the numpy path whatever the device.

Motion blur. ``motion="fast"`` (default) renders with the renderer's fast path (fewer
sub-steps chosen from the on-screen displacement; > 40 dB PSNR against N = 80 on the measured
scenes); ``motion="reference"`` renders the degradation's ``sub_steps`` exactly. The counts
used are in :attr:`DegradedViews.sub_steps`.
"""

from __future__ import annotations

import time
import weakref
from collections import OrderedDict
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from functools import partial
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from spacedg._checks import check_bool, check_choice, check_int, short_repr
from spacedg._checks import check_image_size as check_size_argument
from spacedg.data.chain import Chain, ResolvedDegradation
from spacedg.data.erased_views import warn_if_erased
from spacedg.devices import resolve_device
from spacedg.errors import InvalidDataError, ParameterError, PluginError
from spacedg.limits import check_image_size
from spacedg.plugins.degradations.common import check_display_image, surface_far_depth
from spacedg.plugins.guard import plugin_call
from spacedg.plugins.specs import Stage
from spacedg.render.coverage import CoverageLostError, captured_share, coverage_problem
from spacedg.render.renderer import BACKENDS
from spacedg.render.request import RenderRequest
from spacedg.render.settings import RasterSettings

if TYPE_CHECKING:
    import torch

    from spacedg.plugins.qa_record import QARecord
    from spacedg.render.frame import Frame
    from spacedg.scene.model import Scene

__all__ = [
    "DegradedViews",
    "ItemPlan",
    "PipelineOptions",
    "degrade",
    "degrade_device",
    "degrade_plan",
    "degrade_image",
    "degrade_variants",
    "frames_nbytes",
    "remember_view_depths",
    "replay",
    "sample_scene_depth",
    "sample_image_size",
    "view_depth",
    "view_depths_known",
]

# ----------------------------------------------------------------- running
@dataclass(frozen=True)
class PipelineOptions:
    """How the pipeline renders and resolves (the defaults suit training and the bench).

    Attributes:
        default_preset: preset for degradations named without one (``"bench"`` = the paper's table).
        mixture_preset: preset of the auxiliary degradations of a mixture recipe.
        motion: ``"fast"`` (renderer's fast sub-step choice) or ``"reference"`` (exact ``sub_steps``).
        image_size: ``(width, height)`` bounding box to render in, or ``None`` for the views' own size:
            each view renders at the largest size of its own aspect ratio that fits
            (:meth:`~spacedg.render.camera.Camera.fitted`; intrinsics scaled, never squeezed);
            within the size policy of :mod:`spacedg.limits`.
        backend, device, settings: passed to :func:`spacedg.render.render`.
        degrade_on: where the linear and display chains run: ``"auto"`` (on ``device`` when it is a
            non-CPU torch device, else the numpy path), ``"device"`` (torch tensors on ``device``,
            the CPU when it is ``None``) or ``"host"`` (numpy always). See the module docstring.
    """

    default_preset: str = "bench"
    mixture_preset: str = "2"
    motion: Literal["fast", "reference"] = "fast"
    image_size: tuple[int, int] | None = None
    backend: str = "auto"
    device: str | torch.device | None = None
    settings: RasterSettings | None = None
    degrade_on: Literal["auto", "device", "host"] = "auto"

    def __post_init__(self) -> None:
        check_choice(self.degrade_on, "PipelineOptions.degrade_on", ("auto", "device", "host"))
        check_choice(self.motion, "PipelineOptions.motion", ("fast", "reference"))
        check_choice(self.backend, "PipelineOptions.backend", BACKENDS)
        for name in ("default_preset", "mixture_preset"):
            value = getattr(self, name)
            if not isinstance(value, str) or not value:
                raise ParameterError(f"PipelineOptions.{name} must be a preset name such as 'bench' or '2', got {short_repr(value)}")
        if self.settings is not None and not isinstance(self.settings, RasterSettings):
            raise ParameterError(f"PipelineOptions.settings must be a RasterSettings or None, got {short_repr(self.settings)}")
        resolve_device(self.device, "PipelineOptions.device")  # malformed, CUDA without CUDA, a missing index: now
        if self.image_size is not None:
            size = check_size_argument(self.image_size, "PipelineOptions.image_size")
            object.__setattr__(self, "image_size", size)
            check_image_size(*size, "PipelineOptions.image_size", "render smaller", ParameterError)


@dataclass
class DegradedViews:
    """The images of one chain for the views of a sample.

    Attributes:
        images: uint8 (V, H, W, 3) sRGB RGB, one per view, in the order asked.
        views: the view names.
        degradations: provenance ``{name, params, seed, preset}`` per degradation, pipeline order.
        sub_steps: renders averaged per view (1 without motion blur).
        stats: milliseconds spent (``render_ms`` — shared renders counted in every chain that
            used them —, ``linear_ms``, ``encode_ms``, ``display_ms``).
        captured_share: under a lens change (``distortion``), the smallest share over the views
            of the distorted frame that the clean view covers
            (:func:`~spacedg.render.coverage.captured_share`); ``None`` without one.
    """

    images: np.ndarray
    views: tuple[str, ...]
    degradations: list[dict[str, Any]]
    sub_steps: list[int]
    stats: dict[str, float] = field(default_factory=dict)
    captured_share: float | None = None


#: Cells of the coarse depth grid of :func:`view_depth` (columns, rows).
DEPTH_GRID: tuple[int, int] = (32, 24)
#: Gaussians at least this opaque make a surface for :func:`view_depth`.
DEPTH_MIN_OPACITY = 0.5
#: Each scene's view depths this process holds, measured or handed over (:func:`remember_view_depths`):
#: per (scene id, Gaussian count), camera key (:func:`_camera_key`) → depth, for the last
#: :data:`_SCENE_DEPTHS_SIZE` scenes used.
_SCENE_DEPTHS: OrderedDict[tuple[str, int], dict[tuple[Any, ...], float | None]] = OrderedDict()
_SCENE_DEPTHS_SIZE = 256


def view_depth(scene: Scene, camera: Any) -> float | None:
    """The median depth (metres, along the optical axis) of the surfaces ``camera`` sees:
    the nearest opaque Gaussian centre (opacity >= :data:`DEPTH_MIN_OPACITY`, in front of the
    camera, inside the image) in each cell of a :data:`DEPTH_GRID` grid over the image, and the
    median over the occupied cells. Pinhole projection (a fisheye lens only moves points within
    the image), no rendering: a few milliseconds per view, kept per (scene, Gaussian count,
    camera), or handed over measured (:func:`remember_view_depths`). ``None`` when the view sees no
    Gaussian."""
    depths = _depths_of(scene)
    key = _camera_key(camera)
    if key in depths:
        return depths[key]
    pose = np.asarray(camera.cam_to_world, dtype=np.float64)
    g = scene.gaussians
    from spacedg.data.view_depth_cpu import nearest_per_cell  # numba: compiled on first use, not with spacedg

    pc = (_opaque_means(g) - pose[:3, 3]) @ pose[:3, :3]
    cols, rows = DEPTH_GRID
    nearest = nearest_per_cell(
        pc, float(camera.fx), float(camera.fy), float(camera.cx), float(camera.cy), int(camera.width), int(camera.height), cols, rows,
    )
    occupied = nearest[np.isfinite(nearest)]
    value = float(np.median(occupied)) if occupied.size else None
    depths[key] = value
    return value


def view_depths_known(scene: Scene) -> bool:
    """Whether this process holds the depth of every view of ``scene`` (measured or handed over)."""
    depths = _depths_of(scene)
    return all(_camera_key(camera) in depths for camera in scene.views.values())


def remember_view_depths(scene: Scene, depths: Mapping[str, float | None]) -> None:
    """Give :func:`view_depth` the depths of ``scene``'s views measured before (view name → metres or
    ``None``; :mod:`spacedg.data.view_depths`), as if this process had measured them."""
    known = _depths_of(scene)
    for name, value in depths.items():
        known[_camera_key(scene.camera(name))] = value


def _depths_of(scene: Scene) -> dict[tuple[Any, ...], float | None]:
    """``scene``'s entry of :data:`_SCENE_DEPTHS` (made if new; the least recently used scene forgotten past the limit)."""
    key = (scene.id, len(scene.gaussians))
    depths = _SCENE_DEPTHS.get(key)
    if depths is None:
        depths = _SCENE_DEPTHS[key] = {}
        while len(_SCENE_DEPTHS) > _SCENE_DEPTHS_SIZE:
            _SCENE_DEPTHS.popitem(last=False)
    _SCENE_DEPTHS.move_to_end(key)
    return depths


def _camera_key(camera: Any) -> tuple[Any, ...]:
    """A view's key within its scene: float64 cam-to-world bytes, intrinsics and size."""
    pose = np.asarray(camera.cam_to_world, dtype=np.float64)
    return (pose.tobytes(), camera.fx, camera.fy, camera.cx, camera.cy, camera.width, camera.height)


#: The opaque centres of the last few Gaussian sets :func:`view_depth` saw, made on first use: a
#: :class:`~spacedg.scene.store.ByteLRU` of at most :data:`_OPAQUE_MEANS_SIZE` sets and
#: :data:`_OPAQUE_MEANS_BYTES` bytes of centres (a larger set is used, not kept), keyed by the ids of a
#: set's ``means`` and ``opacities``: (weak references to those arrays, float64 (M, 3) centres or ``None``
#: when nothing was gathered, the means being float64 and all opaque).
_OPAQUE_MEANS: Any = None
_OPAQUE_MEANS_SIZE = 4
_OPAQUE_MEANS_BYTES = 256 << 20


def clear_depth_caches() -> None:
    """Forget this process's scene depths (:func:`view_depth`) and the opaque centres they come from
    (a benchmark that wants every reading to pay its own)."""
    _SCENE_DEPTHS.clear()
    if _OPAQUE_MEANS is not None:
        _OPAQUE_MEANS.clear()


def _opaque_means(g: Any) -> np.ndarray:
    """``g.means[g.opacities >= DEPTH_MIN_OPACITY]`` as float64 (M, 3), kept for the last few Gaussian
    sets (:data:`_OPAQUE_MEANS`): the gather took a quarter of a view's depth, and every view of a scene
    repeats it. An entry is found by the identity of the set's arrays (weak references: it never keeps a
    scene's Gaussians alive after the dataset's own cache let them go; a scene's arrays are not
    modified in place)."""
    global _OPAQUE_MEANS
    if _OPAQUE_MEANS is None:
        from spacedg.scene.store import ByteLRU  # here: the pipeline's import stays light

        _OPAQUE_MEANS = ByteLRU(_OPAQUE_MEANS_BYTES, lambda entry: 0 if entry[2] is None else entry[2].nbytes, _OPAQUE_MEANS_SIZE)
    try:
        refs = weakref.ref(g.means), weakref.ref(g.opacities)
    except TypeError:  # not a numpy array (a list, a tuple): no weak reference to it, not kept
        kept = _opaque_centres(g)
        return np.asarray(g.means, dtype=np.float64) if kept is None else kept
    key = (id(g.means), id(g.opacities))

    def make() -> tuple[Any, Any, np.ndarray | None]:
        return (*refs, _opaque_centres(g))

    entry = _OPAQUE_MEANS.get(key, make)
    if entry[0]() is not g.means or entry[1]() is not g.opacities:  # an id reused after its set was freed
        _OPAQUE_MEANS.discard(key)
        entry = _OPAQUE_MEANS.get(key, make)
    return g.means if entry[2] is None else entry[2]


def _opaque_centres(g: Any) -> np.ndarray | None:
    """The float64 rows of ``g.means`` whose opacity is at least :data:`DEPTH_MIN_OPACITY`; ``None`` when
    that is ``g.means`` itself (float64 and all opaque: nothing to keep, and keeping it would keep the set alive)."""
    means = np.asarray(g.means, dtype=np.float64)
    opaque = np.asarray(g.opacities) >= DEPTH_MIN_OPACITY
    kept = means if opaque.all() else means[opaque]
    return None if kept is g.means else kept


def sample_scene_depth(scene: Scene, views: Sequence[str]) -> float | None:
    """The scene depth of a sample (metres): the median of :func:`view_depth` over its views
    (``None`` when no view sees anything). Depth-relative presets are resolved at it."""
    views = (views,) if isinstance(views, str) else tuple(views)
    depths = [d for d in (view_depth(scene, scene.camera(v)) for v in views) if d is not None]
    return float(np.median(depths)) if depths else None


def _cameras(scene: Scene, views: Sequence[str], options: PipelineOptions) -> list[Any]:
    if not views:
        raise ParameterError("degrade: give at least one view name")
    cameras = []
    for name in views:
        camera = scene.camera(name)
        if options.image_size is not None:
            camera = camera.fitted(*options.image_size)  # a bounding box: the view's aspect is kept
        cameras.append(camera)
    sizes = {(c.width, c.height) for c in cameras}
    if len(sizes) > 1:  # the views of one sample are stacked into one array
        shown = ", ".join(f"{v} {c.width}x{c.height}" for v, c in zip(views, cameras))
        raise InvalidDataError(
            f"scene {scene.id}: the views of one sample render at different sizes ({shown}); images are never "
            "squeezed to one size, so a sample's views must share an aspect ratio (re-import the capture with one camera size)"
        )
    return cameras


def sample_image_size(scene: Scene, views: Sequence[str], options: PipelineOptions) -> tuple[int, int]:
    """``(width, height)`` pixels the views of a sample render at (they share one size): what
    pixel presets stated at the reference size are resolved at. Reads cameras only."""
    camera = _cameras(scene, views, options)[0]
    return int(camera.width), int(camera.height)


def _render_group(
    scene: Scene, cameras: Sequence[Any], raster: Sequence[ResolvedDegradation], outputs: frozenset[str], options: PipelineOptions,
    views: Sequence[str] = (), render_cache: Any = None,
) -> list[Frame]:
    if render_cache is not None and not raster:
        # clean renders are the same for every sample of these views: share them across calls
        key = ("clean-render", scene.id, tuple(views), options.image_size, tuple(sorted(outputs)), options.backend, str(options.device))
        return render_cache.get(key, lambda: _render_group(scene, cameras, raster, outputs, options))
    frames = []
    for index, camera in enumerate(cameras):
        request = RenderRequest(camera, outputs=outputs)
        for step in raster:
            with plugin_call("degradation", step.spec, "apply"):
                edited = step.spec.apply(request, step.params, step.view_rng(index))
            if not isinstance(edited, RenderRequest):
                raise PluginError(f"raster degradation {step.name!r} returned {type(edited).__name__}, not a RenderRequest")
            request = edited
        if request.motion is not None and options.motion == "fast":
            request = replace(request, motion=replace(request.motion, fast=True))
        frame = request.render(scene.gaussians, backend=options.backend, device=options.device, settings=options.settings)
        if request.camera.fisheye is not camera.fisheye:  # a lens change: how much of the new frame the capture covers
            frame.stats["captured_share"] = captured_share(camera, request.camera)
        lost = coverage_problem(scene.gaussians, request.camera, frame.alpha, frame.valid, defocus=request.defocus,
                                motion=request.motion, backend=options.backend, device=options.device, settings=options.settings)
        if lost is not None:  # never a black image without an error
            raise CoverageLostError(f"scene {scene.id}, view {views[index] if views else index!r}, {[s.name for s in raster]}: {lost}")
        for name in ("rgb", "alpha", "depth", "median_depth", "instance_ids"):
            image = getattr(frame, name)
            if image is not None:
                image.flags.writeable = False  # shared by every chain of the group
        frames.append(frame)
    return frames


def _first_non_finite(image: np.ndarray) -> str | None:
    """``None`` if every value of ``image`` is finite, else how many are not and where the first is.

    The image's smallest and largest values are the fast test (numpy's ``min`` and ``max`` return NaN
    when any value is NaN, and ±inf where one is: both finite exactly when every value is; 0.5 ms
    against 1.1 for the float64 sum it replaced, a 640 × 480 × 3 float32 image); the full scan runs
    only to describe a failure.
    """
    if image.size == 0 or (np.isfinite(np.min(image)) and np.isfinite(np.max(image))):
        return None
    bad = ~np.isfinite(image)
    first = tuple(int(i) for i in np.argwhere(bad)[0])
    return f"{int(bad.sum())} of {image.size} values are NaN or ±inf (first at (row, column, channel) {first}: {image[first]})"


def _run_linear(rgb: np.ndarray, aux: Mapping[str, Any], steps: Sequence[ResolvedDegradation], index: int) -> np.ndarray:
    """Run the linear-light chain; every step must return finite float32 light of the input's shape."""
    for step in steps:
        with plugin_call("degradation", step.spec, "apply"):
            out = step.spec.apply(rgb, aux, step.params, step.view_rng(index))
        if not isinstance(out, np.ndarray) or out.dtype != np.float32 or out.shape != rgb.shape:
            got = f"{out.dtype} {out.shape}" if isinstance(out, np.ndarray) else type(out).__name__
            raise PluginError(f"linear degradation {step.name!r} must return float32 {rgb.shape}, got {got}")
        problem = _first_non_finite(out)
        if problem is not None:
            raise PluginError(
                f"linear degradation {step.name!r} (params {step.params}) returned non-finite light: {problem}; "
                "a linear-stage degradation must return finite values (it would be encoded as black pixels). "
                "Fix the plugin, or report it with these parameters and the seed"
            )
        rgb = out
    return rgb


def _run_display(image: np.ndarray, steps: Sequence[ResolvedDegradation], index: int) -> np.ndarray:
    for step in steps:
        with plugin_call("degradation", step.spec, "apply"):
            out = step.spec.apply(image, step.params, step.view_rng(index))
        if not isinstance(out, np.ndarray) or out.dtype != np.uint8 or out.shape != image.shape:
            got = f"{out.dtype} {out.shape}" if isinstance(out, np.ndarray) else type(out).__name__
            raise PluginError(f"display degradation {step.name!r} must return uint8 {image.shape}, got {got}")
        image = out
    return image


def _by_stage(chain: Sequence[ResolvedDegradation], stage: Stage) -> list[ResolvedDegradation]:
    return [step for step in chain if step.spec.stage is stage]


def _finish(
    frame: Frame, linear: Sequence[ResolvedDegradation], display: Sequence[ResolvedDegradation],
    index: int, far_depth: float | None, timer: dict[str, float],
) -> np.ndarray:
    """Linear chain → lens mask → encode → display chain for one view."""
    from spacedg.render.colour_cpu import encode_srgb_u8  # numba: compiled on first use

    t0 = time.perf_counter()
    rgb = frame.rgb
    if linear:
        aux: dict[str, Any] = {name: getattr(frame, name) for step in linear for name in step.spec.needs}
        if far_depth is not None:
            aux["far_depth"] = far_depth
        rgb = _run_linear(rgb, aux, linear, index)
        if frame.valid is not None:
            rgb = np.where(frame.valid[:, :, None], rgb, np.float32(0.0))
    t1 = time.perf_counter()
    image = encode_srgb_u8(rgb)
    t2 = time.perf_counter()
    image = _run_display(image, display, index)
    t3 = time.perf_counter()
    timer["linear_ms"] += (t1 - t0) * 1e3
    timer["encode_ms"] += (t2 - t1) * 1e3
    timer["display_ms"] += (t3 - t2) * 1e3
    return image


# ----------------------------------------------------------------- device path
_HOST_FALLBACK_WARNED: set[str] = set()


def degrade_device(options: PipelineOptions) -> torch.device | None:
    """The torch device the linear and display chains run on, or ``None`` for the numpy path."""
    if options.degrade_on == "host" or (options.device is None and options.degrade_on == "auto"):
        return None
    import torch

    if options.device is None:
        return torch.device("cpu")
    dev = torch.device(options.device)  # checked by PipelineOptions (spacedg.devices.resolve_device)
    if options.degrade_on == "auto" and dev.type == "cpu":
        return None
    return dev


def _host_fallback(step: ResolvedDegradation, device: torch.device, timer: dict[str, float]) -> None:
    """Count a numpy ``apply`` run on the host for a device image; warn once per degradation."""
    timer["host_fallbacks"] = timer.get("host_fallbacks", 0.0) + 1.0
    if step.name not in _HOST_FALLBACK_WARNED:
        _HOST_FALLBACK_WARNED.add(step.name)
        import warnings

        warnings.warn(
            f"degradation {step.name!r} has no apply_torch: its numpy apply runs on the host, the image copied off "
            f"{device} and back (give its DegradationSpec an apply_torch to keep it on the device)",
            stacklevel=4,
        )


def _run_linear_device(rgb: torch.Tensor, aux: Mapping[str, Any], host_aux: Any, steps: Sequence[ResolvedDegradation], index: int,
                       timer: dict[str, float]) -> torch.Tensor:
    """The linear chain on a device tensor; same contract as :func:`_run_linear` (float32, shape, finite)."""
    import torch

    for step in steps:
        with plugin_call("degradation", step.spec, "apply"):
            if step.spec.apply_torch is not None:
                out = step.spec.apply_torch(rgb, aux, step.params, step.view_rng(index))
            else:
                _host_fallback(step, rgb.device, timer)
                host = step.spec.apply(rgb.cpu().numpy(), host_aux(), step.params, step.view_rng(index))
                out = torch.from_numpy(np.array(host)).to(rgb.device) if isinstance(host, np.ndarray) else host
        if not isinstance(out, torch.Tensor) or out.dtype != torch.float32 or tuple(out.shape) != tuple(rgb.shape):
            got = f"{out.dtype} {tuple(out.shape)}" if isinstance(out, (torch.Tensor, np.ndarray)) else type(out).__name__
            raise PluginError(f"linear degradation {step.name!r} must return float32 {tuple(rgb.shape)}, got {got}")
        if not bool(torch.isfinite(out).all()):
            problem = _first_non_finite(out.cpu().numpy())
            raise PluginError(
                f"linear degradation {step.name!r} (params {step.params}) returned non-finite light on {out.device}: {problem}; "
                "a linear-stage degradation must return finite values. Fix the plugin, or report it with these parameters and the seed"
            )
        rgb = out
    return rgb


def _run_display_device(image: torch.Tensor, steps: Sequence[ResolvedDegradation], index: int, timer: dict[str, float]) -> torch.Tensor:
    import torch

    for step in steps:
        with plugin_call("degradation", step.spec, "apply"):
            if step.spec.apply_torch is not None:
                out = step.spec.apply_torch(image, step.params, step.view_rng(index))
            else:
                _host_fallback(step, image.device, timer)
                host = step.spec.apply(image.cpu().numpy(), step.params, step.view_rng(index))
                out = torch.from_numpy(np.array(host)).to(image.device) if isinstance(host, np.ndarray) and host.dtype == np.uint8 else host
        if not isinstance(out, torch.Tensor) or out.dtype != torch.uint8 or tuple(out.shape) != tuple(image.shape):
            got = f"{out.dtype} {tuple(out.shape)}" if isinstance(out, (torch.Tensor, np.ndarray)) else type(out).__name__
            raise PluginError(f"display degradation {step.name!r} must return uint8 {tuple(image.shape)}, got {got}")
        image = out
    return image


def _finish_device(
    frame: Frame, linear: Sequence[ResolvedDegradation], display: Sequence[ResolvedDegradation],
    index: int, far_depth: float | None, timer: dict[str, float], device: torch.device,
) -> np.ndarray:
    """:func:`_finish` on torch tensors on ``device`` (the frame's device copies when it has them)."""
    import torch

    from spacedg.plugins.degradations.device import as_tensor
    from spacedg.render import colour_torch

    def on_device(name: str) -> torch.Tensor:
        kept = (frame.tensors or {}).get(name)
        if kept is not None and kept.device.type == device.type and device.index in (None, kept.device.index):
            return kept
        return as_tensor(getattr(frame, name), device)

    t0 = time.perf_counter()
    rgb = on_device("rgb")
    if linear:
        names = {name for step in linear for name in step.spec.needs}
        aux: dict[str, Any] = {name: on_device(name) for name in names}

        def host_aux() -> dict[str, Any]:
            out: dict[str, Any] = {name: getattr(frame, name) for name in names}
            if far_depth is not None:
                out["far_depth"] = far_depth
            return out

        if far_depth is not None:
            aux["far_depth"] = far_depth
        rgb = _run_linear_device(rgb, aux, host_aux, linear, index, timer)
        if frame.valid is not None:
            rgb = torch.where(as_tensor(frame.valid, device)[:, :, None], rgb, torch.zeros_like(rgb))
    t1 = time.perf_counter()
    image = colour_torch.encode_srgb_u8(rgb)
    t2 = time.perf_counter()
    image = _run_display_device(image, display, index, timer)
    out = image.cpu().numpy()  # synchronises: the times below include the device's work
    t3 = time.perf_counter()
    timer["linear_ms"] += (t1 - t0) * 1e3
    timer["encode_ms"] += (t2 - t1) * 1e3
    timer["display_ms"] += (t3 - t2) * 1e3
    return out


@dataclass(frozen=True)
class ItemPlan:
    """What one dataset item renders, decided once per item (frozen, picklable; no rendering).

    Attributes:
        index: the dataset index.
        record: the question record (its ``scene_id`` and ``views``).
        chain: the degradation chain (an empty :class:`~spacedg.data.chain.Chain` for a clean item).
        seed: the sample seed the chain's parameters and noise are drawn from (module docstring).
    """

    index: int
    record: QARecord
    chain: Chain
    seed: int

    @property
    def views(self) -> tuple[str, ...]:
        return tuple(self.record.views)

    @property
    def degradation_type(self) -> str:
        """``"ori"`` for a clean item, else the chain's name (:attr:`Chain.name <spacedg.data.chain.Chain.name>`)."""
        return self.chain.name


def _check_call(views: Any, seed: Any, options: Any, where: str) -> tuple[tuple[str, ...], int, PipelineOptions]:
    """``views`` as a tuple of names, ``seed`` as an int and ``options`` (default ones for ``None``), or a ParameterError."""
    views = (views,) if isinstance(views, str) else tuple(views) if isinstance(views, Iterable) else views
    if not isinstance(views, tuple) or not views or not all(isinstance(v, str) for v in views):
        raise ParameterError(f"{where}: views must be a view name or a list of view names (give at least one view name), got {short_repr(views)}")
    check_int(seed, f"{where}: seed")
    if options is not None and not isinstance(options, PipelineOptions):
        raise ParameterError(f"{where}: options must be a PipelineOptions or None, got {short_repr(options)}")
    return views, int(seed), options or PipelineOptions()


def degrade_variants(
    scene: Scene,
    views: Sequence[str],
    chains: Sequence[Any],
    seed: int = 0,
    options: PipelineOptions | None = None,
    progress: bool = False,
    render_cache: Any = None,
) -> list[DegradedViews]:
    """Images of ``views`` under each chain of ``chains``, sharing renders between chains.

    Args:
        scene: the scene (its Gaussians load on first use).
        views: view names of the sample, e.g. the two views of a two-view question.
        chains: one entry per variant: a :class:`~spacedg.data.chain.Chain` (used as is) or anything
            :meth:`Chain.parse <spacedg.data.chain.Chain.parse>` accepts (``None`` or ``"clean"`` = no
            degradation), e.g. ``["clean", "haze", "night_capture"]``.
        seed: the sample's seed, an integer (see the module docstring).
        options: rendering and resolving options.
        progress: show a progress bar over the render groups (for long runs such as a gallery).
        render_cache: optional cache with ``get(key, make)`` (e.g.
            :class:`~spacedg.scene.store.ByteLRU` with :func:`frames_nbytes`) that keeps the
            **clean** renders (chains without a raster step) across calls; frames are read-only.

    Returns:
        One :class:`DegradedViews` per chain, in order.
    """
    views, seed, options = _check_call(views, seed, options, "degrade")
    if isinstance(chains, (str, Chain)) or not isinstance(chains, Sequence):
        raise ParameterError(f"degrade_variants: chains must be a list of chains, e.g. ['clean', 'haze'], got {short_repr(chains)}")
    check_bool(progress, "degrade_variants: progress")
    parsed = [Chain.parse(c) for c in chains]
    depth = None
    if any(c.scales_with_depth(options.default_preset, options.mixture_preset) for c in parsed):
        depth = sample_scene_depth(scene, views)
    size = sample_image_size(scene, views, options)
    resolved = [c.resolve(seed, options.default_preset, options.mixture_preset, depth, size) for c in parsed]
    return _run_chains(scene, views, resolved, options, progress, render_cache)


def _run_chains(
    scene: Scene, views: tuple[str, ...], resolved: Sequence[Sequence[ResolvedDegradation]], options: PipelineOptions,
    progress: bool = False, render_cache: Any = None,
) -> list[DegradedViews]:
    """Render and degrade ``views`` under each resolved chain, chains with the same raster steps sharing one render."""
    device = degrade_device(options)
    cameras = _cameras(scene, views, options)
    groups: dict[tuple[Any, ...], list[int]] = {}
    for i, chain in enumerate(resolved):
        groups.setdefault(tuple(step.key() for step in _by_stage(chain, Stage.RASTER)), []).append(i)
    results: list[DegradedViews | None] = [None] * len(resolved)
    group_list: Any = list(groups.values())
    if progress:
        from tqdm import tqdm

        group_list = tqdm(group_list, desc="rendering variants", unit="render set")
    for members in group_list:
        raster = _by_stage(resolved[members[0]], Stage.RASTER)
        needs = frozenset({"rgb"}).union(*(step.spec.needs for i in members for step in _by_stage(resolved[i], Stage.LINEAR)))
        t0 = time.perf_counter()
        frames = _render_group(scene, cameras, raster, needs, options, views, render_cache)
        render_ms = (time.perf_counter() - t0) * 1e3
        _check_renders(scene, views, frames)
        far_depth = max(surface_far_depth(f.depth, f.alpha) for f in frames) if "depth" in needs else None
        for i in members:
            results[i] = _finish_chain(frames, views, resolved[i], far_depth, render_ms, device, f"scene {scene.id}")
    return [r for r in results if r is not None]


def _check_renders(scene: Scene, views: Sequence[str], frames: Sequence[Frame]) -> None:
    for view, frame in zip(views, frames):
        problem = _first_non_finite(frame.rgb)
        if problem is not None:  # a renderer bug: never write it out as black pixels
            raise InvalidDataError(
                f"scene {scene.id}, view {view!r}: the render holds non-finite light: {problem}; "
                "please report this with the scene and the chain"
            )


def _encoded(frame: Frame) -> np.ndarray | None:
    """The render of ``frame`` encoded to 8-bit sRGB, as an item without linear or display steps holds it
    (``None`` without colour)."""
    from spacedg.render.colour_cpu import encode_srgb_u8  # numba: compiled on first use

    return None if frame.rgb is None else encode_srgb_u8(frame.rgb)


def _finish_chain(
    frames: Sequence[Frame], views: tuple[str, ...], chain: Sequence[ResolvedDegradation], far_depth: float | None,
    render_ms: float, device: torch.device | None, where: str = "the sample",
) -> DegradedViews:
    """The linear chain, encode and display chain of one resolved chain over its group's frames; a
    view whose render the chain turned into one flat colour (inside a fisheye's image circle) is reported
    (:func:`~spacedg.data.erased_views.warn_if_erased`, ``where`` names the scene)."""
    timer = {"render_ms": render_ms, "linear_ms": 0.0, "encode_ms": 0.0, "display_ms": 0.0}
    linear, display = _by_stage(chain, Stage.LINEAR), _by_stage(chain, Stage.DISPLAY)
    if device is not None:
        images = [_finish_device(frame, linear, display, v, far_depth, timer, device) for v, frame in enumerate(frames)]
    else:
        images = [_finish(frame, linear, display, v, far_depth, timer) for v, frame in enumerate(frames)]
    warn_if_erased(images, [partial(_encoded, frame) for frame in frames], chain, where, valid=[frame.valid for frame in frames])
    shares = [f.stats["captured_share"] for f in frames if "captured_share" in f.stats]
    return DegradedViews(
        images=np.stack(images),
        views=views,
        degradations=[step.provenance() for step in chain],
        sub_steps=[int(f.stats.get("sub_steps", 1)) for f in frames],
        stats=timer,
        captured_share=min(shares) if shares else None,
    )


def degrade(
    scene: Scene, views: Sequence[str], degradations: Any = None, seed: int = 0, options: PipelineOptions | None = None,
    render_cache: Any = None,
) -> DegradedViews:
    """Images of ``views`` under one chain of ``degradations`` (see :func:`degrade_variants`)."""
    return degrade_variants(scene, views, [degradations], seed, options, render_cache=render_cache)[0]


def degrade_plan(scene: Scene, plan: ItemPlan, options: PipelineOptions | None = None, render_cache: Any = None) -> DegradedViews:
    """Images of one dataset item: ``plan.record.views`` of ``scene`` under ``plan.chain`` at ``plan.seed``
    (what :class:`~spacedg.data.dataset.SpaceDGDataset` renders; the chain object is used as is)."""
    if not isinstance(plan, ItemPlan):
        raise ParameterError(f"degrade_plan: plan must be an ItemPlan (SpaceDGDataset.plan(index)), got {short_repr(plan)}")
    return degrade(scene, plan.views, plan.chain, plan.seed, options, render_cache)


def replay(
    scene: Scene, views: Sequence[str], provenance: Sequence[Mapping[str, Any]], options: PipelineOptions | None = None,
    render_cache: Any = None,
) -> DegradedViews:
    """Images of ``views`` under the degradations a sample recorded (its ``degradation`` provenance
    list): each entry's parameters, seed and preset as recorded, nothing drawn again. With the
    item's image size and device options this gives the item's bytes; an empty list is the clean render."""
    views, _, options = _check_call(views, 0, options, "replay")
    if isinstance(provenance, (str, Mapping)) or not isinstance(provenance, Sequence):
        raise ParameterError(f"replay: provenance must be a list of {{name, params, seed, preset}} entries, got {short_repr(provenance)}")
    steps = [ResolvedDegradation.from_provenance(entry) for entry in provenance]
    names = [step.name for step in steps]
    if len(set(names)) != len(names):
        raise ParameterError(f"replay: provenance names a degradation twice: {names}")
    return _run_chains(scene, views, [sorted(steps, key=lambda r: r.spec.sort_key)], options, False, render_cache)[0]


def frames_nbytes(frames: Sequence[Frame]) -> int:
    """Bytes held by the arrays of ``frames`` (for byte-bounded render caches), device copies
    (``Frame.tensors``, e.g. GPU memory) included."""
    total = 0
    for frame in frames:
        for name in ("rgb", "alpha", "depth", "median_depth", "instance_ids", "valid"):
            array = getattr(frame, name, None)
            if isinstance(array, np.ndarray):
                total += array.nbytes
        for tensor in (getattr(frame, "tensors", None) or {}).values():
            total += int(tensor.numel()) * int(tensor.element_size())
    return total


def _image_input(value: Any, shape: tuple[int, ...], name: str, rule: str) -> np.ndarray:
    try:
        array = np.asarray(value, dtype=np.float32)
    except (TypeError, ValueError) as err:
        raise InvalidDataError(f"degrade_image: {name} must be a numeric (H, W) array ({rule}), got {type(value).__name__}: {err}") from None
    if array.shape != tuple(shape):
        raise InvalidDataError(f"degrade_image: {name} has shape {array.shape}, but the image is {tuple(shape)}; pass one value per pixel ({rule})")
    return array


def _depth_input(depth: Any, shape: tuple[int, ...]) -> np.ndarray:
    """``depth`` as float32 (H, W); negative values (−inf included) are refused, 0 / NaN / +inf mean no surface."""
    rule = "metres along the optical axis, >= 0; 0, NaN or +inf = no surface"
    array = _image_input(depth, shape, "depth", rule)
    negative = array < 0
    if negative.any():
        first = tuple(int(i) for i in np.argwhere(negative)[0])
        raise InvalidDataError(
            f"degrade_image: depth holds {int(negative.sum())} negative value(s) (first at (row, column) {first}: {array[first]}); "
            f"depth is {rule}. Fix the depth map (a disparity or an inverted sign?)"
        )
    return array


def _alpha_input(alpha: Any, shape: tuple[int, ...]) -> np.ndarray:
    """``alpha`` as float32 (H, W) in [0, 1] (NaN refused)."""
    rule = "coverage in [0, 1]"
    array = _image_input(alpha, shape, "alpha", rule)
    bad = ~((array >= 0) & (array <= 1))
    if bad.any():
        first = tuple(int(i) for i in np.argwhere(bad)[0])
        raise InvalidDataError(
            f"degrade_image: alpha holds {int(bad.sum())} value(s) outside [0, 1] or NaN (first at (row, column) {first}: {array[first]}); "
            "alpha is the pixel's coverage in [0, 1]"
        )
    return array


def degrade_image(
    image: np.ndarray,
    degradations: Any,
    seed: int = 0,
    *,
    depth: np.ndarray | None = None,
    alpha: np.ndarray | None = None,
    default_preset: str = "bench",
    mixture_preset: str = "2",
    scene_depth: float | None = None,
) -> tuple[np.ndarray, list[dict[str, Any]]]:
    """Post-render degradations of an existing 8-bit sRGB image (e.g. a photo), no rasterizer.

    Args:
        image: uint8 (H, W, 3) sRGB RGB.
        degradations: one chain (see :class:`~spacedg.data.chain.Chain`); raster-stage degradations are refused
            (they change how the scene is rendered, which needs the Gaussians).
        seed: the sample's seed.
        depth, alpha: (H, W) metric depth (metres along the optical axis, >= 0) and coverage in
            [0, 1] for depth-hungry degradations such as haze. A depth of 0, NaN or +inf means
            "no surface" (haze gives it the far depth's airlight, as for a render's empty pixels);
            a negative depth is refused. alpha defaults to 1 where the depth is a surface and 0
            where it is not.
        scene_depth: the scene depth (metres) depth-relative presets are resolved at; default:
            the median of ``depth`` where covered, else the reference depth (2 m).

    Returns:
        ``(uint8 image, provenance list)``.
    """
    from spacedg.render.colour_cpu import (  # numba: compiled on first use
        decode_srgb,
        encode_srgb_u8,
    )

    image = check_display_image(image, "degrade_image")
    check_int(seed, "degrade_image: seed")
    PipelineOptions(default_preset=default_preset, mixture_preset=mixture_preset)  # the preset names' check
    aux: dict[str, Any] = {}
    if depth is not None:
        aux["depth"] = _depth_input(depth, image.shape[:2])
        surface = np.isfinite(aux["depth"]) & (aux["depth"] > 0)
        aux["alpha"] = surface.astype(np.float32) if alpha is None else _alpha_input(alpha, image.shape[:2])
    elif alpha is not None:
        raise ParameterError("degrade_image: alpha without depth means nothing to any degradation; pass depth= too (metres)")
    if scene_depth is None and depth is not None:
        covered = np.isfinite(aux["depth"]) & (aux["depth"] > 0) & (aux["alpha"] > 0.5)
        scene_depth = float(np.median(aux["depth"][covered])) if np.any(covered) else None
    parsed = Chain.parse(degradations)
    depth_at = scene_depth if parsed.scales_with_depth(default_preset, mixture_preset) else None
    chain = parsed.resolve(seed, default_preset, mixture_preset, depth_at, (int(image.shape[1]), int(image.shape[0])))
    raster = _by_stage(chain, Stage.RASTER)
    if raster:
        raise ParameterError(
            f"degrade_image cannot apply raster-stage degradation(s) {[s.name for s in raster]}: they change the render; "
            "use degrade(scene, views, ...) with the scene's Gaussians"
        )
    linear, display = _by_stage(chain, Stage.LINEAR), _by_stage(chain, Stage.DISPLAY)
    degraded = image
    if linear:
        rgb = decode_srgb(image.astype(np.float32) / np.float32(255.0))
        degraded = encode_srgb_u8(_run_linear(rgb, aux, linear, 0))
    degraded = _run_display(degraded, display, 0)
    warn_if_erased([degraded], [image], chain, "the image", once=False)
    return degraded, [step.provenance() for step in chain]

