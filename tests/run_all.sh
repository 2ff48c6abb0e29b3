#!/usr/bin/env bash
# Install everything the tests need on a bare machine, then lint, type-check and run the tests.
# The README's test command and CI (.ci/run) both run exactly this script; extra arguments go to
# pytest (e.g. `bash tests/run_all.sh -x -k gaze`).
set -euo pipefail
cd "$(dirname "$0")/.."

# Headless Chromium, for the browser tests of the 3D view (screenshots of the meshcat page).
if ! command -v chromium >/dev/null 2>&1 && ! command -v chromium-browser >/dev/null 2>&1 \
        && [ -z "${CPC2URDF_CHROMIUM:-}" ]; then
    if ! command -v apt-get >/dev/null 2>&1; then
        echo "tests/run_all.sh: the view's browser tests need Chromium and this machine has no apt-get;" \
             "install Chromium and set CPC2URDF_CHROMIUM=/path/to/chromium" >&2
        exit 2
    fi
    sudo=""
    [ "$(id -u)" -eq 0 ] || sudo="sudo"
    $sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq chromium >/dev/null
fi

python -m pip install -q -e ".[dev]"
ruff check .
ruff format --check .
mypy
python -m pytest -n auto "$@"   # one worker per core
