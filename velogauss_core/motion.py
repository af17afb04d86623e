"""The motion model's resolved plan and tables (spec/motion.md, "Parameters and configuration").

One frozen `MotionSpec`, the resolved plan of a model's motion, is what `velogauss_ref`,
`velogauss_fast` and the application's motion read; the application resolves it from its
config (`velogauss.model.spec.resolve_motion_spec`). One `init_motion_params` draws the
parameter dict (NumPy arrays; the model converts them to tensors). The networks' sizes are
declared once, as the fields of `NetworkSizes`, which both `MotionSpec` and the training
config's `[model]` section (`velogauss.config.ModelConfig`) inherit. Every list of choices is
defined here once, as a `Literal` type and the tuple of its values.
"""

import dataclasses
from dataclasses import dataclass, fields
from typing import Annotated, Literal, get_args

import numpy as np
from annotated_types import Interval
from pydantic import Field, Strict

from velogauss_core.checks import check_scalar
from velogauss_core.constants import ACC_HARMONICS, ACC_POLY_DEGREE, HARMONIC_CYCLES_INIT, RIGID_OMEGA_INIT

# Number of affine basis velocity fields, the columns of Phi (VG-BASIS).
N_BASIS = 12
# (dx 3, dq 4, ds 3) of VG-ADF.
ADF_OUTPUTS = 10

# Zero-based columns of Phi selected by each effect of a scene's profile (VG-BASIS,
# "Column masks"); a column mask is the union of the groups a scene declares.
COLUMN_GROUPS = {
    "translation": (0, 1, 2),
    "rotation": (3, 4, 5),
    "stretch": (6, 7, 8),
    "shear": (9, 10, 11),
}

Effect = Literal["translation", "rotation", "gravity", "stretch", "shear", "oscillation", "static"]
# The effects a scene may declare (scene.json, --effects), in canonical order. "oscillation":
# the motion repeats (a restoring force), which selects the harmonic time forms
# (VG-COEF-HARM, VG-ACC-HARM) under `model.patterns = auto`.
EFFECTS: tuple[str, ...] = get_args(Effect)
# What a scene that declares nothing may use: every effect but "oscillation", which is not a
# basis column but an assumption about time (the motion repeats past the window) that only
# a declaration may make.
UNDECLARED_EFFECTS: tuple[str, ...] = tuple(e for e in EFFECTS if e != "oscillation")
# The effects that select velocity basis columns (COLUMN_GROUPS).
MOTION_EFFECTS: tuple[str, ...] = tuple(COLUMN_GROUPS)

Integrator = Literal["euler", "rk2", "rk4"]
# The fixed-step integrators of VG-INTEG.
INTEGRATORS: tuple[str, ...] = get_args(Integrator)

Ablation = Literal["full", "no-pds", "no-adf", "no-gpc", "deform-only"]
# The paper's ablations (Table "ablation"): which of PDS, ADF and GPC a model keeps.
ABLATIONS: tuple[str, ...] = get_args(Ablation)

Scheme = Literal["integrate", "adf-step"]
# How the Gaussians' state at t comes from the velocity and the ADF (spec/motion.md;
# `velogauss.model.motion.gaussians_at` has one branch per value). "integrate" (a):
# integrate from the canonical state at t = 0 (VG-TRAJ), then add the ADF residual
# (VG-ADF-COMPOSE), the paper's scheme. "adf-step" (b): the ADF's own state at a start time
# carried to t by the velocity (VG-CARRY), the authors' released code. Defined here, not in
# velogauss.model.spec, because the config and `MotionSpec` type a key with it.

AccelerationForm = Literal["poly", "rigid"]
# How the acceleration of each motion pattern depends on time (spec/physics.md): "poly" a
# polynomial of degree ACC_POLY_DEGREE in t per basis column (VG-ACC), "rigid" a body spinning
# at a constant rate whose centre falls under a constant acceleration (VG-ACC-RIGID). These
# are the config's choices; MotionSpec also takes "harmonic" (VG-ACC-HARM), which the
# harmonic patterns bring with them, as it needs their frequencies.
ACC_FORMS: tuple[str, ...] = (*get_args(AccelerationForm), "harmonic")

PatternForm = Literal["mlp", "rigid", "harmonic"]
# How the motion patterns P(t) depend on time (spec/motion.md): "mlp" the time network of
# VG-COEF, "rigid" a body spinning at a constant rate about a centre that moves under a
# constant acceleration (VG-COEF-RIGID), "harmonic" an oscillator of learned frequency
# (VG-COEF-HARM).
PATTERN_FORMS: tuple[str, ...] = get_args(PatternForm)

QueryCode = Literal["gaussians", "network"]
# Past the observed window the motion carries on ("integrate"), carries on with the motion patterns
# kept at their value at the window's end ("coast": the velocity's persistence forecast), or every
# Gaussian keeps its state at the window's end ("hold": the position's persistence forecast), or a
# form fitted to the trained paths carries the Gaussians on from their state there ("fit": the
# model's forecast, velogauss.model.velogauss_model; the motion's own functions read it as "integrate").
Future = Literal["integrate", "coast", "hold", "fit"]
FUTURES: tuple[str, ...] = get_args(Future)
# Where a material point that is not a Gaussian takes its velocity (spec/motion.md): "gaussians"
# with mixing weights interpolated from its nearest Gaussians' own (VG-FIELD-GAUSS, the affine
# velocity's), "network" from the networks at the point (the velocity MLP of no-pds). Resolved
# from the velocity by velogauss.model.spec, not a config key.

VelocityKind = Literal["affine", "mlp"]
# How particles get a velocity: the affine basis Phi(x) w (PDS on) or an unconstrained MLP
# v(gamma(x), t) (PDS off, "no-pds"); a model without velocity has None.
VELOCITY_KINDS: tuple[str, ...] = get_args(VelocityKind)


def _int_in(low, high=None):
    """An integer in [low, high] (no upper bound when `high` is None), bools, floats and strings
    refused: pydantic enforces both markers on the config's `[model]` keys, and
    `MotionSpec.__post_init__` reads the `Interval` back for a spec built directly."""
    return Annotated[int, Strict(), Interval(ge=low, le=high)]


_Size = _int_in(1)


def _about(text):
    """A size's description: pydantic reads it where the config inherits the field."""
    return Field(description=text)

# Positional-encoding frequencies 2^0 ... 2^(n-1): beyond 2^16 float32 sin(2^k x) is noise.
_Freqs = _int_in(0, 16)


@dataclass(frozen=True)
class NetworkSizes:
    """The fields of the motion networks' sizes (spec/motion.md), with their defaults and
    ranges, declared once: `MotionSpec` and `velogauss.config.ModelConfig` (keys
    `model.n_patterns`, ..., in this order in config.toml) inherit them; nothing builds one alone.

    Each size's description is pydantic's, which `velogauss config` prints.
    """

    n_patterns: Annotated[_Size, _about("K, the motion patterns of VG-COEF; 32, the paper's ablation value")] = 32
    code_dim: Annotated[_Size, _about("L, the physics code's size (VG-CODE)")] = 16
    hidden: Annotated[_Size, _about("Width of every MLP's hidden layers")] = 64
    depth: Annotated[_Size, _about("Hidden layers of every MLP")] = 3
    n_freqs_x: Annotated[_Freqs, _about("Frequencies of gamma(x0) for the code encoder E (VG-CODE)")] = 4
    n_freqs_t: Annotated[_Freqs, _about("Frequencies of gamma(t) for the time network (VG-COEF); 0, raw t, which "
                                        "extrapolates without imposing a period")] = 0
    n_freqs_adf_x: Annotated[_Freqs, _about("Frequencies of the ADF's position input (VG-ADF)")] = 6
    n_freqs_adf_t: Annotated[_Freqs, _about("Frequencies of the ADF's time input (VG-ADF)")] = 6


@dataclass(frozen=True)
class MotionSpec(NetworkSizes):
    """What the motion of one model computes, resolved once from the config, the scene's
    effects and the ablation (`velogauss.model.spec.resolve_motion_spec`); the pure functions
    of `velogauss_ref`, `velogauss_fast` and `velogauss.model.motion` read only this.

    The networks' sizes (`NetworkSizes`), then:
    mask: None (every column) or 12 bools, the velocity's basis columns (VG-BASIS order);
    acc_mask: None (every column) or 12 bools, the acceleration's columns (VG-ACC);
    acc_form: the acceleration's time dependence, "poly" (VG-ACC), "rigid" (VG-ACC-RIGID) or
      "harmonic" (VG-ACC-HARM, only with harmonic patterns, whose frequencies it uses);
    pattern_form: the motion patterns' time dependence, "mlp" (VG-COEF), "rigid"
      (VG-COEF-RIGID) or "harmonic" (VG-COEF-HARM);
    max_time: the end of the observed window in normalised time, in (0, 1], where
      VG-COEF-RIGID's last knot sits;
    rigid_knots: VG-COEF-RIGID's knots per centre, evenly spaced over [0, max_time]: 3 (a
      centre under a constant acceleration) or 2 (a centre drifting uniformly);
    effects: the scene's resolved effects (`Effect`, in canonical order);
    moving: the scene moves at all (False: a static scene, no motion parameters, every
      switch below is then off);
    scheme: how positions come from the velocity (`Scheme`); "adf-step" only where there is
      a velocity and an ADF (it carries the ADF's state);
    velocity: "affine" (PDS: Phi(x) w(t, z) over `mask`, VG-VEL), "mlp" (no-pds) or None
      (deform-only: x* = x0);
    acceleration: the acceleration (`acc_form`) is a parameter (else Q = 0);
    integrator, step: VG-INTEG's method and largest step in normalised time;
    adf: the ADF residual is built and applied (VG-ADF);
    adf_clamp_time: the ADF's input time is min(t, this), or None (evaluated at every t);
    adf_loss: the L2 penalty on the ADF's displacement |x - x*|^2 is on (ADF on top of a
      velocity, scheme "integrate"; under "adf-step" x = x*, the penalty would be 0);
    physics_loss: the VG-LOSS-PHYS transport residual on collocation points is on (GPC);
    divergence: the VG-DIV term of the physics loss is on (incompressible motion);
    carry_until: scheme "adf-step": the end of the ADF's window (max_time), where beyond it
      the velocity alone carries the ADF's state (VG-CARRY); None for "integrate";
    carry_offset: scheme "adf-step": |t - t_start| of VG-CARRY in training (0 otherwise);
    carry_loss: VG-LOSS-CARRY (the affine velocity fitted to the ADF's paths) can be on:
      scheme "adf-step" with the affine velocity; its weight is train.lambda_carry;
    query_code: where a material point that is not a Gaussian takes its mixing weights:
      "gaussians" from its nearest Gaussians' (VG-FIELD-GAUSS) under the affine velocity,
      "network" elsewhere (the velocity MLP of no-pds reads the point itself);
    future: past max_time the motion carries on ("integrate"), carries on with the motion
      patterns kept at P(max_time) ("coast"), holds every Gaussian at its state at max_time
      with zero velocity ("hold"), or hands the Gaussians at max_time to a form fitted to the
      trained paths, the model's forecast ("fit"; spec/motion.md "The future past the window").
    The defaults are the plan of the default config for a scene that declares nothing, over
    the whole window (tests/app/test_profile.py pins it), so a spec built directly for the
    pure functions names only what it changes. Masks and effects are tuples so the spec stays
    hashable and serialisable.
    Raises ValueError naming the field for a size outside its range (`NetworkSizes`), a mask
    that is not 12 bools, an unknown `acc_form` or `pattern_form`, a max_time outside (0, 1]
    or rigid_knots other than 2 or 3, and a harmonic acceleration without harmonic patterns.
    """

    mask: tuple[bool, ...] | None = None
    acc_mask: tuple[bool, ...] | None = None
    acc_form: AccelerationForm = "poly"
    pattern_form: PatternForm = "mlp"
    max_time: float = 1.0
    rigid_knots: int = 3
    effects: tuple[str, ...] = UNDECLARED_EFFECTS
    moving: bool = True
    scheme: Scheme = "integrate"
    velocity: VelocityKind | None = "affine"
    acceleration: bool = True
    integrator: Integrator = "rk2"
    step: float = 0.05
    adf: bool = True
    adf_clamp_time: float | None = 1.0
    adf_loss: bool = True
    physics_loss: bool = True
    divergence: bool = True
    carry_until: float | None = None
    carry_offset: float = 0.0
    carry_loss: bool = False
    query_code: QueryCode = "gaussians"
    future: Future = "integrate"

    def __post_init__(self):
        for field in fields(NetworkSizes):
            (bounds,) = (m for m in field.type.__metadata__ if isinstance(m, Interval))
            _check_int(field.name, getattr(self, field.name), bounds.ge, bounds.le)
        for name in ("mask", "acc_mask"):
            value = getattr(self, name)
            if value is not None:
                object.__setattr__(self, name, _check_mask(name, value))
        if self.acc_form not in ACC_FORMS:
            raise ValueError(f"acc_form: expected one of {ACC_FORMS}, got {self.acc_form!r}")
        if self.pattern_form not in PATTERN_FORMS:
            raise ValueError(f"pattern_form: expected one of {PATTERN_FORMS}, got {self.pattern_form!r}")
        if self.acc_form == "harmonic" and self.pattern_form != "harmonic":
            raise ValueError(f"acc_form: 'harmonic' takes the harmonic patterns' frequencies, got pattern_form "
                             f"{self.pattern_form!r}")
        if not 0.0 < check_scalar("max_time", self.max_time) <= 1.0:
            raise ValueError(f"max_time: expected a time in (0, 1], got {self.max_time!r}")
        if self.rigid_knots not in (2, 3) or isinstance(self.rigid_knots, bool):
            raise ValueError(f"rigid_knots: expected 2 or 3, got {self.rigid_knots!r}")
        if self.future not in FUTURES:
            raise ValueError(f"future: expected one of {FUTURES}, got {self.future!r}")

    @property
    def rigid_patterns(self) -> bool:
        """The affine velocity's motion patterns are VG-COEF-RIGID's rigid bodies (`params["time"]`
        is their B, a (K, 3 + 3 n) tensor)."""
        return self.velocity == "affine" and self.pattern_form == "rigid"

    def without_adf(self) -> "MotionSpec":
        """This spec with the ADF skipped: what training runs before the ADF starts learning
        (its last layer is still zero then, so skipping it is exactly the identity). Scheme
        "adf-step" carries the ADF's state, so without the ADF it is "integrate"."""
        return dataclasses.replace(self, adf=False, scheme="integrate", carry_until=None, carry_offset=0.0,
                                   carry_loss=False)


def spec_from_dict(values: dict) -> MotionSpec:
    """Inverse of `dataclasses.asdict(spec)` (lists back to tuples): checkpoints store the spec.
    ValueError naming the first missing or unknown field: a default must not stand in for a
    saved value."""
    names = [f.name for f in fields(MotionSpec)]
    for name in [*names, *values]:
        if (name in names) != (name in values):
            raise ValueError(f"{name}: {'missing from' if name in names else 'not a field of'} the saved MotionSpec")
    return MotionSpec(**{k: tuple(v) if isinstance(v, list) else v for k, v in values.items()})


def network_shapes(cfg: MotionSpec) -> dict[str, tuple[int, int]]:
    """(d_in, d_out) of each MLP of the parameter dict, by key; every MLP has `cfg.depth`
    hidden layers of width `cfg.hidden`. "code" E (VG-CODE), "time" P(t) (VG-COEF), "adf" F
    (VG-ADF) and "velocity_mlp", the unconstrained velocity v(gamma(x), t) of "no-pds"."""
    L, K = cfg.code_dim, cfg.n_patterns
    return {
        "code": (3 * (1 + 2 * cfg.n_freqs_x), L),
        "time": (1 + 2 * cfg.n_freqs_t, K * N_BASIS),
        "adf": (3 * (1 + 2 * cfg.n_freqs_adf_x) + 1 + 2 * cfg.n_freqs_adf_t + L, ADF_OUTPUTS),
        "velocity_mlp": (3 * (1 + 2 * cfg.n_freqs_x) + 1, 3),
    }


def init_motion_params(rng, cfg):
    """A fresh parameter dict for `cfg` (`MotionSpec`), drawn from the NumPy Generator `rng`.

    Layout (all float64 arrays; MLPs are lists of (W (d_in, d_out), b (d_out,)), sizes from
    `network_shapes`):
      "code": E, 3 (1 + 2 n_freqs_x) -> hidden^depth -> code_dim;
      "mix":  [(A (code_dim, K), c (K,))], the pattern-mixing softmax of VG-COEF;
      "time": 1 (1 + 2 n_freqs_t) -> hidden^depth -> K * 12, the motion patterns P(t), or
              with cfg.pattern_form "rigid" the array B (K, 3 + 3 rigid_knots) of
              VG-COEF-RIGID: each pattern's spin and its centre at the knots, or with
              "harmonic" [(C (3, K, 12), Omega (1,))] of VG-COEF-HARM: each pattern's mean,
              cosine and sine coefficients and the frequency they share;
      "acc":  the acceleration of each pattern: Q (ACC_POLY_DEGREE + 1, K, 12), the polynomial
              of VG-ACC, or with cfg.acc_form "rigid" R (K, 12), each pattern's spin, linear
              acceleration, centre and centre velocity at t = 0 (VG-ACC-RIGID), or with
              "harmonic" Q (2 ACC_HARMONICS + 1, K, 12), the coefficients of 1, cos(j Omega t)
              and sin(j Omega t) at the patterns' frequency (VG-ACC-HARM);
      "adf":  3 (1 + 2 n_freqs_adf_x) + (1 + 2 n_freqs_adf_t) + code_dim -> hidden^depth -> 10;
      "centre": (K, 3), the point each pattern is written about (VG-COEF-CENTRE): the world's
              origin here; training places them on the data (velogauss.train.mixing).
    Hidden layers use PyTorch's default Linear initialisation (uniform within
    +-1/sqrt(fan_in)). Three heads start at zero, so a fresh model is the still canonical
    scene: the time network's last layer (no velocity; B = 0 under "rigid"), Q (no
    acceleration) and the ADF's last layer (identity correction). Their gradients are not zero, so all of them learn.
    The rigid form starts with a small random spin (RIGID_OMEGA_INIT): its acceleration is
    quadratic in the spin, whose gradient at exactly zero would be zero. The harmonic form
    starts at zero coefficients and HARMONIC_CYCLES_INIT cycles over the window (training then
    sets the frequency the video shows, velogauss.train.frequency).
    """
    L, K = cfg.code_dim, cfg.n_patterns
    shapes = network_shapes(cfg)

    def mlp(key, zero_last=False):
        d_in, d_out = shapes[key]
        return mlp_layers(rng, d_in, cfg.hidden, cfg.depth, d_out, zero_last=zero_last)

    return {
        "code": mlp("code"),
        "mix": [(rng.standard_normal((L, K)) / np.sqrt(L), np.zeros(K))],
        "time": _patterns_init(cfg, mlp),
        "acc": _acceleration_init(rng, cfg),
        "adf": mlp("adf", zero_last=True),
        "centre": np.zeros((K, 3)),
    }


def carry_start(t, offset, max_time):
    """Start time of VG-CARRY (spec/motion.md): clamp(t - offset, 0, max_time) inside the
    window (t <= max_time), max_time beyond it. offset: the signed one-step offset drawn in
    training, 0 in evaluation. Plain floats: the reference and the model share it."""
    check_scalar("t", t)
    check_scalar("offset", offset)
    if t > max_time:
        return float(max_time)
    return float(min(max(t - offset, 0.0), max_time))


def _patterns_init(cfg, mlp):
    """The "time" entry of `init_motion_params`: the time network with a zero last layer
    (VG-COEF), B = 0 (VG-COEF-RIGID), or still oscillators at HARMONIC_CYCLES_INIT cycles over
    the window (VG-COEF-HARM)."""
    K = cfg.n_patterns
    if cfg.pattern_form == "mlp":
        return mlp("time", zero_last=True)
    if cfg.pattern_form == "rigid":
        return np.zeros((K, 3 + 3 * cfg.rigid_knots))
    return [(np.zeros((3, K, N_BASIS)), np.array([2.0 * np.pi * HARMONIC_CYCLES_INIT / cfg.max_time]))]


def _acceleration_init(rng, cfg):
    """The "acc" entry of `init_motion_params`: Q = 0 (VG-ACC, VG-ACC-HARM), or a small random
    spin about the origin with no linear acceleration (VG-ACC-RIGID)."""
    K = cfg.n_patterns
    if cfg.acc_form == "poly":
        return np.zeros((ACC_POLY_DEGREE + 1, K, N_BASIS))
    if cfg.acc_form == "harmonic":
        return np.zeros((2 * ACC_HARMONICS + 1, K, N_BASIS))
    rigid = np.zeros((K, N_BASIS))
    rigid[:, :3] = RIGID_OMEGA_INIT * rng.standard_normal((K, 3))
    return rigid


def mlp_layers(rng, d_in, hidden, depth, d_out, zero_last=False):
    """Layers (W (d_in, d_out), b) of an MLP d_in -> hidden^depth -> d_out, PyTorch-Linear init;
    the last layer is zero when `zero_last`."""
    dims = [d_in] + [hidden] * depth + [d_out]
    layers = []
    for k, (a, b) in enumerate(zip(dims[:-1], dims[1:])):
        bound = 1.0 / np.sqrt(a)
        if zero_last and k == len(dims) - 2:
            layers.append((np.zeros((a, b)), np.zeros(b)))
        else:
            layers.append((rng.uniform(-bound, bound, (a, b)), rng.uniform(-bound, bound, b)))
    return layers


def _check_int(name, value, low, high):
    """`value` is an integer (not a bool) in [low, high]; `high` None: no upper bound."""
    if (isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low
            or (high is not None and value > high)):
        wanted = f">= {low}" if high is None else f"in [{low}, {high}]"
        raise ValueError(f"{name}: expected an integer {wanted}, got {value!r}")


def _check_mask(name, value):
    mask = np.asarray(value)
    if mask.shape != (N_BASIS,) or mask.dtype != bool:
        raise ValueError(f"{name}: expected {N_BASIS} booleans (VG-BASIS columns), got {value!r}")
    return tuple(bool(m) for m in mask)
