"""Procedural surface textures for the synthetic rooms.

Every texture is a function of surface coordinates ``uv`` in **metres** (so a pattern has
the same physical size on every object) and of the sampling spacing, returning RGB in
[0, 1]-ish (display-referred, as a 3DGS capture stores colour). Patterns are
chosen so that blur, noise and compression visibly change them: wood grain, fabric weave,
floor planks, tiles, brushed metal, speckle, cardboard fibres, marble veins.

Noise is seeded value noise (a hashed lattice with smoothstep interpolation), vectorised
with numpy; it is deterministic for a given seed.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

#: ``texture(base_rgb (3,), uv (N, 2) metres, spacing metres, rng) -> (N, 3) rgb``. ``spacing`` is
#: the surface sampling step: thin features (seams, grout) are drawn at least that wide so
#: they stay lines instead of aliasing into scattered dots.
TextureFn = Callable[[np.ndarray, np.ndarray, float, np.random.Generator], np.ndarray]


def _hash2(ix: np.ndarray, iy: np.ndarray, seed: int) -> np.ndarray:
    """Deterministic pseudo-random value in [0, 1) per integer lattice point."""
    h = (ix.astype(np.int64) * 374761393 + iy.astype(np.int64) * 668265263 + seed * 1442695041) & 0xFFFFFFFF
    h = ((h ^ (h >> 13)) * 1274126177) & 0xFFFFFFFF
    h = h ^ (h >> 16)
    return (h & 0xFFFFFF).astype(np.float64) / float(0x1000000)


def value_noise(u: np.ndarray, v: np.ndarray, seed: int) -> np.ndarray:
    """Smooth value noise in [0, 1] with unit lattice spacing."""
    iu, iv = np.floor(u), np.floor(v)
    fu, fv = u - iu, v - iv
    su, sv = fu * fu * (3 - 2 * fu), fv * fv * (3 - 2 * fv)
    a = _hash2(iu, iv, seed)
    b = _hash2(iu + 1, iv, seed)
    c = _hash2(iu, iv + 1, seed)
    d = _hash2(iu + 1, iv + 1, seed)
    return (a + (b - a) * su) * (1 - sv) + (c + (d - c) * su) * sv


def fbm(u: np.ndarray, v: np.ndarray, seed: int, octaves: int = 4) -> np.ndarray:
    """Fractal sum of value noise, normalised to [0, 1]."""
    total, amp, norm, freq = np.zeros_like(u, dtype=np.float64), 1.0, 0.0, 1.0
    for o in range(octaves):
        total += amp * value_noise(u * freq, v * freq, seed + 101 * o)
        norm += amp
        amp *= 0.5
        freq *= 2.0
    return total / norm


def _mix(base: np.ndarray, other: np.ndarray, t: np.ndarray) -> np.ndarray:
    return base[None, :] * (1 - t[:, None]) + other[None, :] * t[:, None]


def _seed(rng: np.random.Generator) -> int:
    return int(rng.integers(0, 2**31 - 1))


def _mottled(
    color: np.ndarray, uv: np.ndarray, rng: np.random.Generator, scale: tuple[float, float], octaves: int, light: float, dark: float,
) -> np.ndarray:
    """``color · light`` blended towards ``color · dark`` by :func:`fbm` of ``uv`` scaled by ``scale``
    (lattice cells per metre along u and v) with ``octaves``; one seed drawn from ``rng``."""
    t = fbm(uv[:, 0] * scale[0], uv[:, 1] * scale[1], _seed(rng), octaves)
    return _mix(color * light, color * dark, t)


def wood(color: np.ndarray, uv: np.ndarray, spacing: float, rng: np.random.Generator) -> np.ndarray:
    """Wood grain: stretched rings along u with noisy distortion, dark late-wood lines."""
    seed = _seed(rng)
    u, v = uv[:, 0], uv[:, 1]
    warp = fbm(u * 1.5, v * 12.0, seed) * 3.0
    rings = 0.5 + 0.5 * np.sin((v * 40.0 + warp * 6.0) * np.pi)
    lines = np.clip((rings - 0.8) * 5.0, 0, 1)
    fine = fbm(u * 20.0, v * 200.0, seed + 7, 2)
    t = 0.35 * rings + 0.45 * lines + 0.2 * fine
    return _mix(color * 1.12, color * 0.62, t)


def fabric(color: np.ndarray, uv: np.ndarray, spacing: float, rng: np.random.Generator) -> np.ndarray:
    """Woven fabric: fine crossing threads (period ~6 mm) plus a mottled low frequency."""
    seed = _seed(rng)
    u, v = uv[:, 0], uv[:, 1]
    period = max(0.006, 2.5 * spacing)
    weave = 0.5 + 0.25 * np.sin(u * 2 * np.pi / period) + 0.25 * np.sin(v * 2 * np.pi / period)
    mottle = fbm(u * 6.0, v * 6.0, seed)
    t = 0.25 * weave + 0.45 * mottle
    return _mix(color * 1.1, color * 0.7, t)


def leather(color: np.ndarray, uv: np.ndarray, spacing: float, rng: np.random.Generator) -> np.ndarray:
    """Leather: cellular-looking grain and soft creases."""
    seed = _seed(rng)
    u, v = uv[:, 0], uv[:, 1]
    grain = fbm(u * 90.0, v * 90.0, seed, 2)
    crease = np.abs(fbm(u * 4.0, v * 4.0, seed + 3) - 0.5) * 2.0
    return _mix(color * 1.15, color * 0.65, 0.5 * grain + 0.5 * (1 - crease))


def metal(color: np.ndarray, uv: np.ndarray, spacing: float, rng: np.random.Generator) -> np.ndarray:
    """Brushed metal: fine streaks along u."""
    return _mottled(color, uv, rng, (3.0, 400.0), 3, 1.15, 0.8)


def plastic(color: np.ndarray, uv: np.ndarray, spacing: float, rng: np.random.Generator) -> np.ndarray:
    """Moulded plastic: nearly flat with a fine speckle."""
    return _mottled(color, uv, rng, (60.0, 60.0), 2, 1.06, 0.86)


def ceramic(color: np.ndarray, uv: np.ndarray, spacing: float, rng: np.random.Generator) -> np.ndarray:
    """Glazed ceramic: bands of glaze thickness plus speckle."""
    seed = _seed(rng)
    u, v = uv[:, 0], uv[:, 1]
    band = 0.5 + 0.5 * np.sin(v * 2 * np.pi / 0.03 + 3.0 * fbm(u * 10, v * 10, seed))
    speck = fbm(u * 80.0, v * 80.0, seed + 1, 2)
    return _mix(color * 1.08, color * 0.78, 0.4 * band + 0.35 * speck)


def cardboard(color: np.ndarray, uv: np.ndarray, spacing: float, rng: np.random.Generator) -> np.ndarray:
    """Corrugated cardboard: faint flutes every 8 mm and fibre noise."""
    seed = _seed(rng)
    u, v = uv[:, 0], uv[:, 1]
    flute = 0.5 + 0.5 * np.sin(u * 2 * np.pi / max(0.008, 2.5 * spacing))
    fibre = fbm(u * 50.0, v * 50.0, seed, 3)
    return _mix(color * 1.08, color * 0.72, 0.3 * flute + 0.5 * fibre)


def planks(color: np.ndarray, uv: np.ndarray, spacing: float, rng: np.random.Generator) -> np.ndarray:
    """Floor planks 0.15–0.2 m wide with staggered joints, each plank a tone of its own."""
    seed = _seed(rng)
    width = 0.18
    u, v = uv[:, 0], uv[:, 1]
    row = np.floor(v / width)
    offset = _hash2(row, np.zeros_like(row), seed) * 1.2
    col = np.floor((u + offset) / 1.2)
    tone = _hash2(row, col, seed + 5)
    base = _mix(color * 0.85, color * 1.15, tone)
    grain = wood(np.ones(3), np.stack([v * 0.2, u], axis=1), spacing, rng)[:, 0]
    half_line = max(0.004, 0.5 * spacing)
    seam = (np.minimum(np.mod(v, width), width - np.mod(v, width)) < half_line) | (
        np.minimum(np.mod(u + offset, 1.2), 1.2 - np.mod(u + offset, 1.2)) < half_line
    )
    out = base * grain[:, None]
    out[seam] *= 0.45
    return out


def tiles(color: np.ndarray, uv: np.ndarray, spacing: float, rng: np.random.Generator) -> np.ndarray:
    """Square tiles 0.3 m with grout lines and a slight tone per tile."""
    seed = _seed(rng)
    size = 0.3
    u, v = uv[:, 0], uv[:, 1]
    tone = _hash2(np.floor(u / size), np.floor(v / size), seed)
    out = _mix(color * 0.92, color * 1.06, tone)
    out *= (0.9 + 0.1 * fbm(u * 30, v * 30, seed + 1, 2))[:, None]
    half_line = max(0.005, 0.5 * spacing)
    grout = (np.minimum(np.mod(u, size), size - np.mod(u, size)) < half_line) | (
        np.minimum(np.mod(v, size), size - np.mod(v, size)) < half_line
    )
    out[grout] = color * 0.45
    return out


def paint(color: np.ndarray, uv: np.ndarray, spacing: float, rng: np.random.Generator) -> np.ndarray:
    """Painted wall: roller texture and a faint large-scale blotch."""
    seed = _seed(rng)
    u, v = uv[:, 0], uv[:, 1]
    t = 0.6 * fbm(u * 25.0, v * 25.0, seed, 3) + 0.4 * fbm(u * 1.5, v * 1.5, seed + 9, 2)
    return _mix(color * 1.05, color * 0.85, t)


def wallpaper(color: np.ndarray, uv: np.ndarray, spacing: float, rng: np.random.Generator) -> np.ndarray:
    """Striped wallpaper: vertical stripes 0.08 m with a darker thin pinstripe."""
    seed = _seed(rng)
    u, v = uv[:, 0], uv[:, 1]
    phase = np.mod(u, 0.16) / 0.16
    stripe = (phase < 0.5).astype(np.float64)
    pin = (np.abs(phase - 0.75) < max(0.03, 0.5 * spacing / 0.16)).astype(np.float64)
    t = 0.25 * stripe + 0.5 * pin + 0.15 * fbm(u * 20, v * 20, seed, 2)
    return _mix(color * 1.05, color * 0.7, t)


def marble(color: np.ndarray, uv: np.ndarray, spacing: float, rng: np.random.Generator) -> np.ndarray:
    """Marble: thin dark veins from a turbulence-warped sine."""
    seed = _seed(rng)
    u, v = uv[:, 0], uv[:, 1]
    turb = fbm(u * 3.0, v * 3.0, seed, 5)
    vein = np.abs(np.sin((u + v) * 6.0 + turb * 9.0))
    t = np.clip(1.0 - vein * 6.0, 0, 1)
    return _mix(color, color * 0.45, t * 0.8 + 0.1 * turb)


def foliage(color: np.ndarray, uv: np.ndarray, spacing: float, rng: np.random.Generator) -> np.ndarray:
    """Leaves: high-contrast blotches of light and dark green."""
    return _mottled(color, uv, rng, (40.0, 40.0), 3, 1.35, 0.5)


def screen(color: np.ndarray, uv: np.ndarray, spacing: float, rng: np.random.Generator) -> np.ndarray:
    """A dark screen with a faint reflection gradient."""
    u, v = uv[:, 0], uv[:, 1]
    t = np.clip(0.5 + 0.5 * np.sin(u * 2.0 + v * 3.0), 0, 1)
    return _mix(color, color * 1.8 + 0.03, 0.25 * t)


TEXTURES: dict[str, TextureFn] = {
    "wood": wood,
    "fabric": fabric,
    "leather": leather,
    "metal": metal,
    "plastic": plastic,
    "ceramic": ceramic,
    "cardboard": cardboard,
    "planks": planks,
    "tiles": tiles,
    "paint": paint,
    "wallpaper": wallpaper,
    "marble": marble,
    "foliage": foliage,
    "screen": screen,
}
