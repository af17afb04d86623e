"""The training configuration: defaults, a TOML file, and `section.key=value` overrides.

`load_config(path, overrides)` starts from the defaults below, applies the TOML file at
`path` (if any), then each override `section.key=value` (the value is read as a TOML value;
a bare word is taken as a string), and validates the result. Unknown sections or keys and
values of the wrong type raise ValueError naming the key (and the file). `to_toml(cfg)`
writes a config back; `velogauss train` saves it as `RUN_DIR/config.toml`, which is what
`eval`, `render`, `export` and `--resume` read again.
"""

import dataclasses
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from velogauss_ref.motion.config import MotionConfig

ABLATIONS = ("full", "no-pds", "no-adf", "no-gpc", "deform-only")
INTEGRATORS = ("euler", "rk2", "rk4")
# Training schemes (spec/motion.md): "integrate" (a) VG-TRAJ + VG-ADF from t = 0; "adf-step" (b) VG-CARRY.
SCHEMES = ("integrate", "adf-step")


@dataclass(frozen=True)
class DataConfig:
    """Which scene and how it is loaded (velogauss.data.load_scene)."""

    dir: str = ""  # the scene folder; recorded by `velogauss train`
    max_time: float = 0.75  # end of the observed window; later frames are the future
    half_res: bool = False
    background: tuple = (1.0, 1.0, 1.0)


@dataclass(frozen=True)
class ModelConfig:
    """The representation and the motion model (spec/motion.md, spec/physics.md)."""

    # Effects the motion may use (subset of velogauss.scenes.EFFECTS), or "auto": the
    # scene's declared effects (scene.json), else every effect.
    effects: object = "auto"
    # Divergence loss on/off, or "auto": scene.json's `incompressible`, else true.
    incompressible: object = "auto"
    ablation: str = "full"  # one of ABLATIONS (the paper's PDS / ADF / GPC switches)
    sh_degree: int = 1
    # The motion networks' sizes (velogauss_ref.motion.config.MotionConfig, whose defaults
    # they take; K = 32 is the paper's ablation value).
    n_patterns: int = MotionConfig.n_patterns
    code_dim: int = MotionConfig.code_dim
    hidden: int = MotionConfig.hidden
    depth: int = MotionConfig.depth
    n_freqs_x: int = MotionConfig.n_freqs_x
    n_freqs_t: int = MotionConfig.n_freqs_t
    n_freqs_adf_x: int = MotionConfig.n_freqs_adf_x
    n_freqs_adf_t: int = MotionConfig.n_freqs_adf_t
    integrator: str = "rk2"  # the paper integrates with RK2
    step: float = 0.05  # largest integration step in normalised time (one frame of 21)
    # The ADF has only seen t <= max_time; beyond it, its correction is held at its value
    # at max_time instead of evaluating sinusoids of an unseen t (ablation deform-only,
    # a DefGS-style model, evaluates the network at every t, as DefGS does).
    adf_clamp_time: bool = True
    scheme: str = "integrate"  # one of SCHEMES; chosen by benchmarks/FIDELITY.md
    carry_offset: float = 0.05  # scheme "adf-step": |t - t_start| of VG-CARRY in the window (one frame of 21)
    init_points: int = 5000  # random initial Gaussians when the scene has no points3d.ply
    init_opacity: float = 0.1


@dataclass(frozen=True)
class TrainConfig:
    """Optimisation schedule (3DGS-style learning rates, see velogauss.train.optim)."""

    iterations: int = 3000
    seed: int = 0
    device: str = "cpu"
    warmup: int = 200  # iterations on the t = 0 frames only, motion frozen
    curriculum: int = 1200  # iterations over which the sampled times open up to max_time
    lr_means: float = 1.6e-4  # times the camera extent, decayed to lr_means_final
    lr_means_final: float = 1.6e-6
    lr_sh: float = 2.5e-3  # degree-0 coefficients; higher degrees get lr_sh / 20
    lr_opacity: float = 0.05
    lr_scales: float = 5e-3
    lr_quats: float = 1e-3
    lr_motion: float = 1e-3  # motion networks, decayed to lr_motion_final
    lr_motion_final: float = 1e-4
    lr_acc: float = 0.05  # the acceleration polynomial Q (see velogauss.train.optim)
    # L2 on the ADF's displacement, so velocity carries the motion; at 0.1 the ADF took the
    # motion over on toss (extrapolation 16.6 dB against 20.5 dB at 1.0).
    lambda_adf: float = 1.0
    # Iteration at which the ADF starts learning; -1: once the curriculum has opened the
    # whole window (warmup + curriculum), or with the motion for deform-only.
    adf_start: int = -1
    lambda_carry: float = 0.0  # scheme "adf-step": weight of VG-LOSS-CARRY (velocity fitted to the ADF's paths); 0 disables
    carry_horizon: float = 0.25  # VG-LOSS-CARRY: largest |t - t_a| drawn (normalised time)
    carry_points: int = 2048  # VG-LOSS-CARRY: moving Gaussians drawn per iteration
    motion_only: bool = False  # after the warm-up only the motion trains (the error budget's optimisation floor)
    eval_every: int = 500  # PSNR on the interpolation split -> log.jsonl
    checkpoint_every: int = 500


@dataclass(frozen=True)
class PhysicsConfig:
    """Global physical constraints on collocation points (VG-LOSS-PHYS)."""

    # The residuals are O(|v|²/L) ~ 10 in normalised time, so their squares are ~100 times
    # the photometric loss at these weights: strong enough to bind the future, weak enough
    # not to drown the images' gradients while the velocity forms (measured on toss).
    lambda_transport: float = 1e-3
    lambda_div: float = 1e-3
    ramp: int = 1200  # iterations over which both weights rise linearly from 0
    n_points: int = 1024  # collocation points per iteration, one random time each
    bounds_margin: float = 0.1  # the box grows by this fraction of its size on each side
    placement: str = "box"  # collocation points: "box" (uniform in the grown box) or "gaussians" (near the moving Gaussians at t)
    jitter: float = 0.02  # placement "gaussians": normal offset, as a fraction of the box diagonal


@dataclass(frozen=True)
class DensifyConfig:
    """Adaptive density control (3DGS): clone, split, prune, opacity reset."""

    start: int = 200
    until: int = 2000
    every: int = 100
    # Mean |d loss / d mean2d| in NDC units. 3DGS uses 2e-4 on ~800 px images; on the
    # 64 px synthetic scenes that clones whole objects into ~20k Gaussians while the
    # motion is still misfit, so the default is stricter.
    grad_threshold: float = 5e-4
    percent_dense: float = 0.01  # clone below, split above this fraction of the extent
    prune_opacity: float = 0.005
    opacity_reset_every: int = 1000  # 0 disables
    max_gaussians: int = 10000
    static_every: int = 500  # re-detect particles that do not move (0 disables)


@dataclass(frozen=True)
class Config:
    data: DataConfig = field(default_factory=DataConfig)
    model: ModelConfig = field(default_factory=ModelConfig)
    train: TrainConfig = field(default_factory=TrainConfig)
    physics: PhysicsConfig = field(default_factory=PhysicsConfig)
    densify: DensifyConfig = field(default_factory=DensifyConfig)


def load_config(path=None, overrides=()):
    """Defaults, then the TOML file `path`, then `overrides` (["section.key=value", ...]).

    Raises ValueError naming the file and key for an unknown key, a value of the wrong
    type or an invalid value.
    """
    tree = config_to_dict(Config())
    if path is not None:
        try:
            document = tomllib.loads(Path(path).read_text())
        except tomllib.TOMLDecodeError as err:
            raise ValueError(f"{path}: not valid TOML ({err})") from None
        _merge(tree, document, str(path))
        # Validated stage by stage, so an error names where the bad value came from.
        config_from_dict(tree, str(path))
    for item in overrides:
        key, sep, text = item.partition("=")
        if not sep or "." not in key:
            raise ValueError(f"--set: expected SECTION.KEY=VALUE, got {item!r}")
        section, _, name = key.strip().partition(".")
        _merge(tree, {section: {name: _parse_value(text.strip())}}, "--set")
        config_from_dict(tree, "--set")
    return config_from_dict(tree)


def config_to_dict(cfg):
    """The config as nested plain dicts (tuples become lists)."""
    return {f.name: {k: list(v) if isinstance(v, tuple) else v for k, v in dataclasses.asdict(getattr(cfg, f.name)).items()}
            for f in dataclasses.fields(cfg)}


def config_from_dict(tree, source="config"):
    """Build and validate a `Config` from nested dicts; ValueError names `source` and the key."""
    sections = {}
    for f in dataclasses.fields(Config):
        cls = f.default_factory
        values = dict(tree.get(f.name, {}))
        defaults = cls()
        for key, value in values.items():
            if not hasattr(defaults, key):
                raise ValueError(f"{source}: {f.name}.{key}: unknown key")
            values[key] = _coerce(f"{source}: {f.name}.{key}", value, getattr(defaults, key))
        sections[f.name] = cls(**values)
    cfg = Config(**sections)
    _validate(cfg, source)
    return cfg


def to_toml(cfg):
    """The config as TOML text (one table per section)."""
    lines = []
    for section, values in config_to_dict(cfg).items():
        lines.append(f"[{section}]")
        lines += [f"{key} = {toml_value(value)}" for key, value in values.items()]
        lines.append("")
    return "\n".join(lines)


def toml_value(value):
    """A Python bool, int, float, str or list of them as a TOML value."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, float) and not math.isfinite(value):
        raise ValueError(f"value: TOML cannot hold {value!r} here")
    return repr(value)


def _merge(tree, document, source):
    for section, values in document.items():
        if section not in tree:
            raise ValueError(f"{source}: [{section}]: unknown section; expected one of {', '.join(tree)}")
        if not isinstance(values, dict):
            raise ValueError(f"{source}: {section}: expected a table of keys")
        for key, value in values.items():
            if key not in tree[section]:
                raise ValueError(f"{source}: {section}.{key}: unknown key; expected one of {', '.join(tree[section])}")
            tree[section][key] = value


def _parse_value(text):
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def _coerce(name, value, default):
    """`value` in the type of `default` (ints count as floats; lists become tuples)."""
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise ValueError(f"{name}: expected true or false, got {value!r}")
        return value
    if isinstance(default, int):
        if isinstance(value, bool) or not isinstance(value, int):
            raise ValueError(f"{name}: expected an integer, got {value!r}")
        return value
    if isinstance(default, float):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ValueError(f"{name}: expected a finite number, got {value!r}")
        return float(value)
    if isinstance(default, tuple):
        if not isinstance(value, (list, tuple)):
            raise ValueError(f"{name}: expected a list, got {value!r}")
        return tuple(value)
    if isinstance(value, list):
        return tuple(value)
    return value


def _validate(cfg, source):
    m, t, d, p, data = cfg.model, cfg.train, cfg.densify, cfg.physics, cfg.data
    checks = [
        ("data.max_time", 0.0 < data.max_time < 1.0, "a value in (0, 1)"),
        ("data.background", len(data.background) == 3 and all(isinstance(v, (int, float)) and 0 <= v <= 1
                                                               for v in data.background), "three values in [0, 1]"),
        ("model.ablation", m.ablation in ABLATIONS, f"one of {', '.join(ABLATIONS)}"),
        ("model.integrator", m.integrator in INTEGRATORS, f"one of {', '.join(INTEGRATORS)}"),
        ("model.step", m.step > 0, "a positive step"),
        ("model.scheme", m.scheme in SCHEMES, f"one of {', '.join(SCHEMES)}"),
        ("model.carry_offset", m.carry_offset >= 0, "a step >= 0"),
        ("model.sh_degree", 0 <= m.sh_degree <= 3, "0, 1, 2 or 3"),
        ("model.effects", m.effects == "auto" or (isinstance(m.effects, tuple) and m.effects), '"auto" or a list'),
        ("model.incompressible", m.incompressible == "auto" or isinstance(m.incompressible, bool), '"auto", true or false'),
        ("model.init_opacity", 0 < m.init_opacity < 1, "a value in (0, 1)"),
        ("train.iterations", t.iterations >= 1, "at least 1"),
        ("train.eval_every", t.eval_every >= 0, ">= 0 (0 disables)"),
        ("train.checkpoint_every", t.checkpoint_every >= 0, ">= 0 (0: only at the end)"),
        ("train.adf_start", t.adf_start >= -1, ">= 0, or -1 for the default"),
        ("train.lambda_carry", t.lambda_carry >= 0, ">= 0"),
        ("train.carry_horizon", t.carry_horizon > 0, "> 0"),
        ("train.carry_points", t.carry_points >= 1, "at least 1"),
        ("physics.n_points", p.n_points >= 1, "at least 1"),
        ("physics.placement", p.placement in ("box", "gaussians"), '"box" or "gaussians"'),
        ("densify.every", d.every >= 1, "at least 1"),
        ("densify.max_gaussians", d.max_gaussians >= 1, "at least 1"),
    ]
    for key, ok, expected in checks:
        if not ok:
            section, _, name = key.partition(".")
            raise ValueError(f"{source}: {key}: expected {expected}, got {getattr(getattr(cfg, section), name)!r}")
    if m.effects != "auto":
        from velogauss.scenes import EFFECTS

        unknown = [e for e in m.effects if e not in EFFECTS]
        if unknown:
            raise ValueError(f"{source}: model.effects: unknown effect(s) {unknown}; choose from {', '.join(EFFECTS)}")
    for name in ("n_patterns", "code_dim", "hidden", "depth", "init_points"):
        if getattr(m, name) < 1:
            raise ValueError(f"{source}: model.{name}: expected at least 1, got {getattr(m, name)!r}")
    for name in ("warmup", "curriculum"):
        if getattr(t, name) < 0:
            raise ValueError(f"{source}: train.{name}: expected >= 0, got {getattr(t, name)!r}")
