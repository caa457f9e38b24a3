"""A handheld capture trajectory: a person walking a loop through the room, filming.

In the room's canonical frame (z up): the camera centre follows the layout's loop at eye
height with smooth lateral sway and a walking bob; it looks towards the room's middle,
swinging 50–80° left and right (so every wall and the central group are filmed
from several sides), tilted down 8–22° on average and nodding up to ±14° around it (looking at
the floor, then at shelves), with up to 4° of roll. Consecutive views are 6–20 cm
apart with small rotations, so their fields of view overlap strongly, as in a real scan.

Intrinsics are those of a phone camera in landscape: horizontal field of view 60–75°,
square pixels, principal point within a few pixels of the image centre.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from spacedg.errors import InvalidDataError
from spacedg.limits import check_image_size
from spacedg.render.camera import Camera
from spacedg.scene.synthetic.layout import RoomShape, loop_path
from spacedg.scene.synthetic.textures import value_noise

#: Most views one synthetic capture takes (a walk of ~10⁴ m at 6–20 cm per view).
MAX_VIEWS = 100_000


@dataclass(frozen=True)
class CaptureConfig:
    """Image size in pixels (within :mod:`spacedg.limits`) and how many views to take (sampled in
    ``[min_views, max_views]``, 1 ≤ min_views ≤ max_views ≤ :data:`MAX_VIEWS`)."""

    width: int = 640
    height: int = 480
    min_views: int = 48
    max_views: int = 120

    def __post_init__(self) -> None:
        for name in ("width", "height", "min_views", "max_views"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
                raise InvalidDataError(f"CaptureConfig: {name} must be a positive integer, got {value!r}")
        check_image_size(self.width, self.height, "CaptureConfig", "capture smaller views")
        if not self.min_views <= self.max_views <= MAX_VIEWS:
            raise InvalidDataError(
                f"CaptureConfig: views must satisfy 1 <= min_views <= max_views <= {MAX_VIEWS}, "
                f"got min_views={self.min_views}, max_views={self.max_views}"
            )


def _smooth(t: np.ndarray, seed: int, freq: float) -> np.ndarray:
    """Smooth noise in [-1, 1] along a closed loop parameter t ∈ [0, 1)."""
    # sample noise on a circle so the loop closes without a jump
    ang = 2 * math.pi * t
    return 2 * value_noise(freq * (1 + np.cos(ang)), freq * (1 + np.sin(ang)), seed) - 1


def rotation_from_angles(yaw: np.ndarray, pitch: np.ndarray, roll: np.ndarray) -> np.ndarray:
    """(N, 3, 3) OpenCV cam-to-world rotations in a z-up frame.

    yaw: heading of the optical axis from +x towards +y (rad); pitch: positive tilts up;
    roll: positive turns the image clockwise as seen by the viewer.
    """
    cy, sy = np.cos(yaw), np.sin(yaw)
    cp, sp = np.cos(pitch), np.sin(pitch)
    forward = np.stack([cy * cp, sy * cp, sp], axis=1)
    right0 = np.stack([sy, -cy, np.zeros_like(cy)], axis=1)  # forward × up, horizontal
    down0 = np.cross(forward, right0)
    cr, sr = np.cos(roll)[:, None], np.sin(roll)[:, None]
    right = cr * right0 + sr * down0
    down = -sr * right0 + cr * down0
    return np.stack([right, down, forward], axis=2)


def handheld_trajectory(shape: RoomShape, config: CaptureConfig, rng: np.random.Generator) -> list[Camera]:
    """Cameras along the walking loop (canonical frame, z up), in capture order."""
    n = int(rng.integers(config.min_views, config.max_views + 1))
    path = loop_path(shape, samples=2048)
    start = rng.uniform(0, 1)
    t = (start + np.arange(n) / n) % 1.0
    if rng.uniform() < 0.5:  # walk clockwise or anticlockwise
        t = (start - np.arange(n) / n) % 1.0
    idx = t * len(path)
    i0 = np.floor(idx).astype(int) % len(path)
    frac = idx - np.floor(idx)
    pos2 = path[i0] * (1 - frac[:, None]) + path[(i0 + 1) % len(path)] * frac[:, None]
    seeds = rng.integers(0, 2**31 - 1, size=6)
    # lateral sway (towards/away from the middle) and walking bob
    inward = -pos2 / np.maximum(np.linalg.norm(pos2, axis=1, keepdims=True), 1e-9)
    pos2 = pos2 + inward * (0.12 * _smooth(t, int(seeds[0]), 3.0))[:, None]
    eye = float(rng.uniform(1.45, 1.70))
    z = eye + 0.02 * _smooth(t, int(seeds[1]), 12.0)
    centers = np.column_stack([pos2, z])
    # heading: towards the middle, swinging across the room
    to_middle = np.arctan2(-pos2[:, 1], -pos2[:, 0])
    swing_deg = float(rng.uniform(50, 80))
    swing_amp = math.radians(swing_deg)
    # keep the swing's turn per view under ~12° so neighbouring views overlap
    max_cycles = max(1, min(4, int(12.0 * n / (2 * math.pi * swing_deg))))
    cycles = int(rng.integers(1, max_cycles + 1))
    phase = rng.uniform(0, 2 * math.pi)
    yaw = to_middle + swing_amp * np.sin(2 * math.pi * cycles * t + phase) + math.radians(10) * _smooth(t, int(seeds[2]), 5.0)
    pitch = -math.radians(float(rng.uniform(8, 22))) + math.radians(14) * _smooth(t, int(seeds[3]), 10.0)
    roll = math.radians(4.0) * _smooth(t, int(seeds[4]), 8.0)
    rot = rotation_from_angles(yaw, pitch, roll)
    hfov = math.radians(float(rng.uniform(60, 75)))
    fx = config.width / 2 / math.tan(hfov / 2)
    cx = config.width / 2 + float(rng.uniform(-4, 4))
    cy = config.height / 2 + float(rng.uniform(-4, 4))
    cams = []
    for k in range(n):
        pose = np.eye(4)
        pose[:3, :3] = rot[k]
        pose[:3, 3] = centers[k]
        cams.append(Camera(fx, fx, cx, cy, config.width, config.height, pose))
    return cams
