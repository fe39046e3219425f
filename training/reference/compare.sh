#!/usr/bin/env bash
# rccar-train against opencv_traincascade on the same real photos (issue 28): both trainers get
# the same positives (the same pixels) and the same backgrounds, each with the settings its own
# documentation recommends, and both cascades are scored by the same evaluator with the same
# detection parameters on the same unseen frames. Prints a table (docs/training.md, "Against
# opencv_traincascade, measured").
#
#   bash training/reference/compare.sh OUT SETS TRAINCASCADE
#
# OUT           a working folder (outside the repository); a step whose output is already
#               there is not run again (delete OUT to start over)
# SETS          DeepPiCar's lists, `OUT/sets` of training/realsets/deeppicar.sh
# TRAINCASCADE  an opencv_traincascade binary (OpenCV 3.4's apps/traincascade, or 4.x's copy of
#               it; not built or shipped by this repository)
# Env: RCCAR_TRAIN (default target/release/rccar-train), RCCAR (default: rccar beside it, for
# paired.py's sign-by-sign comparison), RCCAR_PYTHON (default .venv/bin/python,
# needs cv2 for the .vec), PHOTOS (default /usr/share/doc/opencv-doc/examples/data, Debian's
# opencv-doc), NICE (default 10), TARGET (default 0.01: evaluate's --target-fp-per-frame).
#
# The material (the stop sign at the car's 320x240, `SETS/320`):
#   the 91 DeepPiCar photos sorted by name, every other one: even places train, odd ones test;
#   positives: the stop-sign boxes of the training photos; `rccar-train distort` (its defaults:
#     3000 samples, window from the boxes) makes more from them; the distorted samples and the
#     boxes themselves are the positives of both trainers (rccar-train reads the info.dat files,
#     opencv_traincascade a .vec of the same crops: vec.py);
#   backgrounds (training): the first half of DeepPiCar's 219 track frames without signs, every
#     other one of OpenCV's sample photos (PHOTOS, from the first), the training photos without
#     a stop sign;
#   calibration: the third quarter of the track frames (the next part of the drive after the
#     training frames), as the recipe's held-out recording `track-b`: each cascade's
#     minNeighbors is chosen there (`evaluate`'s `choose:`, --target-fp-per-frame TARGET), never
#     on the test frames;
#   test: the test photos (with their stop signs; those without count as negative frames), the
#     last quarter of the track frames, the other OpenCV sample photos.
# rccar-train: `train` with its defaults (min hit rate 0.998, 2000 negatives per stage,
# mirrored negatives, 20 stages), --threads 1, no --holdout (no sign frames to spare for the
# early stop: it runs the 20 stages, as opencv_traincascade does).
# With HOLDOUT=1, also rccar-train as the recipe's step 4: the same, with --holdout on the
# calibration frames (training stops once its false positives per frame there are <= 0.01; on
# both folds the 20 stages ended above that, 1 and 2 false boxes on 55 frames, and the cascade
# was byte for byte the default run's, so it is off by default).
# opencv_traincascade: OpenCV's usual -numStages 20 -minHitRate 0.995 -maxFalseAlarmRate 0.5,
# HAAR BASIC, GAB, stumps, -numPos 0.9 x the samples in the .vec, -numNeg 2 x numPos,
# -w/-h the same window, -numThreads 1.
# Both: `rccar-train evaluate` (scale factor 1.1, minNeighbors 0-10, no size limit, IoU 0.5),
# compared at the detector's default minNeighbors 3 and at each cascade's chosen minNeighbors;
# then sign by sign (paired.py: which signs each finds, the exact sign test on those only one
# finds).
# At one thread rccar-train takes about 6 minutes, opencv_traincascade about an hour;
# /usr/bin/time -v gives time and peak memory. Not run by the test suite or CI (it needs the fetched photos and an OpenCV
# binary this repository does not build).
set -euo pipefail
OUT=${1:?usage: compare.sh OUT SETS TRAINCASCADE}
SETS=$(realpath "${2:?usage: compare.sh OUT SETS TRAINCASCADE}")
TC=$(realpath "${3:?usage: compare.sh OUT SETS TRAINCASCADE}")
HERE=$(cd "$(dirname "$0")" && pwd)
ROOT=$(cd "$HERE/../.." && pwd)
RT=$(realpath "${RCCAR_TRAIN:-$ROOT/target/release/rccar-train}")
PY=${RCCAR_PYTHON:-$ROOT/.venv/bin/python}
[ -x "$PY" ] || PY=python3
PHOTOS=${PHOTOS:-/usr/share/doc/opencv-doc/examples/data}
NICE=${NICE:-10}
TARGET=${TARGET:-0.01}
S320="$SETS/320"
[ -f "$S320/stop_sign.info.dat" ] || { echo "$S320: no photo lists; run training/realsets/deeppicar.sh first" >&2; exit 2; }
[ -x "$TC" ] || { echo "$TC: not an executable" >&2; exit 2; }
mkdir -p "$OUT"
OUT=$(realpath "$OUT")
L="$OUT/lists"
mkdir -p "$L"

echo "== lists ($L)"
# Absolute paths everywhere: rccar-train reads paths relative to the list, opencv_traincascade
# relative to its working folder.
FOLD=${FOLD:-a}
case "$FOLD" in a) TRAINPAR=0 ;; b) TRAINPAR=1 ;; *) echo "FOLD=$FOLD: must be a or b" >&2; exit 2 ;; esac
sort "$S320/stop_sign.info.dat" | awk -v d="$S320" -v L="$L" -v p="$TRAINPAR" '{ $1 = d "/" $1;
  if ((NR - 1) % 2 == p) { if ($2 > 0) print > (L "/train_pos.dat"); else print $1 > (L "/train_nosign.txt") }
  else print > (L "/test_photos.dat") }'
touch "$L/train_nosign.txt"
sort "$S320/track.bg.txt" | awk -v d="$S320" '{ print d "/" $1 }' > "$L/track_all.txt"
n=$(wc -l < "$L/track_all.txt")
if [ "$FOLD" = a ]; then
  head -n $(( (n + 1) / 2 )) "$L/track_all.txt" > "$L/train_track.txt"
  tail -n +$(( (n + 1) / 2 + 1 )) "$L/track_all.txt" > "$L/rest_track.txt"
  m=$(wc -l < "$L/rest_track.txt")
  head -n $(( (m + 1) / 2 )) "$L/rest_track.txt" > "$L/calib_track.txt"
  tail -n +$(( (m + 1) / 2 + 1 )) "$L/rest_track.txt" > "$L/test_track.txt"
else
  # The mirror image of fold a: training is the drive's second half, calibration the stretch
  # just before it, test the start of the drive.
  tail -n +$(( n - (n + 1) / 2 + 1 )) "$L/track_all.txt" > "$L/train_track.txt"
  head -n $(( n - (n + 1) / 2 )) "$L/track_all.txt" > "$L/rest_track.txt"
  m=$(wc -l < "$L/rest_track.txt")
  tail -n +$(( m - (m + 1) / 2 + 1 )) "$L/rest_track.txt" > "$L/calib_track.txt"
  head -n $(( m - (m + 1) / 2 )) "$L/rest_track.txt" > "$L/test_track.txt"
fi
find "$PHOTOS" -maxdepth 1 -type f \( -iname '*.jpg' -o -iname '*.jpeg' -o -iname '*.png' \) | LC_ALL=C sort > "$L/photos_all.txt"
awk -v p="$TRAINPAR" '(NR - 1) % 2 == p' "$L/photos_all.txt" > "$L/train_photos.txt"
# evaluate takes frames of at most 8 megapixels: that leaves out chessboard.png (13 MP).
awk -v p="$TRAINPAR" '(NR - 1) % 2 != p' "$L/photos_all.txt" | "$PY" -c '
import sys, cv2
for l in sys.stdin:
    im = cv2.imread(l.strip(), cv2.IMREAD_GRAYSCALE)
    if im is not None and im.size <= 8_000_000:
        print(l.strip())
    else:
        print("test photos: left out (over 8 megapixels or unreadable):", l.strip(), file=sys.stderr)
' > "$L/test_photos_bg.txt"
cat "$L/train_track.txt" "$L/train_photos.txt" "$L/train_nosign.txt" > "$L/train_bg.txt"
printf '%-34s %s\n' \
  "training photos with stop signs" "$(wc -l < "$L/train_pos.dat") ($(awk '{n+=$2} END{print n}' "$L/train_pos.dat") signs)" \
  "training backgrounds" "$(wc -l < "$L/train_bg.txt") ($(wc -l < "$L/train_track.txt") track, $(wc -l < "$L/train_photos.txt") OpenCV photos, $(wc -l < "$L/train_nosign.txt") DeepPiCar photos without a stop sign)" \
  "calibration (minNeighbors)" "$(wc -l < "$L/calib_track.txt") track frames" \
  "test photos" "$(wc -l < "$L/test_photos.dat") ($(awk '$2>0' "$L/test_photos.dat" | wc -l) with $(awk '{n+=$2} END{print n}' "$L/test_photos.dat") signs)" \
  "test frames without the sign" "$(( $(awk '$2==0' "$L/test_photos.dat" | wc -l) + $(wc -l < "$L/test_track.txt") + $(wc -l < "$L/test_photos_bg.txt") )) ($(wc -l < "$L/test_track.txt") track, $(wc -l < "$L/test_photos_bg.txt") OpenCV photos, the rest DeepPiCar photos)"

echo "== positives: rccar-train distort (its defaults)"
if [ ! -f "$OUT/distorted/info.dat" ]; then
  nice -n "$NICE" "$RT" distort --templates-from-info "$L/train_pos.dat" --bg "$L/train_bg.txt" --out "$OUT/distorted" > "$OUT/distort.log"
fi
WIN=$(grep -o -m1 '[0-9]\+x[0-9]\+' "$OUT/distort.log" || true)
[ -n "$WIN" ] || { echo "no window in $OUT/distort.log" >&2; exit 1; }
W=${WIN%x*} H=${WIN#*x}
echo "window ${W}x${H}"
[ -f "$OUT/pos.vec" ] || "$PY" "$HERE/vec.py" "$OUT/pos.vec" "${W}x${H}" "$OUT/distorted/info.dat" "$L/train_pos.dat" | tee "$OUT/vec.log"
NVEC=$("$PY" -c "import struct,sys; print(struct.unpack('<i', open(sys.argv[1],'rb').read(4))[0])" "$OUT/pos.vec")

echo "== rccar-train train (--threads 1)"
if [ ! -f "$OUT/rccar/cascade.xml" ]; then
  nice -n "$NICE" /usr/bin/time -v -o "$OUT/rccar.time" "$RT" train --pos "$OUT/distorted/info.dat" "$L/train_pos.dat" \
    --bg "$L/train_bg.txt" --threads 1 --out "$OUT/rccar" > "$OUT/rccar.log" 2> "$OUT/rccar.err"
fi
cat "$OUT/rccar.log"

TRAINERS="rccar opencv"
if [ "${HOLDOUT:-0}" != 0 ]; then
  # The recipe's step 4 as written: the same run with its early stop on held-out frames, here
  # the calibration frames (no sign frames to spare: the early stop then watches the false
  # positives alone), which also choose minNeighbors below.
  echo "== rccar-train train --holdout (the calibration frames; --threads 1)"
  if [ ! -f "$OUT/rccar-holdout/cascade.xml" ]; then
    nice -n "$NICE" /usr/bin/time -v -o "$OUT/rccar-holdout.time" "$RT" train --pos "$OUT/distorted/info.dat" "$L/train_pos.dat" \
      --bg "$L/train_bg.txt" --holdout "$L/calib_track.txt" --threads 1 --out "$OUT/rccar-holdout" > "$OUT/rccar-holdout.log" 2> "$OUT/rccar-holdout.err"
  fi
  grep -E '^(stages|held-out|time)' "$OUT/rccar-holdout.log"
  TRAINERS="rccar rccar-holdout opencv"
fi

echo "== opencv_traincascade (-numThreads 1)"
NPOS=$(( NVEC * 9 / 10 ))
NNEG=$(( 2 * NPOS ))
if [ ! -f "$OUT/opencv/cascade.xml" ]; then
  mkdir -p "$OUT/opencv"
  (cd "$OUT" && nice -n "$NICE" /usr/bin/time -v -o "$OUT/opencv.time" "$TC" -data opencv -vec pos.vec -bg "$L/train_bg.txt" \
    -numPos "$NPOS" -numNeg "$NNEG" -numStages 20 -minHitRate 0.995 -maxFalseAlarmRate 0.5 \
    -w "$W" -h "$H" -featureType HAAR -mode BASIC -numThreads 1 > "$OUT/opencv.log" 2>&1)
fi
tr '\r' '\n' < "$OUT/opencv.log" | grep -E '^Training until now|^Required leaf' | tail -1

echo "== minNeighbors chosen on the calibration frames (--target-fp-per-frame $TARGET)"
for t in $TRAINERS; do
  "$RT" evaluate --cascade "$OUT/$t/cascade.xml" --out "$OUT/calib-$t" --target-fp-per-frame "$TARGET" \
    --info "$L/calib_track.txt" > "$OUT/calib-$t.log"
  echo "$t: $(grep '^choose:' "$OUT/calib-$t.log")"
done

echo "== evaluate on the test frames (scale factor 1.1, no size limit, IoU 0.5)"
for t in $TRAINERS; do
  "$RT" evaluate --cascade "$OUT/$t/cascade.xml" --out "$OUT/eval-$t" \
    --info "$L/test_photos.dat" "$L/test_track.txt" "$L/test_photos_bg.txt" > "$OUT/eval-$t.log"
done

"$PY" "$HERE/table.py" "$OUT" "$W" "$H" "$NVEC" "$NPOS" "$NNEG"

echo "== sign by sign on the test photos (paired.py: which cascade finds which sign)"
RCCAR=${RCCAR:-$(dirname "$RT")/rccar}
if [ -x "$RCCAR" ]; then
  chosen() { "$PY" -c 'import json,sys; v=json.load(open(sys.argv[1])).get("chosen_min_neighbors"); print(v if v else 3)' "$1"; }
  for t in $TRAINERS; do
    [ "$t" = opencv ] && continue
    "$PY" "$HERE/paired.py" "$RCCAR" "$L/test_photos.dat" "$t" "$OUT/$t/cascade.xml" opencv "$OUT/opencv/cascade.xml" \
      3:3 "$(chosen "$OUT/calib-$t/report.json"):$(chosen "$OUT/calib-opencv/report.json")"
  done
else
  echo "no rccar binary at $RCCAR (set RCCAR): sign-by-sign comparison skipped"
fi
