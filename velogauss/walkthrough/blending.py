"""Walkthrough part: from footprints to pixels (VG-ALPHA, VG-BLEND, VG-RENDER)."""

import numpy as np
from matplotlib.patches import Rectangle

from velogauss_core.constants import ALPHA_MAX, ALPHA_MIN, GAUSSIAN_EXTENT_SIGMA, TRANSMITTANCE_MIN
from velogauss_ref.raster import blend, rasterize, splat_alpha
from velogauss.walkthrough.figures import covariance_ellipse, new_figure, save
from velogauss.walkthrough.printing import Section, number, session
from velogauss.walkthrough.setups import camera, scene_gaussians

RENDER_SIZE, RENDER_FOCAL = 32, 40.0
WHITE = np.ones(3)


def alpha_section(figures):
    """VG-ALPHA: five pixel/splat cases covering both clamps; the alpha profile figure."""
    pixel = np.array([[4.5, 4.5], [6.0, 4.5], [12.5, 4.5], [4.5, 4.5], [5.5, 3.5]])
    mean2d = np.array([4.5, 4.5])
    conic = np.array([[0.5, 0.1, 0.25]] * 4 + [[1.0, 2.0, 1.0]])
    opacity = np.array([0.8, 0.8, 0.8, 1.0, 0.8])
    return Section(
        "Each footprint is an opacity map: the Gaussian's opacity `o` times `exp(−σ)`, with `σ` half "
        "the squared Mahalanobis distance of the pixel centre from the projected mean (the conic is "
        "the inverse 2D covariance). Two clamps keep rendering well behaved: `α ≤ ALPHA_MAX` so that "
        "light (and gradient) always passes, and contributions below `ALPHA_MIN`, one 8-bit step, "
        "are skipped. The five rows: the pixel at the mean, 1.5 px to the right, 8 px to the right "
        "(below ALPHA_MIN), a fully opaque splat at its mean (clamped), and a conic that is not "
        "positive definite (σ < 0: skipped).",
        [session({"pixel": pixel, "mean2d": mean2d, "conic": conic, "opacity": opacity},
                 "alpha = splat_alpha(pixel, mean2d, conic, opacity)",
                 {"alpha": splat_alpha(pixel, mean2d, conic, opacity)}),
         _alpha_figure(figures)],
    )


def _alpha_figure(figures):
    u = np.linspace(-10, 10, 801)
    pixel = np.stack([u, np.zeros_like(u)], axis=-1)
    conic = np.array([0.25, 0.0, 0.25])  # an isotropic footprint with a 2 px standard deviation
    fig = new_figure(10, 3.0)
    linear, log = fig.subplots(1, 2)
    for opacity, colour in ((1.0, "tab:blue"), (0.5, "tab:orange")):
        alpha = splat_alpha(pixel, np.zeros(2), conic, np.full(len(u), opacity))
        for ax in (linear, log):
            ax.plot(u, alpha, color=colour, label=f"opacity {opacity:g}")
    for ax in (linear, log):
        ax.axhline(ALPHA_MAX, color="k", linestyle="--", linewidth=0.8)
        ax.axhline(ALPHA_MIN, color="tab:red", linestyle=":", linewidth=0.8)
        ax.set_xlabel("distance from the mean along u (px)")
    linear.set(ylabel="α", title=f"the clamp: α ≤ ALPHA_MAX = {ALPHA_MAX:g} (dashed)")
    log.set(yscale="log", ylim=(1e-3, 2), title="the cut: α < ALPHA_MIN = 1/255 (dotted) is 0")
    linear.legend(fontsize=8)
    return save(fig, figures, "alpha-profile",
                "splat_alpha along a line through the mean of a round footprint (σ = 2 px): an opaque splat "
                "is clamped to ALPHA_MAX, and the tails end abruptly where α drops below ALPHA_MIN.")


def blend_section(figures):
    """VG-BLEND: seven splats on one ray with a skip and the early stop; the ray figure."""
    alphas = np.array([0.3, 0.0, 0.6, 0.95, 0.99, 0.99, 0.5])
    colors = np.array([[0.9, 0.2, 0.1], [0.5, 0.5, 0.5], [0.2, 0.8, 0.2], [0.1, 0.3, 0.9],
                       [0.9, 0.8, 0.1], [0.8, 0.1, 0.8], [0.1, 0.8, 0.8]])
    color, T = blend(colors, alphas, WHITE)
    # The transmittance in front of each splat is the final T of blending the splats before it.
    T_before = np.array([blend(colors[:k], alphas[:k], WHITE)[1] for k in range(len(alphas) + 1)])
    weights = T_before[:-1] - T_before[1:]
    # The early stop shows in blend's output as the first non-skipped splat that got no weight.
    stop = int(np.flatnonzero((alphas > 0) & (weights == 0))[0])
    return Section(
        "Along a ray, the depth-sorted splats are composited front to back: each takes the fraction "
        "`α_i` of the light that is still left, the transmittance `T_i = ∏_{j<i} (1 − α_j)`, and "
        "whatever is left at the end shows the background. Once `T` would fall below "
        "`TRANSMITTANCE_MIN` the pixel is done: the splat that would cross it is not blended and "
        "nothing behind is looked at. The example is one pixel covered by seven splats on a white "
        "background; the second is skipped (α = 0, as VG-ALPHA returns below ALPHA_MIN).",
        [session({"alphas": alphas, "colors": colors},
                 "color, T = blend(colors, alphas, background=(1, 1, 1))", {"color": color, "T": T},
                 "# transmittance in front of each splat: the T of blend(colors[:k], alphas[:k], background)",
                 {"T_before": T_before[:-1], "weights": weights, "sum(weights) + T": weights.sum() + T}),
         f"Splat {stop + 1} would bring the transmittance from {number(T_before[stop])} to "
         f"{number(T_before[stop] * (1 - alphas[stop]))} < {TRANSMITTANCE_MIN:g}: it is not blended, the loop "
         f"stops, and splat {stop + 2} is never reached. The weights `α_i T_i` and the final `T` sum to 1.",
         _blend_figure(figures, colors, alphas, T_before, weights, T, color, stop)],
    )


def _blend_figure(figures, colors, alphas, T_before, weights, T, color, stop):
    index = np.arange(1, len(alphas) + 1)
    fig = new_figure(10, 3.2)
    ax_alpha, ax_T, ax_w = fig.subplots(1, 3)
    ax_alpha.bar(index, alphas, color=colors, edgecolor="k")
    ax_alpha.set(xlabel="splat (front to back)", ylabel="α", title="opacity of each splat", ylim=(0, 1.05))
    ax_T.step(np.arange(1, len(T_before) + 1), T_before, where="post", color="k", label="T in front of the splat")
    ax_T.plot([stop + 1, stop + 2], [T_before[stop] * (1 - alphas[stop])] * 2, color="k", linestyle=":",
              label=f"T had splat {stop + 1} been blended")
    ax_T.axhline(TRANSMITTANCE_MIN, color="tab:red", linestyle="--", label="TRANSMITTANCE_MIN")
    ax_T.axvspan(stop + 1, len(alphas) + 1, color="tab:red", alpha=0.12, label="early stop: not blended")
    ax_T.set(yscale="log", xlabel="splat (front to back)", title="transmittance (log scale)",
             xlim=(1, len(alphas) + 1))
    ax_T.legend(fontsize=7, loc="lower left")
    ax_w.bar(index, weights, color=colors, edgecolor="k")
    ax_w.bar(len(alphas) + 1, T, color="white", edgecolor="k")
    ax_w.add_patch(Rectangle((5.5, 0.55), 2.5, 0.3, color=np.clip(color, 0, 1), ec="k"))
    ax_w.text(6.75, 0.9, "the pixel", ha="center")
    ax_w.set(xlabel="splat (last bar: background)", ylabel="α_i T_i", ylim=(0, 1.0), title="blending weights")
    return save(fig, figures, "blend-ray",
                "blend along one ray: the opacities (left); the transmittance in front of each splat, with the "
                "early stop: the splat that would take it below TRANSMITTANCE_MIN is not blended (middle); the "
                "blending weights, which with the background's share sum to 1, and the resulting pixel (right).")


def render_section(figures):
    """VG-RENDER: the four-Gaussian scene at 32 x 32 px; image, alpha and footprints."""
    means, quats, scales, opacities, colours = scene_gaussians()
    viewmat, K = camera(RENDER_SIZE, RENDER_SIZE, RENDER_FOCAL)
    image, alpha, meta = rasterize(means, quats, scales, opacities, colours, viewmat, K, RENDER_SIZE, RENDER_SIZE,
                                   background=WHITE)
    centre = RENDER_SIZE // 2
    return Section(
        "The full image puts the previous steps together, pixel by pixel: project every Gaussian "
        "(VG-PROJ), take the valid ones whose radius box holds the pixel centre, sort them by depth, "
        "compute their α (VG-ALPHA) and blend (VG-BLEND). The reference is this literal loop; the "
        "fast path tiles and vectorises it and is tested to give the same image. The example renders "
        f"four Gaussians at {RENDER_SIZE}×{RENDER_SIZE} px on a white background.",
        [session({"means": means, "opacities": opacities, "colors": colours},
                 f"image, alpha, meta = rasterize(means, quats, scales, opacities, colors, viewmat, K, "
                 f"{RENDER_SIZE}, {RENDER_SIZE}, background=(1, 1, 1))",
                 {"image.shape": str(image.shape), "meta['depth']": meta["depth"], "meta['radius']": meta["radius"],
                  "meta['n_pairs']": meta["n_pairs"], f"image[{centre}, {centre}]": image[centre, centre],
                  f"alpha[{centre}, {centre}]": alpha[centre, centre], "image[0, 0]": image[0, 0],
                  "alpha.mean()": alpha.mean()}),
         _render_figure(figures, image, alpha, meta)],
    )


def _render_figure(figures, image, alpha, meta):
    fig = new_figure(10, 3.6)
    ax_image, ax_alpha, ax_feet = fig.subplots(1, 3)
    extent = (0, RENDER_SIZE, RENDER_SIZE, 0)  # pixel (i, j) covers [j, j+1) x [i, i+1)
    ax_image.imshow(np.clip(image, 0, 1), extent=extent, interpolation="nearest")
    ax_image.set_title("image")
    shown = ax_alpha.imshow(alpha[..., 0], extent=extent, interpolation="nearest", cmap="gray", vmin=0, vmax=1)
    fig.colorbar(shown, ax=ax_alpha, shrink=0.8)
    ax_alpha.set_title("alpha = 1 − T")
    ax_feet.imshow(np.clip(image, 0, 1), extent=extent, interpolation="nearest", alpha=0.35)
    for g in np.argsort(meta["depth"]):
        colour = np.clip(meta["colors"][g] * 0.8, 0, 1)
        covariance_ellipse(ax_feet, meta["mean2d"][g], meta["cov2d"][g], GAUSSIAN_EXTENT_SIGMA, color=colour,
                           linewidth=1.5)
        ax_feet.plot([], [], color=colour, label=f"depth {meta['depth'][g]:.2f}")
    ax_feet.set(xlim=(0, RENDER_SIZE), ylim=(RENDER_SIZE, 0), title="3σ footprints (VG-PROJ)")
    ax_feet.legend(fontsize=7, loc="upper right")
    for ax in (ax_image, ax_alpha, ax_feet):
        ax.set(xlabel="u (px)", ylabel="v (px)")
    return save(fig, figures, "render-image",
                "rasterize of four Gaussians: the image, its alpha and the footprints that made it, with their "
                "depths (the red disk is furthest, the white dot, drawn grey, nearest).")


SECTIONS = {"VG-ALPHA": alpha_section, "VG-BLEND": blend_section, "VG-RENDER": render_section}
