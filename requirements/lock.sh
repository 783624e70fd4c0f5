#!/usr/bin/env bash
# Refresh the locks from pyproject.toml: bash requirements/lock.sh   (needs uv: pip install uv)
# app.txt: the app with its Dask, CommonRoad and PostgreSQL extras (the Docker image, `driftlab serve`); test.txt:
# the app and the test extra.
# Both carry the build backend (installed with --no-build-isolation) and the hash of every file, for Python 3.11+ on
# Linux; pip installs them as they are. Refresh, run the whole suite, and commit the two files together.
set -euo pipefail
cd "$(dirname "$0")/.."
for target in "app dask,commonroad,postgres" "test test"; do
    set -- $target
    extras=(); IFS=, read -ra names <<< "$2"; for e in "${names[@]}"; do extras+=(--extra "$e"); done
    uv pip compile pyproject.toml requirements/build.in "${extras[@]}" --python-version 3.11 --generate-hashes \
        --custom-compile-command "bash requirements/lock.sh" -q -o "requirements/$1.txt"
done
