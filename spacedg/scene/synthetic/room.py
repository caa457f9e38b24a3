"""Procedural indoor rooms: the built-in default scenes.

:func:`generate_room` makes one furnished room from a seed, deterministically: the room
shell (floor, four walls with a door and a window, ceiling), 8–25 furniture-like instances
(several sharing a label), textured surfaces with baked shading and a view-dependent sheen
(SH degree 1), exact oriented boxes, view-invariant descriptions, per-Gaussian instance
ids, and a handheld capture trajectory of 48–120 views. Independent random streams drive
layout, appearance, surface sampling and the trajectory, so changing the Gaussian budget
does not move the furniture.

The scene is finally moved into a seeded world frame (z-up, y-down as in COLMAP, or y-up,
with a random heading), and ``Scene.up`` says which: consumers must never assume an axis.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from spacedg.errors import InvalidDataError
from spacedg.render.gaussians import SH_C0, Gaussians
from spacedg.scene.box import OrientedBox
from spacedg.scene.io.ply import quantize_for_ply
from spacedg.scene.model import Instance, Scene
from spacedg.scene.synthetic.appearance import Appearance, all_appearances
from spacedg.scene.synthetic.catalogue import VOCABULARY
from spacedg.scene.synthetic.external import ExternalObject
from spacedg.scene.synthetic.layout import (
    Layout,
    Placement,
    RoomShape,
    choose_room_shape,
    fill_room,
)
from spacedg.scene.synthetic.primitives import (
    Surfels,
    frames_to_quats,
    rectangle,
    surfel_scales,
)
from spacedg.scene.synthetic.textures import TEXTURES
from spacedg.scene.synthetic.trajectory import CaptureConfig, handheld_trajectory

#: ``metadata["generator"]`` of every built-in room. A stable identifier, not a module path: it
#: stays ``"spacedg.data.synthetic"`` (where the generator first lived) so that rooms written
#: before it moved to :mod:`spacedg.scene.synthetic` keep their bytes and their question indexes.
GENERATOR_ID = "spacedg.data.synthetic"

_SH_C1 = 0.4886025119029199
#: Shell surfaces are sampled this many times more coarsely than furniture.
SHELL_SPACING_RATIO = 1.8
#: Canonical → world rotations; the canonical frame is z-up.
WORLD_FRAMES = {
    "z_up": np.eye(3),
    "y_down": np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]),
    "y_up": np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]]),
}
_LIGHT = np.array([0.25, -0.35, 1.0]) / np.linalg.norm([0.25, -0.35, 1.0])


@dataclass(frozen=True)
class RoomConfig:
    """What to generate.

    Attributes:
        gaussians: target number of Gaussians (the result lands within a few percent);
            ``None`` draws it from [150k, 300k] by seed.
        min_objects, max_objects: range of the number of instances.
        twin_probability: chance that a repeated label copies the appearance (and so the
            description) of an earlier instance: intended ambiguity for the filters.
        world_frame: ``"random"`` or one of ``"z_up"``, ``"y_down"``, ``"y_up"``.
        capture: image size and number of views.
        external: objects from files to place among the furniture.
        size_spread: every catalogue object is scaled by a factor drawn log-uniformly from
            this range (default 0.75–1.35: a chair's longest side then spans 0.62–1.32 m), so
            a label does not fix an object's size: size questions cannot be answered from
            label priors alone. ``(1, 1)`` keeps the catalogue's own ranges.
        row_probability: chance that the room has a row of 4–6 chairs or boxes of one model (one shape and size, each its own colour) along
            a wall (views showing several instances of a label, for counting); 0 draws nothing,
            so a room generated with 0 is the room of before rows existed.
    """

    gaussians: int | None = None
    min_objects: int = 8
    max_objects: int = 25
    twin_probability: float = 0.15
    world_frame: str = "random"
    capture: CaptureConfig = field(default_factory=CaptureConfig)
    external: tuple[ExternalObject, ...] = ()
    size_spread: tuple[float, float] = (0.75, 1.35)
    row_probability: float = 0.5

    def __post_init__(self) -> None:
        lo, hi = (float(v) for v in self.size_spread)
        if not 0.2 <= lo <= hi <= 5.0:
            raise InvalidDataError(f"RoomConfig: size_spread must be (low, high) with 0.2 <= low <= high <= 5, got {self.size_spread}")
        if self.gaussians is not None and not 10_000 <= self.gaussians <= 5_000_000:
            raise InvalidDataError(f"RoomConfig: gaussians must be in [10000, 5000000], got {self.gaussians}")
        if not 1 <= self.min_objects <= self.max_objects <= 40:
            raise InvalidDataError(
                f"RoomConfig: need 1 <= min_objects <= max_objects <= 40, got {self.min_objects}, {self.max_objects}"
            )
        if isinstance(self.row_probability, bool) or not isinstance(self.row_probability, (int, float)) or not 0.0 <= self.row_probability <= 1.0:
            raise InvalidDataError(f"RoomConfig: row_probability must be in [0, 1], got {self.row_probability!r}")
        if not 0.0 <= self.twin_probability <= 1.0:
            raise InvalidDataError(f"RoomConfig: twin_probability must be in [0, 1], got {self.twin_probability}")
        if self.world_frame != "random" and self.world_frame not in WORLD_FRAMES:
            raise InvalidDataError(f"RoomConfig: world_frame must be 'random' or one of {sorted(WORLD_FRAMES)}, got {self.world_frame!r}")


# ------------------------------------------------------------ appearance
def _assign_appearances(
    placements: Sequence[Placement], twin_probability: float, rng: np.random.Generator
) -> list[tuple[dict[str, Appearance], int | None]]:
    """Per placement: slot → appearance, and the id of the instance it twins (or None).

    The describing slot's appearance is unique within a label unless a twin is drawn.
    """
    used: dict[str, list[tuple[Appearance, int]]] = {}
    out = []
    for index, p in enumerate(placements):
        model = p.model
        slots: dict[str, Appearance] = {}
        twin_of = None
        if p.external:
            out.append((slots, None))
            continue
        for slot, materials in model.slots.items():
            if slot in model.fixed:
                colour, material = model.fixed[slot]
                slots[slot] = Appearance(colour, material)
                continue
            options = all_appearances(materials)
            if slot == model.describe_slot:
                taken = used.setdefault(model.label, [])
                if taken and rng.uniform() < twin_probability:
                    chosen, twin_of = taken[int(rng.integers(0, len(taken)))]
                else:
                    free = [a for a in options if a not in {t for t, _ in taken}]
                    chosen = free[int(rng.integers(0, len(free)))] if free else options[int(rng.integers(0, len(options)))]
                taken.append((chosen, index))
                slots[slot] = chosen
            else:
                slots[slot] = options[int(rng.integers(0, len(options)))]
        for slot in model.fixed:
            if slot not in slots:
                colour, material = model.fixed[slot]
                slots[slot] = Appearance(colour, material)
        out.append((slots, twin_of))
    return out


# ------------------------------------------------------------- surfaces
def _shade(colors: np.ndarray, normals: np.ndarray, points: np.ndarray, shape: RoomShape) -> np.ndarray:
    """Bake soft lighting: a ceiling key light, ambient, and darkening near the floor."""
    lambert = np.clip(normals @ _LIGHT, 0.0, 1.0)
    r2 = (points[:, 0] ** 2 + points[:, 1] ** 2) / (shape.width**2 + shape.depth**2)
    falloff = 0.85 + 0.15 * np.exp(-6.0 * r2)
    contact = 0.82 + 0.18 * np.clip(points[:, 2] / 0.35, 0.0, 1.0)
    return colors * ((0.62 + 0.38 * lambert) * falloff * contact)[:, None]


def _sheen_sh(normals: np.ndarray, strength: np.ndarray) -> np.ndarray:
    """(N, 3, 3) SH band-1 coefficients of a white highlight seen along the light's mirror direction."""
    reflect = 2 * (normals @ _LIGHT)[:, None] * normals - _LIGHT  # direction the light leaves
    v = -reflect  # camera→point direction that sees the highlight
    k = (0.12 * strength)[:, None]
    band = np.stack([-k * v[:, 1:2] / _SH_C1, k * v[:, 2:3] / _SH_C1, -k * v[:, 0:1] / _SH_C1], axis=1)
    return np.repeat(band, 3, axis=2)  # same for R, G, B


@dataclass
class _Batch:
    surfels: list[Surfels] = field(default_factory=list)
    colors: list[np.ndarray] = field(default_factory=list)
    sheen: list[np.ndarray] = field(default_factory=list)
    ids: list[np.ndarray] = field(default_factory=list)

    def add(self, s: Surfels, colors: np.ndarray, sheen: float, instance_id: int) -> None:
        self.surfels.append(s)
        self.colors.append(colors)
        self.sheen.append(np.full(len(s), sheen))
        self.ids.append(np.full(len(s), instance_id, dtype=np.int32))


def _texture(appearance: Appearance, s: Surfels, rng: np.random.Generator) -> np.ndarray:
    return TEXTURES[appearance.spec.texture](appearance.rgb, s.uv, float(s.spacing[0]) if len(s) else 0.0, rng)


def _object_surfels(p: Placement, slots: dict[str, Appearance], spacing: float, rng: np.random.Generator, batch: _Batch, iid: int) -> None:
    for part in p.model.parts:
        local = part.sample(spacing, rng)
        world = local.transformed(p.rotation, p.position)
        app = slots[part.slot]
        colors = _texture(app, local, rng)
        batch.add(world, colors, app.spec.sheen, iid)


def _shell(shape: RoomShape, spacing: float, rng: np.random.Generator, batch: _Batch) -> dict[str, object]:
    """Floor, ceiling and walls (normals inward), with a door, a window and a skirting board."""
    W, D, H = shape.width, shape.depth, shape.height
    floor_app = Appearance(*(("light brown", "wood"), ("brown", "wood"), ("beige", "marble"), ("light grey", "marble"))[int(rng.integers(0, 4))])
    floor_tex = "planks" if floor_app.material == "wood" else "tiles"
    wall_colour = ("white", "cream", "beige", "light grey")[int(rng.integers(0, 4))]
    wall_tex = "wallpaper" if rng.uniform() < 0.35 else "paint"
    ex, ey, ez = np.eye(3)
    floor = rectangle(np.array([-W / 2, -D / 2, 0.0]), ex, ey, W, D, spacing, rng)
    batch.add(floor, TEXTURES[floor_tex](floor_app.rgb, floor.uv, spacing, rng), 0.15, -1)
    ceiling = rectangle(np.array([-W / 2, D / 2, H]), ex, -ey, W, D, spacing, rng)
    batch.add(ceiling, TEXTURES["paint"](np.array([0.93, 0.93, 0.92]), ceiling.uv, spacing, rng), 0.0, -1)
    # walls: (origin, along-wall axis); u runs along the wall, v up; normal = u × v points inward
    walls = [
        (np.array([W / 2, -D / 2, 0.0]), -ex, W),  # south wall y = -D/2 (normal +y)
        (np.array([W / 2, D / 2, 0.0]), -ey, D),  # east wall x = +W/2 (normal -x)
        (np.array([-W / 2, D / 2, 0.0]), ex, W),  # north wall y = +D/2 (normal -y)
        (np.array([-W / 2, -D / 2, 0.0]), ey, D),  # west wall x = -W/2 (normal +x)
    ]
    door_wall, window_wall = rng.choice(4, size=2, replace=False)
    base = np.asarray({"white": (0.9, 0.9, 0.88), "cream": (0.95, 0.9, 0.78), "beige": (0.85, 0.76, 0.6), "light grey": (0.72, 0.72, 0.72)}[wall_colour])
    features = {}
    for w, (origin, axis_u, length) in enumerate(walls):
        s = rectangle(origin, axis_u, ez, length, H, spacing, rng)
        col = TEXTURES[wall_tex](base, s.uv, spacing, rng)
        u, v = s.uv[:, 0], s.uv[:, 1]
        col[v < 0.09] = base * 0.55  # skirting board
        if w == door_wall:
            u0 = float(rng.uniform(0.4, length - 1.3))
            door = (u > u0) & (u < u0 + 0.9) & (v < 2.05)
            frame = door & ((u < u0 + 0.05) | (u > u0 + 0.85) | (v > 2.0))
            col[door] = TEXTURES["wood"](np.array([0.45, 0.3, 0.18]), s.uv[door], spacing, rng)
            col[frame] = np.array([0.85, 0.85, 0.82])
            knob = door & (np.hypot(u - (u0 + 0.78), v - 1.0) < 0.035)
            col[knob] = np.array([0.75, 0.65, 0.3])
            features["door"] = {"wall": int(w), "u": u0}
        if w == window_wall:
            width = float(rng.uniform(1.0, min(1.8, length - 1.0)))
            u0 = float(rng.uniform(0.5, length - width - 0.5))
            win = (u > u0) & (u < u0 + width) & (v > 0.9) & (v < 2.1)
            pane = win & ~((np.abs(u - (u0 + width / 2)) < 0.025) | (u < u0 + 0.05) | (u > u0 + width - 0.05) | (v < 0.95) | (v > 2.05))
            col[win] = np.array([0.92, 0.92, 0.9])
            sky = 1.25 + 0.15 * (v[pane] - 0.9)  # emitter brighter than white (HDR)
            col[pane] = np.stack([sky * 0.92, sky * 0.97, sky * 1.05], 1)
            features["window"] = {"wall": int(w), "u": u0, "width": width}
        batch.add(s, col, 0.0, -1)
    features.update(floor=f"{floor_app.colour} {floor_tex}", walls=f"{wall_colour} {wall_tex}")
    return features


def _to_gaussians(batch: _Batch, shape: RoomShape, rng: np.random.Generator) -> Gaussians:
    s = Surfels.concat(batch.surfels)
    colors = np.concatenate(batch.colors)
    shaded = _shade(colors, s.normals, s.points, shape)
    ids = np.concatenate(batch.ids)
    # windows are emitters: keep them unshaded
    emit = colors.max(axis=1) > 1.0
    shaded[emit] = colors[emit]
    sh = np.zeros((len(s), 4, 3))
    sh[:, 0, :] = (shaded - 0.5) / SH_C0
    sh[:, 1:, :] = _sheen_sh(s.normals, np.concatenate(batch.sheen))
    opac = rng.uniform(0.88, 1.0, len(s))
    return Gaussians(
        means=s.points, quats=frames_to_quats(s.tangents, s.normals), scales=surfel_scales(s.spacing),
        opacities=opac, sh=sh, instance_ids=ids,
    )


# ------------------------------------------------------------------ main
def _world_transform(config: RoomConfig, rng: np.random.Generator) -> tuple[str, np.ndarray]:
    frame = config.world_frame if config.world_frame != "random" else sorted(WORLD_FRAMES)[int(rng.integers(0, 3))]
    heading = float(rng.uniform(-math.pi, math.pi))
    c, s = math.cos(heading), math.sin(heading)
    yaw = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return frame, WORLD_FRAMES[frame] @ yaw


def generate_room(seed: int, config: RoomConfig | None = None, scene_id: str | None = None) -> Scene:
    """Generate one furnished room (see module docstring); same seed and config → same bytes."""
    config = config or RoomConfig()
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InvalidDataError(f"generate_room: seed must be an integer >= 0, got {seed!r}")
    root = np.random.SeedSequence(int(seed))
    rng_layout, rng_look, rng_surf, rng_traj, rng_world, rng_budget = (np.random.default_rng(s) for s in root.spawn(6))
    externals = [(ext.model(), ext.placement) for ext in config.external]
    placements: list[Placement] = []
    shape: RoomShape | None = None
    for _attempt in range(8):
        shape = choose_room_shape(rng_layout)
        layout = Layout(shape, rng_layout)
        target = int(rng_layout.integers(config.min_objects, config.max_objects + 1))
        fill_room(layout, target, externals, config.size_spread, config.row_probability)
        placements = layout.placements
        if len(placements) >= config.min_objects and all(any(p.model is m for p in placements) for m, _ in externals):
            break
    else:
        raise InvalidDataError(
            f"generate_room(seed={seed}): could not place {config.min_objects} objects"
            + (" and every external object" if externals else "")
            + " in 8 layouts; lower min_objects or use smaller external objects"
        )
    assert shape is not None
    looks = _assign_appearances(placements, config.twin_probability, rng_look)

    # Gaussian budget → sampling spacing (external objects bring their own Gaussians)
    target_n = config.gaussians if config.gaussians is not None else int(rng_budget.integers(150_000, 300_001))
    shell_area = 2 * shape.width * shape.depth + 2 * (shape.width + shape.depth) * shape.height
    object_area = sum(p.model.area() for p in placements if not p.external)
    external_n = sum(len(p.model.prebuilt) for p in placements if p.external and p.model.prebuilt is not None)
    budget = max(target_n - external_n, 1000)
    spacing = math.sqrt((shell_area / SHELL_SPACING_RATIO**2 + object_area) / budget)

    batch = _Batch()
    features = _shell(shape, spacing * SHELL_SPACING_RATIO, rng_surf, batch)
    instances_raw = []
    prebuilt_parts: list[Gaussians] = []
    for iid, (p, (slots, twin_of)) in enumerate(zip(placements, looks)):
        if p.external:
            g = p.model.prebuilt.transformed(p.rotation, p.position).with_instance_ids(iid)
            prebuilt_parts.append(g)
            desc = p.model.description_template
            centres = g.means.astype(np.float64)
        else:
            start = len(batch.surfels)
            _object_surfels(p, slots, spacing, rng_surf, batch, iid)
            centres = np.concatenate([s.points for s in batch.surfels[start:]])
            app = slots[p.model.describe_slot]
            desc = app.describe(p.model.label, p.model.description_template)
        attrs: dict[str, object] = {"kind": p.kind, "support": None if p.on is None else int(p.on)}
        if p.external:
            attrs.update(external=True, **p.model.attributes)
        else:
            attrs.update(colour=app.colour, material=app.material)
        if twin_of is not None:
            attrs["twin_of"] = int(twin_of)
        if "row" in p.extra:
            attrs["row"] = int(p.extra["row"])  # a member of the wall row starting at this instance id
        instances_raw.append((iid, p.model.label, desc, OrientedBox.fit_points(centres, p.rotation), attrs))
    room_gaussians = _to_gaussians(batch, shape, rng_surf)
    gaussians = Gaussians.concat([room_gaussians, *prebuilt_parts]) if prebuilt_parts else room_gaussians

    cameras = handheld_trajectory(shape, config.capture, rng_traj)

    frame, rot = _world_transform(config, rng_world)
    gaussians = gaussians.transformed(rot)
    to_world = np.eye(4)
    to_world[:3, :3] = rot
    views = {f"frame_{k:04d}": cam.with_pose(to_world @ cam.cam_to_world) for k, cam in enumerate(cameras)}
    instances = [
        Instance(iid, label, desc, box.transformed(rot, np.zeros(3)), attributes=attrs)
        for iid, label, desc, box, attrs in instances_raw
    ]
    metadata = {
        "generator": GENERATOR_ID,
        "seed": int(seed),
        "world_frame": frame,
        "room_size_m": [round(shape.width, 4), round(shape.depth, 4), round(shape.height, 4)],
        "target_gaussians": int(target_n),
        "surfel_spacing_m": round(spacing, 5),
        "shell": features,
    }
    return Scene(
        scene_id or f"room-{int(seed):06d}",
        quantize_for_ply(gaussians),
        views,
        instances,
        up=rot @ np.array([0.0, 0.0, 1.0]),
        vocabulary=VOCABULARY,
        metadata=metadata,
    )
