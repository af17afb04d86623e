"""Walkthrough part: from 3D to the screen, EWA projection and view-dependent colour (VG-PROJ, VG-SH)."""

import numpy as np
from matplotlib.patches import Rectangle

from velogauss_core.constants import EPS2D, GAUSSIAN_EXTENT_SIGMA
from velogauss_ref.covariance import covariance_3d
from velogauss_ref.projection import project_gaussians
from velogauss_ref.sh import sh_to_color
from velogauss.walkthrough.figures import covariance_ellipse, new_figure, save
from velogauss.walkthrough.printing import Section, number, session
from velogauss.walkthrough.setups import axis_angle_quat, camera

WIDTH, HEIGHT, FOCAL = 48, 32, 40.0


def projection_section(figures):
    """VG-PROJ: four Gaussians projected (two culled); the dilation figure on a sub-pixel needle."""
    viewmat, K = camera(WIDTH, HEIGHT, FOCAL)
    means = np.array([[-0.8, 0.0, 0.0], [0.6, 0.0, 0.0], [0.0, 0.0, -4.0], [5.0, 0.0, 0.0]])
    quats = np.stack([axis_angle_quat([0, 0, 1], 0), axis_angle_quat([0, 0, 1], 30),
                      axis_angle_quat([0, 0, 1], 0), axis_angle_quat([0, 0, 1], 0)])
    # Gaussian 1 is a needle 0.002 thick seen side-on: 0.02 px thin on screen before dilation.
    scales = np.array([[0.15, 0.15, 0.15], [0.3, 0.002, 0.002], [0.2, 0.2, 0.2], [0.2, 0.2, 0.2]])
    Sigma = covariance_3d(quats, scales)
    proj = project_gaussians(means, Sigma, viewmat, K, WIDTH, HEIGHT)
    undilated = np.linalg.eigvalsh(proj["cov2d"][1] - EPS2D * np.eye(2))
    return Section(
        "Splatting needs each Gaussian's footprint on the image: a 2D Gaussian with mean at the "
        "projected centre and covariance `J W Σ Wᵀ Jᵀ`, the 3D covariance pushed through the "
        "camera rotation `W` and the perspective map linearised at the mean (`J`; EWA splatting). "
        "Two details matter in practice: every footprint is dilated by `EPS2D` px² so that even a "
        "Gaussian thinner than a pixel covers about one pixel, and the support is cut at "
        f"{GAUSSIAN_EXTENT_SIGMA:g} standard deviations (`radius`). The example is a {WIDTH}×{HEIGHT} px "
        "camera 4 units from the origin, looking at it: a small ball, a thin needle turned 30° in "
        "the image plane, a Gaussian at the camera's own depth (culled: in front of the near plane) "
        "and one far off to the side (culled: off screen).",
        [session({"means": means, "quats": quats, "scales": scales, "K": K},
                 "Sigma = covariance_3d(quats, scales)",
                 f"proj = project_gaussians(means, Sigma, viewmat, K, width={WIDTH}, height={HEIGHT})",
                 {key: proj[key] for key in ("mean2d", "depth", "cov2d", "conic", "radius", "valid")},
                 "np.linalg.eigvalsh(proj['cov2d'][1] - EPS2D * np.eye(2))  # the needle, undilated",
                 {"eigenvalues": undilated}),
         f"Without the {EPS2D:g} px² dilation the needle's footprint would have a variance of "
         f"{number(undilated[0])} px² across it: a standard deviation of {number(np.sqrt(undilated[0]))} px, "
         "a splat that falls between pixel centres, and a nearly singular conic.",
         _projection_figure(figures, proj)],
    )


def _projection_figure(figures, proj):
    fig = new_figure(10, 3.8)
    whole, zoom = fig.subplots(1, 2, width_ratios=(1.6, 1))
    valid = np.flatnonzero(proj["valid"])
    for ax in (whole, zoom):
        for g in valid:
            centre = proj["mean2d"][g]
            covariance_ellipse(ax, centre, proj["cov2d"][g], GAUSSIAN_EXTENT_SIGMA, color="tab:blue", linewidth=1.5)
            covariance_ellipse(ax, centre, proj["cov2d"][g] - EPS2D * np.eye(2), GAUSSIAN_EXTENT_SIGMA,
                               color="tab:red", linewidth=1.2, linestyle="--")
            r = proj["radius"][g]
            ax.add_patch(Rectangle(centre - r, 2 * r, 2 * r, fill=False, color="0.5", linestyle=":"))
            ax.plot(*centre, "k+")
        ax.set_aspect("equal")
        ax.invert_yaxis()
    whole.set(xlim=(0, WIDTH), ylim=(HEIGHT, 0), xlabel="u (px)", ylabel="v (px)",
              title="valid Gaussians: 3σ ellipses and radius boxes")
    whole.add_patch(Rectangle((0, 0), WIDTH, HEIGHT, fill=False, color="k"))
    thin = proj["mean2d"][1]
    zoom.set(xlim=(thin[0] - 4, thin[0] + 4), ylim=(thin[1] + 3, thin[1] - 3), xlabel="u (px)",
             title="the needle, zoomed")
    zoom.set_xticks(np.arange(np.floor(thin[0] - 4), thin[0] + 5))
    zoom.set_yticks(np.arange(np.floor(thin[1] - 3), thin[1] + 4))
    zoom.grid(True, color="0.85")
    zoom.plot([], [], color="tab:red", linestyle="--", label="before dilation (cov2d − EPS2D·I)")
    zoom.plot([], [], color="tab:blue", label=f"after dilation (+{EPS2D:g} px² · I)")
    zoom.legend(loc="lower center", fontsize=8)
    return save(fig, figures, "proj-dilation",
                f"Footprints of project_gaussians: 3σ ellipses of cov2d (blue) and of cov2d − {EPS2D:g}·I, the "
                "footprint before dilation (red, dashed); dotted squares are the radius boxes. Zoomed on the "
                "needle (grid lines on pixel boundaries): before dilation it is a sliver that pixel centres "
                "would miss; after, it covers whole pixels.")


def sh_section(figures):
    """VG-SH: one Gaussian's degree-1 colour from four directions; colour maps of degrees 0 to 3."""
    sh = np.zeros((4, 4, 3))
    sh[:, 0] = 0.3  # DC band: a grey that every direction sees
    sh[:, 3] = [-0.8, 0.0, 0.8]  # the band-1 x term: redder seen along +x, bluer along -x
    dirs = np.array([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 5.0], [0.0, 0.0, 0.0]])
    return Section(
        "A Gaussian's colour may depend on where it is seen from: each colour channel is a function "
        "on the sphere of viewing directions, written in real spherical harmonics up to degree 3 "
        "(16 coefficients per channel, 3DGS's basis and order). The example gives one Gaussian a grey "
        "DC term and a band-1 term along x, seen from +x, from −x, along +z (a direction of length 5: "
        "only its direction counts) and along the zero direction (taken as +z).",
        [session({"sh[:, 0]": sh[0, 0], "sh[:, 3]": sh[0, 3], "dirs": dirs},
                 "rgb = sh_to_color(sh, dirs, degree=1)", {"rgb": sh_to_color(sh, dirs, 1)}),
         _sh_figure(figures)],
    )


def _sh_figure(figures):
    """Colour over every viewing direction of one Gaussian with random coefficients, degree 0..3."""
    azimuth, elevation = np.meshgrid(np.linspace(-np.pi, np.pi, 121), np.linspace(-np.pi / 2, np.pi / 2, 61))
    dirs = np.stack([np.cos(elevation) * np.cos(azimuth), np.cos(elevation) * np.sin(azimuth),
                     np.sin(elevation)], axis=-1).reshape(-1, 3)
    coefficients = 0.4 * np.random.default_rng(3).standard_normal((16, 3))
    sh = np.broadcast_to(coefficients, (len(dirs), 16, 3))
    fig = new_figure(10, 2.4)
    for degree, ax in enumerate(fig.subplots(1, 4)):
        rgb = sh_to_color(sh, dirs, degree).reshape(*azimuth.shape, 3)
        ax.imshow(np.clip(rgb, 0, 1), origin="lower", extent=(-180, 180, -90, 90))
        ax.set(title=f"degree {degree}", xlabel="azimuth (°)", xticks=(-180, 0, 180), yticks=(-90, 0, 90))
    fig.axes[0].set_ylabel("elevation (°)")
    return save(fig, figures, "sh-degrees",
                "sh_to_color of one Gaussian (the same random coefficients) over all viewing directions, "
                "keeping degree 0 to 3: degree 0 is one colour, each higher degree adds finer view dependence.")


SECTIONS = {"VG-PROJ": projection_section, "VG-SH": sh_section}
