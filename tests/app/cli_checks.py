"""What the CLI tests share: the check that a command refused bad input the way the project's
errors do (velogauss/errors.py: one `error:` line, exit code 2, no traceback)."""


def assert_refused(result, *names, code=2):
    """Exit code `code`, one `error:` line naming each of `names`, no traceback."""
    assert result.exit_code == code, result.output
    errors = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert len(errors) == 1, result.output
    for name in names:
        assert str(name) in errors[0], (name, errors[0])
    assert "Traceback" not in result.output
