"""Room layout: where the camera walks and where the furniture stands.

Everything here works in the room's *canonical* frame: floor at z = 0, z up, the room
spanning x ∈ [−W/2, W/2], y ∈ [−D/2, D/2]. (The generated scene is moved to a seeded world
frame afterwards, so no downstream code can rely on these axes.)

The camera walks a closed loop (a rounded rectangle ``inset`` metres from the walls); a
corridor of ``CORRIDOR_HALF_WIDTH`` around it stays free of floor objects, so no view starts
inside furniture. Floor objects are placed by rejection sampling: inside the room, outside
the corridor, footprints apart by a margin. Small objects stand on the tops of tables,
desks, cabinets and low shelves, inside the top's rectangle and apart from each other. The
final 3D boxes never intersect (a cup touching the table top it stands on is not an
intersection).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from spacedg.scene.box import OrientedBox
from spacedg.scene.synthetic.catalogue import CATALOGUE, ObjectModel

CORRIDOR_HALF_WIDTH = 0.45  # metres kept free around the camera path
FOOTPRINT_MARGIN = 0.04  # metres between floor footprints
WALL_GAP = 0.02  # metres between a wall-standing object and its wall
#: Kinds that may stand in a row along a wall (:meth:`Layout.place_row`), and the row's length range.
ROW_KINDS = ("chair", "chair", "box")
ROW_LENGTH = (4, 6)
ROW_GAP = (0.06, 0.2)  # metres between neighbours in a row
#: Kinds that may only stand on certain hosts (others stand on any top).
SUPPORT_HOSTS = {"tv": ("cabinet",), "monitor": ("desk",)}


@dataclass(frozen=True)
class RoomShape:
    """Room size in metres and the camera loop's inset from the walls."""

    width: float
    depth: float
    height: float
    inset: float


@dataclass
class Placement:
    """An object model placed in the room: position of its footprint centre on the floor
    (or on a support), yaw about z (radians), and what it stands on."""

    model: ObjectModel
    kind: str
    position: np.ndarray  # (3,) canonical frame, bottom centre
    yaw: float
    on: int | None = None  # index of the supporting placement, None = floor
    external: bool = False
    extra: dict = field(default_factory=dict)

    @property
    def rotation(self) -> np.ndarray:
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])

    def footprint(self) -> np.ndarray:
        """(4, 2) corners of the conservative footprint rectangle in the floor plane."""
        lo, hi = self.model.local_bounds()
        local = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]])
        return local @ self.rotation[:2, :2].T + self.position[:2]

    def box3d(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Conservative (center, extents, rotation) of the object in the canonical frame."""
        lo, hi = self.model.local_bounds()
        center_local = (lo + hi) / 2
        return self.rotation @ center_local + self.position, hi - lo, self.rotation


def loop_path(shape: RoomShape, samples: int = 480) -> np.ndarray:
    """(samples, 2) points of the closed camera loop, evenly spaced by arc length."""
    ax, ay, rc = _loop_geometry(shape)
    straight_x, straight_y = 2 * (ax - rc), 2 * (ay - rc)
    perimeter = 2 * straight_x + 2 * straight_y + 2 * math.pi * rc
    s = np.linspace(0.0, perimeter, samples, endpoint=False)
    pts = np.zeros((samples, 2))
    # segments: bottom edge (→ +x), corner, right edge (→ +y), corner, top edge, corner, left edge, corner
    segs = [
        ("line", (-ax + rc, -ay), (1.0, 0.0), straight_x),
        ("arc", (ax - rc, -ay + rc), -math.pi / 2, math.pi / 2 * rc),
        ("line", (ax, -ay + rc), (0.0, 1.0), straight_y),
        ("arc", (ax - rc, ay - rc), 0.0, math.pi / 2 * rc),
        ("line", (ax - rc, ay), (-1.0, 0.0), straight_x),
        ("arc", (-ax + rc, ay - rc), math.pi / 2, math.pi / 2 * rc),
        ("line", (-ax, ay - rc), (0.0, -1.0), straight_y),
        ("arc", (-ax + rc, -ay + rc), math.pi, math.pi / 2 * rc),
    ]
    start = 0.0
    for kind, origin, param, length in segs:
        sel = (s >= start) & (s < start + length + 1e-12)
        t = s[sel] - start
        if kind == "line":
            pts[sel] = np.asarray(origin) + np.outer(t, param)
        else:
            ang = param + t / rc
            pts[sel] = np.asarray(origin) + rc * np.stack([np.cos(ang), np.sin(ang)], 1)
        start += length
    return pts


def _loop_geometry(shape: RoomShape) -> tuple[float, float, float]:
    """Half sizes and corner radius of the camera loop (a rounded rectangle)."""
    ax, ay = shape.width / 2 - shape.inset, shape.depth / 2 - shape.inset
    return ax, ay, min(0.7, 0.8 * min(ax, ay))


def loop_distance(points: np.ndarray, shape: RoomShape) -> np.ndarray:
    """Exact distance of 2D points to the camera loop (|signed distance| of a rounded rectangle)."""
    ax, ay, rc = _loop_geometry(shape)
    q = np.abs(points) - [ax - rc, ay - rc]
    outside = np.linalg.norm(np.maximum(q, 0.0), axis=1)
    inside = np.minimum(np.maximum(q[:, 0], q[:, 1]), 0.0)
    return np.abs(outside + inside - rc)


def _rect_samples(corners: np.ndarray, step: float = 0.08) -> np.ndarray:
    """Points covering a rectangle given by its 4 corners (edges and interior)."""
    e1, e2 = corners[1] - corners[0], corners[3] - corners[0]
    n1 = max(2, int(np.linalg.norm(e1) / step) + 1)
    n2 = max(2, int(np.linalg.norm(e2) / step) + 1)
    a, b = np.meshgrid(np.linspace(0, 1, n1), np.linspace(0, 1, n2), indexing="ij")
    return corners[0] + a.reshape(-1, 1) * e1 + b.reshape(-1, 1) * e2


def rects_overlap(a: np.ndarray, b: np.ndarray, margin: float) -> bool:
    """2D separating-axis test for two rectangles (4×2 corners each), grown by ``margin``/2 each."""
    for rect in (a, b):
        for i in range(2):
            edge = rect[(i + 1) % 4] - rect[i]
            axis = np.array([-edge[1], edge[0]]) / max(np.linalg.norm(edge), 1e-12)
            pa, pb = a @ axis, b @ axis
            if pa.max() + margin <= pb.min() or pb.max() + margin <= pa.min():
                return False
    return True


class Layout:
    """Places objects in a room without interpenetration (see module docstring)."""

    def __init__(self, shape: RoomShape, rng: np.random.Generator) -> None:
        self.shape = shape
        self.rng = rng
        self.placements: list[Placement] = []

    # ---------------------------------------------------------------- tests
    def _inside_room(self, fp: np.ndarray) -> bool:
        hx, hy = self.shape.width / 2 - 0.01, self.shape.depth / 2 - 0.01
        return bool((np.abs(fp[:, 0]) <= hx).all() and (np.abs(fp[:, 1]) <= hy).all())

    def _clear_of_corridor(self, fp: np.ndarray) -> bool:
        return bool(loop_distance(_rect_samples(fp), self.shape).min() >= CORRIDOR_HALF_WIDTH)

    def _clear_of_floor_objects(self, fp: np.ndarray) -> bool:
        return not any(
            p.on is None and rects_overlap(fp, p.footprint(), FOOTPRINT_MARGIN) for p in self.placements
        )

    def floor_ok(self, placement: Placement) -> bool:
        fp = placement.footprint()
        return self._inside_room(fp) and self._clear_of_floor_objects(fp) and self._clear_of_corridor(fp)

    # ----------------------------------------------------------- placement
    def wall_pose(self, wall: int, along: float, depth_back: float) -> tuple[np.ndarray, float]:
        """Bottom-centre position and yaw of a footprint centred at ``along`` metres on wall ``wall``
        (0: +y, 1: +x, 2: −y, 3: −x), its back (+y local, ``depth_back`` from the centre) ``WALL_GAP`` from it."""
        W, D = self.shape.width, self.shape.depth
        yaw = (0.0, -math.pi / 2, math.pi, math.pi / 2)[wall]
        if wall in (0, 2):
            return np.array([along, (D / 2 - WALL_GAP - depth_back) * (1 if wall == 0 else -1), 0.0]), yaw
        return np.array([(W / 2 - WALL_GAP - depth_back) * (1 if wall == 1 else -1), along, 0.0]), yaw

    def place_on_floor(self, model: ObjectModel, kind: str, mode: str, tries: int = 60, external: bool = False) -> Placement | None:
        """Try to stand ``model`` on the floor; ``mode`` is "wall", "center" or "floor"."""
        lo, hi = model.local_bounds()
        depth_back = hi[1]  # distance from footprint centre to the back face
        W, D = self.shape.width, self.shape.depth
        for _ in range(tries):
            if mode == "wall":
                wall = int(self.rng.integers(0, 4))
                half_w = (hi[0] - lo[0]) / 2
                length = W if wall in (0, 2) else D
                along = float(self.rng.uniform(-length / 2 + half_w + 0.02, length / 2 - half_w - 0.02)) if length / 2 - half_w > 0.05 else 0.0
                pos, yaw = self.wall_pose(wall, along, depth_back)
            elif mode == "center":
                ax = max(0.05, W / 2 - self.shape.inset - CORRIDOR_HALF_WIDTH)
                ay = max(0.05, D / 2 - self.shape.inset - CORRIDOR_HALF_WIDTH)
                pos = np.array([self.rng.uniform(-ax, ax), self.rng.uniform(-ay, ay), 0.0])
                yaw = float(self.rng.integers(0, 4)) * math.pi / 2 + float(self.rng.normal(0, 0.12))
            else:
                pos = np.array([self.rng.uniform(-W / 2, W / 2), self.rng.uniform(-D / 2, D / 2), 0.0])
                yaw = float(self.rng.uniform(-math.pi, math.pi))
            cand = Placement(model, kind, pos, yaw, None, external)
            if self.floor_ok(cand):
                self.placements.append(cand)
                return cand
        return None

    def place_row(self, model: ObjectModel, kind: str, count: int, tries: int = 20) -> list[Placement]:
        """Stand ``count`` copies of ``model`` side by side along one wall, backs to it, ``ROW_GAP``
        apart (one draw per row), fewer where the wall is too short (never fewer than
        ``ROW_LENGTH[0]``: such a wall is not used); all or none: a try whose row meets the
        corridor or other furniture is dropped whole. A row does not count against the
        catalogue's ``max_count`` (a table's chairs and a row of chairs can make twelve). Each member's ``extra["row"]`` is
        the index of the row's first placement. Returns the placed row (empty if none fit)."""
        lo, hi = model.local_bounds()
        width, depth_back = float(hi[0] - lo[0]), float(hi[1])
        gap = float(self.rng.uniform(*ROW_GAP))
        W, D = self.shape.width, self.shape.depth
        for _ in range(tries):
            wall = int(self.rng.integers(0, 4))
            length = W if wall in (0, 2) else D
            fits = min(count, int((length - 0.1 + gap) // (width + gap)))
            if fits < min(count, ROW_LENGTH[0]):
                continue  # a wall too short for a row
            span = fits * width + (fits - 1) * gap
            start = float(self.rng.uniform(-length / 2 + 0.05, max(-length / 2 + 0.05, length / 2 - 0.05 - span)))
            row: list[Placement] = []
            first = len(self.placements)  # the row's id: the index (= instance id) of its first member
            for i in range(fits):
                pos, yaw = self.wall_pose(wall, start + width / 2 + i * (width + gap), depth_back)
                cand = Placement(model, kind, pos, yaw, extra={"row": first})
                if not self.floor_ok(cand):
                    break
                row.append(cand)
                self.placements.append(cand)
            if len(row) == fits:
                return row
            del self.placements[len(self.placements) - len(row):]
        return []

    def place_around(self, anchor: Placement, model: ObjectModel, kind: str, tries: int = 12) -> Placement | None:
        """Place a chair-like model at one side of ``anchor``, its front (−y) facing it."""
        lo, hi = anchor.model.local_bounds()
        clo, chi = model.local_bounds()
        for _ in range(tries):
            side = int(self.rng.integers(0, 4))
            gap = float(self.rng.uniform(0.05, 0.15))
            if side in (0, 2):  # −y / +y side of the anchor
                along = float(self.rng.uniform(lo[0] * 0.6, hi[0] * 0.6))
                dist = (-lo[1] if side == 0 else hi[1]) + gap + chi[1]
                local = np.array([along, -dist if side == 0 else dist])
                yaw_local = 0.0 if side == 0 else math.pi
            else:
                along = float(self.rng.uniform(lo[1] * 0.6, hi[1] * 0.6))
                dist = (-lo[0] if side == 3 else hi[0]) + gap + chi[1]
                local = np.array([dist if side == 1 else -dist, along])
                yaw_local = math.pi / 2 if side == 1 else -math.pi / 2
            # a chair at local (x, y) of the anchor; its back (+y) points away from the anchor
            world = anchor.rotation[:2, :2] @ local + anchor.position[:2]
            yaw = anchor.yaw + yaw_local + float(self.rng.normal(0, 0.08))
            cand = Placement(model, kind, np.array([world[0], world[1], 0.0]), yaw)
            if self.floor_ok(cand):
                self.placements.append(cand)
                return cand
        return None

    def place_on_support(self, model: ObjectModel, kind: str, tries: int = 25, external: bool = False) -> Placement | None:
        """Stand a small model on the top of a placed table, desk, cabinet or shelf."""
        allowed = SUPPORT_HOSTS.get(kind)
        hosts = [
            (i, s) for i, p in enumerate(self.placements) for s in p.model.supports if allowed is None or p.kind in allowed
        ]
        if not hosts:
            return None
        lo, hi = model.local_bounds()
        for _ in range(tries):
            idx, sup = hosts[int(self.rng.integers(0, len(hosts)))]
            host = self.placements[idx]
            yaw_local = float(self.rng.uniform(-math.pi, math.pi)) if kind not in ("tv", "monitor") else float(self.rng.normal(0, 0.1))
            c, s = math.cos(yaw_local), math.sin(yaw_local)
            rot2 = np.array([[c, -s], [s, c]])
            corners = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]]) @ rot2.T
            ext_lo, ext_hi = corners.min(0), corners.max(0)
            margin = 0.02
            x_lo, x_hi = sup.x0 - ext_lo[0] + margin, sup.x1 - ext_hi[0] - margin
            y_lo, y_hi = sup.y0 - ext_lo[1] + margin, sup.y1 - ext_hi[1] - margin
            if x_lo > x_hi or y_lo > y_hi:
                continue
            local = np.array([self.rng.uniform(x_lo, x_hi), self.rng.uniform(y_lo, y_hi)])
            if kind in ("tv", "monitor"):  # screens stand at the back, facing front
                local[1] = y_hi
            world = host.rotation[:2, :2] @ local + host.position[:2]
            cand = Placement(model, kind, np.array([world[0], world[1], host.position[2] + sup.z]), host.yaw + yaw_local, idx, external)
            fp = cand.footprint()
            clash = any(
                p.on == idx and rects_overlap(fp, p.footprint(), 0.02) for p in self.placements
            )
            if clash or not self._boxes_clear(cand):
                continue
            self.placements.append(cand)
            return cand
        return None

    def _boxes_clear(self, cand: Placement) -> bool:
        c, e, r = cand.box3d()
        box = OrientedBox(c, e, r)
        for p in self.placements:
            pc, pe, pr = p.box3d()
            if box.intersects(OrientedBox(pc, pe, pr), tol=1e-3):
                return False
        top = cand.position[2] + (cand.model.local_bounds()[1][2])
        return top < self.shape.height - 0.05


def choose_room_shape(rng: np.random.Generator) -> RoomShape:
    """A room of 5–8 m × 4.5–7 m × 2.5–3.0 m with a camera loop 1.1–1.6 m from the walls."""
    width, depth = float(rng.uniform(5.0, 8.0)), float(rng.uniform(4.5, 7.0))
    inset = float(rng.uniform(1.15, min(1.6, min(width, depth) / 2 - 0.9)))
    return RoomShape(width, depth, float(rng.uniform(2.5, 3.0)), inset)


def fill_room(
    layout: Layout,
    target_objects: int,
    external_models: list[tuple[ObjectModel, str]] | None = None,
    size_spread: tuple[float, float] = (1.0, 1.0),
    row_probability: float = 0.0,
) -> None:
    """Place furniture until ``target_objects`` instances stand in the room (or space runs out).

    Order: one central group (a table with chairs, or a coffee table), with ``row_probability``
    a row of 4–6 chairs or boxes of one model (one shape and size, each its own colour) along a wall (:data:`ROW_KINDS`: the views that show
    several instances of a label, which counting needs; no draw at all when it is 0, so such a
    room is the room of before), wall furniture, other floor objects, external objects, then
    small objects on the tops. Each catalogue object is
    scaled by a factor drawn log-uniformly from ``size_spread`` (one draw per object, after its
    builder's draws; none when the spread is ``(1, 1)``).
    """
    rng = layout.rng
    counts: dict[str, int] = {}
    lo, hi = (float(v) for v in size_spread)

    def build(kind: str) -> ObjectModel:
        counts[kind] = counts.get(kind, 0) + 1
        model = CATALOGUE[kind].build(rng)
        if lo == hi == 1.0:
            return model
        return model.scaled(math.exp(rng.uniform(math.log(lo), math.log(hi))))

    def room_left() -> bool:
        return len(layout.placements) < target_objects

    # 1. a central group
    center_kind = "table" if rng.uniform() < 0.65 else "coffee table"
    anchor = layout.place_on_floor(build(center_kind), center_kind, "center")
    if anchor is not None and center_kind == "table":
        for _ in range(int(rng.integers(2, 7))):
            layout.place_around(anchor, build("chair"), "chair")
    # 1b. a row of identical objects along a wall
    if row_probability > 0 and rng.uniform() < row_probability:
        kind = ROW_KINDS[int(rng.integers(0, len(ROW_KINDS)))]
        placed_row = layout.place_row(build(kind), kind, int(rng.integers(ROW_LENGTH[0], ROW_LENGTH[1] + 1)))
        counts[kind] += len(placed_row) - 1
    # 2. wall furniture and free-standing floor objects, by weight
    floor_kinds = [k for k, e in CATALOGUE.items() if e.placement in ("wall", "floor", "center")]
    n_floor = max(4, int(round(target_objects * 0.55)))
    attempts = 0
    while sum(p.on is None for p in layout.placements) < n_floor and attempts < 60 and room_left():
        attempts += 1
        weights = np.array([CATALOGUE[k].weight if counts.get(k, 0) < CATALOGUE[k].max_count else 0.0 for k in floor_kinds])
        if weights.sum() == 0:
            break
        kind = floor_kinds[int(rng.choice(len(floor_kinds), p=weights / weights.sum()))]
        placed = layout.place_on_floor(build(kind), kind, CATALOGUE[kind].placement)
        if placed is not None and kind == "desk" and rng.uniform() < 0.7:
            layout.place_around(placed, build("chair"), "chair")
        if placed is None:
            counts[kind] -= 1
    # 3. external objects (on the floor or on supports)
    for model, where in external_models or []:
        if where == "support":
            layout.place_on_support(model, model.label, external=True)
        else:
            layout.place_on_floor(model, model.label, "floor", external=True)
    # 4. small objects on tops
    support_kinds = [k for k, e in CATALOGUE.items() if e.placement == "support"]
    attempts = 0
    while room_left() and attempts < 80:
        attempts += 1
        weights = np.array([CATALOGUE[k].weight if counts.get(k, 0) < CATALOGUE[k].max_count else 0.0 for k in support_kinds])
        if weights.sum() == 0:
            break
        kind = support_kinds[int(rng.choice(len(support_kinds), p=weights / weights.sum()))]
        if layout.place_on_support(build(kind), kind) is None:
            counts[kind] -= 1
    # 5. top up with small floor objects if the room is still too empty
    attempts = 0
    while room_left() and attempts < 40:
        attempts += 1
        kind = ("box", "plant", "ball", "trash can", "stool")[int(rng.integers(0, 5))]
        if layout.place_on_floor(build(kind), kind, "floor") is None:
            counts[kind] -= 1
