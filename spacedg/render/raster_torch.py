"""Readable torch tile binning and compositing: the oracle on CPU, the production path on GPU.

Same rules as the compiled :mod:`spacedg.render.raster_cpu` (see its docstring), written
as whole-tensor operations: Gaussian–tile pairs are expanded with ``repeat_interleave`` and
stably sorted by tile (the input is depth-ordered, so each tile's list stays in depth
order); tiles are composited in batches, ``chunk`` Gaussians at a time, with a cumulative
product of ``1 − α`` giving each pixel's transmittance before and after every Gaussian.
"""

from __future__ import annotations

import math

import torch

from spacedg.render.project_torch import Projected
from spacedg.render.settings import TILE_SIZE, TRANSMITTANCE_MIN


def tile_reaches(
    means2d: torch.Tensor, conics: torch.Tensor, opacities: torch.Tensor, alpha_floor: torch.Tensor,
    tx: torch.Tensor, ty: torch.Tensor, width: int, height: int,
) -> torch.Tensor:
    """Per pair: does the Gaussian's ``alpha >= alpha_floor`` (1/255 when sharp) ellipse reach a pixel centre of tile (tx, ty)?

    Minimum of ``σ`` over the rectangle spanned by the tile's pixel centres (0 if the mean is
    inside it, else the smallest clamped 1-D minimum along its four edges).
    """
    a, b, c = conics.unbind(-1)
    u, v = means2d.unbind(-1)
    x_lo = tx * TILE_SIZE + 0.5 - u
    x_hi = torch.clamp(tx * TILE_SIZE + TILE_SIZE, max=width) - 0.5 - u
    y_lo = ty * TILE_SIZE + 0.5 - v
    y_hi = torch.clamp(ty * TILE_SIZE + TILE_SIZE, max=height) - 0.5 - v

    def sigma(dx: torch.Tensor, dy: torch.Tensor) -> torch.Tensor:
        return 0.5 * (a * dx * dx + c * dy * dy) + b * dx * dy

    a_safe = torch.where(a > 0, a, torch.ones_like(a))
    c_safe = torch.where(c > 0, c, torch.ones_like(c))
    best = torch.full_like(u, math.inf)
    for dx in (x_lo, x_hi):
        dy = torch.minimum(torch.maximum(-b * dx / c_safe, y_lo), y_hi)
        best = torch.minimum(best, sigma(dx, dy))
    for dy in (y_lo, y_hi):
        dx = torch.minimum(torch.maximum(-b * dy / a_safe, x_lo), x_hi)
        best = torch.minimum(best, sigma(dx, dy))
    inside = (x_lo <= 0) & (x_hi >= 0) & (y_lo <= 0) & (y_hi >= 0)
    limit = torch.log(torch.clamp(opacities, min=1e-30) / alpha_floor) + 1e-3
    return inside | (best <= limit) | (a <= 0) | (c <= 0)


def bin_tiles(proj: Projected, width: int, height: int, tight: bool) -> tuple[torch.Tensor, torch.Tensor]:
    """``(offsets (tiles+1,), gauss (pairs,))``: each tile's Gaussians, front to back."""
    device = proj.means2d.device
    tiles_x = (width + TILE_SIZE - 1) // TILE_SIZE
    tiles_y = (height + TILE_SIZE - 1) // TILE_SIZE
    visible = torch.nonzero(proj.visible).squeeze(1)
    visible = visible[torch.argsort(proj.depths[visible], stable=True)]
    rects = proj.rects[visible].long()
    widths = rects[:, 1] - rects[:, 0]
    counts = widths * (rects[:, 3] - rects[:, 2])
    g = torch.repeat_interleave(visible, counts)
    first = torch.repeat_interleave(torch.cumsum(counts, 0) - counts, counts)
    local = torch.arange(g.shape[0], device=device) - first
    w_rep = torch.repeat_interleave(widths, counts)
    tx = torch.repeat_interleave(rects[:, 0], counts) + local % torch.clamp(w_rep, min=1)
    ty = torch.repeat_interleave(rects[:, 2], counts) + local // torch.clamp(w_rep, min=1)
    if tight and g.numel():
        # as the compiled binning: only rectangles of at least 2×2 tiles are tested
        heights = rects[:, 3] - rects[:, 2]
        tested = torch.repeat_interleave((widths >= 2) & (heights >= 2), counts)
        reaches = tile_reaches(proj.means2d[g], proj.conics[g], proj.opacities[g], proj.alpha_floor[g], tx.to(proj.means2d.dtype), ty.to(proj.means2d.dtype), width, height)
        keep = ~tested | reaches
        g, tx, ty = g[keep], tx[keep], ty[keep]
    tile = ty * tiles_x + tx
    tile_sorted, perm = torch.sort(tile, stable=True)
    offsets = torch.zeros(tiles_x * tiles_y + 1, dtype=torch.long, device=device)
    offsets[1:] = torch.cumsum(torch.bincount(tile_sorted, minlength=tiles_x * tiles_y), 0)
    return offsets, g[perm]


def chunk_of_lists(gauss: torch.Tensor, start: torch.Tensor, count: torch.Tensor, pos: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Positions ``pos`` (C,) of each tile's Gaussian list (``start``/``count`` per tile, B): ``(in_list
    (B, C) bool, ids (B, C))``, ids 0 past a list's end (masked by ``in_list``)."""
    in_list = pos[None, :] < count[:, None]
    g = gauss[torch.clamp(start[:, None] + pos[None, :], max=max(gauss.numel() - 1, 0))]
    return in_list, torch.where(in_list, g, torch.zeros_like(g))


def advance_transmittance(
    trans: torch.Tensor, alive: torch.Tensor, t_after: torch.Tensor, take: torch.Tensor,
) -> tuple[torch.Tensor, torch.Tensor, bool]:
    """After a chunk: each pixel's transmittance after its last composited Gaussian, whether it is
    still open (every Gaussian of the chunk taken), and whether any pixel is (else stop)."""
    n_take = take.sum(-1)
    t_last = torch.gather(t_after, 2, torch.clamp(n_take - 1, min=0)[..., None])[..., 0]
    trans = torch.where(n_take > 0, t_last, trans)
    alive = alive & take.all(-1)
    return trans, alive, bool(alive.any())


def median_update(
    hit: torch.Tensor, g: torch.Tensor, steps: torch.Tensor, depths: torch.Tensor, instance_ids: torch.Tensor,
    median: torch.Tensor, ids: torch.Tensor,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Median depth and instance id per pixel after a chunk: the chunk's last Gaussian ``hit``
    (B, P, C: composited while the transmittance before it was > ½) replaces the running values."""
    last = (hit * (steps + 1)).amax(-1)  # 1-based index of the last hit, 0 = none
    has = last > 0
    pick = torch.gather(g[:, None, :].expand(-1, hit.shape[1], -1), 2, torch.clamp(last - 1, min=0)[..., None])[..., 0]
    return torch.where(has, depths[pick], median), torch.where(has, instance_ids[pick], ids)


def tiles_to_image(t: torch.Tensor, tiles_y: int, tiles_x: int, height: int, width: int) -> torch.Tensor:
    """Per-tile planes ``t`` (tiles_y·tiles_x, TILE_SIZE², …) laid out as an image (height, width, …)."""
    tail = t.shape[2:]
    img = t.reshape(tiles_y, tiles_x, TILE_SIZE, TILE_SIZE, *tail).transpose(1, 2)
    return img.reshape(tiles_y * TILE_SIZE, tiles_x * TILE_SIZE, *tail)[:height, :width]


def expected_depth(weighted: torch.Tensor, alpha: torch.Tensor) -> torch.Tensor:
    """``Σ w·z / α``: the expected depth from the weighted depth sum, 0 where nothing was composited."""
    return torch.where(alpha > 0, weighted / torch.clamp(alpha, min=1e-30), torch.zeros_like(weighted))


def images_from_tiles(
    tiles_y: int, tiles_x: int, height: int, width: int, trans: torch.Tensor, colour: dict[str, torch.Tensor],
    depth: torch.Tensor | None, labels: tuple[torch.Tensor, torch.Tensor] | None,
) -> dict[str, torch.Tensor]:
    """A tile compositor's per-tile planes (tiles, TILE_SIZE², …) as (H, W[, …]) images: ``alpha``
    (1 − the final transmittance ``trans``), each of ``colour`` under its name, ``depth`` (the
    weighted depth sum over alpha, 0 where nothing was composited) and, from ``labels`` = (median
    depth, instance ids), ``median_depth`` and ``instance_ids`` (−1 where the transmittance ends above ½)."""

    def to_image(t: torch.Tensor) -> torch.Tensor:
        return tiles_to_image(t, tiles_y, tiles_x, height, width)

    alpha_img = 1.0 - to_image(trans)
    out = {"alpha": alpha_img}
    for name, planes in colour.items():
        out[name] = to_image(planes)
    if depth is not None:
        out["depth"] = expected_depth(to_image(depth), alpha_img)
    if labels is not None:
        median, ids = labels
        out["median_depth"] = to_image(median)
        out["instance_ids"] = torch.where(to_image(trans) <= 0.5, to_image(ids), torch.full_like(to_image(ids), -1))
    return out


def composite(
    proj: Projected,
    offsets: torch.Tensor,
    gauss: torch.Tensor,
    instance_ids: torch.Tensor,
    width: int,
    height: int,
    alpha_max: float,
    want_color: bool = True,
    want_depth: bool = False,
    want_ids: bool = False,
    chunk: int = 32,
    max_elements: int = 1 << 22,
) -> dict[str, torch.Tensor]:
    """Composite all tiles; returns (H, W[, 3]) tensors ``alpha`` and the requested outputs."""
    device, dtype = proj.means2d.device, proj.means2d.dtype
    tiles_x = (width + TILE_SIZE - 1) // TILE_SIZE
    tiles_y = (height + TILE_SIZE - 1) // TILE_SIZE
    n_pix = TILE_SIZE * TILE_SIZE
    lengths = offsets[1:] - offsets[:-1]
    grid = torch.arange(TILE_SIZE, device=device, dtype=dtype) + 0.5
    local_x = grid.repeat(TILE_SIZE)  # (256,) column within the tile + ½
    local_y = grid.repeat_interleave(TILE_SIZE)
    trans_all = torch.ones(tiles_y * tiles_x, n_pix, dtype=dtype, device=device)
    rgb_all = torch.zeros(tiles_y * tiles_x, n_pix, 3, dtype=dtype, device=device)
    depth_all = torch.zeros(tiles_y * tiles_x, n_pix, dtype=dtype, device=device)
    median_all = torch.zeros(tiles_y * tiles_x, n_pix, dtype=dtype, device=device)
    ids_all = torch.full((tiles_y * tiles_x, n_pix), -1, dtype=torch.int32, device=device)
    colors = proj.colors if want_color else None
    active = torch.nonzero(lengths > 0).squeeze(1)
    batch = max(1, max_elements // (n_pix * chunk))
    steps = torch.arange(chunk, device=device)
    for b0 in range(0, active.numel(), batch):
        tiles = active[b0 : b0 + batch]
        origin_x = (tiles % tiles_x).to(dtype) * TILE_SIZE
        origin_y = (tiles // tiles_x).to(dtype) * TILE_SIZE
        px = origin_x[:, None] + local_x  # (B, 256)
        py = origin_y[:, None] + local_y
        trans = torch.ones_like(px)
        alive = torch.ones_like(px, dtype=torch.bool)
        rgb = torch.zeros(*px.shape, 3, dtype=dtype, device=device)
        depth = torch.zeros_like(px)
        median = torch.zeros_like(px)
        ids = torch.full(px.shape, -1, dtype=torch.int32, device=device)
        start, count = offsets[tiles], lengths[tiles]
        for c0 in range(0, int(count.max()), chunk):
            pos = c0 + steps  # (C,)
            in_list, g = chunk_of_lists(gauss, start, count, pos)  # (B, C)
            dx = px[:, :, None] - proj.means2d[g, 0][:, None, :]  # (B, 256, C)
            dy = py[:, :, None] - proj.means2d[g, 1][:, None, :]
            a, bb, c = (proj.conics[g, k][:, None, :] for k in range(3))
            sigma = 0.5 * (a * dx * dx + c * dy * dy) + bb * dx * dy
            alpha = torch.clamp(proj.opacities[g][:, None, :] * torch.exp(-sigma), max=alpha_max)
            ok = (sigma >= 0) & (alpha >= proj.alpha_floor[g][:, None, :]) & in_list[:, None, :] & alive[:, :, None]
            alpha = torch.where(ok, alpha, torch.zeros_like(alpha))
            kept = torch.cumprod(1.0 - alpha, dim=-1)
            t_after = trans[:, :, None] * kept
            t_before = trans[:, :, None] * torch.cat([torch.ones_like(kept[..., :1]), kept[..., :-1]], dim=-1)
            take = t_after > TRANSMITTANCE_MIN  # a prefix along the chunk (t_after never rises)
            weight = alpha * t_before * take
            if want_color:
                rgb = rgb + torch.einsum("bpc,bck->bpk", weight, colors[g])
            if want_depth:
                depth = depth + (weight * proj.depths[g][:, None, :]).sum(-1)
            if want_ids:
                median, ids = median_update(((weight > 0) & (t_before > 0.5)), g, steps, proj.depths, instance_ids, median, ids)
            trans, alive, open_ = advance_transmittance(trans, alive, t_after, take)
            if not open_:
                break
        trans_all[tiles], rgb_all[tiles], depth_all[tiles] = trans, rgb, depth
        median_all[tiles], ids_all[tiles] = median, ids
    return images_from_tiles(
        tiles_y, tiles_x, height, width, trans_all, {"rgb": rgb_all} if want_color else {},
        depth_all if want_depth else None, (median_all, ids_all) if want_ids else None,
    )
