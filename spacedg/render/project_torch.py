"""Projection physics in readable torch: EWA splatting, fisheye Jacobian, circle of confusion, culling.

This is the reference twin of the compiled :mod:`spacedg.render.project_cpu` (same steps,
same order; see its module docstring) and the production projection on a GPU. It runs on
any torch device and dtype; the oracle tests run it in float64 on the CPU.
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass

import numpy as np
import torch

from spacedg.render.camera import Camera, frustum_limits
from spacedg.render.lens_polynomial import equidistant_theta_d, equidistant_theta_d_slope
from spacedg.render.gaussians import Gaussians, quat_to_matrix, sh_basis
from spacedg.render.settings import ALPHA_MIN, DEFOCUS_MIN_COC, FOOTPRINT_CAP, TILE_SIZE, Defocus, RasterSettings, footprint_dilation

_TENSOR_CACHE: "weakref.WeakKeyDictionary[Gaussians, dict]" = weakref.WeakKeyDictionary()


@dataclass
class GaussianTensors:
    """The arrays of a :class:`Gaussians` as tensors on one device (cached per Gaussians object)."""

    means: torch.Tensor
    quats: torch.Tensor
    scales: torch.Tensor
    opacities: torch.Tensor
    sh: torch.Tensor
    instance_ids: torch.Tensor  # int32, -1 where none

    @classmethod
    def of(cls, gaussians: Gaussians, device: torch.device | str, dtype: torch.dtype) -> GaussianTensors:
        per_object = _TENSOR_CACHE.setdefault(gaussians, {})
        key = (str(torch.device(device)), dtype)
        if key not in per_object:
            ids = gaussians.instance_ids if gaussians.instance_ids is not None else np.full(len(gaussians), -1, np.int32)

            def put(a: np.ndarray, dt: torch.dtype) -> torch.Tensor:
                return torch.from_numpy(np.array(a)).to(device=device, dtype=dt)

            per_object[key] = cls(
                put(gaussians.means, dtype), put(gaussians.quats, dtype), put(gaussians.scales, dtype),
                put(gaussians.opacities, dtype), put(gaussians.sh, dtype), put(ids, torch.int32),
            )
        return per_object[key]


@dataclass
class Projected:
    """Per-Gaussian screen-space record (tensors, length N; culled entries have ``radii == 0``).

    Attributes:
        means2d: (N, 2) pixel coordinates of the projected mean.
        conics: (N, 3) inverse 2D covariance ``(a, b, c)``: ``σ = ½(a dx² + c dy²) + b dx dy``.
        opacities: (N,) opacity after antialiasing/defocus compensation.
        alpha_floor: (N,) smallest alpha composited: 1/255, times the defocus compensation
            (a blurred Gaussian keeps the same fraction of its energy as the sharp one).
        colors: (N, 3) sRGB-encoded colour along the view direction (``None`` if not requested).
        depths: (N,) camera z, metres.
        radii: (N, 2) int32 footprint half-extent in pixels; (0, 0) = culled.
        rects: (N, 4) int32 tile rectangle ``x0, x1, y0, y1`` (exclusive ends).
        coc: (N,) defocus circle-of-confusion radius, pixels (0 = sharp; all 0 without defocus;
            ``None`` in records built by hand).
    """

    means2d: torch.Tensor
    conics: torch.Tensor
    opacities: torch.Tensor
    colors: torch.Tensor | None
    depths: torch.Tensor
    radii: torch.Tensor
    rects: torch.Tensor
    alpha_floor: torch.Tensor
    coc: torch.Tensor | None = None

    @property
    def visible(self) -> torch.Tensor:
        return (self.radii > 0).all(dim=-1)


def small_matmul(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """``a @ b`` for stacks of tiny matrices (2×3, 3×3, …; leading dimensions broadcast), written as
    one broadcast product and one sum: batched GEMM on millions of 3×3 matrices is launch- and
    occupancy-bound on a GPU (it was most of a 1M-Gaussian projection on an H200)."""
    return (a.unsqueeze(-1) * b.unsqueeze(-3)).sum(-2)


def quat_scale_to_covariance(quats: torch.Tensor, scales: torch.Tensor) -> torch.Tensor:
    """(N, 3, 3) covariance ``R S Sᵀ Rᵀ`` from wxyz quaternions (normalised here) and scales (m)."""
    m = quat_to_matrix(quats / quats.norm(dim=-1, keepdim=True)) * scales[:, None, :]
    return small_matmul(m, m.transpose(-1, -2))


def pinhole_jacobian(cam: torch.Tensor, camera: Camera, reach: float = 0.0) -> torch.Tensor:
    """(N, 2, 3) Jacobian of ``(fx x/z + cx, fy y/z + cy)``, x/z and y/z clamped to the frustum
    widened by 0.3·tan(fov/2) (as gsplat, so off-screen Gaussians do not explode) and by
    ``reach`` pixels (how far a blurred footprint reaches into the view under defocus)."""
    x, y, z = cam.unbind(-1)
    fx, fy, cx, cy, w, h = camera.fx, camera.fy, camera.cx, camera.cy, camera.width, camera.height
    lim_x_neg, lim_x_pos, lim_y_neg, lim_y_pos = frustum_limits(fx, fy, cx, cy, w, h, reach)
    tx = z * torch.clamp(x / z, -lim_x_neg, lim_x_pos)
    ty = z * torch.clamp(y / z, -lim_y_neg, lim_y_pos)
    zero = torch.zeros_like(z)
    return torch.stack([fx / z, zero, -fx * tx / (z * z), zero, fy / z, -fy * ty / (z * z)], dim=-1).reshape(-1, 2, 3)


def fisheye_terms(cam: torch.Tensor, k: tuple[float, float, float, float]) -> tuple[torch.Tensor, ...]:
    """Equidistant lens terms at camera points (z > 0): ``(theta, rho, g, drho_dz)``.

    ``rho = θ_d / r`` (pixel = f·rho·(x, y) + c), ``g = (∂rho/∂x)/x = (∂rho/∂y)/y`` and
    ``∂rho/∂z = −θ_d'(θ) / (r² + z²)``. For ``r < 1e-4 z`` the series limits
    ``rho = (1 + (k1 − ⅓) r²/z²)/z`` and ``g = 2 (k1 − ⅓)/z³`` replace the 0/0 forms.
    """
    k1, k2, k3, k4 = k
    x, y, z = cam.unbind(-1)
    r2 = x * x + y * y
    r = torch.sqrt(r2)
    rz2 = r2 + z * z
    theta = torch.atan2(r, z)
    theta_d = equidistant_theta_d(theta, k1, k2, k3, k4)
    dtheta_d = equidistant_theta_d_slope(theta, k1, k2, k3, k4)
    near_axis = r < 1e-4 * z
    r_safe = torch.where(near_axis, torch.ones_like(r), r)
    rho = torch.where(near_axis, (1 + (k1 - 1 / 3) * r2 / (z * z)) / z, theta_d / r_safe)
    g = torch.where(near_axis, 2 * (k1 - 1 / 3) / (z * z * z), (dtheta_d * z / rz2 - theta_d / r_safe) / (r_safe * r_safe))
    return theta, rho, g, -dtheta_d / rz2


def fisheye_jacobian(cam: torch.Tensor, camera: Camera) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Fisheye projection of camera points: ``(uv (N, 2), J (N, 2, 3), theta (N,))``."""
    lens = camera.fisheye
    assert lens is not None
    x, y, _ = cam.unbind(-1)
    theta, rho, g, drho_dz = fisheye_terms(cam, lens.coeffs)
    fx, fy = camera.fx, camera.fy
    uv = torch.stack([fx * rho * x + camera.cx, fy * rho * y + camera.cy], dim=-1)
    jac = torch.stack(
        [fx * (rho + x * x * g), fx * x * y * g, fx * x * drho_dz, fy * x * y * g, fy * (rho + y * y * g), fy * y * drho_dz],
        dim=-1,
    ).reshape(-1, 2, 3)
    return uv, jac, theta


def _wide_dtype(dtype: torch.dtype, device: torch.device) -> torch.dtype:
    """float64 for the covariance algebra where the device has it (Apple's MPS has not)."""
    return dtype if device.type == "mps" else torch.float64


def project_gaussians(
    gs: GaussianTensors,
    camera: Camera,
    settings: RasterSettings,
    defocus: Defocus | None = None,
    want_color: bool = True,
) -> Projected:
    """Project every Gaussian into ``camera`` (see the module docstring of ``project_cpu``).

    Means and colours are computed in the tensors' dtype; the covariances (3D, 2D, their
    determinants, the compensations and conics) in float64, as the compiled path does: a
    Gaussian kilometres wide seen from close by has a 2D covariance whose determinant
    overflows float32 (its conic would be NaN and the Gaussian culled), and both paths must
    render it the same way.
    """
    dtype, device = gs.means.dtype, gs.means.device
    wide = _wide_dtype(dtype, device)
    view = torch.tensor(camera.world_to_cam, dtype=dtype, device=device)
    rot, trans = view[:3, :3], view[:3, 3]
    cam = gs.means @ rot.T + trans
    z = cam[:, 2]
    in_range = (z > settings.near) & (z < settings.far)
    # keep the maths finite for culled entries: project them as if at z = 1
    cam_safe = torch.where(in_range[:, None], cam, torch.tensor([0.0, 0.0, 1.0], dtype=dtype, device=device))
    rot_w = rot.to(wide)
    cov_cam = small_matmul(small_matmul(rot_w, quat_scale_to_covariance(gs.quats.to(wide), gs.scales.to(wide))), rot_w.T)
    if camera.fisheye is None:
        zs = cam_safe[:, 2:3]
        means2d = cam_safe[:, :2] / zs * torch.tensor([camera.fx, camera.fy], dtype=dtype, device=device) + torch.tensor(
            [camera.cx, camera.cy], dtype=dtype, device=device
        )
        reach = 0.0
        if defocus is not None and defocus.aperture > 0:
            reach = float(defocus.max_radius) * (settings.defocus_extent if settings.defocus_extent is not None else 3.33)
        jac = pinhole_jacobian(cam_safe, camera, reach)
        lens_ok = torch.ones_like(in_range)
    else:
        means2d, jac, theta = fisheye_jacobian(cam_safe, camera)
        lens_ok = theta <= camera.fisheye.effective_max_theta
    jac = jac.to(wide)
    cov2d = small_matmul(small_matmul(jac, cov_cam), jac.transpose(-1, -2))
    sxx, sxy, syy = cov2d[:, 0, 0], cov2d[:, 0, 1], cov2d[:, 1, 1]
    model_x, model_y, filter_x, filter_y = footprint_dilation(camera, settings)
    sxx, syy = sxx + model_x, syy + model_y
    opacity = gs.opacities.to(wide)
    alpha_floor = torch.full_like(opacity, ALPHA_MIN)
    if filter_x > 0.0 or filter_y > 0.0:  # a low-pass with the opacity compensated (the floor stays 1/255, as gsplat's)
        det_model = sxx * syy - sxy * sxy
        sxx, syy = sxx + filter_x, syy + filter_y
        # as the CPU path: 0/0 is 0, not NaN
        opacity = opacity * torch.sqrt(torch.clamp(det_model / torch.clamp(sxx * syy - sxy * sxy, min=1e-300), min=0.0))
    det = sxx * syy - sxy * sxy
    coc = torch.zeros_like(opacity)
    if defocus is not None and defocus.aperture > 0:
        z_w = cam_safe[:, 2].to(wide)
        coc = torch.clamp(defocus.aperture * torch.abs(z_w - defocus.focus) / z_w, max=defocus.max_radius)
        coc = torch.where(coc < DEFOCUS_MIN_COC, torch.zeros_like(coc), coc)  # below DEFOCUS_MIN_COC: sharp
        sxx, syy = sxx + coc * coc, syy + coc * coc
        det_blur = sxx * syy - sxy * sxy
        compensation = torch.sqrt(torch.clamp(det / torch.clamp(det_blur, min=1e-300), min=0.0))  # as the CPU path: 0/0 is 0, not NaN
        opacity = opacity * compensation
        alpha_floor = alpha_floor * compensation
        det = det_blur
        if settings.defocus_extent is not None:  # truncate blurred footprints, keeping their energy
            tail = math.exp(-0.5 * settings.defocus_extent**2)
            truncated = coc > 1.0
            opacity = torch.where(truncated, opacity / (1.0 - tail), opacity)
            alpha_floor = torch.where(truncated, torch.maximum(alpha_floor, opacity * tail), alpha_floor)
    det = torch.clamp(det, min=1e-10)
    conics = torch.stack([syy / det, -sxy / det, sxx / det], dim=-1)
    if settings.opacity_extent:
        opaque_enough = opacity >= alpha_floor
        ratio = torch.clamp(opacity / torch.clamp(alpha_floor, min=1e-30), min=1.0)
        extent = torch.clamp(torch.sqrt(2.0 * torch.log(ratio)), max=3.33)
    else:
        opaque_enough = torch.ones_like(in_range)
        extent = torch.full_like(opacity, 3.33)
    radii = torch.ceil(torch.clamp(torch.stack([extent * torch.sqrt(sxx), extent * torch.sqrt(syy)], dim=-1), max=FOOTPRINT_CAP))
    finite = torch.isfinite(means2d).all(-1) & torch.isfinite(conics).all(-1) & torch.isfinite(radii).all(-1)
    finite = finite & torch.isfinite(det) & torch.isfinite(opacity)
    on_screen = (
        (means2d[:, 0] + radii[:, 0] > 0) & (means2d[:, 0] - radii[:, 0] < camera.width)
        & (means2d[:, 1] + radii[:, 1] > 0) & (means2d[:, 1] - radii[:, 1] < camera.height)
    )
    keep = in_range & lens_ok & opaque_enough & finite & on_screen & (radii > 0).all(-1) & (alpha_floor > 0)  # as the CPU path
    tiles_x = (camera.width + TILE_SIZE - 1) // TILE_SIZE
    tiles_y = (camera.height + TILE_SIZE - 1) // TILE_SIZE
    lo = torch.floor((means2d.to(wide) - radii) / TILE_SIZE)
    hi = torch.ceil((means2d.to(wide) + radii) / TILE_SIZE)
    limits = torch.tensor([tiles_x, tiles_y], dtype=wide, device=device)
    lo = torch.minimum(torch.clamp(torch.nan_to_num(lo), min=0), limits)
    hi = torch.minimum(torch.clamp(torch.nan_to_num(hi), min=0), limits)
    keep = keep & (hi > lo).all(-1)
    rects = torch.stack([lo[:, 0], hi[:, 0], lo[:, 1], hi[:, 1]], dim=-1).to(torch.int32) * keep[:, None]
    radii = torch.where(keep[:, None], radii, torch.zeros_like(radii)).to(torch.int32)
    colors = None
    if want_color:
        center = torch.tensor(np.array(camera.center), dtype=dtype, device=device)
        dirs = gs.means - center
        dirs = dirs / torch.clamp(dirs.norm(dim=-1, keepdim=True), min=1e-30)
        degree = int(round(math.sqrt(gs.sh.shape[1]))) - 1
        basis = sh_basis(degree, dirs)
        colors = torch.clamp((basis.unsqueeze(-1) * gs.sh).sum(-2) + 0.5, min=0.0)
    return Projected(
        means2d, conics.to(dtype), opacity.to(dtype), colors, z, radii, rects, alpha_floor.to(dtype),
        torch.where(keep, coc, torch.zeros_like(coc)).to(dtype),
    )
