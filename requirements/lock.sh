#!/usr/bin/env bash
# Refresh the locks from pyproject.toml: bash requirements/lock.sh   (needs uv: pip install -r requirements/uv.txt)
# app.txt: the app with its Dask, CommonRoad and PostgreSQL extras (the Docker image, `driftlab serve`); test.txt:
# the app and the test extra.
# Both carry the build backend (installed with --no-build-isolation) and the hash of every file, for Python 3.11+ on
# Linux; uv or pip installs them as they are. uv.txt: the installer the README's commands use, locked the same way.
# Refresh, run the whole suite, and commit the three files together.
set -euo pipefail
cd "$(dirname "$0")/.."
for target in "app dask,commonroad,postgres" "test test"; do
    set -- $target
    extras=(); IFS=, read -ra names <<< "$2"; for e in "${names[@]}"; do extras+=(--extra "$e"); done
    uv pip compile pyproject.toml requirements/build.in "${extras[@]}" --python-version 3.11 --generate-hashes \
        --custom-compile-command "bash requirements/lock.sh" -q -o "requirements/$1.txt"
done
uv pip compile requirements/uv.in --python-version 3.11 --generate-hashes \
    --custom-compile-command "bash requirements/lock.sh" -q -o requirements/uv.txt
