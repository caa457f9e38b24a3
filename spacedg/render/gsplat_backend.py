"""``backend="gsplat"``: our projection physics on gsplat's CUDA tile intersection and compositor.

What runs where (gsplat 1.5.3 API, :mod:`gsplat.cuda._wrapper`):

1. **Projection: ours.** :func:`spacedg.render.project_torch.project_gaussians` (the torch twin of the compiled
   CPU projection: EWA with the exact fisheye Jacobian, culling, antialiasing, footprint radii)
   runs on the render's device. gsplat's own ``fully_fused_projection`` is not used: it has no
   exact fisheye Jacobian with k1..k4, no circle of confusion and not our culling rules.
2. **Tiles: gsplat.** ``isect_tiles(means2d, radii, depths, 16, tiles_x, tiles_y)`` sorts the
   Gaussian–tile pairs by (image, tile, depth) and ``isect_offset_encode`` gives each tile's range.
3. **Colour, alpha, expected depth: gsplat.** ``rasterize_to_pixels`` composites the sRGB-encoded
   colours with **camera z as a fourth channel**: channel 4 is ``Σ w·z`` and the expected depth
   is ``Σ w·z / α`` (as our compositors). A depth-only request composites one channel.
4. **Median depth and instance ids: our own second pass** (:func:`median_pass`, torch, on the
   device) over gsplat's per-tile lists. gsplat's forward kernel keeps only the index of the
   *last* Gaussian composited per pixel (``last_ids``, for its backward pass) and its wrapper
   does not return it; the median Gaussian is the one that takes transmittance across ½, which
   no linear combination of channels gives. The pass composites chunk by chunk and stops when
   every pixel's transmittance is ≤ ½ (a handful of Gaussians per pixel in a real scene), with
   our rules (``settings.alpha_max``, per-Gaussian alpha floor), so ids and median depth equal
   the torch twin's.

gsplat's compositor hard-codes an alpha cap of 0.999 (``RasterizeToPixels3DGSFwd.cu``); ours is
``settings.alpha_max`` (0.99 by default, as 3DGS). For ``alpha_max < 0.999`` the opacities given to
gsplat are clamped to ``alpha_max`` (exact for Gaussians with opacity ≤ ``alpha_max``; for the
others ``alpha = alpha_max·e^(−σ)`` instead of ``min(alpha_max, o·e^(−σ))``, a difference below
1 % of that Gaussian's alpha); ``alpha_max = 0.999`` is exact; above 0.999 is refused. The
1/255 alpha floor and the stop before transmittance ≤ 1e-4 are the same rules as ours.

Defocus (a Gaussian's alpha floor scales with its CoC compensation, and the blurred view is
brought to the sharp view's local flux, :mod:`spacedg.render.defocus_flux`)
has no counterpart in gsplat's kernel: a render with ``defocus`` is delegated to the torch twin
on the same device (``stats["delegated"] = "torch"``).

Motion blur renders its sub-steps **batched**: every sub-step camera is projected by our
projection, the records are stacked as gsplat's leading image dimension ``[S, N, …]`` and one
``isect_tiles`` + one ``rasterize_to_pixels`` call composites ``S`` sub-exposures (``S`` chosen so
that ``S·N`` ≤ :data:`BATCH_ELEMENTS`); the mid-exposure median/ids come from one sharp pass.

Without CUDA (CI, this file's tests): gsplat's CUDA calls are swapped for :func:`reference_ops`:
gsplat's own torch ``_isect_offset_encode``, a vectorised twin of gsplat's torch ``_isect_tiles``
(:func:`isect_tiles_torch`, tested equal to it; gsplat's is a Python loop) and
:func:`rasterize_to_pixels_torch`, a torch transcription of gsplat's CUDA forward kernel (gsplat's
own ``_rasterize_to_pixels`` calls a CUDA kernel and nerfacc, so it cannot run on a CPU).
``backend="gsplat", device="cpu"`` therefore works (slowly); ``backend="auto"`` picks gsplat only
on a CUDA device whose gsplat extension loads (:func:`gsplat_cuda_available`).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from functools import lru_cache
from typing import TYPE_CHECKING, Callable

import numpy as np

from spacedg.errors import ParameterError
from spacedg.render.camera import Camera, exposure_poses
from spacedg.render.composite import composite_view, frame_from_images
from spacedg.render.frame import Frame
from spacedg.render.gaussians import Gaussians
from spacedg.render.settings import ALPHA_MIN, TILE_SIZE, TRANSMITTANCE_MIN, Defocus, MotionBlur, RasterSettings

if TYPE_CHECKING:
    import torch

    from spacedg.render.project_torch import Projected

__all__ = [
    "BATCH_ELEMENTS",
    "GSPLAT_ALPHA_MAX",
    "GsplatOps",
    "cuda_ops",
    "gsplat_cuda_available",
    "isect_tiles_torch",
    "median_pass",
    "ops_for",
    "rasterize_to_pixels_torch",
    "reference_ops",
    "render_gsplat",
]

#: gsplat 1.5.3's compositor caps one Gaussian's alpha at this (hard-coded in its CUDA kernel).
GSPLAT_ALPHA_MAX = 0.999
#: Motion blur: sub-steps per batched call are chosen so that sub-steps × Gaussians stays below this.
BATCH_ELEMENTS = 1 << 23


@dataclass(frozen=True)
class GsplatOps:
    """The three gsplat calls the backend makes (CUDA kernels, or their torch stand-ins)."""

    name: str
    isect_tiles: Callable
    isect_offset_encode: Callable
    rasterize_to_pixels: Callable


@lru_cache(maxsize=1)
def gsplat_cuda_available() -> bool:
    """True when torch sees a CUDA device and gsplat's CUDA extension loads (imported lazily here;
    the first import may JIT-compile gsplat's kernels when no pre-built wheel is installed)."""
    try:
        import torch

        if not torch.cuda.is_available():
            return False
        from gsplat.cuda._backend import _C  # noqa: F401 - the compiled extension, or None

        return _C is not None
    except Exception:  # noqa: BLE001 - any failure to load means "not available"
        return False


def cuda_ops() -> GsplatOps:
    """gsplat's CUDA kernels (``gsplat.cuda._wrapper``)."""
    from gsplat.cuda._wrapper import isect_offset_encode, isect_tiles, rasterize_to_pixels

    return GsplatOps("cuda", isect_tiles, isect_offset_encode, rasterize_to_pixels)


def reference_ops() -> GsplatOps:
    """Torch stand-ins that run on any device (see the module docstring)."""
    from gsplat.cuda._torch_impl import _isect_offset_encode

    return GsplatOps("torch-reference", isect_tiles_torch, _isect_offset_encode, rasterize_to_pixels_torch)


def ops_for(device: torch.device) -> GsplatOps:
    """CUDA kernels on a CUDA device where gsplat loads, else the torch stand-ins."""
    if device.type == "cuda" and gsplat_cuda_available():
        return cuda_ops()
    return reference_ops()


# ------------------------------------------------------------------ torch stand-ins
def isect_tiles_torch(means2d, radii, depths, tile_size: int, tile_width: int, tile_height: int, sort: bool = True):  # type: ignore[no-untyped-def]
    """Vectorised equal of ``gsplat.cuda._torch_impl._isect_tiles`` (same ids, same order)."""
    import torch

    image_dims = means2d.shape[:-2]
    n = means2d.shape[-2]
    count = math.prod(image_dims)
    device = means2d.device
    means2d = means2d.reshape(count, n, 2)
    radii = radii.reshape(count, n, 2)
    depths = depths.reshape(count, n)
    tile_means = means2d / tile_size
    tile_radii = radii / tile_size
    mins = torch.floor(tile_means - tile_radii).int()
    maxs = torch.ceil(tile_means + tile_radii).int()
    limit = torch.tensor([tile_width, tile_height], device=device, dtype=torch.int32)
    mins = torch.minimum(torch.clamp(mins, min=0), limit)
    maxs = torch.minimum(torch.clamp(maxs, min=0), limit)
    per_gauss = (maxs - mins).prod(dim=-1) * (radii > 0).all(dim=-1)
    flat_counts = per_gauss.reshape(-1).long()
    index = torch.repeat_interleave(torch.arange(count * n, device=device), flat_counts)
    first = torch.repeat_interleave(torch.cumsum(flat_counts, 0) - flat_counts, flat_counts)
    local = torch.arange(index.numel(), device=device) - first
    mins_f, maxs_f = mins.reshape(-1, 2)[index].long(), maxs.reshape(-1, 2)[index].long()
    w = torch.clamp(maxs_f[:, 0] - mins_f[:, 0], min=1)
    tx = mins_f[:, 0] + local % w
    ty = mins_f[:, 1] + local // w
    tile_n_bits = (tile_width * tile_height).bit_length()
    image_id = index // n
    depth_bits = depths.reshape(-1).float()[index].view(torch.int32).long() & 0xFFFFFFFF
    isect_ids = ((image_id << tile_n_bits) | (ty * tile_width + tx)) << 32 | depth_bits
    flatten_ids = index.int()
    if sort:
        isect_ids, order = torch.sort(isect_ids, stable=True)
        flatten_ids = flatten_ids[order]
    return per_gauss.reshape(*image_dims, n).int(), isect_ids, flatten_ids


def _tile_lists(offsets: torch.Tensor, n_isects: int) -> tuple[torch.Tensor, torch.Tensor]:
    """gsplat's ``[I, th, tw]`` start offsets → flat ``(start, count)`` per tile."""
    import torch

    start = offsets.reshape(-1).long()
    end = torch.cat([start[1:], torch.tensor([n_isects], device=start.device, dtype=torch.long)])
    return start, end - start


def rasterize_to_pixels_torch(
    means2d, conics, colors, opacities, width: int, height: int, tile_size: int, offsets, flatten_ids,  # type: ignore[no-untyped-def]
    chunk: int = 32, max_elements: int = 1 << 22,
):
    """Torch transcription of gsplat 1.5.3's ``rasterize_to_pixels`` forward CUDA kernel.

    Per pixel, front to back over its tile's list: ``α = min(0.999, o·e^(−σ))``; skip ``σ < 0``
    or ``α < 1/255``; stop before the Gaussian whose ``T·(1 − α) ≤ 1e-4``; ``C += c·α·T``.
    Returns ``(colors [I, H, W, C], alphas [I, H, W, 1])`` like the kernel.
    """
    import torch

    from spacedg.render.raster_torch import advance_transmittance, chunk_of_lists

    image_dims = means2d.shape[:-2]
    count = math.prod(image_dims)
    n = means2d.shape[-2]
    channels = colors.shape[-1]
    device, dtype = means2d.device, means2d.dtype
    m2 = means2d.reshape(count * n, 2)
    cn = conics.reshape(count * n, 3)
    col = colors.reshape(count * n, channels)
    op = opacities.reshape(count * n)
    tiles_y, tiles_x = offsets.shape[-2:]
    start, length = _tile_lists(offsets, flatten_ids.numel())
    gauss = flatten_ids.long()
    n_pix = tile_size * tile_size
    grid = torch.arange(tile_size, device=device, dtype=dtype) + 0.5
    local_x, local_y = grid.repeat(tile_size), grid.repeat_interleave(tile_size)
    total = count * tiles_y * tiles_x
    out_c = torch.zeros(total, n_pix, channels, dtype=dtype, device=device)
    out_t = torch.ones(total, n_pix, dtype=dtype, device=device)
    active = torch.nonzero(length > 0).squeeze(1)
    batch = max(1, max_elements // (n_pix * chunk))
    steps = torch.arange(chunk, device=device)
    for b0 in range(0, active.numel(), batch):
        tiles = active[b0 : b0 + batch]
        in_image = tiles % (tiles_y * tiles_x)
        px = (in_image % tiles_x).to(dtype)[:, None] * tile_size + local_x
        py = (in_image // tiles_x).to(dtype)[:, None] * tile_size + local_y
        trans = torch.ones_like(px)
        alive = torch.ones_like(px, dtype=torch.bool)
        acc = torch.zeros(*px.shape, channels, dtype=dtype, device=device)
        s0, cnt = start[tiles], length[tiles]
        for c0 in range(0, int(cnt.max()), chunk):
            pos = c0 + steps
            in_list, g = chunk_of_lists(gauss, s0, cnt, pos)
            dx = m2[g, 0][:, None, :] - px[:, :, None]
            dy = m2[g, 1][:, None, :] - py[:, :, None]
            a, b, c = (cn[g, k][:, None, :] for k in range(3))
            sigma = 0.5 * (a * dx * dx + c * dy * dy) + b * dx * dy
            alpha = torch.clamp(op[g][:, None, :] * torch.exp(-sigma), max=GSPLAT_ALPHA_MAX)
            ok = (sigma >= 0) & (alpha >= ALPHA_MIN) & in_list[:, None, :] & alive[:, :, None]
            alpha = torch.where(ok, alpha, torch.zeros_like(alpha))
            kept = torch.cumprod(1.0 - alpha, dim=-1)
            t_after = trans[:, :, None] * kept
            t_before = trans[:, :, None] * torch.cat([torch.ones_like(kept[..., :1]), kept[..., :-1]], dim=-1)
            take = t_after > TRANSMITTANCE_MIN
            weight = alpha * t_before * take
            acc = acc + torch.einsum("bpc,bck->bpk", weight, col[g])
            trans, alive, open_ = advance_transmittance(trans, alive, t_after, take)
            if not open_:
                break
        out_c[tiles], out_t[tiles] = acc, trans

    def to_image(t: torch.Tensor) -> torch.Tensor:
        tail = t.shape[2:]
        img = t.reshape(count, tiles_y, tiles_x, tile_size, tile_size, *tail).transpose(2, 3)
        return img.reshape(count, tiles_y * tile_size, tiles_x * tile_size, *tail)[:, :height, :width]

    render_colors = to_image(out_c).reshape(*image_dims, height, width, channels)
    render_alphas = (1.0 - to_image(out_t)).reshape(*image_dims, height, width, 1)
    return render_colors, render_alphas


# ------------------------------------------------------------------ median depth / ids
def median_pass(
    proj: Projected, start: torch.Tensor, length: torch.Tensor, gauss: torch.Tensor, instance_ids: torch.Tensor,
    width: int, height: int, alpha_max: float, chunk: int = 16, max_elements: int = 1 << 22,
) -> tuple[torch.Tensor, torch.Tensor]:
    """``(median_depth (H, W), instance_ids (H, W))`` from per-tile depth-ordered lists (one image).

    Our compositing rules, run only until each pixel's transmittance is ≤ ½: the median Gaussian
    is the last one added while the transmittance before it is > ½ (``stop before T ≤ 1e-4``
    never triggers that early: ``α ≤ 0.999``). Ids are reported where ``T`` ends ≤ ½, else -1.
    """
    import torch

    from spacedg.render.raster_torch import chunk_of_lists, median_update, tiles_to_image

    device, dtype = proj.means2d.device, proj.means2d.dtype
    tiles_x = (width + TILE_SIZE - 1) // TILE_SIZE
    tiles_y = (height + TILE_SIZE - 1) // TILE_SIZE
    n_pix = TILE_SIZE * TILE_SIZE
    grid = torch.arange(TILE_SIZE, device=device, dtype=dtype) + 0.5
    local_x, local_y = grid.repeat(TILE_SIZE), grid.repeat_interleave(TILE_SIZE)
    median_all = torch.zeros(tiles_y * tiles_x, n_pix, dtype=dtype, device=device)
    ids_all = torch.full((tiles_y * tiles_x, n_pix), -1, dtype=torch.int32, device=device)
    done_all = torch.zeros(tiles_y * tiles_x, n_pix, dtype=torch.bool, device=device)
    active = torch.nonzero(length > 0).squeeze(1)
    batch = max(1, max_elements // (n_pix * chunk))
    steps = torch.arange(chunk, device=device)
    for b0 in range(0, active.numel(), batch):
        tiles = active[b0 : b0 + batch]
        px = (tiles % tiles_x).to(dtype)[:, None] * TILE_SIZE + local_x
        py = (tiles // tiles_x).to(dtype)[:, None] * TILE_SIZE + local_y
        trans = torch.ones_like(px)
        median = torch.zeros_like(px)
        ids = torch.full(px.shape, -1, dtype=torch.int32, device=device)
        s0, cnt = start[tiles], length[tiles]
        for c0 in range(0, int(cnt.max()), chunk):
            pos = c0 + steps
            in_list, g = chunk_of_lists(gauss, s0, cnt, pos)
            dx = px[:, :, None] - proj.means2d[g, 0][:, None, :]
            dy = py[:, :, None] - proj.means2d[g, 1][:, None, :]
            a, b, c = (proj.conics[g, k][:, None, :] for k in range(3))
            sigma = 0.5 * (a * dx * dx + c * dy * dy) + b * dx * dy
            alpha = torch.clamp(proj.opacities[g][:, None, :] * torch.exp(-sigma), max=alpha_max)
            ok = (sigma >= 0) & (alpha >= proj.alpha_floor[g][:, None, :]) & in_list[:, None, :]
            alpha = torch.where(ok, alpha, torch.zeros_like(alpha))
            kept = torch.cumprod(1.0 - alpha, dim=-1)
            t_before = trans[:, :, None] * torch.cat([torch.ones_like(kept[..., :1]), kept[..., :-1]], dim=-1)
            median, ids = median_update(((alpha > 0) & (t_before > 0.5)), g, steps, proj.depths, instance_ids, median, ids)
            trans = trans * kept[..., -1]
            if not bool((trans > 0.5).any()):
                break
        median_all[tiles], ids_all[tiles], done_all[tiles] = median, ids, trans <= 0.5

    def to_image(t: torch.Tensor) -> torch.Tensor:
        return tiles_to_image(t, tiles_y, tiles_x, height, width)

    ids_img = torch.where(to_image(done_all), to_image(ids_all), torch.full_like(to_image(ids_all), -1))
    return to_image(median_all), ids_img


# ------------------------------------------------------------------ the backend
def _gsplat_opacities(proj: Projected, settings: RasterSettings) -> torch.Tensor:
    import torch

    if settings.alpha_max > GSPLAT_ALPHA_MAX:
        raise ParameterError(
            f"backend 'gsplat': gsplat's compositor caps alpha at {GSPLAT_ALPHA_MAX}; settings.alpha_max = {settings.alpha_max} "
            "cannot be rendered with it; use backend='torch' or alpha_max <= 0.999"
        )
    if settings.alpha_max < GSPLAT_ALPHA_MAX:
        return torch.clamp(proj.opacities, max=settings.alpha_max)
    return proj.opacities


def _channels(proj: Projected, want_color: bool, want_depth: bool) -> torch.Tensor:
    import torch

    parts = []
    if want_color:
        parts.append(proj.colors)
    if want_depth or not parts:
        parts.append(proj.depths[:, None])
    return torch.cat([p.to(torch.float32) for p in parts], dim=-1)


def _isect(means2d, radii, depths, camera: Camera, ops: GsplatOps):  # type: ignore[no-untyped-def]
    """gsplat's tile intersection of ``[S, N, …]`` stacks for ``camera``'s tile grid: ``(offsets, flatten_ids)``."""
    tiles_x = (camera.width + TILE_SIZE - 1) // TILE_SIZE
    tiles_y = (camera.height + TILE_SIZE - 1) // TILE_SIZE
    _, isect_ids, flatten_ids = ops.isect_tiles(means2d, radii, depths, TILE_SIZE, tiles_x, tiles_y)
    return ops.isect_offset_encode(isect_ids, means2d.shape[0], tiles_x, tiles_y), flatten_ids


def _composite_batch(
    projs: list[Projected], camera: Camera, settings: RasterSettings, ops: GsplatOps, want_color: bool, want_depth: bool,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """gsplat's tiles + compositor on a stack of projections: ``(channels [S,H,W,C], alpha [S,H,W], offsets, flatten_ids)``."""
    import torch

    means2d = torch.stack([p.means2d for p in projs]).float().contiguous()
    conics = torch.stack([p.conics for p in projs]).float().contiguous()
    opac = torch.stack([_gsplat_opacities(p, settings) for p in projs]).float().contiguous()
    colors = torch.stack([_channels(p, want_color, want_depth) for p in projs]).contiguous()
    radii = torch.stack([p.radii for p in projs]).int().contiguous()
    depths = torch.stack([p.depths for p in projs]).float().contiguous()
    offsets, flatten_ids = _isect(means2d, radii, depths, camera, ops)
    rendered, alphas = ops.rasterize_to_pixels(
        means2d, conics, colors, opac, camera.width, camera.height, TILE_SIZE, offsets, flatten_ids
    )
    return rendered, alphas[..., 0], offsets, flatten_ids


def _split(rendered: torch.Tensor, alpha: torch.Tensor, want_color: bool, want_depth: bool) -> dict[str, torch.Tensor]:
    """gsplat's channels by name: ``alpha``, linear ``rgb``, ``depth_weighted`` (``Σ w·z``)."""
    from spacedg.render.colour import srgb_to_linear

    out = {"alpha": alpha}
    if want_color:
        out["rgb"] = srgb_to_linear(rendered[..., :3])
    if want_depth:
        out["depth_weighted"] = rendered[..., -1]
    return out


def _project(gs, camera: Camera, settings: RasterSettings, want_color: bool):  # type: ignore[no-untyped-def]
    from spacedg.render import project_torch

    return project_torch.project_gaussians(gs, camera, settings, None, want_color)


def _sharp_ids(gs, camera: Camera, settings: RasterSettings, proj, ops: GsplatOps, offsets=None, flatten_ids=None):  # type: ignore[no-untyped-def]
    """Median depth and ids of one image from gsplat's tile lists (computed here if not given)."""
    if offsets is None:
        offsets, flatten_ids = _isect(
            proj.means2d[None].float().contiguous(), proj.radii[None].int().contiguous(), proj.depths[None].float().contiguous(),
            camera, ops,
        )
    start, length = _tile_lists(offsets, flatten_ids.numel())
    return median_pass(proj, start, length, flatten_ids.long(), gs.instance_ids, camera.width, camera.height, settings.alpha_max)


def render_gsplat(
    gaussians: Gaussians,
    camera: Camera,
    wanted: frozenset[str],
    device: torch.device,
    settings: RasterSettings,
    defocus: Defocus | None,
    motion: MotionBlur | None,
    ops: GsplatOps | None = None,
) -> Frame:
    """One view on the gsplat backend (see the module docstring). Returns a :class:`Frame` whose
    numpy images are copies of device tensors kept in ``frame.tensors`` (same names)."""
    import torch

    from spacedg.render import motion as motion_model
    from spacedg.render import project_torch
    from spacedg.render.raster_torch import expected_depth

    t0 = time.perf_counter()
    if defocus is not None:  # the defocus model's compositing rules are not gsplat's: the torch twin renders it
        if motion is not None and not motion.is_static:
            frame = motion_model.render_motion(
                motion_model.MotionJob(gaussians, camera, motion, wanted, "torch", device, settings, defocus)
            )
        else:
            images, stats = composite_view(gaussians, camera, wanted, "torch", device, settings, defocus)
            frame = frame_from_images(images, camera, wanted)
            stats.update(sub_steps=1, ms=(time.perf_counter() - t0) * 1e3)
            frame.stats = stats
        frame.stats["delegated"] = "torch"
        return frame
    if motion is not None and motion_model.uses_keyframes(motion, camera):
        # the fast motion path is the keyframe warp on every backend (its sub-step count differs from
        # choose_sub_steps'): the torch twin renders it, so gsplat, torch and cpu blur alike
        frame = motion_model.render_motion(motion_model.MotionJob(gaussians, camera, motion, wanted, "torch", device, settings, None))
        frame.stats["delegated"] = "torch"
        return frame
    ops = ops or ops_for(device)
    want_color, want_depth = "rgb" in wanted, "depth" in wanted
    want_ids = bool(wanted & {"median_depth", "instance_ids"})
    gs = project_torch.GaussianTensors.of(gaussians, device, torch.float32)
    stats: dict[str, float] = {"ops": ops.name}  # type: ignore[dict-item]
    with torch.no_grad():
        if motion is None or motion.is_static:
            proj = _project(gs, camera, settings, want_color)
            t1 = time.perf_counter()
            rendered, alpha, offsets, flatten_ids = _composite_batch([proj], camera, settings, ops, want_color, want_depth)
            tensors = _split(rendered[0], alpha[0], want_color, want_depth)
            if want_depth:
                tensors["depth"] = expected_depth(tensors.pop("depth_weighted"), tensors["alpha"])
            if want_ids:
                tensors["median_depth"], tensors["instance_ids"] = _sharp_ids(gs, camera, settings, proj, ops, offsets, flatten_ids)
            stats.update(visible=int(proj.visible.sum()), pairs=int(flatten_ids.numel()), sub_steps=1)
            stats["project_ms"] = (t1 - t0) * 1e3
        else:
            displacement, count = motion_model.sub_step_plan(gaussians, camera, motion, motion.fast)
            times = motion_model.sub_exposure_times(count)
            poses = exposure_poses(camera, np.array(motion.translation), np.array(motion.rotation), times)
            per_call = max(1, BATCH_ELEMENTS // max(len(gaussians), 1))
            sums: dict[str, torch.Tensor] = {}
            pairs = 0
            for b0 in range(0, count, per_call):
                projs = [_project(gs, camera.with_pose(p), settings, want_color) for p in poses[b0 : b0 + per_call]]
                rendered, alpha, _, flatten_ids = _composite_batch(projs, camera, settings, ops, want_color, want_depth)
                pairs += int(flatten_ids.numel())
                for name, value in _split(rendered, alpha, want_color, want_depth).items():
                    total = value.sum(0)
                    sums[name] = sums[name] + total if name in sums else total
            tensors = {"alpha": sums["alpha"] / count}
            if want_color:
                tensors["rgb"] = sums["rgb"] / count
            if want_depth:
                tensors["depth"] = expected_depth(sums["depth_weighted"], sums["alpha"])
            if want_ids:
                proj = _project(gs, camera, settings, False)
                tensors["median_depth"], tensors["instance_ids"] = _sharp_ids(gs, camera, settings, proj, ops)
            stats.update(sub_steps=count, displacement_px=displacement, pairs=pairs)
    images = {k: v.detach().cpu().numpy() for k, v in tensors.items()}
    for name in ("rgb", "alpha", "depth", "median_depth"):
        if name in images:
            images[name] = images[name].astype(np.float32, copy=False)
    frame = frame_from_images(images, camera, wanted)
    if frame.valid is not None:  # the same fisheye image-circle mask on the device copies
        outside = ~torch.from_numpy(np.array(frame.valid)).to(device)
        for name, value in tensors.items():
            fill = -1 if name == "instance_ids" else 0.0
            tensors[name] = torch.where(outside[..., None] if value.dim() == 3 else outside, torch.full_like(value, fill), value)
    frame.tensors = {k: v for k, v in tensors.items() if getattr(frame, k, None) is not None}
    stats["ms"] = (time.perf_counter() - t0) * 1e3
    frame.stats = stats
    return frame

