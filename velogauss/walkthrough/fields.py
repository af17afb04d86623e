"""Walkthrough part: the affine velocity model, from basis to Eulerian field
(VG-BASIS, VG-CODE, VG-COEF, VG-COEF-CENTRE, VG-COEF-RIGID, VG-COEF-HARM, VG-COEF-COAST, VG-VEL,
VG-FIELD, VG-FIELD-GAUSS)."""

import dataclasses

import numpy as np

from velogauss_ref.motion.basis import affine_from_coefficients, basis_matrix
from velogauss_ref.motion.between import mixing_between
from velogauss_ref.motion.code import physics_code
from velogauss_ref.motion.coefficients import (centred, coefficients, harmonic_velocity_patterns, mixing_weights,
                                              motion_patterns, rigid_velocity_patterns)
from velogauss_ref.motion.velocity import mlp_velocity, velocity, velocity_field
from velogauss.walkthrough.figures import COLUMN_COLOURS, COLUMN_LABELS, new_figure, save
from velogauss.walkthrough.printing import Section, session
from velogauss.walkthrough.setups import CFG, coefficient_vector, learned_motion_params, mlp_velocity_params

# Two canonical positions whose codes mix the motion patterns differently (VG-COEF's figure).
X_A, X_B = np.array([[-0.6, 0.3, 0.0]]), np.array([[0.7, -0.4, 0.2]])


def basis_section(figures):
    """VG-BASIS: Phi at one point, Phi w = A(w) x + b(w); the 12 basis fields as quiver plots."""
    x = np.array([[1.0, 2.0, 3.0]])
    w = np.round(np.random.default_rng(1).standard_normal((1, 12)), 2)
    A, b = affine_from_coefficients(w)
    return Section(
        "VeloGauss does not let a network output velocities directly. Locally, any smooth motion is "
        "affine to first order, `v ≈ A x + b`: 12 degrees of freedom, spanned by 12 fixed fields "
        "of x: 3 translations, 3 rotations, 3 stretches and 3 shears. The networks only choose the "
        "12 coefficients `w`, so every velocity they produce is a physically readable mixture (spin "
        "`ω = (w4, w5, w6)`, divergence `w7 + w8 + w9`, ...). The example evaluates Φ at one point and "
        "checks `Φ(x) w = A(w) x + b(w)` for random `w`.",
        [session({"x": x}, "Phi = basis_matrix(x)", {"Phi[0]": basis_matrix(x)[0]},
                 {"w": w}, "A, b = affine_from_coefficients(w)", {"A": A[0], "b": b[0]},
                 "basis_matrix(x)[0] @ w[0], A[0] @ x[0] + b[0]",
                 {"Phi w": basis_matrix(x)[0] @ w[0], "A x + b": A[0] @ x[0] + b[0]}),
         _basis_figure(figures)],
    )


def _basis_figure(figures):
    """The 12 columns of Phi on the slice z = 0.5: arrows in-plane (vx, vy), colour out-of-plane vz."""
    u = np.linspace(-1, 1, 9)
    gx, gy = np.meshgrid(u, u)
    points = np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, 0.5)], axis=-1)
    Phi = basis_matrix(points)  # (81, 3, 12)
    fig = new_figure(11, 8.6)
    axes = fig.subplots(3, 4).T.ravel()  # one column of panels per group
    for k, ax in enumerate(axes):
        v = Phi[:, :, k]
        shown = ax.imshow(v[:, 2].reshape(gx.shape), origin="lower", extent=(-1.125, 1.125, -1.125, 1.125),
                          cmap="coolwarm", vmin=-1.5, vmax=1.5)
        ax.quiver(points[:, 0], points[:, 1], v[:, 0], v[:, 1], angles="xy", scale_units="xy", scale=4,
                  pivot="mid", color="k")
        ax.set(title=COLUMN_LABELS[k], xticks=(-1, 0, 1), yticks=(-1, 0, 1))
        ax.title.set_color(COLUMN_COLOURS[k])
    fig.colorbar(shown, ax=axes.tolist(), shrink=0.6, label="out-of-plane component v_z")
    return save(fig, figures, "basis-fields",
                "The 12 basis fields Φ(x)[:, k] on the slice z = 0.5 of [-1, 1]³: arrows are the in-plane part "
                "(v_x, v_y), the background colour the out-of-plane part v_z (w3 and w9 have no arrows: they "
                "move straight through the slice). Columns: translation, rotation, stretch, shear.")


def code_section(figures):
    """VG-CODE: the codes of three canonical positions, two of them 1e-3 apart."""
    params = learned_motion_params()
    x0 = np.concatenate([X_A, X_B, X_A + 1e-3])
    return Section(
        "A scene holds several bodies that move differently. Each Gaussian carries a small latent "
        "*physics code*, computed once from its canonical position by an MLP on γ(x0); the code "
        "decides how the shared motion patterns are mixed for this particle (VG-COEF). It is a "
        "material property: a particle keeps the code of where it started. The example uses the "
        f"walkthrough's small configuration (code size L = {CFG.code_dim}); nearby points get nearby codes.",
        [session({"x0": x0}, "z = physics_code(params, x0, cfg)", {"z": physics_code(params, x0, CFG)})],
    )


def coefficients_section(figures):
    """VG-COEF: two codes' mixtures of the K patterns; patterns and w(t) over time."""
    params = learned_motion_params()
    z = physics_code(params, np.concatenate([X_A, X_B]), CFG)
    t = 0.5
    m, P = mixing_weights(params, z), motion_patterns(params, t, CFG)
    return Section(
        f"The 12 coefficients of a particle come from K = {CFG.n_patterns} shared *motion patterns* `P(t)`, "
        "each a 12-vector that evolves in time (one time network, evaluated once per time for all "
        "particles), mixed by softmax weights `m(z)` that depend only on the particle's code. Two "
        "particles with the same code move alike; a rigid body is one code. The example takes the "
        "codes of two points and compares their mixtures.",
        [session({"z": z, "t": t}, "m = mixing_weights(params, z)  # softmax(z A + c), rows sum to 1",
                 {"m": m, "m.sum(axis=1)": m.sum(axis=1)},
                 "P = motion_patterns(params, t, cfg)  # (K, 12)", {"P": P},
                 "w = coefficients(params, t, z, cfg)", {"w": coefficients(params, t, z, CFG), "m @ P": m @ P}),
         _coefficients_figure(figures, params, z)],
    )


def rigid_coefficients_section(figures):
    """VG-COEF-RIGID: a thrown, spinning body as one pattern, inside the window and past it."""
    omega, g, c0, u = np.array([0.0, 0.0, 2.0]), np.array([0.0, 0.0, -8.0]), np.array([-0.5, 0.0, -0.5]), \
        np.array([1.0, 0.0, 4.0])
    window = 0.75

    def centre(t):  # the body's true centre
        return c0 + u * t + 0.5 * g * t * t

    B = np.concatenate([omega, centre(0.0), centre(window / 2), centre(window)])[None, :]
    x = np.array([[0.2, 0.5, 0.3]])
    steps = []
    for t in (0.5, 1.0):
        v = velocity(x, rigid_velocity_patterns(B, t, window))
        steps += [f"v = velocity(x, rigid_velocity_patterns(B, t={t}, max_time={window}))",
                  {"v": v, "ω × (x − c(t)) + ċ(t)": np.cross(omega, x - centre(t)) + u + g * t}]
    return Section(
        "For a scene whose motion is rigid (translation, rotation, gravity), `model.patterns = auto` "
        "replaces the time network by rigid bodies: each pattern is a constant spin ω and a centre "
        "c(t) given by its positions at knots in the observed window (0, T/2, T under gravity; 0 and "
        "T when nothing accelerates the centre), with `v = ω × (x − c(t)) + ċ(t)`. What the window "
        "fixes continues past it as the body would. The example is the default scene's kind of "
        "motion: a spin of 2 about z while the centre is thrown from (−0.5, 0, −0.5) at (1, 0, 4) "
        "under g = (0, 0, −8), stored as its centre at t = 0, 0.375 and 0.75, read inside the "
        "window (t = 0.5) and past it (t = 1).",
        [session({"B": B, "x": x}, "P = rigid_velocity_patterns(B, t, max_time)  # translation | rotation | 0 | 0",
                 {"P(0.5)": rigid_velocity_patterns(B, 0.5, window)}, *steps)],
    )


def centred_section(figures):
    """VG-COEF-CENTRE: a spin about a body's own centre, as one pattern about that centre."""
    omega, c = np.array([[0.0, 0.0, 2.0]]), np.array([[0.6, 0.3, 0.0]])
    P = np.concatenate([np.zeros((1, 3)), omega, np.zeros((1, 6))], axis=1)  # the spin alone
    x = c + np.array([[0.2, 0.0, 0.0]])
    world = centred(P, c)
    return Section(
        "The basis is affine in world coordinates, so a body spinning at ω about its own centre c "
        "needs, in the world's frame, the translation `b = −ω × c` beside the spin: the further the "
        "body sits from the origin, the more its spin and its translation share coefficients, which a "
        "time network that starts still must learn in step. Under `model.pattern_centres = \"clusters\"` "
        "each pattern is written about a centre of its own, which training places on the centroid of its "
        "k-means region of the initial points (the default, `\"origin\"`, keeps the world's origin): about "
        "the body's centre the spin is the rotation columns alone. The example is a spin "
        "of 2 about z through c = (0.6, 0.3, 0), read at a point 0.2 from c along x: it moves along y.",
        [session({"P": P[0, :6], "c": c[0]}, "P_world = centred(P, c)", {"P_world": world[0, :6]},
                 {"x": x[0]}, "velocity(x, P_world)", {"v": velocity(x, world)[0]})],
    )


# The catalogue's `pulse`: a cube stretched along x as exp(sin(w t) diag(k, -k/2, -k/2)).
PULSE_OMEGA, PULSE_K = 3.0 * np.pi, np.log(1.6)


def harmonic_coefficients_section(figures):
    """VG-COEF-HARM: the pulsing cube as oscillating patterns, inside the window and past it."""
    stretch = PULSE_K * np.array([1.0, -0.5, -0.5])
    C = np.zeros((3, 1, 12))
    C[1, 0, 6:9] = PULSE_OMEGA * stretch  # b: the stretch rate at t = 0
    omega = np.array([PULSE_OMEGA])
    x = np.array([[0.2, 0.1, -0.1]])
    steps = []
    for t in (0.3, 0.9):
        steps += [f"v = velocity(x, harmonic_velocity_patterns(C, omega, t={t}))",
                  {"v": velocity(x, harmonic_velocity_patterns(C, omega, t)),
                   "ω cos(ω t) L x": PULSE_OMEGA * np.cos(PULSE_OMEGA * t) * stretch * x}]
    return Section(
        "For a scene that declares `oscillation`, `model.patterns = auto` replaces the time network by "
        "oscillators: each pattern is `a + b cos(Ω t) + c sin(Ω t)`, and all share one learned "
        "frequency Ω. A time network of raw t cannot reverse more than about once inside the window "
        "and continues by its tail past it; an oscillator keeps reversing. The example is the "
        "catalogue's `pulse`, a cube stretched along x by `exp(sin(ω t) L)` with ω = 3π and "
        "`L = ln 1.6 · diag(1, −½, −½)`: its velocity `ω cos(ω t) L x` is one pattern with b = ωL "
        "on the stretch columns, read inside the window (t = 0.3, after its first reversal) and past "
        "it (t = 0.9, after its third).",
        [session({"C[1]": C[1], "omega": omega, "x": x},
                 "P = harmonic_velocity_patterns(C, omega, t)  # a + b cos(Ω t) + c sin(Ω t)",
                 {"P(0)": harmonic_velocity_patterns(C, omega, 0.0)}, *steps)],
    )


def coasting_section(figures):
    """VG-COEF-COAST: the time network's patterns inside the window, and kept at its end past it."""
    params = learned_motion_params()
    coast = dataclasses.replace(CFG, max_time=0.75, future="coast")
    steps = []
    for t in (0.5, 0.75, 1.0):
        steps += [f"P = motion_patterns(params, t={t}, coast)[0, :6]",
                  {"coast": motion_patterns(params, t, coast)[0, :6],
                   "integrate": motion_patterns(params, t, CFG)[0, :6]}]
    return Section(
        "Past the observed window `T = max_time` the time network continues by its activation's tail, "
        "a law nobody chose. Under `model.future = \"coast\"` the patterns read `P(min(t, T))`: the "
        "motion carries on in the field of the window's last patterns, so a spin keeps spinning and a "
        "drift keeps drifting. An option, not the default (benchmarks/FIDELITY.md, 0m). The example "
        "reads the first pattern's translation and rotation columns with T = 0.75: equal to the "
        "network's own inside the window, held at t = 0.75 past it.",
        [session({"T": coast.max_time}, *steps)],
    )


def _coefficients_figure(figures, params, z):
    times = np.linspace(0, 1, 41)
    patterns = np.stack([motion_patterns(params, t, CFG) for t in times])  # (T, K, 12)
    w = np.stack([coefficients(params, t, z, CFG) for t in times])  # (T, 2, 12)
    m = mixing_weights(params, z)
    fig = new_figure(12, 6.2)
    top, bottom = fig.subfigures(2, 1)
    lim = np.abs(patterns).max() * 1.05
    for k, ax in enumerate(top.subplots(1, CFG.n_patterns, sharey=True)):
        for column in range(12):
            ax.plot(times, patterns[:, k, column], color=COLUMN_COLOURS[column])
        ax.set(title=f"pattern P_{k + 1}(t)", xlabel="t", ylim=(-lim, lim))
    ax_m, ax_a, ax_b = bottom.subplots(1, 3, width_ratios=(0.7, 1, 1))
    bar = np.arange(1, CFG.n_patterns + 1)
    ax_m.bar(bar - 0.2, m[0], width=0.4, label="code A", color="0.3")
    ax_m.bar(bar + 0.2, m[1], width=0.4, label="code B", color="0.7")
    ax_m.set(xticks=bar, xlabel="pattern k", ylabel="m_k(z)", title="mixing weights")
    ax_m.legend(fontsize=8)
    for ax, row, name in ((ax_a, 0, "A"), (ax_b, 1, "B")):
        for column in range(12):
            ax.plot(times, w[:, row, column], color=COLUMN_COLOURS[column], label=COLUMN_LABELS[column])
        ax.set(title=f"w(t) of code {name} = m(z_{name}) P(t)", xlabel="t", ylim=(-lim, lim))
    ax_b.legend(fontsize=6, ncol=2, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    return save(fig, figures, "coef-patterns",
                f"Top: the K = {CFG.n_patterns} motion patterns over time, 12 coefficients each (colours: "
                "translation blue, rotation red, stretch green, shear purple). Bottom: two physics codes mix "
                "them with different softmax weights, so the same patterns give each particle its own "
                "coefficients w(t).")


def velocity_section(figures):
    """VG-VEL: a spinning-drifting and a stretching particle, against A(w) x + b(w)."""
    x = np.array([[1.0, 0.0, 0.0], [0.0, 2.0, 0.0]])
    w = np.stack([coefficient_vector(translation=(0.5, 0, 0), rotation=(0, 0, 1)),
                  coefficient_vector(stretch=(0.5, 0.5, -1.0))])
    A, b = affine_from_coefficients(w)
    return Section(
        "A particle's velocity is the basis evaluated at its position, weighted by its coefficients. "
        "The first row spins about z at 1 rad per unit time while drifting along x; the second "
        "stretches in x and y and squeezes in z (divergence 0).",
        [session({"x": x, "w": w}, "v = velocity(x, w)", {"v": velocity(x, w)},
                 "# the same as A(w) x + b(w)", {"A x + b": np.einsum("nij,nj->ni", A, x) + b})],
    )


def field_section(figures):
    """VG-FIELD: the Eulerian field against the particle velocity with a frozen code; field slices."""
    params = learned_motion_params()
    x = np.concatenate([X_A, X_B])
    t = 0.5
    x_moved = x + np.array([0.3, 0.0, 0.0])
    z_frozen = physics_code(params, x, CFG)
    return Section(
        "The physics constraints are statements about a field `v(x, t)` defined everywhere, not only "
        "where particles are. The Eulerian field takes the code *at the query point*: "
        "`v(x, t) = Φ(x) w(t, E(γ(x)))`. A particle that started at x0 uses its own frozen code "
        "instead; the two agree at the particle's canonical position and differ elsewhere unless the "
        "code is constant over the body, which is what training drives it to.",
        [session({"x": x, "t": t}, "v = velocity_field(params, x, t, cfg)", {"v": velocity_field(params, x, t, CFG)},
                 "velocity(x, coefficients(params, t, physics_code(params, x, cfg), cfg))  # the same, spelt out",
                 {"v": velocity(x, coefficients(params, t, z_frozen, CFG))},
                 "# 0.3 further along x: the field uses the new point's code, a particle its frozen code",
                 {"field": velocity_field(params, x_moved, t, CFG),
                  "particle": velocity(x_moved, coefficients(params, t, z_frozen, CFG))}),
         _field_figure(figures, params)],
    )


def _field_figure(figures, params):
    u = np.linspace(-1, 1, 13)
    gx, gy = np.meshgrid(u, u)
    points = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], axis=-1)
    fig = new_figure(10, 4.0)
    for ax, t in zip(fig.subplots(1, 3), (0.0, 0.5, 1.0)):
        v = velocity_field(params, points, t, CFG)
        speed = np.linalg.norm(v, axis=1)
        ax.quiver(points[:, 0], points[:, 1], v[:, 0], v[:, 1], speed, cmap="viridis", clim=(0, 2), angles="xy",
                  scale_units="xy", scale=8, pivot="mid")
        ax.set(title=f"t = {t:g}", xlabel="x", aspect="equal", xlim=(-1.15, 1.15), ylim=(-1.15, 1.15))
    fig.axes[0].set_ylabel("y")
    return save(fig, figures, "field-slices",
                "velocity_field of the example parameters on the slice z = 0 at three times: in-plane arrows (one "
                "scale for all panels), colour the speed |v|. Random networks give a smooth but physically "
                "meaningless field; "
                "the physics residuals (VG-TRANSPORT, VG-DIV) measure how far from physical it is.")


def between_section(figures):
    """VG-FIELD-GAUSS: a ball's Gaussians and the still ground's; the weights between them."""
    centres, weights = _ball_on_ground()
    # The ball's lowest point, a point on its side, one halfway across the gap, one on the ground.
    x = np.array([[0.0, 0.0, 0.05], [0.5, 0.0, 0.55], [0.0, 0.0, 0.025], [0.8, 0.0, 0.0]])
    return Section(
        "A Gaussian moves with the mixing weights of its own canonical mean. A material point that "
        "is not a Gaussian (a surface point the evaluation scores, an arrow in the viewer) takes, "
        "by default, the inverse-square-distance mean of its 8 nearest Gaussians' weights, the "
        "still (static) Gaussians' rows zero. The example: a ball of 800 Gaussians on pattern 0, 0.05 "
        "above a still ground of Gaussians 0.1 apart. The ball's lowest point keeps 0.89 of the "
        "ball's pattern, its side all of it, the middle of the gap half, the ground none. On the "
        "`multi` scene the smooth code network, asked the same, leaned to the ground's pattern on "
        "the bodies' lowest points (benchmarks/FIDELITY.md, section 0e).",
        [session({"x": x}, "m = mixing_between(x, centres, weights)  # ball's Gaussians: (1, 0); ground's: (0, 0)",
                 {"m": mixing_between(x, centres, weights)}),
         _between_figure(figures, centres, weights)],
    )


def _ball_on_ground():
    """(centres (N, 3), weights (N, 2)): 800 Gaussians on a ball of radius 0.5 at height 0.55
    on pattern 0, and a grid 0.1 apart on the ground z = 0, static (zero rows)."""
    golden = np.pi * (3 - np.sqrt(5))  # a Fibonacci sphere: evenly spread points
    k = np.arange(800)
    z = 1 - 2 * (k + 0.5) / 800
    r = np.sqrt(1 - z**2)
    ball = 0.5 * np.stack([r * np.cos(golden * k), r * np.sin(golden * k), z], axis=1) + [0.0, 0.0, 0.55]
    u = np.linspace(-1.2, 1.2, 25)
    gx, gy = np.meshgrid(u, u)
    ground = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], axis=1)
    weights = np.concatenate([np.tile([1.0, 0.0], (len(ball), 1)), np.zeros((len(ground), 2))])
    return np.concatenate([ball, ground]), weights


def _between_figure(figures, centres, weights):
    u = np.linspace(-1.2, 1.2, 97)
    gx, gz = np.meshgrid(u, np.linspace(-0.2, 1.2, 57))
    points = np.stack([gx.ravel(), np.zeros(gx.size), gz.ravel()], axis=1)
    share = mixing_between(points, centres, weights)[:, 0].reshape(gx.shape)
    fig = new_figure(6, 3.6)
    ax = fig.subplots()
    image = ax.pcolormesh(gx, gz, share, cmap="viridis", vmin=0, vmax=1, shading="auto")
    near = np.abs(centres[:, 1]) < 0.06
    ax.scatter(centres[near, 0], centres[near, 2], s=6, c="white", edgecolors="black", linewidths=0.3)
    ax.set(xlabel="x", ylabel="z", aspect="equal", title="weight of the ball's pattern between the Gaussians")
    fig.colorbar(image, ax=ax, shrink=0.8)
    return save(fig, figures, "between-gaussians",
                "mixing_between on the slice y = 0 through a ball of Gaussians (weights (1, 0)) 0.05 above "
                "a still ground (weights (0, 0)); dots: the Gaussians near the slice. The ball's pattern "
                "holds to its surface and falls off across the gap to the ground; away from both, a point "
                "takes the pattern of the nearer.")


def mlp_velocity_section(figures):
    """VG-VEL-MLP: the no-pds velocity at a few points and times; no code, no basis."""
    params = mlp_velocity_params()
    x = np.array([[1.0, 0.0, 0.0], [0.0, -0.5, 0.3]])
    return Section(
        "The \"no-pds\" ablation replaces the affine basis and the physics code by one unconstrained "
        "network of position and time, as the paper's ablation does. Nothing ties neighbouring "
        "points to a shared rigid or affine motion, and the velocity carries no rotation or strain "
        "rule: integrated from t = 0 it moves positions only. Training starts its last layer at "
        "zero; here it is random so that the field moves.",
        [session({"x": x}, "v = mlp_velocity(params, x, 0.0, cfg)", {"v": mlp_velocity(params, x, 0.0, CFG)},
                 "v = mlp_velocity(params, x, 0.5, cfg)", {"v": mlp_velocity(params, x, 0.5, CFG)})],
    )


SECTIONS = {"VG-BASIS": basis_section, "VG-CODE": code_section, "VG-COEF": coefficients_section,
            "VG-COEF-CENTRE": centred_section, "VG-COEF-RIGID": rigid_coefficients_section,
            "VG-COEF-HARM": harmonic_coefficients_section, "VG-COEF-COAST": coasting_section, "VG-VEL": velocity_section, "VG-FIELD": field_section,
            "VG-FIELD-GAUSS": between_section, "VG-VEL-MLP": mlp_velocity_section}
