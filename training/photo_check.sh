#!/usr/bin/env bash
# The photo-like generalisation check of docs/training.md ("Does it generalise?"): the real-photo
# workflow (boxes -> distort -> train with the documented defaults -> evaluate) on frames made
# from the system's photographs (opencv-doc samples, scikit-image data) with the simulator's
# stop sign pasted in. Three disjoint sets of photos: training (four fifths of half 0), validation
# (the last fifth of half 0: the early stop and every choice of settings), test (half 1, other
# seeds: looked at once, at the end).
# Also trains a baseline with the trainer of another build (BASELINE=path/to/rccar-train, e.g.
# main before issue 16) on the same positives and window, its defaults otherwise.
# Usage: bash training/photo_check.sh [WORKDIR]   (default out/photo_check; about 8 min of CPU for the training with THREADS=1, 30 min wall under a load of 3-10)
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release -p rccar-train
B=$PWD/target/release/rccar-train
W=${1:-out/photo_check}
THREADS=${THREADS:-2}
# The photos: OpenCV's samples (opencv-doc) and scikit-image's data photos (the figures in
# docs/training.md were measured on both; photoset's default is the opencv-doc samples alone).
PY=${RCCAR_PYTHON:-$PWD/.venv/bin/python}
SKI=$("$PY" -c 'import os, skimage; print(os.path.join(os.path.dirname(skimage.__file__), "data"))' 2>/dev/null || true)
PHOTOS=(/usr/share/doc/opencv-doc/examples/data ${SKI:+"$SKI"})
rm -rf "$W"; mkdir -p "$W"; cd "$W"
# 1. Frames: 42 with a sign + 300 without to train on (like the issue's set); a validation set
#    for the early stop and a larger one for comparing settings, both from photos the training
#    never sees; the test set: the other half of the photos, other seeds.
$B photoset --half 0-train --seed 1 --with-sign 42 --without 300 --out train --photos "${PHOTOS[@]}"
$B photoset --half 0-val --seed 2 --with-sign 48 --without 300 --out val --photos "${PHOTOS[@]}"
$B photoset --half 0-val --seed 4 --with-sign 200 --without 200 --out valbig --photos "${PHOTOS[@]}"
$B photoset --half 1 --seed 3 --with-sign 48 --without 350 --out test --photos "${PHOTOS[@]}"
# 2. Boxes (the CSV a student would type) -> info.dat + previews.
$B boxes --csv train/boxes.csv --out train/pos.dat --preview train/preview
$B boxes --csv val/boxes.csv --out val/pos.dat
# 3. Distorted positives (the default --count) from the 42 crops, over the training backgrounds.
$B distort --templates-from-info train/pos.dat --bg train/bg.txt --out dist
# 4. Train with the documented defaults (window and counts from the data, held-out stop).
T0=$(date +%s)
/usr/bin/time -v $B train --pos dist/info.dat train/pos.dat --bg train/bg.txt \
  --holdout val/pos.dat val/bg.txt --out model --threads "$THREADS" > train.out 2> train.err
echo "train: $(( $(date +%s) - T0 )) s"; cat train.out
# 5. The larger validation set (what settings are compared on), then the test frames.
$B evaluate --cascade model/cascade.xml --info valbig/info.dat valbig/bg.txt --out val_eval | tee val_eval.txt
$B evaluate --cascade model/cascade.xml --info test/info.dat test/bg.txt --out eval | tee eval.txt
if [ -n "${BASELINE:-}" ]; then
  WIN=$(sed -n 's/^# rccar-train distort window //p' dist/info.dat)
  T0=$(date +%s)
  /usr/bin/time -v "$BASELINE" train --pos dist/info.dat --pos train/pos.dat --bg train/bg.txt \
    -W "${WIN%x*}" -H "${WIN#*x}" --out base --threads "$THREADS" > base.out 2> base.err || true
  echo "baseline train: $(( $(date +%s) - T0 )) s"
  $B evaluate --cascade base/cascade.xml --info test/info.dat test/bg.txt --out base_eval | tee base_eval.txt
fi
