"""Which code trained a run: the run folder's `provenance.json`.

Training writes one entry per session into it, a new run's and then each resume's: the
iteration the session started from, when (UTC), velogauss's installed version, and, where
velogauss was imported from a git checkout (an editable install), the checkout's commit and
whether its tracked files differed from it. A study that merges runs trained over months (the
family's, FIDELITY.md) can then say which version trained each row instead of trusting notes.
"""

import datetime
import importlib.metadata
import json
import subprocess
from pathlib import Path

from velogauss.io_utils import write_text

PROVENANCE_FILE = "provenance.json"
# The folder above the package: the checkout's root in an editable install.
SOURCE_ROOT = Path(__file__).resolve().parent.parent
# Long enough for git on a slow shared disk, short enough that a hung git cannot stall a run.
GIT_TIMEOUT_S = 10.0


def code_version(root=SOURCE_ROOT):
    """{"version": velogauss's installed version (None when not installed), "commit": the 40-hex
    commit of the git checkout at `root` (None when `root` is no checkout or git is missing),
    "dirty": whether its tracked files differ from that commit (None with no commit)}."""
    try:
        version = importlib.metadata.version("velogauss")
    except importlib.metadata.PackageNotFoundError:
        version = None
    commit = _git(root, "rev-parse", "--verify", "HEAD") if (Path(root) / ".git").exists() else None
    changes = _git(root, "status", "--porcelain", "--untracked-files=no") if commit else None
    return {"version": version, "commit": commit, "dirty": None if changes is None else changes != ""}


def _git(root, *args):
    """git's stripped output at `root`, or None when git is missing, fails or hangs."""
    try:
        done = subprocess.run(["git", "-C", str(root), *args], capture_output=True, text=True,
                              timeout=GIT_TIMEOUT_S, check=True)
    except (OSError, subprocess.SubprocessError):
        return None
    return done.stdout.strip()


def read_provenance(run_dir):
    """The sessions of `run_dir`'s provenance.json (a list of dicts, oldest first); [] where the
    file is absent (a run trained before velogauss wrote it). ValueError naming the file when it
    is not such a list."""
    path = Path(run_dir) / PROVENANCE_FILE
    if not path.is_file():
        return []
    try:
        sessions = json.loads(path.read_text())
    except json.JSONDecodeError as err:
        raise ValueError(f"{path}: not valid JSON ({err.msg}, line {err.lineno})") from None
    if not isinstance(sessions, list) or not all(isinstance(s, dict) and "iteration" in s for s in sessions):
        raise ValueError(f"{path}: expected a list of training sessions, each with an `iteration`")
    return sessions


def record_session(run_dir, iteration, root=SOURCE_ROOT):
    """Append this session (training from `iteration`) to `run_dir`'s provenance.json, atomically;
    a new run (`iteration` 0) starts the list afresh."""
    entry = {"iteration": int(iteration),
             "started": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
             **code_version(root)}
    sessions = read_provenance(run_dir) if iteration > 0 else []
    write_text(Path(run_dir) / PROVENANCE_FILE, json.dumps(sessions + [entry], indent=1))


def code_label(run_dir):
    """The code that trained `run_dir`, for a table: each session's short commit (the version
    where there is none), a "+" after one whose checkout had changes, distinct ones joined by
    ", " in order; None for a run without provenance.json."""
    labels = []
    for session in read_provenance(run_dir):
        name = (session.get("commit") or "")[:7] or session.get("version") or "unknown"
        name += "+" if session.get("dirty") else ""
        if name not in labels:
            labels.append(name)
    return ", ".join(labels) or None
