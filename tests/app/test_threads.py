"""velogauss.threads: the thread counts and wait policy a velogauss process sets, and where
they come from (`--threads`, train.threads, OMP_NUM_THREADS, OMP_WAIT_POLICY). Speed is
measured by `velogauss bench load`, never asserted here."""

import os
import subprocess
import sys

import pytest
import torch

from velogauss.config import check_resume_config, load_config
from velogauss.run import train_flags
from velogauss.threads import apply_threads, available_cores, prepare_environment, resolve_threads
from velogauss_fast.backends import numba_backend


def test_available_cores_is_the_affinity_mask():
    assert available_cores() == len(os.sched_getaffinity(0))


@pytest.mark.parametrize("requested, environ, expected", [
    (0, {}, (1, 6)),                              # default: one torch thread, compositing on every core
    (0, {"OMP_NUM_THREADS": "1"}, (1, 1)),        # the user's OMP_NUM_THREADS caps the compositing
    (0, {"OMP_NUM_THREADS": " 3 "}, (1, 3)),
    (0, {"OMP_NUM_THREADS": "0"}, (1, 6)),        # not a thread count: ignored
    (0, {"OMP_NUM_THREADS": "4,2"}, (1, 6)),      # nested-level lists are OpenMP's business
    (3, {"OMP_NUM_THREADS": "1"}, (3, 3)),        # --threads wins over the environment
    (1, {}, (1, 1)),
])
def test_resolve_threads(requested, environ, expected):
    assert resolve_threads(requested, 6, environ) == expected


@pytest.mark.parametrize("bad", [-1, 1.5, True, "2"])
def test_resolve_threads_refuses_bad_counts(bad):
    with pytest.raises(ValueError, match="threads"):
        resolve_threads(bad, 2, {})


def test_prepare_environment_sets_a_passive_wait_policy_unless_the_user_chose():
    environ = {}
    assert prepare_environment(environ) == "PASSIVE" and environ == {"OMP_WAIT_POLICY": "PASSIVE"}
    environ = {"OMP_WAIT_POLICY": "ACTIVE"}
    assert prepare_environment(environ) == "ACTIVE" and environ == {"OMP_WAIT_POLICY": "ACTIVE"}


@pytest.fixture
def restore_threads():
    torch_threads, composite = torch.get_num_threads(), numba_backend.set_num_threads(0)
    yield
    torch.set_num_threads(torch_threads)
    numba_backend.set_num_threads(composite)


def test_apply_threads_sets_torch_and_the_compositing(restore_threads, monkeypatch):
    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    assert apply_threads(3) == (3, 3)
    assert torch.get_num_threads() == 3 and numba_backend.get_num_threads() == 3
    assert apply_threads(0) == (1, available_cores())
    assert torch.get_num_threads() == 1 and numba_backend.get_num_threads() == available_cores()


def test_compositing_threads_follow_torch_unless_set(restore_threads):
    torch.set_num_threads(2)
    assert numba_backend.get_num_threads() == 2
    assert numba_backend.set_num_threads(3) == 0
    assert numba_backend.get_num_threads() == 3
    with pytest.raises(ValueError, match="n: expected an integer >= 0"):
        numba_backend.set_num_threads(-1)


def _fresh_interpreter(code, **env):
    environ = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"} | env
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=environ, check=True).stdout


def test_the_command_sets_the_wait_policy_before_torch_loads():
    # Importing the command line sets nothing up and loads no torch; its entry point `main`
    # sets the wait policy before the command it runs (here a stand-in for `app`) can load torch.
    code = ("import os, sys, velogauss.cli as cli; print('torch' in sys.modules, os.environ.get('OMP_WAIT_POLICY')); "
            "cli.app = lambda args, prog_name: print('torch' in sys.modules, os.environ['OMP_WAIT_POLICY']); cli.main()")
    assert _fresh_interpreter(code).split() == ["False", "None", "False", "PASSIVE"]
    assert _fresh_interpreter(code, OMP_WAIT_POLICY="ACTIVE").split() == ["False", "ACTIVE", "False", "ACTIVE"]


def test_the_console_script_and_python_m_velogauss_run_main():
    import tomllib
    from pathlib import Path

    pyproject = tomllib.loads((Path(__file__).resolve().parents[2] / "pyproject.toml").read_text())
    assert pyproject["project"]["scripts"]["velogauss"] == "velogauss.cli:main"
    result = subprocess.run([sys.executable, "-m", "velogauss", "--help"], capture_output=True, text=True, check=True)
    assert "Usage: python -m velogauss" in result.stdout


def test_threads_config_key_and_flag():
    assert load_config().train.threads == 0
    assert load_config(None, ["train.threads=4"]).train.threads == 4
    assert load_config(None, [], train_flags(threads=2)).train.threads == 2
    for bad in ("-1", "2000", "1.5"):
        with pytest.raises(ValueError, match="train.threads"):
            load_config(None, [f"train.threads={bad}"])
    with pytest.raises(ValueError, match="--threads"):
        load_config(None, [], train_flags(threads=-2))


def test_resume_may_change_the_threads():
    check_resume_config(load_config(), load_config(None, ["train.threads=2"]))


def test_train_refuses_a_negative_thread_count(tmp_path):
    from typer.testing import CliRunner

    from velogauss.cli import app

    result = CliRunner().invoke(app, ["train", "--out", str(tmp_path / "run"), "--threads", "-1"])
    assert result.exit_code == 2 and "error: --threads: train.threads:" in result.output, result.output
    assert not (tmp_path / "run").exists()
