"""The inputs the examples share: a camera, a few Gaussians, a small motion configuration and
motion parameters whose fields are known in closed form. Everything comes from fixed seeds.
"""

import numpy as np

from velogauss_core.motion import COLUMN_GROUPS, N_BASIS, init_motion_params, mlp_layers, MotionSpec, network_shapes

# Far smaller networks than training's defaults (spec/motion.md: L = 16, K = 32, hidden 64,
# depth 3), so that every example, and the per-point autograd residuals in particular, runs
# in a fraction of a second; every branch of the model still runs (gamma of x with two
# frequencies, the code, the K-pattern mixing, the ADF's time encoding).
CFG = MotionSpec(n_freqs_x=2, n_freqs_t=0, n_freqs_adf_x=2, n_freqs_adf_t=1, code_dim=4, n_patterns=4,
                   hidden=16, depth=2)


def camera(width, height, focal):
    """(viewmat, K) of a camera 4 units in front of the origin, on the -z side, looking along +z.

    World and camera axes are parallel (OpenCV: +x right, +y down), so a Gaussian at the
    origin is at depth 4 and lands on the image centre (width / 2, height / 2).
    """
    viewmat = np.eye(4)
    viewmat[2, 3] = 4.0
    K = np.array([[focal, 0.0, width / 2], [0.0, focal, height / 2], [0.0, 0.0, 1.0]])
    return viewmat, K


def axis_angle_quat(axis, degrees):
    """The unit quaternion (w, x, y, z) of a rotation by `degrees` about `axis`."""
    axis = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    half = np.radians(degrees) / 2
    return np.concatenate([[np.cos(half)], np.sin(half) * axis])


def scene_gaussians():
    """Four Gaussians around the origin (means, quats, scales, opacities, colours) for the
    rendering and metric examples: a red disk behind, a green cigar, a blue ball and a
    small white dot in front."""
    means = np.array([[0.0, 0.0, 0.5], [-0.35, -0.2, 0.0], [0.35, 0.25, -0.1], [0.05, 0.3, -0.5]])
    quats = np.stack([axis_angle_quat([1, 0, 0], 30), axis_angle_quat([0, 0, 1], 35),
                      axis_angle_quat([0, 1, 0], 0), axis_angle_quat([1, 1, 0], 60)])
    scales = np.array([[0.6, 0.5, 0.05], [0.45, 0.08, 0.08], [0.2, 0.2, 0.2], [0.06, 0.06, 0.06]])
    opacities = np.array([0.9, 0.8, 0.95, 1.0])
    colours = np.array([[0.85, 0.2, 0.15], [0.2, 0.75, 0.3], [0.2, 0.35, 0.9], [1.0, 1.0, 1.0]])
    return means, quats, scales, opacities, colours


def coefficient_vector(**groups):
    """The 12 coefficients w with the given VG-BASIS groups set, e.g. rotation=(0, 0, 1);
    the other columns are 0."""
    w = np.zeros(N_BASIS)
    for group, values in groups.items():
        w[list(COLUMN_GROUPS[group])] = values
    return w


def constant_motion_params(w, alpha=None, seed=0):
    """Motion parameters whose coefficients are `w` (12,) for every particle and time, and whose
    acceleration coefficients are `alpha` (12,) (default 0).

    The time network's last layer becomes zero weights with bias tile(w, K): every motion
    pattern is w, so any mixture m(z) gives w. Q_0 holds alpha for every pattern, Q_1 = Q_2 = 0.
    The code network stays random: the Eulerian field still runs through E(gamma(x)), without
    effect on the value.
    """
    params = init_motion_params(np.random.default_rng(seed), CFG)
    W, _ = params["time"][-1]
    params["time"][-1] = (np.zeros_like(W), np.tile(w, CFG.n_patterns))
    if alpha is not None:
        params["acc"][0] = np.tile(alpha, (CFG.n_patterns, 1))
    return params


def learned_motion_params(seed=0, time_scale=0.6, adf_scale=0.05, mix_scale=10.0):
    """Motion parameters as training might leave them: `init_motion_params`, then the heads it
    starts at zero (the time network's and the ADF's last layers) drawn at random, so that the
    K patterns move and the ADF corrects, and the mixing matrix scaled by `mix_scale`, so that
    different codes pick different patterns (at initialisation every mixture is nearly
    uniform). No acceleration (Q = 0)."""
    rng = np.random.default_rng(seed)
    params = init_motion_params(rng, CFG)
    A, c = params["mix"][0]
    params["mix"] = [(mix_scale * A, c)]
    for head, scale in (("time", time_scale), ("adf", adf_scale)):
        W, b = params[head][-1]
        params[head][-1] = (scale * rng.standard_normal(W.shape), scale * rng.standard_normal(b.shape))
    return params


def mlp_velocity_params(seed=0, head_scale=0.5):
    """`learned_motion_params` plus the no-pds velocity MLP "velocity_mlp" (VG-VEL-MLP), its
    last layer (zero when training starts) drawn at random with standard deviation
    `head_scale`, so that the example field moves."""
    rng = np.random.default_rng(seed + 1)
    d_in, d_out = network_shapes(CFG)["velocity_mlp"]
    layers = mlp_layers(rng, d_in, CFG.hidden, CFG.depth, d_out, zero_last=True)
    W, b = layers[-1]
    layers[-1] = (head_scale * rng.standard_normal(W.shape), head_scale * rng.standard_normal(b.shape))
    return {**learned_motion_params(seed), "velocity_mlp": layers}
