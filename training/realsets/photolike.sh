#!/usr/bin/env bash
# Trains a candidate stop-sign or traffic-light cascade on a mix of simulator renders (the
# data of training/models/train_all.sh, same seeds) and photo-like frames (`rccar-train
# photoset`: the object pasted into the system's photographs, with its printed / toy-like
# variety), negatives from both; then scores it on the held-out renders and, when OUT is
# given, on DeepPiCar's real photos (score.sh). docs/training.md, "The shipped cascades on real
# photos (issue 28)". It never trains on DeepPiCar's photos and never touches config/cascades/.
#
#   bash training/realsets/photolike.sh KIND WORK [OUT]
#
# KIND  stop_sign | traffic_light
# WORK  work folder (outside the repository; recreated)
# OUT   DeepPiCar's set as made by deeppicar.sh (optional)
# The photos: OpenCV's samples (Debian's opencv-doc) and scikit-image's data photos (the .venv
# of tests/all.sh's setup), as training/photo_check.sh. About 12-20 min with one thread.
# Env: THREADS (default 1), MIN_HIT_RATE (default 0.998, as train_all.sh), PHOTOS_STYLE (photoset's style flag; default --printed for the stop
# sign, --traffic-light for the light).
set -euo pipefail
KIND=${1:?usage: photolike.sh KIND WORK [OUT]}
W=${2:?usage: photolike.sh KIND WORK [OUT]}
OUT=${3:-}
HERE=$(cd "$(dirname "$0")" && pwd)
ROOT=$(cd "$HERE/../.." && pwd)
cd "$ROOT"
cargo build --release -p rccar-train
B=$ROOT/target/release/rccar-train
PY=${RCCAR_PYTHON:-$ROOT/.venv/bin/python}
SKI=$("$PY" -c 'import os, skimage; print(os.path.join(os.path.dirname(skimage.__file__), "data"))' 2>/dev/null || true)
PHOTOS=(/usr/share/doc/opencv-doc/examples/data ${SKI:+"$SKI"})
case $KIND in
  stop_sign) WIN=(-W 16 -H 16); STYLE=${PHOTOS_STYLE:---printed}; PX=16x64; PSEED=23 ;;
  traffic_light) WIN=(-W 8 -H 20); STYLE=${PHOTOS_STYLE:---traffic-light}; PX=20x100; PSEED=31 ;;
  *) echo "KIND: stop_sign or traffic_light" >&2; exit 2 ;;
esac
rm -rf "$W"; mkdir -p "$W"
# 1. Renders as train_all.sh (positives seed 1, backgrounds seed 2, held-out seed 1001) and
#    photo-like frames (3000 with the object, 1000 without).
$B gen --kind "$KIND" --split positives --count 3000 --seed 1 --min-distance 0.18 --max-distance 1.6 --light-variation 0 --out "$W/pos"
$B gen --kind "$KIND" --split negatives --count 1000 --seed 2 --light-variation 0 --out "$W/neg"
$B gen --kind "$KIND" --split eval --count 300 --seed 1001 --light-variation 0 --out "$W/eval"
$B photoset $STYLE --half all --seed $PSEED --with-sign 3000 --without 1000 --sign-px $PX --out "$W/ps" --photos "${PHOTOS[@]}"
# 2. Train: train_all.sh's stage settings, 5000 positives per stage.
/usr/bin/time -v $B train --out "$W/model" --pos "$W/pos/info.dat" "$W/ps/info.dat" --bg "$W/neg/bg.txt" "$W/ps/bg.txt" \
  "${WIN[@]}" --num-stages 22 --num-pos 5000 --num-neg 2000 --min-hit-rate "${MIN_HIT_RATE:-0.998}" --max-false-alarm 0.5 \
  --mode basic --boost gentle --mem-mb 400 --seed 1 --threads "${THREADS:-1}" > "$W/train.out" 2> "$W/train.log"
grep -E "Elapsed|User time|Maximum resident" "$W/train.log"
# 3. Held-out renders; DeepPiCar's photos.
$B evaluate --cascade "$W/model/cascade.xml" --info "$W/eval/info.dat" --out "$W/eval_report" --title "$KIND: held-out renders" | tee "$W/eval.txt"
mkdir -p "$W/cascades" && cp "$W/model/cascade.xml" "$W/cascades/$KIND.xml"
[ -z "$OUT" ] || CASCADES="$W/cascades" CLASSES=$KIND PART1_ONLY=1 bash "$HERE/score.sh" "$OUT"
