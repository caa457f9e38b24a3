"""Cameras: intrinsics, pose and lens.

Conventions:

- Camera axes are **OpenCV**: x right, y down, z forward (viewing direction).
- ``cam_to_world`` (4, 4) float64 maps camera coordinates to world coordinates (metres);
  its first three columns are the camera's right, down and forward axes in the world.
- Pixel coordinates: ``u`` along the image width, ``v`` along the height; the centre of
  pixel (row i, column j) is at ``(j + 0.5, i + 0.5)``.
- Lens: pinhole, or equidistant fisheye (OpenCV ``cv2.fisheye`` / Kannala–Brandt) with
  ``θ_d = θ (1 + k1 θ² + k2 θ⁴ + k3 θ⁶ + k4 θ⁸)`` where θ is the angle between the ray and
  the optical axis, and ``pixel = (fx θ_d x/r + cx, fy θ_d y/r + cy)`` with r = √(x² + y²).
  Rays beyond ``max_theta`` (radians) are invalid, never NaN.

Conversions from other conventions (OpenGL/nerfstudio, COLMAP world-to-camera) happen in
``spacedg.scene.io``, once.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Any

import numpy as np

from spacedg._checks import finite_float, require_homogeneous, require_rotation
from spacedg.errors import InvalidDataError
from spacedg.limits import check_image_size
from spacedg.render.gaussians import quat_from_matrix
from spacedg.render.lens_polynomial import equidistant_theta_d, equidistant_theta_d_slope

_SOURCE = "Camera"


def frustum_limits(fx: float, fy: float, cx: float, cy: float, width: int, height: int, reach: float) -> tuple[float, float, float, float]:
    """``(lim_x_neg, lim_x_pos, lim_y_neg, lim_y_pos)``: the pinhole Jacobian's clamp of ``x/z, y/z`` (the
    projectors', compiled and torch), the view widened by 0.3·tan(fov/2) (gsplat) and by ``reach`` pixels
    (how far a blurred footprint reaches in). Plain float arithmetic: compiled as it is for numba."""
    return (
        (cx + reach) / fx + 0.3 * (0.5 * width / fx),
        (width - cx + reach) / fx + 0.3 * (0.5 * width / fx),
        (cy + reach) / fy + 0.3 * (0.5 * height / fy),
        (height - cy + reach) / fy + 0.3 * (0.5 * height / fy),
    )


def fitted_size(view_width: int, view_height: int, box_width: int, box_height: int) -> tuple[int, int]:
    """``(width, height)`` pixels: the largest image of the view's aspect ratio
    ``view_width : view_height`` inside the box ``box_width × box_height`` (pixels).

    The side that binds takes the box's size; the other is the view's aspect times it, rounded,
    at least 1 px. A side within one pixel of the box's keeps the box's size, so a view already
    at the box's aspect (a 4:3 view asked at 4:3, a 1296×968 view at 320×240) keeps exactly the
    size asked: the aspect then changes by under one pixel across the image, no more than rounding
    does. The result may be larger than the view (a re-render, not an interpolation)."""
    vw, vh, bw, bh = (int(v) for v in (view_width, view_height, box_width, box_height))
    if min(vw, vh, bw, bh) < 1:
        raise InvalidDataError(f"fitted_size: sizes must be positive pixels, got view {vw}x{vh}, box {bw}x{bh}")
    if bw * vh <= bh * vw:  # the width binds
        exact = vh * bw / vw
        return bw, (bh if abs(bh - exact) <= 1.0 else min(bh, max(1, round(exact))))
    exact = vw * bh / vh
    return (bw if abs(bw - exact) <= 1.0 else min(bw, max(1, round(exact)))), bh


#: ``capture_focal`` / the camera's own focal, per axis: 2⁻¹⁶–2¹⁶, wider than any resize the image
#: size policy allows (16384 px a side to 1 px and back), so resizing a captured camera never fails,
#: while a hostile value (1e-300, 1e300) is refused.
CAPTURE_SCALE_RANGE = (2.0**-16, 2.0**16)


@dataclass(frozen=True)
class FisheyeLens:
    """Equidistant fisheye distortion (OpenCV fisheye model).

    Attributes:
        k1..k4: radial polynomial coefficients (dimensionless, θ in radians).
        max_theta: largest ray angle from the optical axis that the lens images, radians,
            in (0, π). Rays beyond it map to no pixel.
    """

    k1: float = 0.0
    k2: float = 0.0
    k3: float = 0.0
    k4: float = 0.0
    max_theta: float = math.pi / 2

    def __post_init__(self) -> None:
        for name in ("k1", "k2", "k3", "k4", "max_theta"):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or not math.isfinite(value):
                raise InvalidDataError(f"{_SOURCE}: fisheye {name} must be a finite number, got {value!r}")
            object.__setattr__(self, name, float(value))
        if not 0.0 < self.max_theta < math.pi:
            raise InvalidDataError(f"{_SOURCE}: fisheye max_theta must be in (0, π) radians, got {self.max_theta}")

    @property
    def coeffs(self) -> tuple[float, float, float, float]:
        return (self.k1, self.k2, self.k3, self.k4)

    def distort_theta(self, theta: np.ndarray) -> np.ndarray:
        """``θ_d(θ)`` for ray angles θ (radians)."""
        return equidistant_theta_d(theta, self.k1, self.k2, self.k3, self.k4)

    def distort_theta_derivative(self, theta: np.ndarray) -> np.ndarray:
        """``dθ_d/dθ = 1 + 3 k1 θ² + 5 k2 θ⁴ + 7 k3 θ⁶ + 9 k4 θ⁸``."""
        return equidistant_theta_d_slope(theta, self.k1, self.k2, self.k3, self.k4)

    def undistort_theta(self, theta_d: np.ndarray) -> np.ndarray:
        """Ray angles θ (radians) with ``θ_d(θ) = theta_d``, on the one-to-one range [0, effective max θ].

        ``theta_d`` beyond the image circle (``> θ_d(effective max θ)``) gives the effective
        maximum. Bisection, 60 halvings (float64 resolution), compiled
        (:func:`spacedg.render.lens_cpu.undistort_theta`). Returns float64 of ``theta_d``'s shape (a numpy
        scalar for a scalar).
        """
        from spacedg.render.lens_cpu import undistort_theta

        return undistort_theta(theta_d, self.k1, self.k2, self.k3, self.k4, self.effective_max_theta)

    @cached_property
    def effective_max_theta(self) -> float:
        """Largest ray angle (radians) the lens maps one-to-one: ``min(max_theta, fold)``.

        Strong barrel coefficients make ``θ_d(θ)`` turn back (the bench preset k1 = −0.24
        folds near θ ≈ 1.18 rad): beyond the fold two rays land on one pixel and the
        Jacobian changes sign. The renderer treats the fold as the edge of the image circle.
        The fold is found on a dense grid and refined by bisection to ~1e-12 rad.
        """
        grid = np.linspace(0.0, self.max_theta, 4097)
        slope = self.distort_theta_derivative(grid)
        bad = np.flatnonzero(slope <= 0.0)
        if bad.size == 0:
            return self.max_theta
        lo, hi = float(grid[bad[0] - 1]), float(grid[bad[0]])
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            if self.distort_theta_derivative(np.float64(mid)) > 0.0:
                lo = mid
            else:
                hi = mid
        return lo


@dataclass(frozen=True, eq=False)
class Camera:
    """A calibrated camera: intrinsics in pixels, pose as cam-to-world, optional fisheye lens.

    Attributes:
        fx, fy: focal lengths, pixels (> 0).
        cx, cy: principal point, pixels (pixel centres at +0.5).
        width, height: image size, pixels, within the size policy of :mod:`spacedg.limits`
            (at most 16384 a side and 2²⁵ pixels in all).
        cam_to_world: (4, 4) rigid transform, OpenCV camera axes, metres.
        fisheye: ``None`` for a pinhole camera, else the equidistant lens.
        capture_focal: ``(fx, fy)`` pixels of the images the Gaussians were optimised on, when known
            (the capture importers set it: the camera files' own, or an INRIA output's training
            size; :meth:`resized` and :meth:`fitted` keep it). 3DGS training dilates every footprint by ``eps2d`` (0.3 px²) in
            *those* pixels, so that dilation is part of the trained model: rendered at focal ``fx``
            (scale ``s = fx / capture fx``) it is ``eps2d · s²`` output px², and where ``s < 1`` a
            low-pass of the capture pixels' area-average is added with the opacity compensated (as
            Mip-Splatting's 2D filter), so a smaller render is the area-average of the native one
            (issue 29: size invariance on real captures). Within 2⁻¹⁶–2¹⁶× the camera's own focal.
            ``None``: no training scale is known; the classic 3DGS dilation (``eps2d`` in output
            pixels, uncompensated). See :func:`spacedg.render.settings.footprint_dilation`.
    """

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int
    cam_to_world: np.ndarray = field(repr=False)
    fisheye: FisheyeLens | None = None
    capture_focal: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        for name in ("fx", "fy", "cx", "cy"):
            object.__setattr__(self, name, finite_float(getattr(self, name), f"{_SOURCE}: {name}"))
        if self.fx <= 0 or self.fy <= 0:
            raise InvalidDataError(f"{_SOURCE}: focal lengths must be > 0 pixels (got fx={self.fx}, fy={self.fy})")
        if self.capture_focal is not None:
            pair = tuple(self.capture_focal) if isinstance(self.capture_focal, (tuple, list, np.ndarray)) else ()
            if len(pair) != 2:
                raise InvalidDataError(f"{_SOURCE}: capture_focal must be (fx, fy) pixels or None, got {self.capture_focal!r}")
            focal = tuple(finite_float(v, f"{_SOURCE}: capture_focal") for v in pair)
            ratios = (focal[0] / self.fx, focal[1] / self.fy) if min(focal) > 0 else (0.0, 0.0)
            if not all(CAPTURE_SCALE_RANGE[0] <= r <= CAPTURE_SCALE_RANGE[1] for r in ratios):
                raise InvalidDataError(
                    f"{_SOURCE}: capture_focal {focal} px must be > 0 and within {CAPTURE_SCALE_RANGE[0]:g}–"
                    f"{CAPTURE_SCALE_RANGE[1]:g}× the camera's own focal lengths ({self.fx:g}, {self.fy:g}); it is the "
                    "focal of the images the Gaussians were trained on"
                )
            object.__setattr__(self, "capture_focal", focal)
        for name in ("width", "height"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or int(value) < 1:
                raise InvalidDataError(f"{_SOURCE}: {name} must be a positive integer number of pixels, got {value!r}")
            object.__setattr__(self, name, int(value))
        check_image_size(
            self.width, self.height, _SOURCE,
            "resize the camera (scale fx, fy, cx, cy with width and height, e.g. Camera.resized) or render smaller",
        )
        pose = np.array(self.cam_to_world, dtype=np.float64)
        if pose.shape != (4, 4):
            raise InvalidDataError(f"{_SOURCE}: cam_to_world must be 4×4, got shape {pose.shape}")
        require_homogeneous(pose, f"{_SOURCE}: cam_to_world")
        require_rotation(pose[:3, :3], "cam_to_world rotation", _SOURCE, tol=1e-5)
        pose.flags.writeable = False
        object.__setattr__(self, "cam_to_world", pose)

    # ------------------------------------------------------------------ pose
    @property
    def rotation(self) -> np.ndarray:
        """(3, 3) camera-to-world rotation; columns are the camera's x (right), y (down), z (forward)."""
        return self.cam_to_world[:3, :3]

    @property
    def center(self) -> np.ndarray:
        """(3,) camera centre in world coordinates, metres."""
        return self.cam_to_world[:3, 3]

    @property
    def forward(self) -> np.ndarray:
        """(3,) unit viewing direction (camera +z) in world coordinates."""
        return self.cam_to_world[:3, 2]

    @property
    def world_to_cam(self) -> np.ndarray:
        """(4, 4) inverse of :attr:`cam_to_world`."""
        out = np.eye(4)
        rot_t = self.rotation.T
        out[:3, :3] = rot_t
        out[:3, 3] = -rot_t @ self.center
        return out

    @property
    def is_fisheye(self) -> bool:
        return self.fisheye is not None

    @property
    def K(self) -> np.ndarray:  # noqa: N802 - the usual name of the intrinsics matrix
        """(3, 3) intrinsics matrix ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]``."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def as_captured(self) -> Camera:
        """This camera marked as the one the Gaussians were optimised on (``capture_focal`` = its own
        focal lengths); a camera already marked is returned unchanged."""
        return self if self.capture_focal is not None else replace(self, capture_focal=(self.fx, self.fy))

    def with_pose(self, cam_to_world: np.ndarray) -> Camera:
        """Same intrinsics and lens at another pose."""
        return replace(self, cam_to_world=cam_to_world)

    def resized(self, width: int, height: int) -> Camera:
        """The same camera imaging at another resolution (intrinsics scaled per axis).

        This changes the image's aspect ratio when ``width : height`` differs from the view's
        (the picture is squeezed); a requested image size goes through :meth:`fitted` instead."""
        sx, sy = width / self.width, height / self.height
        return replace(self, fx=self.fx * sx, fy=self.fy * sy, cx=self.cx * sx, cy=self.cy * sy, width=width, height=height)

    def fitted(self, width: int, height: int) -> Camera:
        """This camera at the largest image of its own aspect ratio that fits in ``width × height``
        pixels (a bounding box): the one size policy of every command and API that takes an image
        size (``--image-size``, ``SpaceDGDataset(image_size=...)``, ``export``, ``predict``, the QA
        preview and judge renders). Nothing is cropped and no pixel is squeezed: a 1920×1080 view
        asked at 320×240 renders at 320×180, a 640×480 view at 320×240 (see :func:`fitted_size`).
        The intrinsics are scaled per axis with the rounded size (:meth:`resized`), so pixels and
        intrinsics stay consistent. Returns ``self`` when the size is unchanged."""
        size = fitted_size(self.width, self.height, width, height)
        return self if size == (self.width, self.height) else self.resized(*size)

    def widened(self, margin: int) -> Camera:
        """The same camera with its image grown by ``margin`` pixels on every side (principal point
        shifted by ``margin``; same focal lengths, pose and lens)."""
        return replace(
            self, cx=self.cx + margin, cy=self.cy + margin, width=self.width + 2 * margin, height=self.height + 2 * margin
        )

    # ------------------------------------------------------------ projection
    def to_camera(self, points_world: np.ndarray) -> np.ndarray:
        """(N, 3) world points → (N, 3) camera coordinates (float64)."""
        pts = np.asarray(points_world, dtype=np.float64).reshape(-1, 3)
        return (pts - self.center) @ self.rotation

    def project(self, points_world: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Project world points to pixels.

        Returns:
            ``(uv, depth, valid)``: (N, 2) pixel coordinates (float64, 0 where invalid),
            (N,) camera-space z in metres, and (N,) bool: in front of the camera for a
            pinhole (z > 0), within ``max_theta`` for a fisheye. ``valid`` does not test the
            image bounds; see :meth:`in_image`.
        """
        cam = self.to_camera(points_world)
        x, y, z = cam[:, 0], cam[:, 1], cam[:, 2]
        uv = np.zeros((cam.shape[0], 2))
        if self.fisheye is None:
            valid = z > 0
            zs = np.where(valid, z, 1.0)
            uv[:, 0] = self.fx * x / zs + self.cx
            uv[:, 1] = self.fy * y / zs + self.cy
        else:
            r = np.hypot(x, y)
            theta = np.arctan2(r, z)
            valid = theta <= self.fisheye.max_theta
            theta_d = self.fisheye.distort_theta(theta)
            # θ_d / r → 1/z as r → 0 (on-axis rays): use that limit to avoid 0/0.
            tiny = r <= 1e-12 * np.maximum(np.abs(z), 1e-300)
            scale = np.where(tiny, 1.0 / np.where(z > 0, z, 1.0), theta_d / np.where(tiny, 1.0, r))
            uv[:, 0] = self.fx * scale * x + self.cx
            uv[:, 1] = self.fy * scale * y + self.cy
        uv[~valid] = 0.0
        return uv, z, valid

    def in_image(self, uv: np.ndarray) -> np.ndarray:
        """(N,) bool: pixel coordinates inside ``[0, width) × [0, height)``."""
        return (uv[:, 0] >= 0) & (uv[:, 0] < self.width) & (uv[:, 1] >= 0) & (uv[:, 1] < self.height)

    # ----------------------------------------------------------- (de)serialise
    def to_dict(self) -> dict[str, Any]:
        """JSON-friendly dict (the native scene format's camera record)."""
        out: dict[str, Any] = {
            "model": "fisheye" if self.fisheye else "pinhole",
            "fx": self.fx,
            "fy": self.fy,
            "cx": self.cx,
            "cy": self.cy,
            "width": self.width,
            "height": self.height,
            "cam_to_world": self.cam_to_world.tolist(),
        }
        if self.fisheye is not None:
            out.update(
                k1=self.fisheye.k1, k2=self.fisheye.k2, k3=self.fisheye.k3, k4=self.fisheye.k4,
                max_theta=self.fisheye.max_theta,
            )
        if self.capture_focal is not None:
            out["capture_focal"] = list(self.capture_focal)
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Camera:
        """Inverse of :meth:`to_dict`; raises :class:`InvalidDataError` naming a missing key."""
        required = ("fx", "fy", "cx", "cy", "width", "height", "cam_to_world")
        missing = [k for k in required if k not in data]
        if missing:
            raise InvalidDataError(f"{_SOURCE}: missing key(s) {missing}; a camera needs {list(required)}")
        model = data.get("model", "pinhole")
        if model not in ("pinhole", "fisheye"):
            raise InvalidDataError(f"{_SOURCE}: unknown model {model!r}; use 'pinhole' or 'fisheye'")
        lens = None
        if model == "fisheye":
            lens = FisheyeLens(
                data.get("k1", 0.0), data.get("k2", 0.0), data.get("k3", 0.0), data.get("k4", 0.0),
                data.get("max_theta", math.pi / 2),
            )
        return cls(
            data["fx"], data["fy"], data["cx"], data["cy"], data["width"], data["height"],
            np.asarray(data["cam_to_world"], dtype=np.float64), lens, data.get("capture_focal"),
        )


def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray) -> np.ndarray:
    """(4, 4) OpenCV cam-to-world placing the camera at ``eye`` looking at ``target``.

    ``up`` is the world's up direction; the image's "down" axis is aligned with ``-up``
    projected onto the image plane (no roll). Raises if ``target - eye`` is parallel to ``up``.
    """
    eye = np.asarray(eye, dtype=np.float64)
    forward = np.asarray(target, dtype=np.float64) - eye
    norm = np.linalg.norm(forward)
    if norm < 1e-12:
        raise InvalidDataError("look_at: eye and target coincide")
    forward /= norm
    right = np.cross(forward, np.asarray(up, dtype=np.float64))
    rn = np.linalg.norm(right)
    if rn < 1e-9:
        raise InvalidDataError("look_at: viewing direction is parallel to up; roll is undefined")
    right /= rn
    down = np.cross(forward, right)
    pose = np.eye(4)
    pose[:3, 0], pose[:3, 1], pose[:3, 2], pose[:3, 3] = right, down, forward, eye
    return pose


# ------------------------------------------------------------------ pose interpolation
def rotvec_to_matrix(rotvec: np.ndarray) -> np.ndarray:
    """(3,) axis-angle vector (radians, right-handed) → (3, 3) rotation (Rodrigues, float64)."""
    vec = np.asarray(rotvec, dtype=np.float64).reshape(3)
    angle = float(np.linalg.norm(vec))
    if angle < 1e-12:
        return np.eye(3)
    axis = vec / angle
    kx = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return np.eye(3) + math.sin(angle) * kx + (1.0 - math.cos(angle)) * (kx @ kx)


def matrix_to_rotvec(rotation: np.ndarray) -> np.ndarray:
    """(3, 3) rotation → (3,) axis-angle vector with angle in [0, π] (float64)."""
    w, x, y, z = quat_from_matrix(rotation)
    sin_half = math.sqrt(x * x + y * y + z * z)
    if sin_half < 1e-15:
        return np.zeros(3)
    angle = 2.0 * math.atan2(sin_half, w)
    return np.array([x, y, z]) * (angle / sin_half)


def interpolate_pose(pose_a: np.ndarray, pose_b: np.ndarray, u: float) -> np.ndarray:
    """Cam-to-world pose a fraction ``u`` of the way from ``pose_a`` to ``pose_b``.

    Rotation: slerp (constant angular speed about the fixed relative axis); centre: lerp.
    ``u = 0`` returns ``pose_a`` and ``u = 1`` returns ``pose_b`` exactly.
    """
    a = np.asarray(pose_a, dtype=np.float64)
    b = np.asarray(pose_b, dtype=np.float64)
    if u == 0.0:
        return a.copy()
    if u == 1.0:
        return b.copy()
    relative = a[:3, :3].T @ b[:3, :3]
    out = np.eye(4)
    out[:3, :3] = a[:3, :3] @ rotvec_to_matrix(u * matrix_to_rotvec(relative))
    out[:3, 3] = (1.0 - u) * a[:3, 3] + u * b[:3, 3]
    return out


def exposure_poses(
    camera: Camera, translation: np.ndarray, rotation: np.ndarray, times: np.ndarray
) -> list[np.ndarray]:
    """Cam-to-world poses of a camera moving during one exposure.

    The camera's own pose is the **mid-exposure** pose. Over the exposure the centre moves
    by ``translation`` (3,) metres and the camera turns by ``rotation`` (3,) (axis-angle,
    radians), both given in the mid-exposure *camera* frame (x right, y down, z forward).
    ``times`` are in [-0.5, 0.5] (fraction of the exposure, 0 = mid): the pose at time s is
    the centre moved by ``s·translation`` and the orientation turned by ``s·rotation``,
    which is exactly the slerp/lerp between the start (s = -½) and end (s = ½) poses.
    """
    rot = camera.rotation
    move_world = rot @ np.asarray(translation, dtype=np.float64).reshape(3)
    turn = np.asarray(rotation, dtype=np.float64).reshape(3)
    poses = []
    for s in np.asarray(times, dtype=np.float64).reshape(-1):
        pose = np.eye(4)
        pose[:3, :3] = rot @ rotvec_to_matrix(s * turn)
        pose[:3, 3] = camera.center + s * move_world
        poses.append(pose)
    return poses
