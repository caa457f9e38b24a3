"""Hand-built scenes for golden question tests: every answer is known by construction.

No rendering: visibility and covisibility are written in by hand, so a test states exactly
which objects each view shows and which views overlap.

World frame: z up, metres. ``camera(eye, yaw_deg, pitch_deg=0, roll_deg=0)`` builds an OpenCV
camera at ``eye`` whose optical axis points along heading ``yaw`` (0 = +x, 90 = +y, i.e.
counter-clockwise seen from above, as in ``spacedg.scene.synthetic.trajectory``), tilted up by
``pitch`` and rolled clockwise by ``roll``. A camera with yaw 0 at the origin sees +x ahead,
−y to its right and +z up.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from spacedg.scene.box import OrientedBox
from spacedg.scene.model import Instance, InstanceVisibility, Scene, ViewCovisibility
from spacedg.scene.synthetic.trajectory import rotation_from_angles
from spacedg.render.camera import Camera
from spacedg.render.gaussians import Gaussians

#: Visibility of a clearly visible instance (well above the default thresholds at 640×480).
CLEAR = InstanceVisibility(5000, 0.9)
#: A grey-zone (partly visible) instance.
PARTLY = InstanceVisibility(60, 0.2)


def camera(eye: Sequence[float], yaw_deg: float = 0.0, pitch_deg: float = 0.0, roll_deg: float = 0.0,
           width: int = 640, height: int = 480) -> Camera:
    rot = rotation_from_angles(np.radians([yaw_deg]), np.radians([pitch_deg]), np.radians([roll_deg]))[0]
    pose = np.eye(4)
    pose[:3, :3] = rot
    pose[:3, 3] = np.asarray(eye, dtype=np.float64)
    f = 0.8 * width
    return Camera(f, f, width / 2, height / 2, width, height, pose)


def obj(iid: int, label: str, center: Sequence[float], extents: Sequence[float] = (0.4, 0.4, 0.4),
        description: str | None = None, yaw_deg: float = 0.0) -> Instance:
    """An instance with an axis-aligned (or yawed about z) box; description defaults to "a <label>"."""
    c, s = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    box = OrientedBox(np.asarray(center, dtype=np.float64), np.asarray(extents, dtype=np.float64), rot)
    return Instance(iid, label, f"{label}" if description is None else description, box)


def build(
    instances: Sequence[Instance],
    views: Mapping[str, Camera],
    visibility: Mapping[str, Mapping[int, InstanceVisibility]] | None = None,
    covisibility: float | np.ndarray = 0.5,
    vocabulary: Sequence[str] | None = None,
    scene_id: str = "golden",
) -> Scene:
    """A scene with one tiny Gaussian per instance, the given visibility and covisibility.

    ``visibility``: view → instance id → :class:`InstanceVisibility` (missing = hidden);
    ``None`` makes every instance clearly visible in every view. ``covisibility``: one number
    for every pair (diagonal 1) or a full (V, V) matrix in ``views`` order.
    """
    names = list(views)
    if visibility is None:
        visibility = {v: {inst.id: CLEAR for inst in instances} for v in names}
    filled = []
    for inst in instances:
        vis = {v: row[inst.id] for v, row in visibility.items() if inst.id in row}
        filled.append(Instance(inst.id, inst.label, inst.description, inst.box, visibility=vis))
    n = max(1, len(instances))
    means = np.array([inst.box.center for inst in instances], dtype=np.float64).reshape(-1, 3) if instances else np.zeros((1, 3))
    gaussians = Gaussians.from_colors(
        means, np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)), np.full((n, 3), 0.05), np.full(n, 0.9), np.full((n, 3), 0.5),
        instance_ids=np.array([inst.id for inst in instances]) if instances else np.array([-1]),
    )
    if np.isscalar(covisibility):
        matrix = np.full((len(names), len(names)), float(covisibility), dtype=np.float32)
        np.fill_diagonal(matrix, 1.0)
    else:
        matrix = np.asarray(covisibility, dtype=np.float32)
    return Scene(scene_id, gaussians, views, filled, vocabulary=vocabulary, covisibility=ViewCovisibility(tuple(names), matrix))


def random_rigid(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A random rotation (any up direction) and translation, for invariance tests."""
    rng = np.random.default_rng(seed)
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    w, x, y, z = q
    rot = np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])
    return rot, rng.uniform(-5, 5, size=3)
