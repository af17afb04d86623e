"""Compiled CPU kernels of the numba backend's per-view preparation, scalar float64:
VG-QUAT, VG-COV, VG-PROJ and VG-SH of every Gaussian in one loop, forward and an analytic
backward.

The torch path runs these equations as about 200 small tensor operations per view, and
autograd as as many again backward; here each Gaussian is one pass of scalar code. The
forward follows `velogauss_fast.projection.project_gaussians`, `covariance_3d` and
`sh_to_color` step by step (the same clamps, stand-ins and culling); the backward is their
chain rule, written out, with torch's conventions where a derivative is a choice: a clamp
passes the gradient on its closed interval, a culled Gaussian's stand-in depth and
determinant (1) and a zero quaternion or viewing direction pass none.

The backward recomputes the forward's intermediates from the inputs instead of saving
them: a few hundred flops per Gaussian, cheaper than storing and reloading them.
"""

import math

import numba
import numpy as np

from velogauss_core.constants import (
    ANTIALIAS_DET_RATIO_FLOOR,
    EIGEN_DISCRIMINANT_FLOOR,
    FAR_PLANE,
    FRUSTUM_GUARD,
    GAUSSIAN_EXTENT_SIGMA,
    NEAR_PLANE,
    QUAT_ZERO_NORM_SQ,
    VIEW_DIRECTION_MIN,
)
from velogauss_fast.projection import RADIUS_CAP
from velogauss_fast.sh import C0, C1, C2, C3

N_BASIS = 16  # (3 + 1)^2, the basis of the highest degree

# As numba_kernels: no Python division checks (every division is by a tested or stand-in
# value), IEEE rounding (no fastmath), cached on disk, the GIL released.
_JIT = dict(cache=True, nogil=True, error_model="numpy")


@numba.njit(**_JIT)
def _unit_quaternion(q):
    """(w, x, y, z) of q / |q|, 1 / |q|, and whether q is (near) zero (VG-QUAT: the identity)."""
    n2 = q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]
    if n2 < QUAT_ZERO_NORM_SQ:
        return 1.0, 0.0, 0.0, 0.0, 1.0, True
    inv = 1.0 / math.sqrt(n2)
    return q[0] * inv, q[1] * inv, q[2] * inv, q[3] * inv, inv, False


@numba.njit(**_JIT)
def _rotation(w, x, y, z, R):
    """VG-QUAT's matrix of the unit quaternion (w, x, y, z), into R (3, 3)."""
    R[0, 0] = 1 - 2 * (y * y + z * z)
    R[0, 1] = 2 * (x * y - w * z)
    R[0, 2] = 2 * (x * z + w * y)
    R[1, 0] = 2 * (x * y + w * z)
    R[1, 1] = 1 - 2 * (x * x + z * z)
    R[1, 2] = 2 * (y * z - w * x)
    R[2, 0] = 2 * (x * z - w * y)
    R[2, 1] = 2 * (y * z + w * x)
    R[2, 2] = 1 - 2 * (x * x + y * y)


@numba.njit(**_JIT)
def _covariance(R, s, M, Sigma):
    """VG-COV: M = R diag(s) (3, 3) and Sigma = M M^T (3, 3), in place."""
    for i in range(3):
        for j in range(3):
            M[i, j] = R[i, j] * s[j]
    for i in range(3):
        for j in range(3):
            Sigma[i, j] = M[i, 0] * M[j, 0] + M[i, 1] * M[j, 1] + M[i, 2] * M[j, 2]


@numba.njit(**_JIT)
def _frustum_limits(fx, fy, cx, cy, width, height):
    """VG-PROJ 4's clip limits (-lim_x-, lim_x+, -lim_y-, lim_y+) of p.x / p.z and p.y / p.z."""
    tan_x = 0.5 * width / fx
    tan_y = 0.5 * height / fy
    return (-(cx / fx + FRUSTUM_GUARD * tan_x), (width - cx) / fx + FRUSTUM_GUARD * tan_x,
            -(cy / fy + FRUSTUM_GUARD * tan_y), (height - cy) / fy + FRUSTUM_GUARD * tan_y)


@numba.njit(**_JIT)
def _jacobian_times_view(W, fx, fy, z, tx, ty, A):
    """A = J W (2, 3) of VG-PROJ 4-5, J = [[fx/z, 0, -fx tx/z^2], [0, fy/z, -fy ty/z^2]]."""
    j00, j02 = fx / z, -fx * tx / (z * z)
    j11, j12 = fy / z, -fy * ty / (z * z)
    for k in range(3):
        A[0, k] = j00 * W[0, k] + j02 * W[2, k]
        A[1, k] = j11 * W[1, k] + j12 * W[2, k]


@numba.njit(**_JIT)
def _sandwich(A, Sigma):
    """(r00, r01, r11) of A Sigma A^T (2, 2) (symmetric: r10 = r01)."""
    r00 = r01 = r11 = 0.0
    for i in range(3):
        for j in range(3):
            r00 += A[0, i] * Sigma[i, j] * A[0, j]
            r01 += A[0, i] * Sigma[i, j] * A[1, j]
            r11 += A[1, i] * Sigma[i, j] * A[1, j]
    return r00, r01, r11


@numba.njit(**_JIT)
def _unit_direction(mx, my, mz, c):
    """d / |d| of the viewing direction d = mean - camera centre c, |d|, and whether |d| is below
    VIEW_DIRECTION_MIN (VG-SH: then +z)."""
    dx, dy, dz = mx - c[0], my - c[1], mz - c[2]
    n2 = dx * dx + dy * dy + dz * dz
    if n2 < VIEW_DIRECTION_MIN * VIEW_DIRECTION_MIN:
        return 0.0, 0.0, 1.0, 1.0, True
    n = math.sqrt(n2)
    return dx / n, dy / n, dz / n, n, False


@numba.njit(**_JIT)
def sh_basis(x, y, z, degree, Y, dY):
    """VG-SH's real basis at the unit direction (x, y, z), degrees <= `degree`: Y (16,) and
    its partial derivatives dY (16, 3) with respect to (x, y, z)."""
    Y[0] = C0
    dY[0, 0] = dY[0, 1] = dY[0, 2] = 0.0
    if degree >= 1:
        Y[1], Y[2], Y[3] = -C1 * y, C1 * z, -C1 * x
        dY[1, 0], dY[1, 1], dY[1, 2] = 0.0, -C1, 0.0
        dY[2, 0], dY[2, 1], dY[2, 2] = 0.0, 0.0, C1
        dY[3, 0], dY[3, 1], dY[3, 2] = -C1, 0.0, 0.0
    if degree >= 2:
        xx, yy, zz = x * x, y * y, z * z
        Y[4] = C2[0] * x * y
        dY[4, 0], dY[4, 1], dY[4, 2] = C2[0] * y, C2[0] * x, 0.0
        Y[5] = C2[1] * y * z
        dY[5, 0], dY[5, 1], dY[5, 2] = 0.0, C2[1] * z, C2[1] * y
        Y[6] = C2[2] * (2.0 * zz - xx - yy)
        dY[6, 0], dY[6, 1], dY[6, 2] = -2.0 * C2[2] * x, -2.0 * C2[2] * y, 4.0 * C2[2] * z
        Y[7] = C2[3] * x * z
        dY[7, 0], dY[7, 1], dY[7, 2] = C2[3] * z, 0.0, C2[3] * x
        Y[8] = C2[4] * (xx - yy)
        dY[8, 0], dY[8, 1], dY[8, 2] = 2.0 * C2[4] * x, -2.0 * C2[4] * y, 0.0
    if degree >= 3:
        xx, yy, zz = x * x, y * y, z * z
        Y[9] = C3[0] * y * (3 * xx - yy)
        dY[9, 0], dY[9, 1], dY[9, 2] = C3[0] * 6 * x * y, C3[0] * (3 * xx - 3 * yy), 0.0
        Y[10] = C3[1] * x * y * z
        dY[10, 0], dY[10, 1], dY[10, 2] = C3[1] * y * z, C3[1] * x * z, C3[1] * x * y
        Y[11] = C3[2] * y * (4 * zz - xx - yy)
        dY[11, 0], dY[11, 1], dY[11, 2] = -C3[2] * 2 * x * y, C3[2] * (4 * zz - xx - 3 * yy), C3[2] * 8 * y * z
        Y[12] = C3[3] * z * (2 * zz - 3 * xx - 3 * yy)
        dY[12, 0], dY[12, 1], dY[12, 2] = -C3[3] * 6 * x * z, -C3[3] * 6 * y * z, C3[3] * (6 * zz - 3 * xx - 3 * yy)
        Y[13] = C3[4] * x * (4 * zz - xx - yy)
        dY[13, 0], dY[13, 1], dY[13, 2] = C3[4] * (4 * zz - 3 * xx - yy), -C3[4] * 2 * x * y, C3[4] * 8 * x * z
        Y[14] = C3[5] * z * (xx - yy)
        dY[14, 0], dY[14, 1], dY[14, 2] = C3[5] * 2 * x * z, -C3[5] * 2 * y * z, C3[5] * (xx - yy)
        Y[15] = C3[6] * x * (xx - 3 * yy)
        dY[15, 0], dY[15, 1], dY[15, 2] = C3[6] * (3 * xx - 3 * yy), -C3[6] * 6 * x * y, 0.0


@numba.njit(**_JIT)
def _camera_centre(W, t):
    """The camera centre -W^T t (3,) of VG-SH's viewing directions."""
    centre = np.empty(3)
    for k in range(3):
        centre[k] = -(W[0, k] * t[0] + W[1, k] * t[1] + W[2, k] * t[2])
    return centre


@numba.njit(**_JIT)
def _view_geometry(mean, q, s, W, t, fx, fy, limits, R, M, Sigma, A):
    """One Gaussian's forward up to A Sigma A^T (VG-QUAT, VG-COV, VG-PROJ 1-5 before the
    dilation), filling R, M, Sigma (3, 3) and A = J W (2, 3). Returns the camera-space point
    (px, py, pz), whether pz passes the near/far test, the depth z used (1 for a culled
    Gaussian: it keeps everything finite), p.x / z and p.y / z, the unit quaternion
    (w, x, y, z), 1 / |q|, whether q is zero, and (r00, r01, r11) of A Sigma A^T."""
    lo_x, hi_x, lo_y, hi_y = limits
    px = W[0, 0] * mean[0] + W[0, 1] * mean[1] + W[0, 2] * mean[2] + t[0]
    py = W[1, 0] * mean[0] + W[1, 1] * mean[1] + W[1, 2] * mean[2] + t[1]
    pz = W[2, 0] * mean[0] + W[2, 1] * mean[1] + W[2, 2] * mean[2] + t[2]
    in_depth = NEAR_PLANE <= pz <= FAR_PLANE
    z = pz if in_depth else 1.0
    rx, ry = px / z, py / z
    tx = z * min(max(rx, lo_x), hi_x)
    ty = z * min(max(ry, lo_y), hi_y)
    w, x, y, zq, inv_norm, zero_q = _unit_quaternion(q)
    _rotation(w, x, y, zq, R)
    _covariance(R, s, M, Sigma)
    _jacobian_times_view(W, fx, fy, z, tx, ty, A)
    r00, r01, r11 = _sandwich(A, Sigma)
    return px, py, pz, in_depth, z, rx, ry, w, x, y, zq, inv_norm, zero_q, r00, r01, r11


@numba.njit(**_JIT)
def project_forward(means, quats, scales, opacities, sh, degree, W, t, intr, width, height, eps2d, antialiased,
                    mean2d, depth, cov2d, conic, compensation, opacity_out, rgb, radius, valid):
    """VG-COV, VG-PROJ and VG-SH of every Gaussian, and the opacities VG-RENDER composites.

    means (N, 3), quats (N, 4), scales (N, 3), opacities (N,), sh (N, K, 3) (unused when
    degree < 0: the colours are RGB and the caller passes them on), W (3, 3) and t (3,) of
    the world-to-camera viewmat, intr = (fx, fy, cx, cy). Fills mean2d (N, 2), depth (N,),
    cov2d (N, 2, 2), conic (N, 3), compensation (N,), opacity_out (N,) (times the
    compensation when antialiased), rgb (N, 3) (degree >= 0), radius (N,) int64, valid (N,)
    uint8.
    """
    fx, fy, cx, cy = intr[0], intr[1], intr[2], intr[3]
    limits = _frustum_limits(fx, fy, cx, cy, width, height)
    centre = _camera_centre(W, t)
    R, M, Sigma, A = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3)), np.empty((2, 3))
    Y, dY = np.empty(N_BASIS), np.empty((N_BASIS, 3))
    for i in range(means.shape[0]):
        px, py, pz, ok, z, _, _, _, _, _, _, _, _, r00, r01, r11 = _view_geometry(
            means[i], quats[i], scales[i], W, t, fx, fy, limits, R, M, Sigma, A)
        depth[i] = pz
        u = fx * px / z + cx
        v = fy * py / z + cy
        mean2d[i, 0], mean2d[i, 1] = u, v
        c00, c11 = r00 + eps2d, r11 + eps2d
        cov2d[i, 0, 0], cov2d[i, 0, 1], cov2d[i, 1, 0], cov2d[i, 1, 1] = c00, r01, r01, c11
        det = c00 * c11 - r01 * r01
        ok = ok and det > 0
        ds = det if det > 0 else 1.0
        conic[i, 0], conic[i, 1], conic[i, 2] = c11 / ds, -r01 / ds, c00 / ds
        comp = math.sqrt(max((r00 * r11 - r01 * r01) / ds, ANTIALIAS_DET_RATIO_FLOOR))
        compensation[i] = comp
        opacity_out[i] = opacities[i] * comp if antialiased else opacities[i]
        b = 0.5 * (c00 + c11)
        lam = b + math.sqrt(max(b * b - det, EIGEN_DISCRIMINANT_FLOOR))
        r = math.ceil(GAUSSIAN_EXTENT_SIGMA * math.sqrt(max(lam, 0.0)))
        r = 0.0 if r != r else min(r, RADIUS_CAP)
        radius[i] = int(r)
        on_screen = u + r >= 0 and u - r <= width and v + r >= 0 and v - r <= height
        valid[i] = 1 if ok and on_screen else 0
        if degree >= 0:
            dx, dy, dz, _, _ = _unit_direction(means[i, 0], means[i, 1], means[i, 2], centre)
            sh_basis(dx, dy, dz, degree, Y, dY)
            for c in range(3):
                value = 0.0
                for k in range((degree + 1) ** 2):
                    value += sh[i, k, c] * Y[k]
                rgb[i, c] = max(value + 0.5, 0.0)


@numba.njit(**_JIT)
def project_backward(means, quats, scales, opacities, sh, degree, W, t, intr, width, height, eps2d, antialiased,
                     g_mean2d, g_depth, g_cov2d, g_conic, g_compensation, g_opacity_out, g_rgb,
                     g_means, g_quats, g_scales, g_opacities, g_sh):
    """The vector-Jacobian product of `project_forward` (same inputs): from the gradients of
    its differentiable outputs (g_cov2d (N, 2, 2) entry by entry; g_rgb unused when
    degree < 0) into g_means (N, 3), g_quats (N, 4), g_scales (N, 3), g_opacities (N,) and
    g_sh (N, K, 3), which it overwrites. No gradient reaches the camera."""
    fx, fy, cx, cy = intr[0], intr[1], intr[2], intr[3]
    limits = _frustum_limits(fx, fy, cx, cy, width, height)
    lo_x, hi_x, lo_y, hi_y = limits
    centre = _camera_centre(W, t)
    R, M, Sigma, A = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3)), np.empty((2, 3))
    gS, gA, gM, gR = np.empty((3, 3)), np.empty((2, 3)), np.empty((3, 3)), np.empty((3, 3))
    Y, dY = np.empty(N_BASIS), np.empty((N_BASIS, 3))
    for i in range(means.shape[0]):
        # Forward, again.
        px, py, pz, in_depth, z, rx, ry, w, x, y, zq, inv_norm, zero_q, r00, r01, r11 = _view_geometry(
            means[i], quats[i], scales[i], W, t, fx, fy, limits, R, M, Sigma, A)
        crx, cry = min(max(rx, lo_x), hi_x), min(max(ry, lo_y), hi_y)
        tx, ty = z * crx, z * cry
        c00, c11 = r00 + eps2d, r11 + eps2d
        det = c00 * c11 - r01 * r01
        ds = det if det > 0 else 1.0
        det_raw = r00 * r11 - r01 * r01
        ratio = det_raw / ds
        comp = math.sqrt(max(ratio, ANTIALIAS_DET_RATIO_FLOOR))

        # Opacities and the compensation.
        g_comp = g_compensation[i]
        if antialiased:
            g_opacities[i] = g_opacity_out[i] * comp
            g_comp += g_opacity_out[i] * opacities[i]
        else:
            g_opacities[i] = g_opacity_out[i]
        # The 2D covariance, entry by entry (g01 and g10 apart: cov2d's two off-diagonal
        # entries are outputs of their own), and the determinant behind conic and compensation.
        g00, g01, g10, g11 = g_cov2d[i, 0, 0], g_cov2d[i, 0, 1], g_cov2d[i, 1, 0], g_cov2d[i, 1, 1]
        ga, gb, gc = g_conic[i, 0], g_conic[i, 1], g_conic[i, 2]
        g11 += ga / ds
        g01 -= gb / ds
        g00 += gc / ds
        g_ds = -(ga * c11 - gb * r01 + gc * c00) / (ds * ds)
        # Raw (undilated) entries enter only the compensation's determinant.
        h00 = h01 = h11 = 0.0
        if ratio >= ANTIALIAS_DET_RATIO_FLOOR:
            g_ratio = g_comp * 0.5 / comp
            g_det_raw = g_ratio / ds
            g_ds -= g_ratio * det_raw / (ds * ds)
            h00, h11, h01 = g_det_raw * r11, g_det_raw * r00, -2.0 * g_det_raw * r01
        if det > 0:
            g00 += g_ds * c11
            g11 += g_ds * c00
            g01 -= 2.0 * g_ds * r01
        # G on A Sigma A^T: the full 2 x 2 (its off-diagonal entries are distinct outputs).
        G00, G01, G10, G11 = g00 + h00, g01 + h01, g10, g11 + h11
        # g_Sigma = A^T G A, g_A = (G + G^T) A Sigma.
        for a in range(3):
            for b in range(3):
                gS[a, b] = (A[0, a] * (G00 * A[0, b] + G01 * A[1, b])
                            + A[1, a] * (G10 * A[0, b] + G11 * A[1, b]))
        S00, S01, S10, S11 = 2.0 * G00, G01 + G10, G01 + G10, 2.0 * G11
        for k in range(3):
            as0 = A[0, 0] * Sigma[0, k] + A[0, 1] * Sigma[1, k] + A[0, 2] * Sigma[2, k]
            as1 = A[1, 0] * Sigma[0, k] + A[1, 1] * Sigma[1, k] + A[1, 2] * Sigma[2, k]
            gA[0, k] = S00 * as0 + S01 * as1
            gA[1, k] = S10 * as0 + S11 * as1
        # A = J W: dL/dJ = g_A W^T (only J's non-zero entries matter).
        gj00 = gA[0, 0] * W[0, 0] + gA[0, 1] * W[0, 1] + gA[0, 2] * W[0, 2]
        gj02 = gA[0, 0] * W[2, 0] + gA[0, 1] * W[2, 1] + gA[0, 2] * W[2, 2]
        gj11 = gA[1, 0] * W[1, 0] + gA[1, 1] * W[1, 1] + gA[1, 2] * W[1, 2]
        gj12 = gA[1, 0] * W[2, 0] + gA[1, 1] * W[2, 1] + gA[1, 2] * W[2, 2]
        z2, z3 = z * z, z * z * z
        g_z = -gj00 * fx / z2 - gj11 * fy / z2 + 2.0 * gj02 * fx * tx / z3 + 2.0 * gj12 * fy * ty / z3
        g_tx, g_ty = -gj02 * fx / z2, -gj12 * fy / z2
        # tx = z clip(px / z): torch's product rule, through the clip on its closed interval.
        g_z += g_tx * crx + g_ty * cry
        g_rx = g_tx * z if lo_x <= rx <= hi_x else 0.0
        g_ry = g_ty * z if lo_y <= ry <= hi_y else 0.0
        # The mean: u = fx px / z + cx, v = fy py / z + cy.
        gu, gv = g_mean2d[i, 0], g_mean2d[i, 1]
        g_px = gu * fx / z + g_rx / z
        g_py = gv * fy / z + g_ry / z
        g_z -= gu * fx * px / z2 + gv * fy * py / z2 + g_rx * px / z2 + g_ry * py / z2
        g_pz = g_depth[i] + (g_z if in_depth else 0.0)
        for k in range(3):
            g_means[i, k] = W[0, k] * g_px + W[1, k] * g_py + W[2, k] * g_pz

        # Sigma = M M^T, M = R diag(s).
        for a in range(3):
            for b in range(3):
                gM[a, b] = ((gS[a, 0] + gS[0, a]) * M[0, b] + (gS[a, 1] + gS[1, a]) * M[1, b]
                            + (gS[a, 2] + gS[2, a]) * M[2, b])
        for b in range(3):
            g_scales[i, b] = gM[0, b] * R[0, b] + gM[1, b] * R[1, b] + gM[2, b] * R[2, b]
            for a in range(3):
                gR[a, b] = gM[a, b] * scales[i, b]
        # R of the unit quaternion, then the normalisation q / |q| (none for a zero quaternion).
        if zero_q:
            g_quats[i, 0] = g_quats[i, 1] = g_quats[i, 2] = g_quats[i, 3] = 0.0
        else:
            gw = 2.0 * (-zq * gR[0, 1] + y * gR[0, 2] + zq * gR[1, 0] - x * gR[1, 2] - y * gR[2, 0] + x * gR[2, 1])
            gx = 2.0 * (y * gR[0, 1] + zq * gR[0, 2] + y * gR[1, 0] - 2.0 * x * gR[1, 1] - w * gR[1, 2]
                        + zq * gR[2, 0] + w * gR[2, 1] - 2.0 * x * gR[2, 2])
            gy = 2.0 * (-2.0 * y * gR[0, 0] + x * gR[0, 1] + w * gR[0, 2] + x * gR[1, 0] + zq * gR[1, 2]
                        - w * gR[2, 0] + zq * gR[2, 1] - 2.0 * y * gR[2, 2])
            gz = 2.0 * (-2.0 * zq * gR[0, 0] - w * gR[0, 1] + x * gR[0, 2] + w * gR[1, 0] - 2.0 * zq * gR[1, 1]
                        + y * gR[1, 2] + x * gR[2, 0] + y * gR[2, 1])
            dot = w * gw + x * gx + y * gy + zq * gz
            g_quats[i, 0] = (gw - w * dot) * inv_norm
            g_quats[i, 1] = (gx - x * dot) * inv_norm
            g_quats[i, 2] = (gy - y * dot) * inv_norm
            g_quats[i, 3] = (gz - zq * dot) * inv_norm

        # Colours: rgb = max(0, sum_k sh_k Y_k(d / |d|) + 0.5).
        if degree >= 0:
            dx, dy, dz, n, zero_d = _unit_direction(means[i, 0], means[i, 1], means[i, 2], centre)
            sh_basis(dx, dy, dz, degree, Y, dY)
            gdx = gdy = gdz = 0.0
            for c in range(3):
                value = 0.0
                for k in range((degree + 1) ** 2):
                    value += sh[i, k, c] * Y[k]
                g_value = g_rgb[i, c] if value + 0.5 >= 0.0 else 0.0
                for k in range(g_sh.shape[1]):
                    g_sh[i, k, c] = g_value * Y[k] if k < (degree + 1) ** 2 else 0.0
                    if k < (degree + 1) ** 2:
                        gdx += g_value * sh[i, k, c] * dY[k, 0]
                        gdy += g_value * sh[i, k, c] * dY[k, 1]
                        gdz += g_value * sh[i, k, c] * dY[k, 2]
            if not zero_d:
                dot = dx * gdx + dy * gdy + dz * gdz
                g_means[i, 0] += (gdx - dx * dot) / n
                g_means[i, 1] += (gdy - dy * dot) / n
                g_means[i, 2] += (gdz - dz * dot) / n
