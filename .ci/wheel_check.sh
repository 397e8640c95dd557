#!/usr/bin/env bash
# Build the sdist and the wheel (python -m build: the wheel is built from the sdist, so both are checked),
# install the wheel alone in a fresh venv and run the smoke test from a folder outside the source tree; then
# the new-user walk in that venv with the wheel's [rl] and [marl] extras added (the pages show SB3, TorchRL and
# BenchMARL): every python block of the README and the docs pages (copies), and a video recorded with
# RecordVideo (scripts/new_user_walk.py).
# Usage: .ci/wheel_check.sh [PYTHON]   (PYTHON builds; default .venv/bin/python, which has `build`)
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${1:-.venv/bin/python}
BASE=$(command -v python3.11 || command -v python3)
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
"$PY" -m build --outdir "$WORK/dist" . > "$WORK/build.log" 2>&1 || { cat "$WORK/build.log"; exit 1; }
ls "$WORK/dist"
SDIST=$(ls "$WORK"/dist/*.tar.gz)
WHEEL=$(ls "$WORK"/dist/*.whl)
# what must ship: the package data and the project's own files
tar -tzf "$SDIST" > "$WORK/sdist.txt"
"$PY" -c "import sys, zipfile; print('\n'.join(zipfile.ZipFile(sys.argv[1]).namelist()))" "$WHEEL" > "$WORK/wheel.txt"
for f in LICENSE CHANGELOG.md CITATION.cff; do
    grep -q "/$f\$" "$WORK/sdist.txt" || { echo "sdist lacks $f"; exit 1; }
done
# what must not: the results (results/, and the folder baselines/results/ had before)
if grep -E "(^|/)results/|(^|/)benchmarks/" "$WORK/wheel.txt" "$WORK/sdist.txt"; then
    echo "the sdist or the wheel ships results or benchmarks (above)"; exit 1
fi
for f in impact_env/transport/scenarios/corridor.toml impact_env/tether/stations/L.toml baselines/hyperparams/ppo.yml \
         planners/expert/expert.py impact_env/py.typed planners/py.typed baselines/py.typed; do
    grep -q "^$f\$" "$WORK/wheel.txt" || { echo "wheel lacks $f"; exit 1; }
done
# the compiled helpers (setup.py): built into the wheel, their C sources in the sdist
for f in impact_env/transport/_substeps impact_env/tether/_substeps impact_env/stl/_cmonitor; do
    grep -q "^$f\..*\.so\$" "$WORK/wheel.txt" || { echo "wheel lacks the compiled $f"; exit 1; }
    grep -q "/$f\.c\$" "$WORK/sdist.txt" || { echo "sdist lacks $f.c"; exit 1; }
done
"$BASE" -m venv "$WORK/venv"
"$WORK/venv/bin/pip" install --quiet --upgrade pip
"$WORK/venv/bin/pip" install --quiet "$WHEEL"
cp scripts/smoke_installed.py "$WORK/smoke.py"
cp scripts/new_user_walk.py "$WORK/walk.py"
mkdir -p "$WORK/pages/docs"
cp README.md "$WORK/pages/"
cp docs/*.md "$WORK/pages/docs/"
cd "$WORK"  # outside the source tree: nothing can be imported from the checkout
PATH="$WORK/venv/bin:$PATH" SDL_VIDEODRIVER=dummy MPLBACKEND=Agg "$WORK/venv/bin/python" smoke.py
# [rl] and [marl] as a new user adds them, torch pinned to the CPU build first (as the dev install does)
"$WORK/venv/bin/pip" install --quiet torch==2.13.0
"$WORK/venv/bin/pip" install --quiet torch==2.13.0 "$WHEEL[rl,marl]"
mkdir "$WORK/walk"
cd "$WORK/walk"
PATH="$WORK/venv/bin:$PATH" SDL_VIDEODRIVER=dummy MPLBACKEND=Agg "$WORK/venv/bin/python" ../walk.py \
    ../pages/README.md ../pages/docs/*.md
