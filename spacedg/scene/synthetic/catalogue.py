"""The furniture catalogue of the synthetic rooms.

Each entry builds an :class:`ObjectModel` in its own frame: x = width, y = depth, z = up,
origin at the centre of the footprint on the floor, the front facing −y. A model is a list of
:class:`Part` shapes (boxes, frusta, ellipsoids) with a material *slot* each, plus the
flat tops other objects may stand on. Geometry is only described here; surfaces are sampled
into Gaussians later, once the room's Gaussian budget fixes the sampling spacing.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from spacedg.render.gaussians import Gaussians
from spacedg.scene.synthetic import primitives as prim
from spacedg.scene.synthetic.primitives import Surfels


@dataclass(frozen=True)
class Part:
    """One shape of an object, in the object's frame.

    ``shape``: ``"box"`` (params: size (3,)), ``"frustum"`` (r_bottom, r_top, height; its base
    at ``offset``), or ``"ellipsoid"`` (radii (3,), bumpiness, z_min). ``slot`` names the
    appearance slot ("main", "accent", "leaf", ...).
    """

    shape: str
    params: tuple
    offset: tuple[float, float, float]
    slot: str = "main"
    faces: tuple[str, ...] = ("-x", "+x", "-y", "+y", "-z", "+z")
    caps: tuple[bool, bool] = (True, True)
    yaw: float = 0.0

    def area(self) -> float:
        """Surface area in m² (for the Gaussian budget)."""
        if self.shape == "box":
            sx, sy, sz = self.params[0]
            per_face = {"-x": sy * sz, "+x": sy * sz, "-y": sx * sz, "+y": sx * sz, "-z": sx * sy, "+z": sx * sy}
            return float(sum(per_face[f] for f in self.faces))
        if self.shape == "frustum":
            rb, rt, hgt = self.params
            side = math.pi * (rb + rt) * math.hypot(hgt, rb - rt)
            return side + (math.pi * rb * rb if self.caps[0] else 0) + (math.pi * rt * rt if self.caps[1] else 0)
        a, b, c = self.params[0]
        return 4 * math.pi * ((a**1.6 * b**1.6 + a**1.6 * c**1.6 + b**1.6 * c**1.6) / 3) ** (1 / 1.6) * (1 + self.params[1])

    def sample(self, spacing: float, rng: np.random.Generator) -> Surfels:
        """Surfels of this part at ``spacing`` metres, in the object's frame."""
        if self.shape == "box":
            s = prim.box(np.asarray(self.params[0]), spacing, rng, self.faces)
        elif self.shape == "frustum":
            s = prim.frustum(*self.params, spacing, rng, self.caps)
        else:
            s = prim.ellipsoid(np.asarray(self.params[0]), spacing, rng, self.params[1], self.params[2])
        c, sn = math.cos(self.yaw), math.sin(self.yaw)
        rot = np.array([[c, -sn, 0.0], [sn, c, 0.0], [0.0, 0.0, 1.0]])
        return s.transformed(rot, np.asarray(self.offset, dtype=np.float64))


@dataclass(frozen=True)
class Support:
    """A flat top other objects can stand on: rectangle [x0, x1] × [y0, y1] at height z (object frame)."""

    x0: float
    x1: float
    y0: float
    y1: float
    z: float


@dataclass
class ObjectModel:
    """An object before placement: label, parts, supports, and appearance slots to fill.

    ``slots`` maps slot name → materials allowed for it; the ``"main"`` slot's appearance
    becomes the description unless ``describe_slot`` names another (a plant is described by
    its pot).
    """

    label: str
    parts: list[Part]
    slots: dict[str, tuple[str, ...]]
    supports: list[Support] = field(default_factory=list)
    fixed: dict[str, tuple[str, str]] = field(default_factory=dict)  # slot -> (colour, material)
    describe_slot: str = "main"
    description_template: str = "{colour} {material} {label}"
    #: Ready-made Gaussians in the object frame (objects imported from files), else None.
    prebuilt: Gaussians | None = None
    attributes: dict[str, object] = field(default_factory=dict)

    def scaled(self, factor: float) -> ObjectModel:
        """This model scaled uniformly by ``factor`` about its footprint centre on the floor
        (parts, offsets and supports; a prebuilt model is returned unchanged)."""
        if self.prebuilt is not None or factor == 1.0:
            return self
        f = float(factor)
        parts = []
        for p in self.parts:
            if p.shape == "box":
                params = (tuple(float(v) * f for v in p.params[0]),)
            elif p.shape == "frustum":
                params = tuple(float(v) * f for v in p.params)
            else:
                radii, bump, z_min = p.params
                params = (tuple(float(v) * f for v in radii), bump, None if z_min is None else float(z_min) * f)
            parts.append(Part(p.shape, params, tuple(float(v) * f for v in p.offset), p.slot, p.faces, p.caps, p.yaw))
        supports = [Support(s.x0 * f, s.x1 * f, s.y0 * f, s.y1 * f, s.z * f) for s in self.supports]
        return ObjectModel(self.label, parts, self.slots, supports, dict(self.fixed), self.describe_slot,
                           self.description_template, None, dict(self.attributes))

    def area(self) -> float:
        """Total surface area of the parts, m² (0 for prebuilt objects)."""
        return float(sum(p.area() for p in self.parts))

    def local_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Conservative (min, max) corners of the object in its frame, metres."""
        if self.prebuilt is not None:
            lo, hi = self.prebuilt.bounds()
            return lo, hi
        lows, highs = [], []
        for p in self.parts:
            off = np.asarray(p.offset, dtype=np.float64)
            if p.shape == "box":
                c, s = math.cos(p.yaw), math.sin(p.yaw)
                sx, sy, sz = p.params[0]
                half = np.array([abs(c) * sx + abs(s) * sy, abs(s) * sx + abs(c) * sy, sz]) / 2
                lo, hi = off - half, off + half
            elif p.shape == "frustum":
                r = max(p.params[0], p.params[1])
                lo, hi = off - [r, r, 0.0], off + [r, r, p.params[2]]
            else:
                radii = np.asarray(p.params[0]) * (1 + p.params[1])
                lo, hi = off - radii, off + radii
                if p.params[2] is not None:
                    lo[2] = max(lo[2], off[2] + p.params[2])
            lows.append(lo)
            highs.append(hi)
        return np.min(lows, axis=0), np.max(highs, axis=0)


# ----------------------------------------------------------------- helpers
def _box(cx: float, cy: float, z0: float, sx: float, sy: float, sz: float, slot: str = "main", faces=None) -> Part:
    """Box whose bottom face is at height z0 and centre at (cx, cy)."""
    return Part("box", ((sx, sy, sz),), (cx, cy, z0 + sz / 2), slot, faces or ("-x", "+x", "-y", "+y", "-z", "+z"))


def _legs(width: float, depth: float, height: float, thick: float, inset: float, slot: str) -> list[Part]:
    dx, dy = width / 2 - inset - thick / 2, depth / 2 - inset - thick / 2
    side_faces = ("-x", "+x", "-y", "+y")
    return [_box(sx * dx, sy * dy, 0.0, thick, thick, height, slot, side_faces) for sx in (-1, 1) for sy in (-1, 1)]


def _u(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(rng.uniform(lo, hi))


# ----------------------------------------------------------------- builders
def table(rng: np.random.Generator) -> ObjectModel:
    w, d, h, t = _u(rng, 1.0, 1.8), _u(rng, 0.7, 1.0), _u(rng, 0.72, 0.78), 0.04
    parts = [_box(0, 0, h - t, w, d, t)] + _legs(w, d, h - t, 0.06, 0.05, "legs")
    return ObjectModel("table", parts, {"main": ("wood", "marble"), "legs": ("wood", "metal")},
                       [Support(-w / 2, w / 2, -d / 2, d / 2, h)])


def coffee_table(rng: np.random.Generator) -> ObjectModel:
    w, d, h, t = _u(rng, 0.8, 1.2), _u(rng, 0.45, 0.65), _u(rng, 0.38, 0.46), 0.035
    parts = [_box(0, 0, h - t, w, d, t), _box(0, 0, 0.08, w - 0.1, d - 0.1, 0.02, "legs")]
    parts += _legs(w, d, h - t, 0.045, 0.03, "legs")
    return ObjectModel("coffee table", parts, {"main": ("wood", "marble"), "legs": ("wood", "metal")},
                       [Support(-w / 2, w / 2, -d / 2, d / 2, h)])


def desk(rng: np.random.Generator) -> ObjectModel:
    w, d, h, t = _u(rng, 1.0, 1.5), _u(rng, 0.55, 0.75), _u(rng, 0.72, 0.76), 0.03
    drawer_w = 0.4
    parts = [
        _box(0, 0, h - t, w, d, t),
        _box(w / 2 - drawer_w / 2 - 0.02, 0, 0.0, drawer_w, d - 0.06, h - t, "main", ("-x", "+x", "-y", "+y")),
        _box(-w / 2 + 0.03, 0, 0.0, 0.04, d - 0.06, h - t, "main", ("-x", "+x", "-y", "+y")),
        _box(w / 2 - drawer_w / 2 - 0.02, -(d - 0.06) / 2 - 0.012, h * 0.55, 0.12, 0.02, 0.02, "handles"),
    ]
    return ObjectModel("desk", parts, {"main": ("wood",), "handles": ("metal",)},
                       [Support(-w / 2, w / 2, -d / 2, d / 2, h)])


def chair(rng: np.random.Generator) -> ObjectModel:
    w, d, seat, back = _u(rng, 0.42, 0.5), _u(rng, 0.42, 0.5), _u(rng, 0.43, 0.48), _u(rng, 0.82, 0.98)
    t = 0.04
    parts = [_box(0, 0, seat - t, w, d, t)] + _legs(w, d, seat - t, 0.035, 0.01, "legs")
    parts.append(_box(0, d / 2 - 0.02, seat, w, 0.03, back - seat))
    return ObjectModel("chair", parts, {"main": ("wood", "plastic", "fabric", "leather"), "legs": ("wood", "metal")})


def stool(rng: np.random.Generator) -> ObjectModel:
    r, h = _u(rng, 0.16, 0.2), _u(rng, 0.45, 0.72)
    parts = [Part("frustum", (r, r, 0.035), (0, 0, h - 0.035))]
    for k in range(4):
        a = k * math.pi / 2 + math.pi / 4
        parts.append(Part("frustum", (0.018, 0.015, h - 0.035), (0.7 * r * math.cos(a), 0.7 * r * math.sin(a), 0.0), "legs",
                          caps=(False, False)))
    return ObjectModel("stool", parts, {"main": ("wood", "metal", "plastic"), "legs": ("wood", "metal")})


def sofa(rng: np.random.Generator, label: str = "sofa", width: tuple[float, float] = (1.6, 2.3)) -> ObjectModel:
    w, d, h = _u(rng, *width), _u(rng, 0.82, 0.95), _u(rng, 0.75, 0.88)
    seat, arm = 0.42, 0.18
    parts = [
        _box(0, 0, 0.0, w, d, seat, faces=("-x", "+x", "-y", "+y", "+z")),
        _box(0, d / 2 - 0.1, seat, w - 2 * arm, 0.2, h - seat),
        _box(-w / 2 + arm / 2, 0, seat, arm, d, 0.2),
        _box(w / 2 - arm / 2, 0, seat, arm, d, 0.2),
    ]
    n_cush = 2 if w < 1.2 else 3
    cw = (w - 2 * arm) / n_cush
    for i in range(n_cush):
        cx = -w / 2 + arm + cw * (i + 0.5)
        parts.append(Part("ellipsoid", ((cw / 2 - 0.02, 0.12, 0.1), 0.0, None), (cx, -0.05, seat + 0.04), "cushions"))
    if label == "armchair":
        parts.pop()
    return ObjectModel(label, parts, {"main": ("fabric", "leather"), "cushions": ("fabric",)})


def armchair(rng: np.random.Generator) -> ObjectModel:
    return sofa(rng, "armchair", (0.78, 0.95))


def bed(rng: np.random.Generator) -> ObjectModel:
    w, l = _u(rng, 1.4, 1.8), _u(rng, 1.95, 2.1)
    frame, mattress = 0.28, 0.22
    parts = [
        _box(0, 0, 0.0, w, l, frame, "frame", ("-x", "+x", "-y", "+y")),
        _box(0, 0, frame, w - 0.04, l - 0.04, mattress, "main", ("-x", "+x", "-y", "+y", "+z")),
        _box(0, l / 2 - 0.03, 0.0, w, 0.06, _u(rng, 0.95, 1.15), "frame"),
        Part("ellipsoid", ((w / 4 - 0.05, 0.2, 0.07), 0.0, None), (-w / 4, l / 2 - 0.3, frame + mattress + 0.03), "pillows"),
        Part("ellipsoid", ((w / 4 - 0.05, 0.2, 0.07), 0.0, None), (w / 4, l / 2 - 0.3, frame + mattress + 0.03), "pillows"),
    ]
    return ObjectModel("bed", parts, {"main": ("fabric",), "frame": ("wood",), "pillows": ("fabric",)},
                       fixed={"pillows": ("white", "fabric")})


def wardrobe(rng: np.random.Generator) -> ObjectModel:
    w, d, h = _u(rng, 0.9, 1.6), _u(rng, 0.55, 0.62), _u(rng, 1.8, 2.2)
    parts = [_box(0, 0, 0.0, w, d, h, faces=("-x", "+x", "-y", "+y", "+z"))]
    parts += [_box(sx * 0.06, -d / 2 - 0.015, h * 0.5, 0.03, 0.03, 0.25, "handles") for sx in (-1, 1)]
    parts.append(_box(0, -d / 2 - 0.003, 0.02, 0.008, 0.006, h - 0.04, "handles", ("-y",)))
    return ObjectModel("wardrobe", parts, {"main": ("wood",), "handles": ("metal",)})


def bookshelf(rng: np.random.Generator) -> ObjectModel:
    w, d, h, t = _u(rng, 0.6, 1.2), _u(rng, 0.28, 0.35), _u(rng, 1.1, 2.0), 0.025
    parts = [
        _box(-w / 2 + t / 2, 0, 0.0, t, d, h),
        _box(w / 2 - t / 2, 0, 0.0, t, d, h),
        _box(0, d / 2 - 0.005, 0.0, w - 2 * t, 0.01, h, faces=("-y",)),
    ]
    shelves = max(3, int(h / 0.35))
    gap = h / shelves
    for i in range(shelves + 1):
        z = min(i * gap, h - t)
        parts.append(_box(0, 0, z, w - 2 * t, d, t))
        if i < shelves:  # a row of books on every shelf
            x = -w / 2 + t + 0.01
            k = 0
            while True:
                bw = _u(rng, 0.02, 0.05)
                if x + bw > w / 2 - t - 0.01 - (0.15 if i % 2 else 0):
                    break
                bh = min(_u(rng, 0.17, 0.3), gap - t - 0.02)
                parts.append(_box(x + bw / 2, -0.005, z + t, bw, d - 0.05, bh, f"book{k % 4}", ("-x", "+x", "-y", "+z")))
                x += bw + 0.002
                k += 1
    model = ObjectModel("bookshelf", parts, {"main": ("wood",), **{f"book{k}": ("hardcover",) for k in range(4)}})
    if h < 1.3:
        model.supports.append(Support(-w / 2, w / 2, -d / 2, d / 2, h))
    return model


def cabinet(rng: np.random.Generator) -> ObjectModel:
    w, d, h = _u(rng, 0.8, 1.6), _u(rng, 0.4, 0.5), _u(rng, 0.6, 0.9)
    parts = [_box(0, 0, 0.0, w, d, h, faces=("-x", "+x", "-y", "+y", "+z"))]
    n = max(2, int(w / 0.45))
    for i in range(n):
        cx = -w / 2 + w * (i + 0.5) / n
        parts.append(_box(cx, -d / 2 - 0.012, h * 0.75, 0.1, 0.02, 0.02, "handles"))
    return ObjectModel("cabinet", parts, {"main": ("wood",), "handles": ("metal",)}, [Support(-w / 2, w / 2, -d / 2, d / 2, h)])


def _screen(label: str, width: float, stand: tuple[float, float, float], bezel: float, depth: float) -> ObjectModel:
    """A 16:9 screen on a foot: ``stand`` = (foot width, foot depth, neck height)."""
    sh = width * 9 / 16
    foot_w, foot_d, neck = stand
    parts = [
        _box(0, 0.03 if label == "monitor" else 0.0, 0.0, foot_w, foot_d, 0.015, "frame"),
        _box(0, depth + 0.02, 0.015, 0.05, 0.03, neck, "frame"),
        _box(0, 0, 0.1, width, depth, sh, "frame", ("-x", "+x", "+y", "+z", "-z")),
        _box(0, -depth / 2 - 0.001, 0.1 + bezel, width - 2 * bezel, 0.002, sh - 2 * bezel, "screen", ("-y",)),
    ]
    return ObjectModel(label, parts, {"frame": ("plastic",), "screen": ("plastic",)}, describe_slot="frame",
                       fixed={"screen": ("black", "screen")})


def tv(rng: np.random.Generator) -> ObjectModel:
    return _screen("tv", _u(rng, 0.8, 1.3), (0.3, 0.2, 0.12), 0.02, 0.05)


def monitor(rng: np.random.Generator) -> ObjectModel:
    return _screen("monitor", _u(rng, 0.5, 0.7), (0.22, 0.16, 0.12), 0.015, 0.04)


def floor_lamp(rng: np.random.Generator) -> ObjectModel:
    h = _u(rng, 1.4, 1.8)
    rs = _u(rng, 0.18, 0.25)
    parts = [
        Part("frustum", (0.16, 0.14, 0.03), (0, 0, 0), "base"),
        Part("frustum", (0.015, 0.015, h - 0.33), (0, 0, 0.03), "base", caps=(False, False)),
        Part("frustum", (rs, rs * 0.7, 0.3), (0, 0, h - 0.3), "main", caps=(False, False)),
    ]
    return ObjectModel("floor lamp", parts, {"main": ("fabric",), "base": ("metal",)},
                       description_template="{label} with a {colour} {material} shade")


def table_lamp(rng: np.random.Generator) -> ObjectModel:
    h = _u(rng, 0.35, 0.55)
    rs = _u(rng, 0.1, 0.16)
    parts = [
        Part("frustum", (0.08, 0.05, h * 0.45), (0, 0, 0), "base"),
        Part("frustum", (0.01, 0.01, h * 0.2), (0, 0, h * 0.45), "base", caps=(False, False)),
        Part("frustum", (rs, rs * 0.65, h * 0.35), (0, 0, h * 0.65), "main", caps=(False, False)),
    ]
    return ObjectModel("lamp", parts, {"main": ("fabric",), "base": ("ceramic", "metal")},
                       description_template="{label} with a {colour} {material} shade")


def plant(rng: np.random.Generator, small: bool = False) -> ObjectModel:
    pot_h = _u(rng, 0.12, 0.18) if small else _u(rng, 0.25, 0.45)
    pot_r = pot_h * _u(rng, 0.5, 0.7)
    fol = pot_h * _u(rng, 1.2, 2.2) if small else _u(rng, 0.35, 0.9)
    parts = [
        Part("frustum", (pot_r * 0.8, pot_r, pot_h), (0, 0, 0), "main", caps=(False, True)),
        Part("ellipsoid", ((pot_r * 1.6, pot_r * 1.6, fol / 2), 0.25, -fol / 2 * 0.8), (0, 0, pot_h + fol / 2 * 0.8), "leaf"),
    ]
    return ObjectModel("plant", parts, {"main": ("ceramic", "plastic"), "leaf": ("fabric",)},
                       fixed={"leaf": ("green", "foliage")}, description_template="{label} in a {colour} {material} pot")


def small_plant(rng: np.random.Generator) -> ObjectModel:
    return plant(rng, small=True)


def storage_box(rng: np.random.Generator) -> ObjectModel:
    w, d, h = _u(rng, 0.25, 0.6), _u(rng, 0.2, 0.45), _u(rng, 0.15, 0.4)
    return ObjectModel("box", [_box(0, 0, 0.0, w, d, h, faces=("-x", "+x", "-y", "+y", "+z"))], {"main": ("cardboard", "plastic")})


def vase(rng: np.random.Generator) -> ObjectModel:
    h, r = _u(rng, 0.2, 0.4), _u(rng, 0.05, 0.09)
    parts = [
        Part("frustum", (r * 0.7, r, h * 0.6), (0, 0, 0), caps=(True, False)),
        Part("frustum", (r, r * 0.45, h * 0.4), (0, 0, h * 0.6), caps=(False, True)),
    ]
    return ObjectModel("vase", parts, {"main": ("ceramic",)})


def cup(rng: np.random.Generator) -> ObjectModel:
    h, r = _u(rng, 0.09, 0.12), _u(rng, 0.038, 0.05)
    parts = [
        Part("frustum", (r * 0.85, r, h), (0, 0, 0)),
        _box(r + 0.012, 0, h * 0.3, 0.024, 0.012, h * 0.45),
    ]
    return ObjectModel("cup", parts, {"main": ("ceramic", "plastic", "metal")})


def bowl(rng: np.random.Generator) -> ObjectModel:
    r = _u(rng, 0.08, 0.14)
    parts = [Part("ellipsoid", ((r, r, r * 0.6), 0.0, 0.0), (0, 0, 0))]
    return ObjectModel("bowl", parts, {"main": ("ceramic", "wood", "plastic")})


def book(rng: np.random.Generator) -> ObjectModel:
    w, d, t = _u(rng, 0.15, 0.24), _u(rng, 0.21, 0.3), _u(rng, 0.02, 0.05)
    parts = [_box(0, 0, 0.0, w, d, t, faces=("-x", "+x", "-y", "+y", "+z"))]
    return ObjectModel("book", parts, {"main": ("hardcover",)})


def trash_can(rng: np.random.Generator) -> ObjectModel:
    h, r = _u(rng, 0.3, 0.5), _u(rng, 0.12, 0.17)
    return ObjectModel("trash can", [Part("frustum", (r * 0.85, r, h), (0, 0, 0), caps=(False, False))], {"main": ("metal", "plastic")})


def ball(rng: np.random.Generator) -> ObjectModel:
    r = _u(rng, 0.1, 0.13)
    return ObjectModel("ball", [Part("ellipsoid", ((r, r, r), 0.0, None), (0, 0, r))], {"main": ("plastic",)})


def suitcase(rng: np.random.Generator) -> ObjectModel:
    w, d, h = _u(rng, 0.4, 0.5), _u(rng, 0.22, 0.28), _u(rng, 0.55, 0.75)
    parts = [
        _box(0, 0, 0.0, w, d, h, faces=("-x", "+x", "-y", "+y", "+z")),
        _box(0, 0, h, 0.16, 0.03, 0.03, "handles"),
    ]
    return ObjectModel("suitcase", parts, {"main": ("plastic", "fabric"), "handles": ("metal",)},
                       fixed={"handles": ("black", "plastic")})


@dataclass(frozen=True)
class CatalogueEntry:
    """How an object kind is placed: ``"wall"`` (back against a wall), ``"center"`` (free
    standing, away from walls), ``"floor"`` (anywhere on the floor) or ``"support"`` (on a
    table, desk, cabinet or low shelf). ``weight`` is its relative frequency."""

    build: Callable[[np.random.Generator], ObjectModel]
    placement: str
    weight: float
    max_count: int


CATALOGUE: dict[str, CatalogueEntry] = {
    "table": CatalogueEntry(table, "center", 1.0, 1),
    "coffee table": CatalogueEntry(coffee_table, "center", 0.7, 1),
    "bed": CatalogueEntry(bed, "wall", 0.5, 1),
    "sofa": CatalogueEntry(sofa, "wall", 0.8, 1),
    "armchair": CatalogueEntry(armchair, "floor", 0.7, 2),
    "desk": CatalogueEntry(desk, "wall", 0.8, 1),
    "wardrobe": CatalogueEntry(wardrobe, "wall", 0.6, 1),
    "bookshelf": CatalogueEntry(bookshelf, "wall", 0.9, 2),
    "cabinet": CatalogueEntry(cabinet, "wall", 0.9, 2),
    "chair": CatalogueEntry(chair, "floor", 1.0, 6),
    "stool": CatalogueEntry(stool, "floor", 0.5, 2),
    "floor lamp": CatalogueEntry(floor_lamp, "floor", 0.6, 2),
    "plant": CatalogueEntry(plant, "floor", 0.9, 3),
    "box": CatalogueEntry(storage_box, "floor", 0.8, 4),
    "trash can": CatalogueEntry(trash_can, "floor", 0.5, 1),
    "ball": CatalogueEntry(ball, "floor", 0.3, 2),
    "suitcase": CatalogueEntry(suitcase, "floor", 0.3, 1),
    "tv": CatalogueEntry(tv, "support", 0.5, 1),
    "monitor": CatalogueEntry(monitor, "support", 0.5, 2),
    "lamp": CatalogueEntry(table_lamp, "support", 0.7, 2),
    "small plant": CatalogueEntry(small_plant, "support", 0.6, 3),
    "vase": CatalogueEntry(vase, "support", 0.7, 3),
    "cup": CatalogueEntry(cup, "support", 1.0, 5),
    "bowl": CatalogueEntry(bowl, "support", 0.6, 3),
    "book": CatalogueEntry(book, "support", 0.9, 5),
}

#: Every label the catalogue can produce (the rooms' category vocabulary).
VOCABULARY: tuple[str, ...] = tuple(sorted({e.build(np.random.default_rng(0)).label for e in CATALOGUE.values()}))
