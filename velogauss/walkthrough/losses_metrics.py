"""Walkthrough part: what training minimises and what evaluation reports
(VG-LOSS, VG-LOSS-PHYS, VG-LOSS-MIX, VG-METRIC, VG-METRIC-SSIM, VG-METRIC-LPIPS)."""

import functools

import numpy as np

from velogauss_ref.losses import mixing_entropy_loss, physics_loss, photometric_loss
from velogauss_ref.metrics import lpips, psnr, ssim
from velogauss_ref.motion.code import physics_code
from velogauss_ref.physics.residuals import divergence, transport_residual
from velogauss_ref.raster import rasterize
from velogauss.walkthrough.blending import RENDER_FOCAL, RENDER_SIZE, WHITE
from velogauss.walkthrough.figures import new_figure, save
from velogauss.walkthrough.physics import POINTS, T, fields
from velogauss.walkthrough.printing import Section, session
from velogauss.walkthrough.setups import CFG, camera, scene_gaussians

NOISE = 0.06


@functools.cache
def images():
    """(gt, shifted, noisy), each (RENDER_SIZE, RENDER_SIZE, 3): the four-Gaussian scene of VG-RENDER;
    the same with every mean moved 0.08 along x; and gt plus Gaussian noise of std NOISE (seed 0),
    clipped to [0, 1]."""
    means, quats, scales, opacities, colours = scene_gaussians()
    viewmat, K = camera(RENDER_SIZE, RENDER_SIZE, RENDER_FOCAL)

    def render(m):
        return rasterize(m, quats, scales, opacities, colours, viewmat, K, RENDER_SIZE, RENDER_SIZE,
                         background=WHITE)[0]

    gt = render(means)
    noisy = np.clip(gt + NOISE * np.random.default_rng(0).standard_normal(gt.shape), 0, 1)
    return gt, render(means + [0.08, 0.0, 0.0]), noisy


def photometric_section(figures):
    """VG-LOSS: the loss of a shifted and a noisy image, and its two terms; the images."""
    gt, shifted, noisy = images()
    return Section(
        "Training compares each rendered view with the photograph: mostly an L1 difference, plus "
        "a D-SSIM term (the 3DGS recipe, weight 0.2) that rewards matching local structure. The "
        "examples in this part compare the four-Gaussian image of VG-RENDER with two degraded "
        "copies: the same scene with every Gaussian moved 0.08 along x (a geometry error, the "
        f"kind motion makes), and the image plus pixel noise of standard deviation {NOISE:g}.",
        [session("L = photometric_loss(pred, gt)",
                 {"shifted": photometric_loss(shifted, gt), "noisy": photometric_loss(noisy, gt)},
                 "# its two terms: 0.8 mean|pred − gt| + 0.2 (1 − SSIM)",
                 {"L1 (shifted)": np.mean(np.abs(shifted - gt)), "1 − SSIM (shifted)": 1 - ssim(shifted, gt),
                  "L1 (noisy)": np.mean(np.abs(noisy - gt)), "1 − SSIM (noisy)": 1 - ssim(noisy, gt)},
                 "photometric_loss(gt, gt)", {"L": photometric_loss(gt, gt)}),
         _images_figure(figures, gt, shifted, noisy)],
    )


def _images_figure(figures, gt, shifted, noisy):
    fig = new_figure(10, 2.8)
    panels = (("gt", gt), ("shifted", shifted), ("noisy", noisy),
              ("4 |shifted − gt|", 4 * np.abs(shifted - gt)), ("4 |noisy − gt|", 4 * np.abs(noisy - gt)))
    for ax, (title, image) in zip(fig.subplots(1, 5), panels):
        ax.imshow(np.clip(image, 0, 1), interpolation="nearest")
        ax.set(title=title, xticks=(), yticks=())
    return save(fig, figures, "loss-images",
                "The images the losses and metrics compare: ground truth, a geometry error (every Gaussian "
                "moved 0.08 along x) and pixel noise, with their absolute differences (times 4, to be visible).")


def physics_loss_section(figures):
    """VG-LOSS-PHYS: the random field's residuals weighted, without divergence, and with no points."""
    params = fields()["random network"]
    r, div = transport_residual(params, POINTS, T, CFG), divergence(params, POINTS, T, CFG)
    return Section(
        "The physics loss is the mean squared transport residual plus, for an incompressible scene, "
        "the mean squared divergence, each with its weight (0.01 by default, ramped up from 0 early "
        "in training so that the constraints do not fight geometry that is still forming). Its "
        "inputs are the residuals of VG-TRANSPORT and VG-DIV at collocation points; here, the "
        "random network field's at the three points used there.",
        [session({"r": r, "div": div},
                 "physics_loss(r, div, lambda_transport=0.01, lambda_div=0.01)",
                 {"L": physics_loss(r, div, 0.01, 0.01)},
                 "physics_loss(r, None, 0.01, 0.01)  # a compressible scene: no divergence term",
                 {"L": physics_loss(r, None, 0.01, 0.01)},
                 "physics_loss(np.zeros((0, 3)), np.zeros(0), 0.01, 0.01)  # no collocation points",
                 {"L": physics_loss(np.zeros((0, 3)), np.zeros(0), 0.01, 0.01)})],
    )


def mixing_entropy_section(figures):
    """VG-LOSS-MIX: the random field's mixing logits at the three points, an even and a one-hot row."""
    params = fields()["random network"]
    A, c = params["mix"][0]
    logits = physics_code(params, POINTS, CFG) @ A + c
    k = CFG.n_patterns
    return Section(
        "Each particle moves with a mixture of the K motion patterns (VG-COEF). A particle whose "
        "weights are spread moves with their average, so one pattern must then serve several bodies. "
        "This loss is the mean entropy of the particles' weights: 0 when each puts all its weight on "
        f"one pattern, log K when it spreads it evenly (K = {k} here, log K = {np.log(k):.4f}). "
        "Training adds it with weight 1e-3 at moving Gaussians. Here: the random network field's "
        "logits at the three points, an even row and a one-hot row.",
        [session({"logits": logits},
                 "mixing_entropy_loss(logits, weight=1.0)", {"L": mixing_entropy_loss(logits, 1.0)},
                 f"mixing_entropy_loss(np.zeros((1, {k})), 1.0)  # even weights: log K",
                 {"L": mixing_entropy_loss(np.zeros((1, k)), 1.0)},
                 f"mixing_entropy_loss(np.array([[0.0, 800.0] + [0.0] * {k - 2}]), 1.0)  # one-hot in floating point",
                 {"L": mixing_entropy_loss(np.array([[0.0, 800.0] + [0.0] * (k - 2)]), 1.0)})],
    )


def psnr_section(figures):
    """VG-METRIC: PSNR of the shifted and noisy images, and the 100 dB cap."""
    gt, shifted, noisy = images()
    return Section(
        "PSNR is the mean squared error on a log scale, in dB (data range 1): every +10 dB is a "
        "tenfold smaller MSE. It is blind to where the error is and to what it looks like: only the "
        "energy of the difference counts. Identical images would score +∞; the MSE floor caps PSNR at "
        "100 dB so that averages over frames stay finite.",
        [session("psnr(pred, gt)",
                 {"shifted": psnr(shifted, gt), "noisy": psnr(noisy, gt), "gt itself": psnr(gt, gt)})],
    )


def ssim_section(figures):
    """VG-METRIC-SSIM: SSIM of the shifted and noisy images, and of identical images."""
    gt, shifted, noisy = images()
    return Section(
        "SSIM compares local means, contrasts and correlations in an 11 × 11 Gaussian window, so it "
        "measures structure rather than energy: noise disturbs local correlations everywhere, while a "
        "small displacement of smooth blobs changes them only near their edges. It is 1 for identical "
        "images; only windows that fit inside the image count (no padding).",
        [session("ssim(pred, gt)",
                 {"shifted": ssim(shifted, gt), "noisy": ssim(noisy, gt), "gt itself": ssim(gt, gt)})],
    )


def lpips_section(figures):
    """VG-METRIC-LPIPS: LPIPS-alex of the shifted and noisy images, and of identical images."""
    gt, shifted, noisy = images()
    return Section(
        "LPIPS compares the images' activations in a pretrained network (AlexNet by default, the "
        "setting NeRF and 3DGS papers report), normalised per pixel and weighted by a learned linear "
        "head: a distance that tracks human judgements of similarity. Lower is better, 0 for "
        "identical images. The weights are read from `.npz` files (the spec lists where they are "
        "looked for).",
        [session("lpips(pred, gt, net='alex')",
                 {"shifted": lpips(shifted, gt, "alex"), "noisy": lpips(noisy, gt, "alex"),
                  "gt itself": lpips(gt, gt, "alex")})],
    )


SECTIONS = {"VG-LOSS": photometric_section, "VG-LOSS-PHYS": physics_loss_section,
            "VG-LOSS-MIX": mixing_entropy_section, "VG-METRIC": psnr_section,
            "VG-METRIC-SSIM": ssim_section, "VG-METRIC-LPIPS": lpips_section}
