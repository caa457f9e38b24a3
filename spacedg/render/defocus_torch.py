"""Readable torch twin of the defocus model (:mod:`spacedg.render.defocus`, :mod:`spacedg.render.defocus_cpu`).

Same two passes, as whole-tensor operations over batches of tiles, ``chunk`` Gaussians at a time:

- :func:`measure_sharp` — the sharp composite of :func:`spacedg.render.raster_torch.composite`
  (cumulative products of ``1 − α``), plus per-pair sums ``M, S, W, U_r, U_g, U_b``. The
  transmittance through a Gaussian's own depth slab is ``T_before / T_slab_start`` (slabs are
  contiguous in the depth-sorted list, and start at the same list position for every pixel of
  a tile). A second sweep over the chunks adds ``U`` once each pixel's ``ρ`` is known.
- :func:`composite_defocus` — in-focus Gaussians by the sharp rules, blurred ones adding
  ``w = min(α·T_f, T)``. A chunk of only blurred Gaussians is closed-form
  (``T_k = max(T₀ − T_f·Σ_{j≤k} α_j, 0)``); a chunk with an in-focus one is walked Gaussian
  by Gaussian.
"""

from __future__ import annotations

import math
from dataclasses import replace

import torch

from spacedg.limits import image_size_problem
from spacedg.render.camera import Camera
from spacedg.render.colour import srgb_to_linear
from spacedg.render.defocus_lens import PRIOR
from spacedg.render.project_torch import GaussianTensors, Projected, project_gaussians
from spacedg.render.raster_torch import advance_transmittance, bin_tiles, images_from_tiles, median_update
from spacedg.render.settings import (
    DEFOCUS_SLAB,
    TILE_SIZE,
    TRANSMITTANCE_MIN,
    Defocus,
    RasterSettings,
)

__all__ = ["alpha_mass", "composite_defocus", "has_blur", "match_factors", "measure_sharp", "render_torch"]


def has_blur(proj: Projected) -> bool:
    """Whether any visible Gaussian of a defocused projection has a circle of confusion > 0."""
    return proj.coc is not None and bool((proj.coc[proj.visible] > 0).any())


def _slab(depths: torch.Tensor) -> torch.Tensor:
    return torch.floor(torch.log(torch.clamp(depths.double(), min=1e-30)) / math.log1p(DEFOCUS_SLAB)).long()


def _tile_grid(tiles: torch.Tensor, tiles_x: int, dtype: torch.dtype) -> tuple[torch.Tensor, torch.Tensor]:
    grid = torch.arange(TILE_SIZE, device=tiles.device, dtype=dtype) + 0.5
    px = (tiles % tiles_x).to(dtype)[:, None] * TILE_SIZE + grid.repeat(TILE_SIZE)
    py = (tiles // tiles_x).to(dtype)[:, None] * TILE_SIZE + grid.repeat_interleave(TILE_SIZE)
    return px, py


def _alphas(proj: Projected, g: torch.Tensor, px: torch.Tensor, py: torch.Tensor, in_list: torch.Tensor,
            alive: torch.Tensor, alpha_max: float) -> torch.Tensor:
    """(B, 256, C) alpha of the chunk's Gaussians at the batch's pixels (0 where skipped)."""
    dx = px[:, :, None] - proj.means2d[g, 0][:, None, :]
    dy = py[:, :, None] - proj.means2d[g, 1][:, None, :]
    a, bb, c = (proj.conics[g, k][:, None, :] for k in range(3))
    sigma = 0.5 * (a * dx * dx + c * dy * dy) + bb * dx * dy
    alpha = torch.clamp(proj.opacities[g][:, None, :] * torch.exp(-sigma), max=alpha_max)
    ok = (sigma >= 0) & (alpha >= proj.alpha_floor[g][:, None, :]) & in_list[:, None, :] & alive[:, :, None]
    return torch.where(ok, alpha, torch.zeros_like(alpha))


def _chunks(offsets: torch.Tensor, gauss: torch.Tensor, width: int, height: int, chunk: int, max_elements: int):
    """Yield ``(tiles, start, count)`` batches of non-empty tiles."""
    n_pix = TILE_SIZE * TILE_SIZE
    lengths = offsets[1:] - offsets[:-1]
    active = torch.nonzero(lengths > 0).squeeze(1)
    batch = max(1, max_elements // (n_pix * chunk))
    for b0 in range(0, active.numel(), batch):
        tiles = active[b0 : b0 + batch]
        yield tiles, offsets[tiles], lengths[tiles]


def measure_sharp(
    proj: Projected, offsets: torch.Tensor, gauss: torch.Tensor, slab: torch.Tensor, width: int, height: int,
    alpha_max: float, chunk: int = 32, max_elements: int = 1 << 22,
) -> torch.Tensor:
    """Per-pair sums ``(pairs, 11)``: M, S, W, U_r, U_g, U_b and the visible weight's moments about the
    Gaussian's mean Σw·dx, Σw·dy, Σw·dx², Σw·dx·dy, Σw·dy² (see the module docstring)."""
    device, dtype = proj.means2d.device, proj.means2d.dtype
    tiles_x = (width + TILE_SIZE - 1) // TILE_SIZE
    out = torch.zeros(gauss.numel(), 11, dtype=dtype, device=device)
    steps = torch.arange(chunk, device=device)
    colors = proj.colors if proj.colors is not None else torch.zeros(proj.means2d.shape[0], 3, dtype=dtype, device=device)
    linear = srgb_to_linear(colors)
    last_index = max(gauss.numel() - 1, 0)
    for tiles, start, count in _chunks(offsets, gauss, width, height, chunk, max_elements):
        px, py = _tile_grid(tiles, tiles_x, dtype)
        rho = None
        for sweep in (1, 2):
            trans = torch.ones_like(px)
            alive = torch.ones_like(px, dtype=torch.bool)
            enc = torch.zeros(*px.shape, 3, dtype=dtype, device=device)
            mix = torch.zeros_like(enc)
            t_start = torch.ones_like(px)  # transmittance where the current slab started
            slab_prev = torch.full((tiles.numel(),), torch.iinfo(torch.int64).min, dtype=torch.long, device=device)
            for c0 in range(0, int(count.max()), chunk):
                pos = c0 + steps
                in_list = pos[None, :] < count[:, None]
                pair = torch.clamp(start[:, None] + pos[None, :], max=last_index)
                g = torch.where(in_list, gauss[pair], torch.zeros_like(pair))
                alpha = _alphas(proj, g, px, py, in_list, alive, alpha_max)
                kept = torch.cumprod(1.0 - alpha, dim=-1)
                t_after = trans[:, :, None] * kept
                t_before = trans[:, :, None] * torch.cat([torch.ones_like(kept[..., :1]), kept[..., :-1]], dim=-1)
                take = t_after > TRANSMITTANCE_MIN
                taken = alpha * take
                weight = taken * t_before
                if sweep == 1:
                    s = torch.where(in_list, slab[g], slab_prev[:, None])
                    previous = torch.cat([slab_prev[:, None], s[:, :-1]], dim=1)
                    new = (s != previous) & in_list
                    marks = torch.where(new, steps[None, :].expand_as(s), torch.full_like(s, -1))
                    last = torch.cummax(marks, dim=1).values  # (B, C) list position of the slab's start, -1 = before the chunk
                    at = torch.gather(t_before, 2, torch.clamp(last, min=0)[:, None, :].expand(-1, px.shape[1], -1))
                    t_slab_start = torch.where((last >= 0)[:, None, :], at, t_start[:, :, None])
                    t_slab = t_before / torch.clamp(t_slab_start, min=1e-30)
                    sums = torch.stack([taken.sum(1), (taken * t_slab).sum(1), weight.sum(1)], dim=-1)  # (B, C, 3)
                    out[pair[in_list], :3] += sums[in_list]
                    dx = px[:, :, None] - proj.means2d[g, 0][:, None, :]
                    dy = py[:, :, None] - proj.means2d[g, 1][:, None, :]
                    moments = torch.stack([(weight * dx).sum(1), (weight * dy).sum(1), (weight * dx * dx).sum(1),
                                           (weight * dx * dy).sum(1), (weight * dy * dy).sum(1)], dim=-1)
                    out[pair[in_list], 6:] += moments[in_list]
                    enc = enc + torch.einsum("bpc,bck->bpk", weight, colors[g])
                    mix = mix + torch.einsum("bpc,bck->bpk", weight, linear[g])
                    t_start = torch.where((last[:, -1] >= 0)[:, None], at[:, :, -1], t_start)
                    slab_prev = s[:, -1]
                else:
                    u = torch.einsum("bpc,bpk->bck", weight, rho)
                    out[pair[in_list], 3:6] += u[in_list]
                trans, alive, open_ = advance_transmittance(trans, alive, t_after, take)
                if not open_:
                    break
            if sweep == 1:
                rho = torch.where(mix > 0, srgb_to_linear(enc) / torch.clamp(mix, min=1e-30), torch.ones_like(mix))
    return out


def measurement_margin(proj: Projected, width: int, height: int) -> int:
    """As :func:`spacedg.render.defocus.measurement_margin`, from a torch projection."""

    from spacedg.render.defocus import margin_cap

    visible = proj.visible
    if not bool(visible.any()):
        return 0
    wanted = float(proj.radii[visible].max())
    margin = int(min(math.ceil(wanted), margin_cap(width, height)))
    while margin > 0 and image_size_problem(width + 2 * margin, height + 2 * margin) is not None:
        margin //= 2
    return margin


def inside_fraction(proj: Projected, width: int, height: int) -> torch.Tensor:
    """(N,) share of each Gaussian's mass inside the frame, as :func:`spacedg.render.defocus.inside_fraction`."""
    u, v = proj.means2d[:, 0].double(), proj.means2d[:, 1].double()
    conics = proj.conics.double()
    a, b, c = conics[:, 0], conics[:, 1], conics[:, 2]
    det = a * c - b * b
    safe = torch.where(det > 0, det, torch.ones_like(det))
    sx = torch.clamp(torch.nan_to_num(torch.where(det > 0, torch.sqrt(torch.clamp(c / safe, min=0.0)), torch.full_like(det, 0.5)), nan=0.5), min=1e-6)
    sy = torch.clamp(torch.nan_to_num(torch.where(det > 0, torch.sqrt(torch.clamp(a / safe, min=0.0)), torch.full_like(det, 0.5)), nan=0.5), min=1e-6)
    root2 = math.sqrt(2.0)
    fx = 0.5 * (torch.erf((width - u) / (root2 * sx)) - torch.erf(-u / (root2 * sx)))
    fy = 0.5 * (torch.erf((height - v) / (root2 * sy)) - torch.erf(-v / (root2 * sy)))
    return torch.clamp(fx * fy, 0.0, 1.0)


def alpha_mass(proj: Projected) -> torch.Tensor:
    """(N,) float64 integrated alpha of each projected Gaussian, as :func:`spacedg.render.defocus.alpha_mass`."""
    opa = proj.opacities.double()
    conics = proj.conics.double()
    det_conic = conics[:, 0] * conics[:, 2] - conics[:, 1] * conics[:, 1]
    ok = (opa > 0) & (det_conic > 0) & proj.visible
    safe_opa = torch.where(ok, opa, torch.ones_like(opa))
    kept = 1.0 - torch.clamp(proj.alpha_floor.double() / safe_opa, 0.0, 1.0)
    mass = opa * 2.0 * math.pi / torch.sqrt(torch.where(ok, det_conic, torch.ones_like(det_conic))) * kept
    return torch.where(ok & torch.isfinite(mass), mass, torch.zeros_like(mass))


def match_factors(sums: torch.Tensor, inside: torch.Tensor, mass: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Per-Gaussian ``(κ (N,), ρ (N, 3))`` from per-Gaussian sums (N, 6), as :func:`spacedg.render.defocus.match_factors`."""
    sums = sums.double()
    w, u = sums[:, 2], sums[:, 3:6]
    share = torch.clamp(inside.double(), 0.0, 1.0)
    mass = mass.double()
    expected = float((mass * share).sum())
    kappa_mean = min(float(w.sum()) / expected, 1.0) if expected > 0 else 1.0
    rho_mean = u.sum(0) / w.sum() if float(w.sum()) > 0 else torch.ones(3, dtype=sums.dtype, device=sums.device)
    kappa = torch.where(mass > 0, (w + PRIOR * mass * kappa_mean) / torch.where(mass > 0, mass * (share + PRIOR), torch.ones_like(mass)),
                        torch.full_like(mass, kappa_mean))
    rho = torch.where(
        (w > 0)[:, None],
        share[:, None] * (u / torch.where(w > 0, w, torch.ones_like(w))[:, None]) + (1 - share[:, None]) * rho_mean[None, :],
        rho_mean[None, :].expand_as(u),
    )
    kappa = torch.clamp(torch.nan_to_num(kappa, nan=kappa_mean), 0.0, 1.0)
    rho = torch.clamp(torch.nan_to_num(rho, nan=1.0, posinf=1.0), min=0.0)
    return kappa, rho


def apply_match(proj: Projected, kappa: torch.Tensor, rho: torch.Tensor) -> Projected:
    """The blurred projection with the measured factors applied (see :func:`spacedg.render.defocus.apply_match`)."""
    blurred = proj.coc > 0
    scale = torch.where(blurred, kappa.to(proj.opacities.dtype), torch.ones_like(proj.opacities))
    gone = blurred & (kappa <= 0)
    colors = proj.colors
    if colors is not None:
        colors = torch.where(blurred[:, None], srgb_to_linear(colors) * rho.to(colors.dtype), colors)
    return replace(
        proj, opacities=proj.opacities * scale, alpha_floor=proj.alpha_floor * scale, colors=colors,
        radii=torch.where(gone[:, None], torch.zeros_like(proj.radii), proj.radii),
        rects=torch.where(gone[:, None], torch.zeros_like(proj.rects), proj.rects),
    )


def composite_defocus(
    proj: Projected, offsets: torch.Tensor, gauss: torch.Tensor, instance_ids: torch.Tensor, width: int, height: int,
    alpha_max: float, want_color: bool = True, want_depth: bool = False, want_ids: bool = False,
    chunk: int = 32, max_elements: int = 1 << 22,
) -> dict[str, torch.Tensor]:
    """Composite the blurred projection: ``alpha``, ``enc`` (in-focus mix, sRGB-encoded), ``lin``
    (blurred light, linear) and the requested depth/id images, each (H, W[, 3])."""
    device, dtype = proj.means2d.device, proj.means2d.dtype
    tiles_x = (width + TILE_SIZE - 1) // TILE_SIZE
    tiles_y = (height + TILE_SIZE - 1) // TILE_SIZE
    n_pix = TILE_SIZE * TILE_SIZE
    n_tiles = tiles_x * tiles_y
    trans_all = torch.ones(n_tiles, n_pix, dtype=dtype, device=device)
    enc_all = torch.zeros(n_tiles, n_pix, 3, dtype=dtype, device=device)
    lin_all = torch.zeros(n_tiles, n_pix, 3, dtype=dtype, device=device)
    depth_all = torch.zeros(n_tiles, n_pix, dtype=dtype, device=device)
    median_all = torch.zeros(n_tiles, n_pix, dtype=dtype, device=device)
    ids_all = torch.full((n_tiles, n_pix), -1, dtype=torch.int32, device=device)
    colors = proj.colors if (want_color and proj.colors is not None) else torch.zeros(proj.means2d.shape[0], 3, dtype=dtype, device=device)
    steps = torch.arange(chunk, device=device)
    last_index = max(gauss.numel() - 1, 0)
    for tiles, start, count in _chunks(offsets, gauss, width, height, chunk, max_elements):
        px, py = _tile_grid(tiles, tiles_x, dtype)
        trans = torch.ones_like(px)
        t_focus = torch.ones_like(px)
        alive = torch.ones_like(px, dtype=torch.bool)
        enc = torch.zeros(*px.shape, 3, dtype=dtype, device=device)
        lin = torch.zeros_like(enc)
        depth = torch.zeros_like(px)
        median = torch.zeros_like(px)
        ids = torch.full(px.shape, -1, dtype=torch.int32, device=device)
        for c0 in range(0, int(count.max()), chunk):
            pos = c0 + steps
            in_list = pos[None, :] < count[:, None]
            g = torch.where(in_list, gauss[torch.clamp(start[:, None] + pos[None, :], max=last_index)], torch.zeros_like(pos)[None, :])
            alpha = _alphas(proj, g, px, py, in_list, alive, alpha_max)
            blurred = proj.coc[g] > 0  # (B, C)
            if bool((blurred | ~in_list).all()):
                # only blurred Gaussians: the saturating sum in closed form
                t_after = torch.clamp(trans[:, :, None] - torch.cumsum(alpha * t_focus[:, :, None], dim=-1), min=0.0)
                t_before = torch.cat([trans[:, :, None], t_after[..., :-1]], dim=-1)
                live = t_before > TRANSMITTANCE_MIN
                weight = (t_before - t_after) * live
                trans = trans - weight.sum(-1)
                alive = alive & (trans > TRANSMITTANCE_MIN)
                enc_w = torch.zeros_like(weight)
                lin_w = weight
            else:
                enc_w = torch.zeros_like(alpha)
                lin_w = torch.zeros_like(alpha)
                t_before = torch.zeros_like(alpha)
                for k in range(alpha.shape[-1]):
                    a = alpha[..., k] * alive  # a pixel that stopped takes nothing more
                    t_before[..., k] = trans
                    w_blur = torch.minimum(a * t_focus, trans)
                    after_sharp = trans * (1.0 - a)
                    take = after_sharp > TRANSMITTANCE_MIN
                    w_sharp = a * trans * take
                    is_blur = blurred[:, k][:, None]
                    lin_w[..., k] = torch.where(is_blur, w_blur, torch.zeros_like(a))
                    enc_w[..., k] = torch.where(is_blur, torch.zeros_like(a), w_sharp)
                    new_trans = torch.where(is_blur, trans - w_blur, torch.where(take, after_sharp, trans))
                    t_focus = torch.where(is_blur, t_focus, t_focus * (1.0 - a * take))
                    alive = alive & torch.where(is_blur, new_trans > TRANSMITTANCE_MIN, take)
                    trans = new_trans
                weight = enc_w + lin_w
            if want_color:
                enc = enc + torch.einsum("bpc,bck->bpk", enc_w, colors[g])
                lin = lin + torch.einsum("bpc,bck->bpk", lin_w, colors[g])
            if want_depth:
                depth = depth + (weight * proj.depths[g][:, None, :]).sum(-1)
            if want_ids:
                median, ids = median_update(((weight > 0) & (t_before > 0.5)), g, steps, proj.depths, instance_ids, median, ids)
            if not bool(alive.any()):
                break
        trans_all[tiles], enc_all[tiles], lin_all[tiles], depth_all[tiles] = trans, enc, lin, depth
        median_all[tiles], ids_all[tiles] = median, ids
    return images_from_tiles(
        tiles_y, tiles_x, height, width, trans_all, {"enc": enc_all, "lin": lin_all} if want_color else {},
        depth_all if want_depth else None, (median_all, ids_all) if want_ids else None,
    )


def _measure(gs: GaussianTensors, camera: Camera, settings: RasterSettings, want_color: bool) -> tuple[Projected, torch.Tensor]:
    """One sharp measurement pass: the projection and its per-Gaussian sums (N, 6) float64."""
    from spacedg.render.defocus import measurement_settings

    tight = settings.tight_tiles and settings.opacity_extent
    sharp = project_gaussians(gs, camera, measurement_settings(settings), None, want_color)
    offsets, gauss = bin_tiles(sharp, camera.width, camera.height, tight)
    pairs = measure_sharp(sharp, offsets, gauss, _slab(sharp.depths), camera.width, camera.height, settings.alpha_max)
    sums = torch.zeros(sharp.means2d.shape[0], pairs.shape[1], dtype=torch.float64, device=pairs.device)
    sums.index_add_(0, gauss.long(), pairs.double())
    return sharp, sums


def render_torch(
    gs: GaussianTensors, camera: Camera, settings: RasterSettings, proj: Projected,
    want_color: bool, want_depth: bool, want_ids: bool, defocus: Defocus,
) -> dict[str, torch.Tensor]:
    """Both passes on the torch path: ``alpha``, ``enc`` + ``lin`` (when colour is wanted), depth/ids, ``n_pairs``."""
    from spacedg.render.defocus import measurement_camera
    from spacedg.render.defocus_lens import lens_camera, lens_defocus, lens_points, visibility
    
    tight = settings.tight_tiles and settings.opacity_extent
    width, height = camera.width, camera.height
    wide = measurement_camera(camera, measurement_margin(proj, width, height))
    sharp, sums = _measure(gs, wide, settings, want_color)
    kappa, rho = match_factors(sums, inside_fraction(sharp, wide.width, wide.height), alpha_mass(sharp))
    lens = lens_defocus(defocus, wide.fx / camera.fx, wide.fx)
    seen = torch.zeros_like(kappa)
    largest = float(proj.coc[proj.visible].max()) if bool(proj.visible.any()) else 0.0
    centre_weight, points = lens_points(largest)
    for offset, weight in points:
        seen_b, sums_b = _measure(gs, lens_camera(wide, lens, offset), settings, False)
        share = visibility(sums_b[:, 2].cpu().numpy(), alpha_mass(seen_b).cpu().numpy(), inside_fraction(seen_b, wide.width, wide.height).cpu().numpy())
        seen = seen + weight * torch.from_numpy(share).to(seen)
    kappa = torch.clamp(centre_weight * kappa + seen, 0.0, 1.0)
    blurred = place_visible_torch(
        apply_match(proj, kappa, rho), sums[:, [2, 6, 7, 8, 9, 10]], wide.fx / camera.fx, width, height,
        inside_fraction(sharp, wide.width, wide.height),
    )
    factor = composite_factor(blurred, width, height)
    if factor > 1:  # as the compiled path: every visible Gaussian blurred by >= COMPOSITE_MIN_COC px
        blurred, width, height = coarse_view(blurred, width, height, factor)
    offsets, gauss = bin_tiles(blurred, width, height, tight)
    out = composite_defocus(blurred, offsets, gauss, gs.instance_ids, width, height, settings.alpha_max, want_color, want_depth, want_ids)
    out["n_pairs"] = torch.tensor(gauss.numel())
    out["factor"] = torch.tensor(factor)  # the caller upsamples (spacedg.render.defocus.upsample)
    return out


def place_visible_torch(proj: Projected, sums: torch.Tensor, scale: float, width: int, height: int, inside: torch.Tensor) -> Projected:
    """:func:`spacedg.render.defocus_place.place_visible` on a torch projection (the per-Gaussian
    arithmetic runs in float64 numpy on the host, as the compiled path's; the result is on ``proj``'s device)."""
    import numpy as np

    from spacedg.render.defocus_place import place_visible
    from spacedg.render.project_cpu import AMIN, CA, CB, CC, COC, OPA, PX, PY, RADX, RADY

    n = proj.means2d.shape[0]
    packed = np.zeros((n, 14), np.float32)
    host = {PX: proj.means2d[:, 0], PY: proj.means2d[:, 1], CA: proj.conics[:, 0], CB: proj.conics[:, 1], CC: proj.conics[:, 2],
            OPA: proj.opacities, AMIN: proj.alpha_floor, RADX: proj.radii[:, 0], RADY: proj.radii[:, 1], COC: proj.coc}
    for column, value in host.items():
        packed[:, column] = value.detach().double().cpu().numpy()
    rects = proj.rects.detach().cpu().numpy()
    placed, placed_rects = place_visible(packed, rects, sums.detach().double().cpu().numpy(), scale, width, height, inside.detach().cpu().numpy())
    dev, dtype = proj.means2d.device, proj.means2d.dtype
    column = lambda k: torch.from_numpy(placed[:, k]).to(device=dev, dtype=dtype)  # noqa: E731
    return replace(
        proj, means2d=torch.stack([column(PX), column(PY)], dim=-1), conics=torch.stack([column(CA), column(CB), column(CC)], dim=-1),
        opacities=column(OPA), alpha_floor=column(AMIN),
        radii=torch.from_numpy(placed[:, [RADX, RADY]]).to(device=dev, dtype=proj.radii.dtype),
        rects=torch.from_numpy(placed_rects).to(device=dev, dtype=proj.rects.dtype),
    )


def composite_factor(proj: Projected, width: int, height: int) -> int:
    """As :func:`spacedg.render.defocus.composite_factor`, from a torch projection."""
    from spacedg.render import defocus

    visible = proj.visible
    if defocus.COMPOSITE_MIN_COC <= 0 or proj.coc is None or not bool(visible.any()):
        return 1
    return defocus.factor_for_coc(float(proj.coc[visible].min()), width, height)


def coarse_view(proj: Projected, width: int, height: int, factor: int) -> tuple[Projected, int, int]:
    """As :func:`spacedg.render.defocus.coarse_view`: the projection on a grid ``factor`` times coarser."""
    f = float(factor)
    w2, h2 = -(-width // factor), -(-height // factor)
    visible = proj.visible
    means2d = proj.means2d / f
    radii = torch.ceil(proj.radii.to(means2d.dtype) / f)
    wide = torch.float64 if means2d.device.type != "mps" else means2d.dtype
    limits = torch.tensor([(w2 + TILE_SIZE - 1) // TILE_SIZE, (h2 + TILE_SIZE - 1) // TILE_SIZE], dtype=wide, device=means2d.device)
    lo = torch.minimum(torch.clamp(torch.floor((means2d.to(wide) - radii.to(wide)) / TILE_SIZE), min=0), limits)
    hi = torch.minimum(torch.clamp(torch.ceil((means2d.to(wide) + radii.to(wide)) / TILE_SIZE), min=0), limits)
    keep = visible & (hi > lo).all(-1)
    rects = torch.stack([lo[:, 0], hi[:, 0], lo[:, 1], hi[:, 1]], dim=-1).to(torch.int32) * keep[:, None]
    radii = torch.where(keep[:, None], radii, torch.zeros_like(radii)).to(torch.int32)
    return replace(proj, means2d=means2d, conics=proj.conics * (f * f), radii=radii, rects=rects), w2, h2
