#!/usr/bin/env bash
# Fetches DeepPiCar's published photo set (real photos of miniature road signs on a floor
# track, with the project's own box labels) and writes rccar-train lists for it. The photos
# are GPL-3.0 material of github.com/dctian/DeepPiCar: they are read, never committed here.
#
#   bash training/realsets/deeppicar.sh OUT [SOURCE]
#
# OUT     where the set goes (outside the repository), e.g. ~/data/realsigns/deeppicar
# SOURCE  a clone of DeepPiCar (a bare or normal git folder) to read instead of cloning
#         https://github.com/dctian/DeepPiCar
# Needs git and Python with OpenCV (the repository's .venv: tests/parity/requirements.txt).
# Then: bash training/realsets/score.sh OUT   (docs/training.md, "Real photos").
# Not run by the test suite or CI (it needs the network); tests/real_photos.rs skips without it.
set -euo pipefail
OUT=${1:?usage: deeppicar.sh OUT [SOURCE]}
SRC=${2:-}
# The commit the figures in docs/training.md were measured on (2020-03-19).
COMMIT=d01bd627c0bbbf4d167cbfdd9ad86f4741c3496c
HERE=$(cd "$(dirname "$0")" && pwd)
PY=${RCCAR_PYTHON:-$HERE/../../.venv/bin/python}
[ -x "$PY" ] || PY=python3
[ -x "$PY" ] || PY=python3
mkdir -p "$OUT"
if [ -z "$SRC" ]; then
  SRC="$OUT/DeepPiCar.git"
  [ -d "$SRC" ] || git clone --bare --quiet https://github.com/dctian/DeepPiCar "$SRC"
fi
GITDIR=$(git -C "$SRC" rev-parse --git-dir)
case "$GITDIR" in /*) ;; *) GITDIR="$SRC/$GITDIR" ;; esac
mkdir -p "$OUT/src"
git --git-dir="$GITDIR" archive "$COMMIT" models/object_detection/data/images models/lane_navigation/data/images \
  | tar -x -C "$OUT/src"
"$PY" "$HERE/deeppicar.py" "$OUT/src" "$OUT/sets"
