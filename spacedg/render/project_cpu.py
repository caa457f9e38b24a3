"""Compiled (numba) projection: one fused pass per Gaussian, parallel over Gaussians.

Same physics as the readable torch twin :mod:`spacedg.render.project_torch` (tested against it,
against gsplat's torch reference and against float64 finite differences):

1. world → camera (OpenCV axes); cull ``z <= near`` or ``z >= far``.
2. 3D covariance ``Σ = R S Sᵀ Rᵀ`` from the wxyz quaternion and scales, rotated into the camera.
3. 2D covariance ``J Σ Jᵀ`` with the exact Jacobian ``J`` of the lens map at the mean:
   pinhole (x/z, y/z clamped to the frustum widened by 0.3·tan(fov/2), as gsplat, and under
   defocus also by the reach of the widest blurred footprint, ``defocus_extent · max_radius``
   px: a Gaussian outside the view whose blur reaches into it needs its true footprint), or
   equidistant fisheye with k1..k4 (rays beyond the lens's effective max θ are culled).
4. the dilation of :func:`~spacedg.render.settings.footprint_dilation` (``+ eps2d·I`` classic; the
   training dilation plus a compensated low-pass when the camera knows its capture's focal or
   the render is antialiased); optional defocus
   (``+ r_CoC²·I`` with the sqrt-det opacity compensation taken after the dilation).
5. alpha floor ``f = 1/255``, times the defocus compensation under defocus (a blurred
   Gaussian then keeps the same fraction of its energy as the sharp one; with a fixed 1/255
   a small Gaussian spread over a large CoC would lose its tails or vanish); cull
   ``opacity < f``; footprint radius ``ceil(extent·sqrt(Σ_ii))`` per axis (capped at
   ``FOOTPRINT_CAP`` = 2³⁰ px) with
   ``extent = min(3.33, sqrt(2 ln(o / f)))``; cull footprints outside the image. A defocused
   Gaussian (CoC > 1 px) is truncated at ``settings.defocus_extent`` σ instead, its opacity
   divided by the mass kept (``f = max(f, o e^(−E²/2))``), so its energy is unchanged.
6. colour from SH along the camera-centre → mean direction, ``max(0, 0.5 + Σ sh·Y)``.

Everything is computed in float64 and stored in float32. :func:`project_with_sharp` also projects into
a second camera of the same pose and lens in the same pass (defocus's sharp pass; steps 1, 2 and 6
done once), with the bytes a projection of its own gives. The result is a packed
``(N, PACKED)`` float32 array (one 64-byte cache line per Gaussian for the compositor) and an
``(N, 4)`` int32 tile rectangle ``[x0, x1) × [y0, y1)``, all zero for a culled Gaussian.
"""

from __future__ import annotations

import math

from typing import TYPE_CHECKING

import numba
import numpy as np

from spacedg.render.camera import frustum_limits
from spacedg.render.lens_cpu import theta_d as _theta_d
from spacedg.render.lens_cpu import theta_d_slope as _theta_d_slope
from spacedg.render.gaussians import _SH_C1, _SH_C2, _SH_C3, SH_C0
from spacedg.render.settings import DEFOCUS_MIN_COC, FOOTPRINT_CAP, footprint_dilation
from spacedg.render import kernel_cache  # noqa: F401 - numba's cache entries checked before any kernel here compiles
from spacedg.render.threads import fork_safe

if TYPE_CHECKING:
    from spacedg.render.camera import Camera
    from spacedg.render.gaussians import Gaussians
    from spacedg.render.settings import Defocus, RasterSettings

#: Columns of the packed per-Gaussian record (``COC``: the defocus blur radius, pixels; 0 = sharp).
PX, PY, CA, CB, CC, OPA, CR, CG, CBL, DEPTH, RADX, RADY, AMIN, COC = range(14)
PACKED = 14

_C1 = _SH_C1
_C20, _C21, _C22, _C23, _C24 = _SH_C2
_C30, _C31, _C32, _C33, _C34, _C35, _C36 = _SH_C3


@numba.njit(cache=True, inline="always")
def _sh_channel(sh, i, ch, degree, x, y, z):
    """``Σ_k sh[i, k, ch] Y_k(x, y, z)`` for bands up to ``degree`` (3DGS ordering)."""
    value = SH_C0 * sh[i, 0, ch]
    if degree >= 1:
        value += _C1 * (-y * sh[i, 1, ch] + z * sh[i, 2, ch] - x * sh[i, 3, ch])
    if degree >= 2:
        xx, yy, zz, xy, yz, xz = x * x, y * y, z * z, x * y, y * z, x * z
        value += (
            _C20 * xy * sh[i, 4, ch]
            + _C21 * yz * sh[i, 5, ch]
            + _C22 * (2.0 * zz - xx - yy) * sh[i, 6, ch]
            + _C23 * xz * sh[i, 7, ch]
            + _C24 * (xx - yy) * sh[i, 8, ch]
        )
        if degree >= 3:
            value += (
                _C30 * y * (3.0 * xx - yy) * sh[i, 9, ch]
                + _C31 * xy * z * sh[i, 10, ch]
                + _C32 * y * (4.0 * zz - xx - yy) * sh[i, 11, ch]
                + _C33 * z * (2.0 * zz - 3.0 * xx - 3.0 * yy) * sh[i, 12, ch]
                + _C34 * x * (4.0 * zz - xx - yy) * sh[i, 13, ch]
                + _C35 * z * (xx - yy) * sh[i, 14, ch]
                + _C36 * x * (xx - 3.0 * yy) * sh[i, 15, ch]
            )
    return value


#: the Jacobian's frustum (:func:`~spacedg.render.camera.frustum_limits`), widened by ``reach`` px
_frustum = numba.njit(cache=True, inline="always")(frustum_limits)


@numba.njit(cache=True, inline="always")
def _fisheye_terms(x, y, z, k1, k2, k3, k4):
    """Equidistant lens at camera point (x, y, z), z > 0.

    Returns ``(theta, rho, g, drho_dz)`` with ``rho = θ_d / r`` (so u = fx·rho·x + cx),
    ``g = (∂rho/∂x) / x = (∂rho/∂y) / y`` and ``∂rho/∂z``. Near the axis (r ≪ z) the
    series limits are used, so nothing divides by zero.
    """
    r2 = x * x + y * y
    r = math.sqrt(r2)
    rz2 = r2 + z * z
    theta = math.atan2(r, z)
    theta_d = _theta_d(theta, k1, k2, k3, k4)
    dtheta_d = _theta_d_slope(theta, k1, k2, k3, k4)
    drho_dz = -dtheta_d / rz2
    if r < 1e-4 * z:
        # θ = t − t³/3 + …, θ_d = θ + k1 θ³ + …  with t = r/z  ⇒  rho = (1 + (k1 − 1/3) t²)/z
        rho = (1.0 + (k1 - 1.0 / 3.0) * r2 / (z * z)) / z
        g = 2.0 * (k1 - 1.0 / 3.0) / (z * z * z)
    else:
        rho = theta_d / r
        g = (dtheta_d * z / rz2 - rho) / r2
    return theta, rho, g, drho_dz


@numba.njit(cache=True, inline="always")
def _surely_outside(
    x, y, z, scales, i, rot_norm, fx, fy, cx, cy, width, height, lim_x_neg, lim_x_pos, lim_y_neg, lim_y_pos, eps2d
):
    """Whether a pinhole Gaussian at camera point (x, y, z) is culled whatever its rotation.

    A coarse, exact frustum test before the covariance: ``Σ2D = J M Mᵀ Jᵀ`` with ``M = W R S``, so
    ``Σ_xx <= |J row 0|² ‖W‖² max(s)²`` (``rot_norm`` >= ‖W‖₂, R orthonormal), plus ``eps2d``: the
    dilation's largest term and, under defocus, the square of the Gaussian's circle of confusion; with
    ``extent <= 3.33`` (also for a blurred footprint, whose truncation is at most that) the footprint
    radius is at most ``ceil`` of that bound (taken 1e-6 relative wider, far above rounding), and a
    footprint that cannot reach the image is culled by the full test too.
    """
    u = fx * x / z + cx
    v = fy * y / z + cy
    if 0.0 <= u <= width and 0.0 <= v <= height:  # the mean is in view: kept by the full test
        return False
    tx = z * min(max(x / z, -lim_x_neg), lim_x_pos)
    ty = z * min(max(y / z, -lim_y_neg), lim_y_pos)
    inv_z = 1.0 / z
    jx = fx * inv_z * math.sqrt(1.0 + (tx * inv_z) ** 2)
    jy = fy * inv_z * math.sqrt(1.0 + (ty * inv_z) ** 2)
    return _box_outside(u, v, jx * jx, jy * jy, scales, i, rot_norm, eps2d, width, height)


@numba.njit(cache=True, inline="always")
def _box_outside(u, v, row_x2, row_y2, scales, i, rot_norm, eps2d, width, height):
    """Whether the footprint box of Gaussian ``i`` at pixel ``(u, v)`` whose Jacobian rows have squared norms at most
    ``row_x2``, ``row_y2`` misses a ``width × height`` image: radius ``ceil(3.33·√(row² · smax² + eps2d))`` per axis,
    ``smax`` its largest scale times ``rot_norm`` (≥ ‖W‖₂), all taken 1e-6 relative wider (far above rounding)."""
    smax = max(abs(float(scales[i, 0])), abs(float(scales[i, 1])), abs(float(scales[i, 2]))) * rot_norm * (1.0 + 1e-6)
    rad_x = np.ceil(3.33 * math.sqrt(row_x2 * smax * smax + eps2d) * (1.0 + 1e-6) + 1e-6)
    rad_y = np.ceil(3.33 * math.sqrt(row_y2 * smax * smax + eps2d) * (1.0 + 1e-6) + 1e-6)
    return u + rad_x <= 0 or u - rad_x >= width or v + rad_y <= 0 or v - rad_y >= height


@numba.njit(cache=True, inline="always")
def _surely_outside_fisheye(x, y, scales, i, rot_norm, fx, fy, cx, cy, width, height, terms, theta_max, eps2d):
    """:func:`_surely_outside` for the equidistant fisheye lens: culled whatever its rotation. Beyond the lens's
    effective max θ (the full test's first cull, the same terms), or a footprint box outside the image: the box
    bound of :func:`_surely_outside` with the fisheye Jacobian's rows at the mean (``‖J row‖ · ‖W‖₂ · max(s)``
    bounds ``√Σ_ii`` before the dilation ``eps2d``), taken 1e-6 relative wider. Cheaper than what it skips (the
    3D covariance and the footprint), which the fisheye path ran for every Gaussian in front of the camera (62 %
    of a dataset view's are culled there: its projection 12.0 ms against 5.5 for the same view through a
    pinhole). ``terms``: :func:`_fisheye_terms` at the point."""
    theta, rho, g, drho_dz = terms
    if theta > theta_max:
        return True
    u = fx * rho * x + cx
    v = fy * rho * y + cy
    if 0.0 <= u <= width and 0.0 <= v <= height:  # the mean is in view: kept by the full test
        return False
    j00, j01, j02 = fx * (rho + x * x * g), fx * x * y * g, fx * x * drho_dz
    j10, j11, j12 = fy * x * y * g, fy * (rho + y * y * g), fy * y * drho_dz
    row_x2 = (j00 * j00 + j01 * j01 + j02 * j02) * (1.0 + 1e-6)
    row_y2 = (j10 * j10 + j11 * j11 + j12 * j12) * (1.0 + 1e-6)
    return _box_outside(u, v, row_x2, row_y2, scales, i, rot_norm, eps2d, width, height)


@numba.njit(cache=True, inline="always")
def _pre_culled(x, y, z, scales, i, rot_norm, view, lims, fisheye, lens, terms, eps2d):
    """The pre-cull of Gaussian ``i`` at camera point (x, y, z) in one camera (``view = (fx, fy, cx, cy, width, height)``,
    ``lims`` of :func:`_frustum`, ``lens = (k1, k2, k3, k4, theta_max)``, ``terms`` :func:`_fisheye_terms` at the point
    when ``fisheye``): :func:`_surely_outside_fisheye` through the fisheye lens, else :func:`_surely_outside`."""
    fx, fy, cx, cy, width, height = view
    if fisheye:
        return _surely_outside_fisheye(x, y, scales, i, rot_norm, fx, fy, cx, cy, width, height, terms, lens[4], eps2d)
    return _surely_outside(x, y, z, scales, i, rot_norm, fx, fy, cx, cy, width, height, lims[0], lims[1], lims[2], lims[3], eps2d)


@numba.njit(cache=True, inline="always")
def _footprint(i, x, y, z, lens_coc, m, opacity, view, lims, fisheye, lens, terms, dilation, opacity_extent, blur, packed, rects):
    """Steps 3–5 of the module docstring for Gaussian ``i`` at camera point (x, y, z) with ``M = W R S``
    (the 9-tuple ``m``, row-major) in one camera: writes its packed record but the colour and its tile
    rectangle; ``False`` when it is culled (the row is then left as it was: zeros). Tuples (a call of
    more than 30 arguments compiles to ``*args``, which numba cannot inline): ``view = (fx, fy, cx, cy,
    width, height)``, ``lims`` of :func:`_frustum`, ``lens = (k1, k2, k3, k4, theta_max)`` and ``terms``
    (:func:`_fisheye_terms` at the point, read when ``fisheye``), ``dilation =
    (model_x, model_y, filter_x, filter_y)``, ``blur = (aperture, defocus_extent, defocus_tail, defocus_boost)``."""
    m00, m01, m02, m10, m11, m12, m20, m21, m22 = m
    fx, fy, cx, cy, width, height = view
    lim_x_neg, lim_x_pos, lim_y_neg, lim_y_pos = lims
    theta_max = lens[4]
    model_x, model_y, filter_x, filter_y = dilation
    aperture, defocus_extent, defocus_tail, defocus_boost = blur
    tiles_x = (width + 15) // 16
    tiles_y = (height + 15) // 16
    # ---- lens: mean and Jacobian rows (j0·, j1·)
    if fisheye:
        theta, rho, g, drho_dz = terms
        if theta > theta_max:
            return False
        u = fx * rho * x + cx
        v = fy * rho * y + cy
        j00 = fx * (rho + x * x * g)
        j01 = fx * x * y * g
        j02 = fx * x * drho_dz
        j10 = fy * x * y * g
        j11 = fy * (rho + y * y * g)
        j12 = fy * y * drho_dz
    else:
        u = fx * x / z + cx
        v = fy * y / z + cy
        tx = z * min(max(x / z, -lim_x_neg), lim_x_pos)
        ty = z * min(max(y / z, -lim_y_neg), lim_y_pos)
        j00 = fx / z
        j01 = 0.0
        j02 = -fx * tx / (z * z)
        j10 = 0.0
        j11 = fy / z
        j12 = -fy * ty / (z * z)
    # T = J M (2×3); Σ2D = T Tᵀ
    t00 = j00 * m00 + j01 * m10 + j02 * m20
    t01 = j00 * m01 + j01 * m11 + j02 * m21
    t02 = j00 * m02 + j01 * m12 + j02 * m22
    t10 = j10 * m00 + j11 * m10 + j12 * m20
    t11 = j10 * m01 + j11 * m11 + j12 * m21
    t12 = j10 * m02 + j11 * m12 + j12 * m22
    sxx = t00 * t00 + t01 * t01 + t02 * t02
    sxy = t00 * t10 + t01 * t11 + t02 * t12
    syy = t10 * t10 + t11 * t11 + t12 * t12
    sxx += model_x
    syy += model_y
    alpha_floor = 1.0 / 255.0
    if filter_x > 0.0 or filter_y > 0.0:  # footprint_dilation: a low-pass with the opacity compensated (the floor stays 1/255, as gsplat's)
        det_model = sxx * syy - sxy * sxy
        sxx += filter_x
        syy += filter_y
        opacity *= math.sqrt(max(det_model / max(sxx * syy - sxy * sxy, 1e-300), 0.0))
    det = sxx * syy - sxy * sxy
    coc = 0.0
    if aperture > 0.0:
        coc = lens_coc
        if coc < DEFOCUS_MIN_COC:  # below DEFOCUS_MIN_COC: sharp
            coc = 0.0
        coc2 = coc * coc
        sxx += coc2
        syy += coc2
        det_blur = sxx * syy - sxy * sxy
        compensation = math.sqrt(max(det / max(det_blur, 1e-300), 0.0))
        opacity *= compensation
        alpha_floor *= compensation
        det = det_blur
        if not alpha_floor > 0.0:  # compensation underflowed: the Gaussian is spread over ~∞ pixels
            return False
        if coc > 1.0 and defocus_extent > 0.0:  # truncate the blurred footprint, keeping its energy
            opacity *= defocus_boost
            alpha_floor = max(alpha_floor, opacity * defocus_tail)
    det = max(det, 1e-10)
    if opacity_extent:
        if not opacity >= alpha_floor:
            return False
        extent = min(3.33, math.sqrt(2.0 * math.log(opacity / alpha_floor)))
    else:
        extent = 3.33
    rad_x = math.ceil(min(extent * math.sqrt(sxx), FOOTPRINT_CAP))
    rad_y = math.ceil(min(extent * math.sqrt(syy), FOOTPRINT_CAP))
    ok = (
        math.isfinite(u) and math.isfinite(v) and math.isfinite(det)
        and math.isfinite(rad_x) and math.isfinite(rad_y) and rad_x > 0 and rad_y > 0
    )
    if not ok:
        return False
    if u + rad_x <= 0 or u - rad_x >= width or v + rad_y <= 0 or v - rad_y >= height:
        return False
    # tile rectangle as gsplat's isect: [floor((u-r)/16), ceil((u+r)/16)) clamped
    x0 = min(max(math.floor((u - rad_x) / 16.0), 0.0), tiles_x)
    x1 = min(max(math.ceil((u + rad_x) / 16.0), 0.0), tiles_x)
    y0 = min(max(math.floor((v - rad_y) / 16.0), 0.0), tiles_y)
    y1 = min(max(math.ceil((v + rad_y) / 16.0), 0.0), tiles_y)
    if x1 <= x0 or y1 <= y0:
        return False
    rects[i, 0], rects[i, 1], rects[i, 2], rects[i, 3] = int(x0), int(x1), int(y0), int(y1)
    packed[i, PX] = u
    packed[i, PY] = v
    packed[i, CA] = syy / det
    packed[i, CB] = -sxy / det
    packed[i, CC] = sxx / det
    packed[i, OPA] = opacity
    packed[i, AMIN] = alpha_floor
    packed[i, DEPTH] = z
    packed[i, RADX] = rad_x
    packed[i, RADY] = rad_y
    packed[i, COC] = coc
    return True


#: Fewest Gaussians one call of :func:`_project_range` projects. The parallel kernel's loop runs over blocks of
#: Gaussians (:func:`project_block`: about four a thread), so numba's parallel passes see one call instead of the
#: whole projection inlined (their copy propagation over that body was most of its compile). Measured with an
#: empty cache (``NUMBA_CACHE_DIR``, 10k Gaussians): the kernel and its serial twin compiled in 27.4 + 11.2 s
#: inlined; now the block body ``_project_range`` ~8–9 s, shared by both (compiled once, cached on disk), the
#: kernel's parallel loop ~1–2 s and the twin's ~0.6 s; the same bytes; a projection of three built-in rooms and
#: a room of another seed (155k–205k Gaussians, 640 × 480, paired medians, one and two threads) 0–6 % longer
#: (mostly 2–3 %), a clean render 0.6–2 %.
MIN_PROJECT_BLOCK = 256


def project_block(n: int, threads: int) -> int:
    """Gaussians a block of the parallel projection holds, for ``n`` Gaussians on ``threads`` threads: about four
    blocks a thread (numba hands each thread an equal run of blocks), at least :data:`MIN_PROJECT_BLOCK`."""
    return max(MIN_PROJECT_BLOCK, -(-int(n) // (4 * max(1, int(threads)))))


# As numba compiles a parallel loop's body, which this was: error_model="numpy" (a division by zero gives
# ±inf or NaN, unchecked) and an unsigned row index (no negative-index wraparound at the array accesses).
# _nrt=False: no reference counting of the arrays the inlined helpers receive (atomic counts of arrays the
# threads share); it allocates nothing (an allocation added here fails to compile). Without either the
# projection took 4–20 % longer (paired medians).
@numba.njit(cache=True, error_model="numpy", _nrt=False)
def _project_range(
    lo, hi, means, quats, scales, opacities, sh, degree, want_color,
    view_rot, view_trans, cam_center, rot_norm, view, lims, fisheye, lens, near, far, dilation, opacity_extent,
    defocus, eps_cull, packed, rects,
    paired, s_view, s_dilation, s_lims, s_eps_cull, sharp_packed, sharp_rects,
):  # pragma: no cover - compiled; covered through render() and the oracle tests
    """Project Gaussians ``lo`` to ``hi - 1`` (0 ≤ lo ≤ hi ≤ N): :func:`_project_kernel`'s loop body, its arguments
    grouped: ``view = (fx, fy, cx, cy, width, height)``, ``lens = (k1, k2, k3, k4, theta_max)``, ``dilation =
    (model_x, model_y, filter_x, filter_y)``, ``defocus = (aperture, focus, max_coc, defocus_extent, defocus_tail,
    defocus_boost)``; ``lims`` the view's :func:`_frustum`, ``eps_cull`` the pre-cull's dilation bound (px²);
    ``paired``: the sharp camera's arrays are filled too, its ``s_view``, ``s_dilation``, frustum ``s_lims`` and
    bound ``s_eps_cull`` as the view's."""
    aperture, focus, max_coc, defocus_extent, defocus_tail, defocus_boost = defocus
    for k in range(lo, hi):
        i = np.uint64(k)  # the row (only ever an index)
        for c in range(PACKED):
            packed[i, c] = 0.0
        for c in range(4):
            rects[i, c] = 0
        if paired:
            for c in range(PACKED):
                sharp_packed[i, c] = 0.0
            for c in range(4):
                sharp_rects[i, c] = 0
        wx, wy, wz = means[i, 0], means[i, 1], means[i, 2]
        x = view_rot[0, 0] * wx + view_rot[0, 1] * wy + view_rot[0, 2] * wz + view_trans[0]
        y = view_rot[1, 0] * wx + view_rot[1, 1] * wy + view_rot[1, 2] * wz + view_trans[1]
        z = view_rot[2, 0] * wx + view_rot[2, 1] * wy + view_rot[2, 2] * wz + view_trans[2]
        if not (z > near and z < far):
            continue
        # the circle of confusion (px; 0 without defocus): under defocus it widens every footprint by coc² px²
        lens_coc = min(aperture * abs(z - focus) / z, max_coc) if aperture > 0.0 else 0.0
        # the fisheye's terms at the point, once for both pre-culls and both footprints (the same lens and point)
        terms = _fisheye_terms(x, y, z, lens[0], lens[1], lens[2], lens[3]) if fisheye else (0.0, 0.0, 0.0, 0.0)
        main_in = not _pre_culled(
            x, y, z, scales, i, rot_norm, view, lims, fisheye, lens, terms, eps_cull + lens_coc * lens_coc,
        )
        sharp_in = False
        if paired:
            sharp_in = not _pre_culled(
                x, y, z, scales, i, rot_norm, s_view, s_lims, fisheye, lens, terms, s_eps_cull,
            )
        if not (main_in or sharp_in):
            continue
        # ---- 3D covariance in the camera frame: Σc = (W R S)(W R S)ᵀ
        qw, qx, qy, qz = quats[i, 0], quats[i, 1], quats[i, 2], quats[i, 3]
        qn = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
        qw, qx, qy, qz = qw / qn, qx / qn, qy / qn, qz / qn
        r00 = 1.0 - 2.0 * (qy * qy + qz * qz)
        r01 = 2.0 * (qx * qy - qw * qz)
        r02 = 2.0 * (qx * qz + qw * qy)
        r10 = 2.0 * (qx * qy + qw * qz)
        r11 = 1.0 - 2.0 * (qx * qx + qz * qz)
        r12 = 2.0 * (qy * qz - qw * qx)
        r20 = 2.0 * (qx * qz - qw * qy)
        r21 = 2.0 * (qy * qz + qw * qx)
        r22 = 1.0 - 2.0 * (qx * qx + qy * qy)
        s0, s1, s2 = float(scales[i, 0]), float(scales[i, 1]), float(scales[i, 2])
        # M = W R S (3×3); columns scaled by s
        m = (
            (view_rot[0, 0] * r00 + view_rot[0, 1] * r10 + view_rot[0, 2] * r20) * s0,
            (view_rot[0, 0] * r01 + view_rot[0, 1] * r11 + view_rot[0, 2] * r21) * s1,
            (view_rot[0, 0] * r02 + view_rot[0, 1] * r12 + view_rot[0, 2] * r22) * s2,
            (view_rot[1, 0] * r00 + view_rot[1, 1] * r10 + view_rot[1, 2] * r20) * s0,
            (view_rot[1, 0] * r01 + view_rot[1, 1] * r11 + view_rot[1, 2] * r21) * s1,
            (view_rot[1, 0] * r02 + view_rot[1, 1] * r12 + view_rot[1, 2] * r22) * s2,
            (view_rot[2, 0] * r00 + view_rot[2, 1] * r10 + view_rot[2, 2] * r20) * s0,
            (view_rot[2, 0] * r01 + view_rot[2, 1] * r11 + view_rot[2, 2] * r21) * s1,
            (view_rot[2, 0] * r02 + view_rot[2, 1] * r12 + view_rot[2, 2] * r22) * s2,
        )
        opacity = float(opacities[i])
        main_kept = False
        if main_in:
            main_kept = _footprint(
                i, x, y, z, lens_coc, m, opacity, view, lims, fisheye, lens, terms, dilation, opacity_extent, (aperture, defocus_extent, defocus_tail, defocus_boost),
                packed, rects,
            )
        sharp_kept = False
        if sharp_in:
            sharp_kept = _footprint(
                i, x, y, z, 0.0, m, opacity, s_view, s_lims, fisheye, lens, terms, s_dilation, opacity_extent, (0.0, defocus_extent, defocus_tail, defocus_boost),
                sharp_packed, sharp_rects,
            )
        if (want_color and main_kept) or sharp_kept:
            dx = wx - cam_center[0]
            dy = wy - cam_center[1]
            dz = wz - cam_center[2]
            dn = math.sqrt(dx * dx + dy * dy + dz * dz)
            dn = dn if dn > 0.0 else 1.0
            dx, dy, dz = dx / dn, dy / dn, dz / dn
            red = max(_sh_channel(sh, i, 0, degree, dx, dy, dz) + 0.5, 0.0)
            green = max(_sh_channel(sh, i, 1, degree, dx, dy, dz) + 0.5, 0.0)
            blue = max(_sh_channel(sh, i, 2, degree, dx, dy, dz) + 0.5, 0.0)
            if want_color and main_kept:
                packed[i, CR], packed[i, CG], packed[i, CBL] = red, green, blue
            if sharp_kept:
                sharp_packed[i, CR], sharp_packed[i, CG], sharp_packed[i, CBL] = red, green, blue


@fork_safe
@numba.njit(parallel=True, cache=True)
def _project_kernel(
    means, quats, scales, opacities, sh, degree, want_color,
    view_rot, view_trans, cam_center, rot_norm,
    fx, fy, cx, cy, width, height,
    fisheye, k1, k2, k3, k4, theta_max,
    near, far, model_x, model_y, filter_x, filter_y, opacity_extent,
    aperture, focus, max_coc, defocus_extent,
    packed, rects,
    sharp_view, sharp_packed, sharp_rects, block,
):  # pragma: no cover - compiled; covered through render() and the oracle tests
    """Fill ``packed`` (N, PACKED) and ``rects`` (N, 4) in place, ``block`` Gaussians a call of :func:`_project_range`
    (:func:`project_block`; the bytes do not depend on it); see the module docstring.

    ``sharp_packed`` (N, PACKED) and ``sharp_rects`` (N, 4), when not empty, get in the same pass the
    projection into a second camera of the same pose and lens, without defocus and with colour:
    ``sharp_view = (fx, fy, cx, cy, width, height, model_x, model_y, filter_x, filter_y)``, each value
    computed exactly as a projection of its own would (the shared steps, pose, rotation and
    colour, are done once)."""
    n = means.shape[0]
    paired = sharp_packed.shape[0] > 0
    s_fx, s_fy, s_cx, s_cy, s_width, s_height, s_model_x, s_model_y, s_filter_x, s_filter_y = sharp_view
    # the Jacobian's frustum, widened by how far a blurred footprint reaches into the view
    reach = max_coc * (defocus_extent if defocus_extent > 0.0 else 3.33) if aperture > 0.0 else 0.0
    lims = _frustum(fx, fy, cx, cy, width, height, reach)
    s_lims = _frustum(s_fx, s_fy, s_cx, s_cy, s_width, s_height, 0.0)
    # alpha at the truncation per unit opacity, and 1 / the mass kept inside defocus_extent σ
    defocus_tail = math.exp(-0.5 * defocus_extent * defocus_extent) if defocus_extent > 0.0 else 0.0
    defocus_boost = 1.0 / (1.0 - defocus_tail)
    eps_cull = max(model_x + filter_x, model_y + filter_y)  # an upper bound of the dilation, for _surely_outside
    s_eps_cull = max(s_model_x + s_filter_x, s_model_y + s_filter_y)
    block = max(1, block)
    blocks = (n + block - 1) // block
    for b in numba.prange(blocks):
        _project_range(
            b * block, min(n, (b + 1) * block), means, quats, scales, opacities, sh, degree, want_color,
            view_rot, view_trans, cam_center, rot_norm, (fx, fy, cx, cy, width, height), lims, fisheye, (k1, k2, k3, k4, theta_max),
            near, far, (model_x, model_y, filter_x, filter_y), opacity_extent,
            (aperture, focus, max_coc, defocus_extent, defocus_tail, defocus_boost), eps_cull, packed, rects,
            paired, (s_fx, s_fy, s_cx, s_cy, s_width, s_height), (s_model_x, s_model_y, s_filter_x, s_filter_y), s_lims, s_eps_cull,
            sharp_packed, sharp_rects,
        )


_NO_SHARP_VIEW = (1.0, 1.0, 0.0, 0.0, 1, 1, 0.0, 0.0, 0.0, 0.0)


def project_gaussians(
    gaussians: Gaussians,
    camera: Camera,
    settings: RasterSettings,
    defocus: Defocus | None = None,
    want_color: bool = True,
) -> tuple[np.ndarray, np.ndarray]:
    """Project ``gaussians`` into ``camera``: ``(packed (N, PACKED) float32, rects (N, 4) int32)``."""
    packed, rects, _, _ = _project(gaussians, camera, settings, defocus, want_color, None, None)
    return packed, rects


def project_with_sharp(
    gaussians: Gaussians,
    camera: Camera,
    settings: RasterSettings,
    defocus: Defocus | None,
    want_color: bool,
    sharp_camera: Camera,
    sharp_settings: RasterSettings,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``project_gaussians(gaussians, camera, settings, defocus, want_color)`` and
    ``project_gaussians(gaussians, sharp_camera, sharp_settings, None, True)`` in one pass, the same
    bytes as the two calls: ``(packed, rects, sharp_packed, sharp_rects)``. ``sharp_camera`` must have
    ``camera``'s pose and lens and ``sharp_settings`` the same clipping and cut-offs (defocus's sharp
    pass: the view on a rescaled grid, :func:`spacedg.render.defocus.measurement_camera`)."""
    same_pose = np.array_equal(sharp_camera.world_to_cam, camera.world_to_cam) and sharp_camera.fisheye == camera.fisheye
    same_cuts = all(getattr(sharp_settings, k) == getattr(settings, k) for k in ("near", "far", "opacity_extent", "defocus_extent"))
    if not (same_pose and same_cuts):
        raise ValueError("project_with_sharp: the sharp camera must share the view's pose and lens, and its settings the view's near, far and cut-offs")
    return _project(gaussians, camera, settings, defocus, want_color, sharp_camera, sharp_settings)


def _project(
    gaussians: Gaussians, camera: Camera, settings: RasterSettings, defocus: Defocus | None, want_color: bool,
    sharp_camera: Camera | None, sharp_settings: RasterSettings | None, block: int | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Run :func:`_project_kernel` (the sharp arrays empty without ``sharp_camera``), ``block`` Gaussians a block
    (default :func:`project_block` for this process's numba threads)."""
    n = len(gaussians)
    packed = np.empty((n, PACKED), np.float32)
    rects = np.empty((n, 4), np.int32)
    m = n if sharp_camera is not None else 0
    sharp_packed = np.empty((m, PACKED), np.float32)
    sharp_rects = np.empty((m, 4), np.int32)
    sharp_view = _NO_SHARP_VIEW
    if sharp_camera is not None:
        sharp_view = (
            float(sharp_camera.fx), float(sharp_camera.fy), float(sharp_camera.cx), float(sharp_camera.cy),
            int(sharp_camera.width), int(sharp_camera.height), *footprint_dilation(sharp_camera, sharp_settings),
        )
    lens = camera.fisheye
    view = camera.world_to_cam
    _project_kernel(
        gaussians.means, gaussians.quats, gaussians.scales, gaussians.opacities, gaussians.sh,
        gaussians.sh_degree, want_color,
        np.ascontiguousarray(view[:3, :3]), np.ascontiguousarray(view[:3, 3]), np.array(camera.center),
        float(np.linalg.norm(view[:3, :3], 2)),
        camera.fx, camera.fy, camera.cx, camera.cy, camera.width, camera.height,
        lens is not None, *(lens.coeffs if lens else (0.0, 0.0, 0.0, 0.0)),
        lens.effective_max_theta if lens else math.pi,
        settings.near, settings.far, *footprint_dilation(camera, settings), settings.opacity_extent,
        defocus.aperture if defocus else 0.0, defocus.focus if defocus else 1.0, defocus.max_radius if defocus else 0.0,
        settings.defocus_extent or 0.0,
        packed, rects, sharp_view, sharp_packed, sharp_rects,
        project_block(n, numba.get_num_threads()) if block is None else int(block),
    )
    return packed, rects, sharp_packed, sharp_rects
