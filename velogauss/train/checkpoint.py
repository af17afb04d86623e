"""Checkpoints: everything needed to rebuild a model, and to resume training exactly.

`RUN_DIR/checkpoints/latest.pt` is written atomically (velogauss.io_utils.atomic_path):
a crash or Ctrl-C during the write leaves the previous checkpoint intact. It holds the
config, the resolved effect profile, the model's state (its shapes follow from it), the
optimiser, the density statistics, the NumPy and torch RNG states, the iteration count
and the training time so far.
"""

import dataclasses
from pathlib import Path

import torch

from velogauss.config import config_from_dict, config_to_dict
from velogauss.io_utils import atomic_path
from velogauss.model.build import model_from_state, profile_from_dict

FORMAT = "velogauss-checkpoint/1"


def checkpoint_path(run_dir):
    return Path(run_dir) / "checkpoints" / "latest.pt"


def save_checkpoint(run_dir, cfg, profile, model, optimizer, stats, rng, iteration, extra):
    """Write `latest.pt` atomically. extra: JSON-like training state (elapsed time, flags)."""
    payload = {
        "format": FORMAT,
        "iteration": int(iteration),
        "config": config_to_dict(cfg),
        "profile": dataclasses.asdict(profile),
        "model": model.state_dict(),
        "optimizer": optimizer.state_dict(),
        "density": stats.state_dict(),
        "numpy_rng": rng.bit_generator.state,
        "torch_rng": torch.get_rng_state(),
        "extra": extra,
    }
    with atomic_path(checkpoint_path(run_dir)) as tmp:
        torch.save(payload, tmp)


def load_checkpoint(run_dir, device="cpu"):
    """The payload of `latest.pt`; ValueError naming the file when it is not a velogauss checkpoint."""
    path = checkpoint_path(run_dir)
    if not path.is_file():
        raise FileNotFoundError(2, "no checkpoint in the run folder (train it first)", str(path))
    try:
        payload = torch.load(path, map_location=device, weights_only=False)
    except Exception as err:  # torch raises many types for a corrupt file; all mean "unreadable"
        raise ValueError(f"{path}: unreadable checkpoint ({type(err).__name__}: {err})") from None
    if not isinstance(payload, dict) or payload.get("format") != FORMAT:
        raise ValueError(f"{path}: format: not a {FORMAT} file")
    return payload


def load_model(run_dir, device="cpu"):
    """(model in eval mode on `device`, its Config) from `RUN_DIR/checkpoints/latest.pt`."""
    payload = load_checkpoint(run_dir, device)
    cfg = config_from_dict(payload["config"], source=str(checkpoint_path(run_dir)))
    model = model_from_state(cfg, profile_from_dict(payload["profile"]), payload["model"])
    model.load_state_dict(payload["model"])
    return model.to(device).eval(), cfg
