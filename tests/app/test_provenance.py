"""velogauss.provenance: which code trained a run. The commit is read from a git checkout made
here and checked against what git's log prints (tests/app/test_train.py: a training run and
its resume each add a session)."""

import importlib.metadata
import json
import shutil
import subprocess

import pytest

from velogauss.provenance import PROVENANCE_FILE, code_label, code_version, read_provenance, record_session

pytestmark = pytest.mark.skipif(shutil.which("git") is None, reason="needs the git command")


def git(root, *args):
    return subprocess.run(["git", "-C", str(root), *args], capture_output=True, text=True, check=True).stdout


@pytest.fixture
def checkout(tmp_path):
    """A git checkout of one commit: (root, the commit's hash as `git log` prints it)."""
    root = tmp_path / "checkout"
    root.mkdir()
    git(root, "init", "-q")
    (root / "tracked.txt").write_text("one\n")
    git(root, "add", "tracked.txt")
    git(root, "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-q", "-m", "first")
    return root, git(root, "log", "-1", "--format=%H").strip()


def test_the_commit_of_a_clean_checkout(checkout):
    root, commit = checkout
    found = code_version(root)
    assert found["commit"] == commit and len(commit) == 40 and found["dirty"] is False
    assert found["version"] == importlib.metadata.version("velogauss")


def test_a_changed_tracked_file_makes_it_dirty_an_untracked_one_does_not(checkout):
    root, commit = checkout
    (root / "notes.txt").write_text("not tracked\n")
    assert code_version(root)["dirty"] is False
    (root / "tracked.txt").write_text("two\n")
    assert code_version(root)["dirty"] is True and code_version(root)["commit"] == commit


def test_no_checkout_or_no_git_gives_no_commit(checkout, tmp_path, monkeypatch):
    assert code_version(tmp_path / "plain")["commit"] is None
    monkeypatch.setenv("PATH", str(tmp_path / "no-bin"))
    found = code_version(checkout[0])
    assert found["commit"] is None and found["dirty"] is None


def test_sessions_append_on_resume_and_restart_with_a_new_run(checkout, tmp_path):
    root, commit = checkout
    run = tmp_path / "run"
    run.mkdir()
    record_session(run, 0, root)
    record_session(run, 40, root)
    sessions = read_provenance(run)
    assert [s["iteration"] for s in sessions] == [0, 40] and {s["commit"] for s in sessions} == {commit}
    assert all(s["started"].endswith("+00:00") for s in sessions)
    record_session(run, 0, root)
    assert [s["iteration"] for s in read_provenance(run)] == [0]


@pytest.mark.parametrize("text", ["{not json", '{"iteration": 0}', '[{"commit": "abc"}]'])
def test_a_malformed_file_is_named_and_kept(tmp_path, text):
    (tmp_path / PROVENANCE_FILE).write_text(text)
    with pytest.raises(ValueError, match=str(tmp_path / PROVENANCE_FILE)):
        record_session(tmp_path, 7)
    assert (tmp_path / PROVENANCE_FILE).read_text() == text


@pytest.mark.parametrize("sessions, label", [
    (None, None),
    ([{"iteration": 0, "commit": "0123456789" * 4, "dirty": False}], "0123456"),
    ([{"iteration": 0, "commit": "0123456789" * 4, "dirty": True},
      {"iteration": 9, "commit": "0123456789" * 4, "dirty": True},
      {"iteration": 20, "commit": "f" * 40, "dirty": False}], "0123456+, fffffff"),
    # An installed (not editable) velogauss: no checkout, its version.
    ([{"iteration": 0, "version": "0.1.0", "commit": None, "dirty": None}], "0.1.0"),
])
def test_code_label(tmp_path, sessions, label):
    if sessions is not None:
        (tmp_path / PROVENANCE_FILE).write_text(json.dumps(sessions))
    assert code_label(tmp_path) == label

