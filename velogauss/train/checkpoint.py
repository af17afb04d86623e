"""Checkpoints: everything needed to rebuild a model, and to resume training exactly.

`RUN_DIR/checkpoints/latest.pt` is written atomically (velogauss.io_utils.atomic_path):
a crash or Ctrl-C during the write leaves the previous checkpoint intact. It holds the
config, the model's resolved `MotionSpec`, its state (its shapes follow from both), the
optimiser, the density statistics, the NumPy and torch RNG states, the iteration count
and, under the key "extra", the trainer's run state (`velogauss.train.loop.RunState` as a
dict: training time so far, whether an opacity reset has happened, the PSNR moving average).

The file is one header line `velogauss-checkpoint format_version=<n> sha256=<hex>` followed
by the bytes of the `torch.save`d dict above, whose SHA-256 the header holds and every load
checks: flipped bytes are reported as a corrupt checkpoint naming the file, never read as
other weights. A load refuses any format version but CHECKPOINT_FORMAT: a checkpoint is read
only by the code that wrote its layout.
"""

import dataclasses
import hashlib
import io
from pathlib import Path

import torch

from velogauss.config import config_from_dict, config_to_dict
from velogauss.io_utils import write_bytes
from velogauss.model.build import model_from_state
from velogauss_core.motion import spec_from_dict

MAGIC = "velogauss-checkpoint"  # the first word of every checkpoint
# The layout of the payload, its config and spec; raise it with any change that an older
# checkpoint would load wrongly under.
CHECKPOINT_FORMAT = 6
_KEYS = ("iteration", "config", "spec", "forecast_spec", "model", "optimizer", "density", "numpy_rng", "torch_rng", "extra")


def checkpoint_path(run_dir):
    return Path(run_dir) / "checkpoints" / "latest.pt"


def save_checkpoint(run_dir, cfg, model, optimizer, stats, rng, iteration, run_state):
    """Write `latest.pt` atomically. run_state: the trainer's `RunState` as a dict
    (dataclasses.asdict), plain numbers and flags."""
    payload = {
        "iteration": int(iteration),
        "config": config_to_dict(cfg),
        "spec": dataclasses.asdict(model.spec),
        # The forecast's plan (None without one): its parameters are in the model's state.
        "forecast_spec": None if model.forecast is None else dataclasses.asdict(model.forecast.spec),
        "model": model.state_dict(),
        "optimizer": optimizer.state_dict(),
        "density": stats.state_dict(),
        "numpy_rng": rng.bit_generator.state,
        "torch_rng": torch.get_rng_state(),
        "extra": run_state,
    }
    # Serialised in memory first: a full disk then fails in a plain file write (an OSError
    # naming the path), not inside torch's zip writer.
    buffer = io.BytesIO()
    torch.save(payload, buffer)
    data = buffer.getvalue()
    write_bytes(checkpoint_path(run_dir), header(data) + data)


def header(data):
    """The header line (bytes) of a checkpoint whose payload is `data`."""
    return f"{MAGIC} format_version={CHECKPOINT_FORMAT} sha256={_digest(data)}\n".encode("ascii")


def load_checkpoint(run_dir, device="cpu"):
    """The payload of `latest.pt`; ValueError naming the file when it is not a velogauss
    checkpoint, has another format version than CHECKPOINT_FORMAT, fails its checksum, lacks a
    key or holds non-finite model values."""
    path = checkpoint_path(run_dir)
    if not path.is_file():
        raise FileNotFoundError(2, "no checkpoint in the run folder (train it first)", str(path))
    first, _, data = path.read_bytes().partition(b"\n")
    name, *fields = first.decode("ascii", errors="replace").split(" ")
    if not name.startswith(MAGIC):
        raise ValueError(f"{path}: format: not a {MAGIC} file")
    fields = dict(field.partition("=")[::2] for field in fields)
    version = fields.get("format_version")
    if version != str(CHECKPOINT_FORMAT):
        found = "no version" if version is None else f"version {version}"
        raise ValueError(f"{path}: checkpoint format {found}, expected version {CHECKPOINT_FORMAT}: another "
                         "version of velogauss wrote it; retrain with this version, or check out the release "
                         "that wrote it")
    digest = fields.get("sha256")
    if _digest(data) != digest:
        raise ValueError(f"{path}: corrupt checkpoint (its content does not match its sha256 checksum)")
    try:
        payload = torch.load(io.BytesIO(data), map_location=device, weights_only=False)
    except Exception as err:  # torch raises many types for a bad payload; all mean "unreadable"
        raise ValueError(f"{path}: unreadable checkpoint ({type(err).__name__}: {err})") from None
    if not isinstance(payload, dict):
        raise ValueError(f"{path}: format: not a {MAGIC} file")
    missing = [key for key in _KEYS if key not in payload]
    if missing:
        raise ValueError(f"{path}: {missing[0]}: missing from the checkpoint")
    for name, value in payload["model"].items():
        if value.is_floating_point() and not bool(torch.isfinite(value).all()):
            raise ValueError(f"{path}: model.{name}: non-finite values (NaN or inf) in the checkpoint")
    return payload


def load_model(run_dir, device="cpu"):
    """(model in eval mode on `device`, without gradients, its Config) from
    `RUN_DIR/checkpoints/latest.pt`: every caller (eval, render, export, view) is inference."""
    payload = load_checkpoint(run_dir, device)
    cfg = config_from_dict(payload["config"], source=str(checkpoint_path(run_dir)))
    model = model_from_state(cfg, spec_from_dict(payload["spec"]), payload["model"], forecast_spec(payload))
    model.load_state_dict(payload["model"])
    return model.to(device).eval().requires_grad_(False), cfg


def forecast_spec(payload):
    """The MotionSpec of the forecast a checkpoint's model holds, or None."""
    saved = payload["forecast_spec"]
    return None if saved is None else spec_from_dict(saved)


def remove_stale_temporaries(run_dir):
    """Delete `.latest.pt.*.tmp.pt` files that a killed checkpoint write left behind."""
    folder = checkpoint_path(run_dir).parent
    if folder.is_dir():
        for tmp in folder.glob(".latest.pt.*.tmp.pt"):
            tmp.unlink(missing_ok=True)


def _digest(data):
    return hashlib.sha256(data).hexdigest()
