"""The training configuration: defaults, a TOML file, and `section.key=value` overrides.

`load_config(path, overrides, flags)` starts from the defaults below, applies the TOML file
at `path` (if any), then each override `section.key=value` (the value is read as a TOML
value; a bare word is taken as a string), then the command-line `flags` (typed values), and
validates the result with pydantic: each field's type and range (`Field(ge=..., ...)`) is
written next to it below (the motion networks' sizes, `model.n_patterns` ...
`model.n_freqs_adf_t`, in `velogauss_core.motion.NetworkSizes`, shared with `MotionSpec`),
and is checked before any training. Unknown sections or keys and values of the wrong type or
out of range raise ValueError naming the key and where the value came from (the file, `--set`
or the flag). `to_toml(cfg)` writes a config back (tomli-w); `velogauss train` saves it as
`RUN_DIR/config.toml`, which is what `eval`, `render`, `export` and `--resume` read again.
Keys whose default is "auto" and that depend on the run (the schedule's, scaled to
`train.iterations`, and `physics.lambda_transport`, set by the scene's motion patterns) are
resolved when a run starts (`resolve_schedule`, `resolve_transport`); its config.toml holds
the numbers, and a resumed run keeps them (`resolve_from_run`).

The lists of choices are defined once, as `Literal` types (`Ablation`, `Integrator`,
`Effect`, `Scheme` in velogauss_core.motion; `Placement` here); the command line shows them
and validation enforces them.
"""

import dataclasses
import tomllib
from pathlib import Path
from typing import Annotated, Literal, Union, get_args

import tomli_w
from pydantic import ConfigDict, Field, TypeAdapter, ValidationError
from pydantic.dataclasses import dataclass

from velogauss_core.motion import (ABLATIONS, EFFECTS, INTEGRATORS, AccelerationForm, Ablation, Effect, Integrator,
                                   NetworkSizes, PatternForm, Scheme)
from velogauss_core.rendering import RasterizeMode


def _int(**bounds):
    """An integer (bools and floats refused) within `bounds` (pydantic's ge, le, ...)."""
    return Annotated[int, Field(strict=True, **bounds)]


def _float(**bounds):
    """A finite number (ints accepted, strings refused) within `bounds`."""
    return Annotated[float, Field(strict=True, allow_inf_nan=False, **bounds)]


Flag = Annotated[bool, Field(strict=True)]
Unit = _float(ge=0.0, le=1.0)
# Learning rates decayed log-linearly (velogauss.train.optim) need a positive start and end;
# the others may be 0, which freezes that group.
Rate = _float(gt=0.0)
Rate0 = _float(ge=0.0)
Count = _int(ge=1)
Every = _int(ge=0)  # an interval in iterations; 0 disables
# Each field's docstring is its description (`describe`, `velogauss config`): what, and why this default.
_STRICT = ConfigDict(extra="forbid", use_attribute_docstrings=True)
Placement = Literal["box", "gaussians"]  # where VG-LOSS-PHYS's collocation points are drawn
# A schedule key: a number of iterations, or "auto", its share of train.iterations in
# SCHEDULE (resolve_schedule). Intervals (`Period`) are at least 1 iteration when "auto".
Span = Union[Literal["auto"], _int(ge=0)]
Period = Union[Literal["auto"], Every]


# data.split's "future:F": F a decimal strictly inside (0, 1) ("0.8", ".8"), so 0, 1 and above never parse.
FUTURE_SPLIT = r"future:(0?\.[0-9]*[1-9][0-9]*)"  # the loader parses F with the same pattern
FutureSplit = Annotated[str, Field(strict=True, pattern=rf"^{FUTURE_SPLIT}$")]


@dataclass(frozen=True, config=_STRICT)
class DataConfig:
    """Which scene and how it is loaded (velogauss.data.load_scene)."""

    dir: str = ""
    """The scene folder; recorded by `velogauss train`"""
    format: Literal["auto", "dnerf", "nerfstudio", "panoptic"] = "auto"
    """The scene folder's layout: "dnerf" (transforms_train.json, transforms_test.json), "nerfstudio"
    (transforms.json), "panoptic" (train_meta.json) or "auto", detected from the files (spec/data.md)"""
    max_time: _float(gt=0.0, le=1.0) = 0.75
    """End of the observed window; later frames are the future to predict. Under a "future:F" or "all" split it
    is derived (the last trained frame's time) and recorded so; a value other than 0.75 that differs is an error."""
    split: Union[Literal["time", "all"], FutureSplit] = "time"
    """How frames split into train and future: "time" at max_time, each file's role kept (the default, the layout's
    own split); "future:F" (ODE-GS's D-NeRF protocol) sorts the train and test frames by time and trains on the
    first round(F n), max_time then being the last one's time; "all" (D-NeRF's standard protocol) trains on every
    train frame and scores the test frames as interpolation, with no future (spec/data.md, "Splits")."""
    half_res: Flag = False
    """Load the images at half resolution (quick looks)"""
    background: tuple[Unit, Unit, Unit] = (1.0, 1.0, 1.0)
    """RGB behind the Gaussians and under RGBA images (white)"""
    heldout_cameras: Union[Literal["auto"], Annotated[tuple[_int(ge=0), ...], Field(min_length=1)]] = "auto"
    """Cameras whose frames never train and score as interpolation: "auto", the layout's own held-out split;
    or camera ids, Panoptic `cam_id`s or nerfstudio camera numbers, for a capture without one (spec/data.md)"""


@dataclass(frozen=True, config=_STRICT)
class _ModelChoices:
    """The first keys of `ModelConfig`, a base of it only so that config.toml lists them
    before the networks' sizes (a dataclass's inherited fields come first, base by base)."""

    effects: Union[Literal["auto", "declared"], Annotated[tuple[Effect, ...], Field(min_length=1)]] = "auto"
    """Effects the motion may use; "auto": all but oscillation, whatever the scene declares; "declared": the
    scene's declared ones (scene.json), an optional prior."""
    incompressible: Union[Literal["auto", "declared"], Flag] = "auto"
    """The divergence loss (VG-DIV) on or off; "auto": on; "declared": scene.json's `incompressible`."""
    acceleration: Union[Literal["auto"], AccelerationForm] = "poly"
    """The acceleration's time form: "poly" (VG-ACC), "rigid" (VG-ACC-RIGID) or "auto" (rigid for rigid
    effects); "poly", as "rigid" helped one rigid scene and hurt another (benchmarks/FIDELITY.md, section
    6)."""
    patterns: Union[Literal["auto"], PatternForm] = "auto"
    """The motion patterns' time form: "mlp" (VG-COEF), "rigid" (VG-COEF-RIGID), "harmonic" (VG-COEF-HARM), or
    "auto": the form that best predicts the held-out end of the window from a short probe's Gaussian paths
    (velogauss.train.backtest), or "mlp" without a probe when the window reaches t = 1 and leaves nothing to
    forecast; config.toml records the choice."""
    future: Literal["auto", "integrate", "coast", "hold", "fit"] = "auto"
    """Past the observed window: "integrate" carries the motion on; "coast" carries it on with the motion
    patterns kept at their value at the window's end (the velocity's persistence forecast); "hold" keeps every
    Gaussian where it is at the window's end (the position's); "fit": at the end of training the form that
    best forecasts the trained paths' held-out tails carries the Gaussians on from the window's end
    (velogauss.train.forecast); "auto": "fit" when the backtest of `patterns = "auto"` chose a form whose probe
    reconstructs the window worse than the time network's (which then trains the window), "hold" when it found no form that
    predicts the held-out end of the window better than freezing it, else "integrate" (spec/motion.md, "The
    future past the window")."""
    mixing_init: Literal["auto", "uniform", "clusters"] = "auto"
    """How the mixing weights start: "uniform", "clusters" (one k-means region per pattern,
    velogauss.train.mixing) or "auto": clusters when the backtest's probe found still Gaussians beside
    moving ones, as they cost a single body (FIDELITY.md, section 0b); "uniform" where `patterns = "auto"`
    needs no probe (a window that reaches t = 1); without a probe otherwise, when the effects allow `static`."""
    rigid_centre: Literal["auto", "hull"] = "auto"
    """Rigid patterns' centres: "hull", anchored on the moving Gaussians' hull centroid
    (velogauss.train.centres), or "auto": hull for one body on a parabola, where learned ones drift off it,
    else learned (section 0a)."""
    pattern_centres: Literal["clusters", "origin"] = "origin"
    """Where the time network's and the oscillators' patterns are written about (VG-COEF-CENTRE): "origin", the
    world's origin (VG-BASIS as it is), or "clusters", each about the centroid of its k-means region of the
    initial points (velogauss.train.mixing), so that a body's spin about its own centre needs no translation;
    "origin" as the family's tuning seeds learned their windows better with it (FIDELITY.md, section 0za)."""
    ablation: Ablation = "full"
    """The paper's ablations (velogauss.model.spec); "full" keeps PDS, ADF and GPC"""
    sh_degree: _int(ge=0, le=3) = 1
    """Spherical-harmonics degree of the colours (VG-SH is written up to 3)"""


@dataclass(frozen=True, config=_STRICT)
class ModelConfig(NetworkSizes, _ModelChoices):
    """The representation and the motion model (spec/motion.md, spec/physics.md).

    Keys in config.toml's order: `_ModelChoices`'s (effects ... sh_degree), the motion
    networks' sizes with their defaults and ranges (`NetworkSizes`, n_patterns ...
    n_freqs_adf_t, which the resolved `MotionSpec` shares), then the fields below.
    """

    integrator: Integrator = "rk2"
    """VG-INTEG's method; RK2, as the paper"""
    step: _float(gt=0.0, le=1.0) = 0.05
    """Largest integration step in normalised time: one frame of 21"""
    adf_clamp_time: Flag = True
    """Hold the ADF's correction at its value at max_time beyond the window, where it never saw t
    (deform-only, a DefGS-style model, evaluates it at every t, as DefGS does)."""
    scheme: Scheme = "integrate"
    """How x(t) comes from the velocity and the ADF: "integrate" (a) from t = 0, or "adf-step" (b), the ADF's
    state carried by the velocity (VG-CARRY); (a) extrapolated best (benchmarks/FIDELITY.md)."""
    carry_offset: Unit = 0.05
    """Scheme "adf-step": |t - t_start| of VG-CARRY in training, one frame, as the authors'"""
    init_points: Count = 5000
    """Random initial Gaussians when the scene has no points3d.ply"""
    init_opacity: _float(gt=0.0, lt=1.0) = 0.1
    """Every Gaussian's initial opacity, as 3DGS's"""
    rasterize_mode: RasterizeMode = "antialiased"
    """How splats are filtered (VG-RENDER): "classic", 3DGS's dilation, or "antialiased", Mip-Splatting's 2D
    filter, which learned the rate of strain more closely on every scene (FIDELITY.md, section 0c)."""


@dataclass(frozen=True, config=_STRICT)
class TrainConfig:
    """Optimisation schedule (3DGS-style learning rates, see velogauss.train.optim)."""

    iterations: Union[Literal["auto"], Count] = "auto"
    """The run's length; "auto": SCHEDULE_ITERATIONS (every benchmarked run's) times train.views over the
    views an iteration finds (frames of one time), so that a monocular video renders as many training views
    as a multi-view one (velogauss.train.sampling.auto_iterations)."""
    seed: _int(ge=0) = 0
    """Of NumPy's and torch's generators; NumPy refuses negative seeds"""
    device: str = "cpu"
    """Checked against this machine's devices by the command line"""
    threads: _int(ge=0, le=1024) = 0
    """CPU threads of torch and of the compositing kernels; 0: velogauss.threads chooses (one torch thread,
    one compositing thread per core), as more threads than cores only wait for each other."""
    warmup: Span = "auto"
    """Iterations on the earliest frames only, motion frozen ("auto": SCHEDULE's share)"""
    warmup_views: _int(ge=1, le=1024) = 1
    """Frames the warm-up draws from where t = 0 has fewer than train.views (monocular video): the earliest this
    many, within WARMUP_WINDOW_SHARE of the window. 1 (the default): the t = 0 frames only, since 8 lifted the scene
    it was tried on (D-NeRF bouncingballs) and not those it was then measured on (spec/density.md, "The warm-up's
    views")."""
    curriculum: Span = "auto"
    """Iterations over which the sampled times open up to max_time"""
    views: _int(ge=1, le=64) = 3
    """Training views per iteration, all of one time: several cameras pin the positions in depth, which one
    view cannot (benchmarks/FIDELITY.md, "Defaults")."""
    lr_means: Rate = 1.6e-4
    """Times the camera extent, decayed to lr_means_final (3DGS's)"""
    lr_means_final: Rate = 1.6e-6
    """Where lr_means's decay ends, times the camera extent (3DGS's)."""
    lr_sh: Rate0 = 2.5e-3
    """Degree-0 coefficients; higher degrees get lr_sh / 20 (3DGS's)"""
    lr_opacity: Rate0 = 0.05
    """Opacities' rate (3DGS's); 0 freezes them."""
    lr_scales: Rate0 = 5e-3
    """Log-scales' rate (3DGS's); 0 freezes them."""
    lr_quats: Rate0 = 1e-3
    """Quaternions' rate (3DGS's); 0 freezes them."""
    lr_motion: Rate = 1e-3
    """Motion networks, decayed to lr_motion_final"""
    lr_motion_final: Rate = 1e-4
    """Where lr_motion's decay ends: 10x lower, as 3DGS's position rate falls."""
    lr_acc: Rate = 0.05
    """The "acc" group (Q, rigid patterns, oscillators' coefficients): world quantities, which need a larger
    rate than the networks' weights (velogauss.train.optim)."""
    lr_acc_final: Rate = 5e-3
    """Where lr_acc's decay ends: 10x lower, as the networks'; a 100x decay starves short runs (FIDELITY.md,
    0d)."""
    acc_cooldown: _float(ge=0.0, lt=1.0) = 0.1
    """The last fraction of the iterations over which the acc rate falls on to lr_acc_cooled (0: off), so that
    the patterns' world quantities stop wandering before training ends (FIDELITY.md, section 0d)."""
    lr_acc_cooled: Rate = 5e-4
    """The "acc" group's rate at the last iteration, reached over acc_cooldown."""
    lambda_adf: _float(ge=0.0) = 10.0
    """L2 on the ADF's displacement, so that the velocity, not the ADF, carries the motion (FIDELITY.md,
    "Defaults")."""
    adf_start: Union[Literal["auto"], _int(ge=0)] = "auto"
    """Iteration at which the ADF starts learning; "auto": with the motion under the time network's patterns,
    deform-only and "adf-step", else once the curriculum has opened the window (FIDELITY.md, section 0f)."""
    lambda_carry: _float(ge=0.0) = 0.0
    """Scheme "adf-step": weight of VG-LOSS-CARRY (the velocity fitted to the ADF's paths); 0, off, by
    default."""
    carry_horizon: _float(gt=0.0, le=1.0) = 0.25
    """VG-LOSS-CARRY: largest |t - t_a| drawn, in normalised time (at most the whole window [0, 1])."""
    carry_points: Count = 2048
    """VG-LOSS-CARRY: moving Gaussians drawn per iteration"""
    lambda_mix: _float(ge=0.0) = 1e-3
    """VG-LOSS-MIX: weight of the mixing weights' entropy, which makes each particle commit to one motion
    pattern, so that bodies moving apart do not share one (FIDELITY.md, section 0)."""
    mix_points: Count = 2048
    """VG-LOSS-MIX: moving Gaussians drawn per iteration"""
    motion_only: Flag = False
    """After the warm-up only the motion trains (the error budget's optimisation floor)"""
    eval_every: Every = 500
    """PSNR on the interpolation split -> log.jsonl"""
    checkpoint_every: Every = 500
    """0: only at the end (and on Ctrl-C)"""


@dataclass(frozen=True, config=_STRICT)
class PhysicsConfig:
    """Global physical constraints on collocation points (VG-LOSS-PHYS)."""

    lambda_transport: Union[Literal["auto"], _float(ge=0.0)] = "auto"
    """VG-TRANSPORT's weight; "auto": TRANSPORT_WEIGHT, or 0 under oscillating patterns (resolve_transport)."""
    lambda_div: _float(ge=0.0) = 1e-3
    """VG-DIV's weight, as the transport's: strong enough to bind the motion, weak enough not to drown the
    images."""
    ramp: Span = "auto"
    """Iterations over which both weights rise linearly from 0, while the velocity forms"""
    n_points: Count = 1024
    """Collocation points per iteration, at one random time in [0, 1]"""
    bounds_margin: _float(ge=0.0) = 0.1
    """"box": the scene box grows by this fraction of its size on each side"""
    placement: Placement = "gaussians"
    """Where the collocation points lie: "box" uniform in the grown box, or "gaussians" near the moving
    Gaussians, where the residual binds the bodies rather than empty space (benchmarks/FIDELITY.md)."""
    jitter: _float(ge=0.0) = 0.02
    """"gaussians": the normal offsets' standard deviation, a fraction of the box diagonal (0: at the means)."""


@dataclass(frozen=True, config=_STRICT)
class DensifyConfig:
    """Adaptive density control (3DGS): clone, split, prune, opacity reset."""

    start: Span = "auto"
    """First iteration of densification ("auto": SCHEDULE's share)"""
    until: Span = "auto"
    """Last iteration of densification"""
    every: Union[Literal["auto"], Count] = "auto"
    """Iterations between densification rounds"""
    grad_threshold: _float(gt=0.0) = 5e-4
    """Mean |d loss / d mean2d| in NDC units that clones or splits a Gaussian; stricter than 3DGS's 2e-4,
    which on the 64 px synthetic scenes cloned whole objects while the motion was still misfit
    (FIDELITY.md)."""
    percent_dense: Unit = 0.01
    """Clone below, split above this fraction of the camera extent (3DGS's)"""
    prune_opacity: _float(ge=0.0, lt=1.0) = 0.005
    """Prune below this opacity (at 1 every Gaussian would go)"""
    opacity_reset_every: Period = "auto"
    """Iterations between opacity resets (3DGS's floaters' cure)"""
    max_gaussians: Count = 10000
    """The count densification never exceeds"""
    cap_schedule: Literal["fixed", "linear"] = "fixed"
    """"fixed": up to max_gaussians at every round; "linear": the cap rises from 0 at `start` to max_gaussians
    at `until`, so that a scene does not spend its budget before the motion has settled."""
    static_every: Period = "auto"
    """Iterations between detections of particles that do not move"""


@dataclass(frozen=True, config=_STRICT)
class Config:
    data: DataConfig = Field(default_factory=DataConfig)
    model: ModelConfig = Field(default_factory=ModelConfig)
    train: TrainConfig = Field(default_factory=TrainConfig)
    physics: PhysicsConfig = Field(default_factory=PhysicsConfig)
    densify: DensifyConfig = Field(default_factory=DensifyConfig)


_ADAPTER = TypeAdapter(Config)

# The default schedule, in iterations of a run of SCHEDULE_ITERATIONS (the one every benchmark
# measured). An "auto" key gets its value here times train.iterations / SCHEDULE_ITERATIONS, so
# that a run of any length keeps the schedule's shape: fixed counts leave a shorter run too few
# iterations on the whole window (benchmarks/FIDELITY.md, section 4).
SCHEDULE_ITERATIONS = 3000
SCHEDULE = {"train.warmup": 200, "train.curriculum": 1200, "physics.ramp": 1200, "densify.start": 200,
            "densify.until": 2000, "densify.every": 100, "densify.opacity_reset_every": 1000,
            "densify.static_every": 500}
# Intervals: scaled to 0 they would switch their step off, or divide by zero.
PERIODS = ("densify.every", "densify.opacity_reset_every", "densify.static_every")


# VG-LOSS-PHYS's transport weight where "auto" keeps the transport residual on: its residuals are
# O(|v|²/L), so this binds the future without drowning the images' gradients while the velocity forms.
TRANSPORT_WEIGHT = 1e-3


def resolve_transport(cfg, pattern_form, saved=None):
    """`cfg` with an "auto" `physics.lambda_transport` replaced: by the value `saved` holds (the
    run being resumed; `pattern_form` is then not read), else by 0 when the motion patterns
    oscillate (`pattern_form` "harmonic", VG-COEF-HARM) and TRANSPORT_WEIGHT otherwise. A
    number is kept.

    Why 0 there: the oscillating patterns continue the motion past the window by themselves,
    and their acceleration (VG-ACC-HARM) lags the velocity while it trains, so the residual
    holds the motion back (benchmarks/FIDELITY.md, section 8).
    """
    if cfg.physics.lambda_transport != "auto":
        return cfg
    if saved is not None:
        weight = resolve_transport(saved, pattern_form).physics.lambda_transport
    else:
        weight = 0.0 if pattern_form == "harmonic" else TRANSPORT_WEIGHT
    return dataclasses.replace(cfg, physics=dataclasses.replace(cfg.physics, lambda_transport=weight))


# The model keys whose "auto" a new run resolves from its data before training (the backtest,
# velogauss.train.backtest); config.toml records the values chosen.
CHOSEN_KEYS = ("patterns", "effects", "mixing_init", "future")


def resolve_from_run(cfg, saved):
    """`cfg` with its "auto" keys (train.iterations, the schedule's, the transport weight and the
    backtest's CHOSEN_KEYS) set to the values of `saved`, the config of an existing run: what `cfg` means
    for that run when `--resume` or a sweep continues it."""
    chosen = {key: getattr(saved.model, key) for key in CHOSEN_KEYS if getattr(cfg.model, key) == "auto"}
    cfg = dataclasses.replace(cfg, model=dataclasses.replace(cfg.model, **chosen))
    if cfg.train.iterations == "auto":
        cfg = dataclasses.replace(cfg, train=dataclasses.replace(cfg.train, iterations=saved.train.iterations))
    return resolve_transport(resolve_schedule(cfg, saved), None, saved)


def resolve_schedule(cfg, saved=None):
    """`cfg` with each "auto" key of SCHEDULE replaced by a number of iterations: the value the
    config `saved` holds (the run being resumed keeps its schedule), else its SCHEDULE value
    times `cfg.train.iterations / SCHEDULE_ITERATIONS`, rounded, intervals to at least 1.
    Keys set to a number are kept as they are. `cfg.train.iterations` must be a number (the
    training resolves "auto" first, velogauss.train.sampling.auto_iterations)."""
    if cfg.train.iterations == "auto":
        raise ValueError('train.iterations is "auto": the schedule scales with a number of iterations, which the '
                         'training resolves from the data first (velogauss.train.sampling.auto_iterations)')
    changes = {}
    saved = resolve_schedule(saved) if saved is not None else None
    for name, value in SCHEDULE.items():
        section, key = name.split(".")
        if getattr(getattr(cfg, section), key) != "auto":
            continue
        if saved is not None:
            value = getattr(getattr(saved, section), key)
        else:
            value = round(value * cfg.train.iterations / SCHEDULE_ITERATIONS)
            value = max(1, value) if name in PERIODS else value
        changes.setdefault(section, {})[key] = value
    return dataclasses.replace(cfg, **{section: dataclasses.replace(getattr(cfg, section), **values)
                                       for section, values in changes.items()})


def load_config(path=None, overrides=(), flags=None):
    """Defaults, then the TOML file `path`, then `overrides` (["section.key=value", ...]), then
    `flags` ({"section.key": (flag name, value)} from the command line, None values skipped).

    Raises ValueError naming where the value came from (the file, `--set` or the flag) and the
    key for an unknown key, a value of the wrong type or out of its range.
    """
    tree = config_to_dict(Config())
    if path is not None:
        try:
            document = tomllib.loads(Path(path).read_text())
        except tomllib.TOMLDecodeError as err:
            raise ValueError(f"{path}: not valid TOML ({err})") from None
        tree = _merged(tree, document)
        config_from_dict(tree, str(path))  # validated stage by stage: an error names its source
    for item in overrides:
        key, sep, text = item.partition("=")
        if not sep or "." not in key:
            raise ValueError(f"--set: expected SECTION.KEY=VALUE, got {item!r}")
        section, _, name = key.strip().partition(".")
        tree = _merged(tree, {section: {name: _parse_value(text.strip())}})
        config_from_dict(tree, "--set")
    for key, (flag, value) in (flags or {}).items():
        section, _, name = key.partition(".")
        tree = _merged(tree, {section: {name: value}})
        config_from_dict(tree, flag)
    return config_from_dict(tree)


def config_to_dict(cfg):
    """The config as nested plain dicts (tuples become lists), as TOML and checkpoints hold it."""
    return _ADAPTER.dump_python(cfg, mode="json")


def config_from_dict(tree, source="config"):
    """Build and validate a `Config` from nested dicts; ValueError names `source` and the key."""
    try:
        return _ADAPTER.validate_python(tree)
    except ValidationError as err:
        raise ValueError(_describe(err, tree, source)) from None


def describe(cfg=None):
    """Every key of `cfg` (default: the defaults) in config.toml's order, as (`section.key`,
    value, description): the field's docstring, which says what it is and why this default."""
    cfg = Config() if cfg is None else cfg
    return [(f"{section.name}.{field.name}", getattr(getattr(cfg, section.name), field.name),
             _description(type(getattr(cfg, section.name)), field.name))
            for section in dataclasses.fields(cfg) for field in dataclasses.fields(getattr(cfg, section.name))]


def _description(cls, name):
    """The description of field `name` of `cls`, read where it is declared (pydantic keeps an
    attribute docstring on the declaring class only); "" if it has none."""
    declaring = next((k for k in cls.__mro__ if name in vars(k).get("__annotations__", {})), cls)
    info = getattr(declaring, "__pydantic_fields__", {}).get(name) or cls.__pydantic_fields__[name]
    return info.description or ""


def to_toml(cfg):
    """The config as TOML text (one table per section)."""
    return tomli_w.dumps(config_to_dict(cfg))


# What `--resume` may change: how long to train (the learning-rate decay then stretches to the
# new end), on which device and with how many threads, how often to log and checkpoint, and where the scene folder now
# lies. Every other key shapes the model, its losses or its schedule, so a change would
# make the checkpoint disagree with config.toml (or fail to load into the model).
RESUME_SAFE_KEYS = ("train.iterations", "train.device", "train.threads", "train.eval_every", "train.checkpoint_every",
                    "data.dir")


def check_resume_config(saved, cfg):
    """Raise ValueError naming the first key, its old and new value, where `cfg` differs from
    the config `saved` in a run's checkpoint other than in RESUME_SAFE_KEYS."""
    old, new = config_to_dict(saved), config_to_dict(cfg)
    for section, values in old.items():
        for key, value in values.items():
            name = f"{section}.{key}"
            if name not in RESUME_SAFE_KEYS and new[section][key] != value:
                raise ValueError(f"--resume: {name}: the run was trained with {value!r}, got {new[section][key]!r}; "
                                 f"only {', '.join(RESUME_SAFE_KEYS)} may change on resume (start a new run with "
                                 "another --out to change it)")


def _merged(tree, document):
    """`tree` with `document`'s sections merged in key by key (a section that is not a table
    replaces the defaults, so that validation reports it)."""
    out = {section: dict(values) for section, values in tree.items()}
    for section, values in document.items():
        if isinstance(values, dict) and section in out:
            out[section].update(values)
        else:
            out[section] = values
    return out


def toml_value(value):
    """`value` (bool, number, string or list of them) as TOML writes it after `key = `."""
    if isinstance(value, (list, tuple)):  # on one line: it goes into `--set key=value` and run names
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    return tomli_w.dumps({"v": value}).removeprefix("v = ").rstrip("\n")


def _parse_value(text):
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def _describe(err, tree, source):
    """One line for the first key pydantic rejects: `source: section.key: what, got value`."""
    first = err.errors()[0]
    loc = first["loc"]
    sections = [f.name for f in dataclasses.fields(Config)]
    if len(loc) == 1:
        if loc[0] not in sections:
            return f"{source}: [{loc[0]}]: unknown section; expected one of {', '.join(sections)}"
        return f"{source}: {loc[0]}: expected a table of keys, got {tree[loc[0]]!r}"
    section, key = loc[0], loc[1]
    if first["type"] == "unexpected_keyword_argument":
        known = [f.name for f in dataclasses.fields(getattr(Config(), section))]
        return f"{source}: {section}.{key}: unknown key; expected one of {', '.join(known)}"
    reasons = dict.fromkeys(e["msg"] for e in err.errors() if e["loc"][:2] == (section, key))
    return f"{source}: {section}.{key}: {' or '.join(reasons)}, got {tree[section][key]!r}"
