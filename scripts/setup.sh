#!/usr/bin/env bash
# One-step, idempotent set-up on a fresh machine: a virtual environment in .venv with
# velogauss and its test tools installed. torch is pinned to the CPU build first because
# an open `torch` requirement would otherwise pull a CUDA build of several GB.
set -euo pipefail
cd "$(dirname "$0")/.."
if [ ! -x .venv/bin/python ]; then
  python3 -m venv .venv
fi
.venv/bin/python -m pip install -q --upgrade pip >/dev/null
.venv/bin/python -m pip install -q "torch==2.13.0"
.venv/bin/python -m pip install -q -e ".[test,sweep]"
