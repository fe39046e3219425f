#!/usr/bin/env bash
# Scores the shipped cascades and Abdollahi's colour + template detector on DeepPiCar's real
# photos (made by deeppicar.sh; docs/detect.md, "Real photos"):
#
#   bash training/realsets/score.sh OUT      (OUT as given to deeppicar.sh)
#
# 1. The shipped stop-sign and traffic-light cascades on all 91 photos, at the photos' own size
#    (`full`: 48 at 640x480, 43 at 320x240) and at the car's 320x240 (`320`), with the car's
#    detectMultiScale parameters (scale factor 1.1, minNeighbors 3, no size limit: `rccar
#    detect`'s defaults, config/car.toml [detect]), whole frames; OpenCV's boxes with the same
#    cascade beside them when Python has cv2.
# 2. Side by side for the stop sign: the cascade and `rccar detect --method colour-template`
#    (the [colour_template] options of config/car.toml) on DeepPiCar's `train` folder, 43 photos
#    (42 with stop signs, 61 signs) that neither detector was built or tuned on (the colour
#    options were chosen on the `test` and `ver1` folders: tune_colour.py), and on 219 frames of
#    the track without signs.
# Env: RCCAR (default target/release/rccar), RCCAR_PYTHON (default .venv/bin/python),
# CASCADES (folder of stop_sign.xml / traffic_light.xml; default config/cascades), CLASSES (part 1's
# classes; default "stop_sign traffic_light"), PART1_ONLY=1 (skip part 2), NO_OPENCV=1 (rccar only).
# Not run by the test suite or CI (the photos are fetched, never committed).
set -euo pipefail
OUT=${1:?usage: score.sh OUT}
HERE=$(cd "$(dirname "$0")" && pwd)
ROOT=$(cd "$HERE/../.." && pwd)
RCCAR=$(realpath "${RCCAR:-$ROOT/target/release/rccar}")
PY=${RCCAR_PYTHON:-$ROOT/.venv/bin/python}
[ -x "$PY" ] || PY=python3
CONF="--config $ROOT/config/car.toml --no-local"
SETS="$OUT/sets"
[ -f "$SETS/full/stop_sign.info.dat" ] || { echo "$SETS: no photo lists; run training/realsets/deeppicar.sh $OUT first" >&2; exit 2; }
OPENCV=()
[ -z "${NO_OPENCV:-}" ] && "$PY" -c "import cv2" 2>/dev/null && OPENCV=(--opencv) || echo "(no cv2 for $PY: rccar's boxes only)"
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
# run NAME DIR LIST DETECTOR-FLAGS...: rccar detect on the paths of LIST, from DIR.
run() {
  local name=$1 dir=$2 list=$3
  shift 3
  (cd "$dir" && awk '{print $1}' "$list" | xargs "$RCCAR" detect --no-annotate "$@") > "$TMP/$name.jsonl"
}
echo "== 1. shipped cascades, all 91 photos (IoU >= 0.5)"
CAS=$(realpath "${CASCADES:-$ROOT/config/cascades}")
for cls in ${CLASSES:-stop_sign traffic_light}; do
  cas="$CAS/$cls.xml"
  for res in full 320; do
    run "$res-$cls" "$SETS/$res" "$cls.info.dat" --cascade "$cas"
    bg=() rc=()
    if [ "$res" = 320 ]; then
      run "track-$cls" "$SETS/320" track.bg.txt --cascade "$cas"
      bg=(--bg "$SETS/320/track.bg.txt") rc=(--rccar "$TMP/track-$cls.jsonl")
    fi
    opencv=()
    [ ${#OPENCV[@]} -gt 0 ] && opencv=(--opencv "$cas")
    "$PY" "$HERE/score.py" --name "$cls cascade $res" --info "$SETS/$res/$cls.info.dat" "${bg[@]}" \
      --rccar "$TMP/$res-$cls.jsonl" "${rc[@]}" "${opencv[@]}"
  done
done
[ -n "${PART1_ONLY:-}" ] && exit 0
echo "== 2. stop sign, cascade vs colour + template, held-out photos (DeepPiCar's train folder)"
for res in full 320; do
  grep '^train/' "$SETS/$res/stop_sign.info.dat" > "$SETS/$res/heldout.info.dat"
  run "h-$res-cas" "$SETS/$res" heldout.info.dat --cascade "$CAS/stop_sign.xml"
  run "h-$res-ct" "$SETS/$res" heldout.info.dat --method colour-template $CONF
  bg=() rcas=() rct=()
  if [ "$res" = 320 ]; then
    run track-ct "$SETS/320" track.bg.txt --method colour-template $CONF
    bg=(--bg "$SETS/320/track.bg.txt") rcas=(--rccar "$TMP/track-stop_sign.jsonl") rct=(--rccar "$TMP/track-ct.jsonl")
  fi
  "$PY" "$HERE/score.py" --name "cascade $res" --info "$SETS/$res/heldout.info.dat" "${bg[@]}" --rccar "$TMP/h-$res-cas.jsonl" "${rcas[@]}"
  "$PY" "$HERE/score.py" --name "colour-template $res" --info "$SETS/$res/heldout.info.dat" "${bg[@]}" --rccar "$TMP/h-$res-ct.jsonl" "${rct[@]}"
done
