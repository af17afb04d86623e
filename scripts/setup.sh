#!/usr/bin/env bash
# One-step, idempotent set-up on a fresh machine: a virtual environment in .venv with
# velogauss and its test tools installed. torch is pinned to the CPU build first because
# an open `torch` requirement would otherwise pull a CUDA build of several GB; constraints.txt
# pins the packages whose releases can change results.
set -euo pipefail
cd "$(dirname "$0")/.."
if [ ! -x .venv/bin/python ]; then
  python3 -m venv .venv
fi
.venv/bin/python -m pip install -q --upgrade pip >/dev/null
.venv/bin/python -m pip install -q -c constraints.txt "torch==2.13.0"
.venv/bin/python -m pip install -q -c constraints.txt -e ".[test,sweep,view]"
# The viewer's end-to-end test drives headless Chromium (tests/app/test_view.py; it skips, with
# the reason, where there is none). CI (CI=true, root) installs Debian's package: about 75 s.
if [ "${CI:-}" = "true" ] && ! command -v chromium >/dev/null && command -v apt-get >/dev/null; then
  { apt-get update -q && DEBIAN_FRONTEND=noninteractive apt-get install -y -q chromium; } >/dev/null \
    || echo "setup.sh: could not install chromium; the viewer's browser test will be skipped" >&2
fi
