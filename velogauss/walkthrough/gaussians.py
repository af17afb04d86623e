"""Walkthrough part: a Gaussian's rotation and covariance (VG-QUAT, VG-QUAT-MUL, VG-COV)."""

import numpy as np

from velogauss_ref.covariance import covariance_3d
from velogauss_ref.quaternion import quat_multiply, quat_to_rotmat
from velogauss.walkthrough.figures import new_figure, save
from velogauss.walkthrough.printing import Section, session
from velogauss.walkthrough.setups import axis_angle_quat


def quat_section(figures):
    """VG-QUAT: a 45° turn, the same quaternion doubled and the zero quaternion through quat_to_rotmat."""
    q = np.stack([axis_angle_quat([0, 1, 0], 45), 2 * axis_angle_quat([0, 1, 0], 45), np.zeros(4)])
    return Section(
        "A Gaussian's orientation is a quaternion `q = (w, x, y, z)`. The optimiser moves it freely, "
        "so it is normalised inside the function rather than kept unit; the example shows a 45° turn "
        "about y, the same quaternion doubled (same matrix) and the zero quaternion (the identity, "
        "not a NaN).",
        [session({"q": q}, "R = quat_to_rotmat(q)", {"R": quat_to_rotmat(q)})],
    )


def quat_multiply_section(figures):
    """VG-QUAT-MUL: two quarter turns composed both ways, against R(a) R(b)."""
    a, b = axis_angle_quat([0, 0, 1], 90), axis_angle_quat([1, 0, 0], 90)
    return Section(
        "Composing rotations is a Hamilton product. The order matters: `a ⊗ b` applies `b` first. "
        "The example composes a quarter turn about x (`b`) with a quarter turn about z (`a`) and "
        "checks `R(a ⊗ b) = R(a) R(b)`; swapping the factors gives a different rotation.",
        [session({"a": a, "b": b}, "c = quat_multiply(a, b)", {"c": quat_multiply(a, b)},
                 "quat_to_rotmat(c)", {"R(c)": quat_to_rotmat(quat_multiply(a, b))},
                 "quat_to_rotmat(a) @ quat_to_rotmat(b)", {"R(a) R(b)": quat_to_rotmat(a) @ quat_to_rotmat(b)},
                 "quat_multiply(b, a)", {"b ⊗ a": quat_multiply(b, a)})],
    )


def covariance_section(figures):
    """VG-COV: a ball, a cigar and a disk; their eigenvalues against s²; the ellipsoid figure."""
    quats = np.stack([axis_angle_quat([0, 0, 1], 0), axis_angle_quat([0, 0, 1], 45), axis_angle_quat([1, 0, 0], -60)])
    scales = np.array([[0.3, 0.3, 0.3], [0.5, 0.12, 0.12], [0.4, 0.4, 0.06]])
    Sigma = covariance_3d(quats, scales)
    return Section(
        "The shape of a Gaussian is an ellipsoid: rotate the axes by `R(q)`, stretch them by the "
        "scales `s`. Written as `Σ = R S Sᵀ Rᵀ` the covariance is symmetric positive semi-definite by "
        "construction, whatever the optimiser does to `q` and `s`, and its eigenvalues are `s²`. The "
        "example builds a ball, a cigar turned 45° about z and a disk tilted −60° about x.",
        [session({"quats": quats, "scales": scales}, "Sigma = covariance_3d(quats, scales)", {"Sigma": Sigma},
                 "np.linalg.eigvalsh(Sigma)  # ascending", {"eigenvalues": np.linalg.eigvalsh(Sigma),
                                                              "sorted s²": np.sort(scales**2, axis=1)}),
         _ellipsoid_figure(figures, quats, scales, Sigma)],
    )


def _ellipsoid_figure(figures, quats, scales, Sigma):
    """The 1σ ellipsoid of each Σ, drawn from Σ's own eigendecomposition, with the axes R(q) s."""
    fig = new_figure(10, 4.0)
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, 40), np.linspace(0, np.pi, 20))
    sphere = np.stack([np.cos(u) * np.sin(v), np.sin(u) * np.sin(v), np.cos(v)], axis=-1)
    names = ["ball", "cigar, 45° about z", "disk, −60° about x"]
    for k in range(len(quats)):
        ax = fig.add_subplot(1, len(quats), k + 1, projection="3d")
        eigenvalues, eigenvectors = np.linalg.eigh(Sigma[k])
        surface = sphere @ (eigenvectors * np.sqrt(np.maximum(eigenvalues, 0))).T
        ax.plot_wireframe(surface[..., 0], surface[..., 1], surface[..., 2], color="0.6", linewidth=0.4)
        R = quat_to_rotmat(quats[k])
        for axis, colour in zip(range(3), ("tab:red", "tab:green", "tab:blue")):
            tip = R[:, axis] * scales[k, axis]
            ax.plot([0, tip[0]], [0, tip[1]], [0, tip[2]], color=colour, linewidth=2.5)
        ax.set(xlim=(-0.5, 0.5), ylim=(-0.5, 0.5), zlim=(-0.5, 0.5), xlabel="x", ylabel="y", zlabel="z",
               title=f"{names[k]}\ns = {tuple(float(s) for s in scales[k])}", box_aspect=(1, 1, 1))
    return save(fig, figures, "cov-ellipsoids",
                "1σ ellipsoids of Σ = covariance_3d(q, s) (grey wireframe, from Σ's eigenvectors and "
                "√eigenvalues) "
                "and the principal axes s_k · R(q)[:, k] (red, green, blue): the two agree.")


SECTIONS = {"VG-QUAT": quat_section, "VG-QUAT-MUL": quat_multiply_section, "VG-COV": covariance_section}
