#!/usr/bin/env bash
# The teacher's key of the labs (docs/labs/*.md): reruns every experiment whose result a lab
# page quotes, with the page's own command (plus --no-local, so a student's config/local.toml
# cannot change it), and writes each figure with that command and the tolerance within which a
# rerun must agree, to OUT/key.json and OUT/key.md.
#
#   bash docs/labs/key/make.sh [OUT]      OUT defaults to docs/labs/key (the committed key)
#   LABS=01,11 bash docs/labs/key/make.sh /tmp/k    only those labs (to work on a page)
#   KEY_JOBS=1 bash docs/labs/key/make.sh          one lab at a time (default: two at a time)
#
# Needs: rccar built with the serial link (cargo build --release --features serial; lab 11
# talks to the firmware) and rccar-train (cargo build --release -p rccar-train) on PATH or in
# target/release; jq; the firmware toolchain and simavr (make -C firmware all sim); opencv-doc's
# stereo photos (lab 10). About 6 min of CPU; two labs at a time, about 3.5 min on 2 cores.
#
# Every run is seeded; the simulator runs use --no-timing. Figures are the same on every
# machine up to floating point, and the tolerances allow for that. Figures marked "timing" are
# wall-clock times of the machine that generated the key (a training's duration, a round trip
# to the emulator): they vary with the machine and its load, so a rerun only checks that they
# are produced. tests/labs.rs: `key_matches_committed` regenerates the key into a temporary
# folder and compares it with the committed one and with the figures quoted on the lab pages;
# `pages_quote_the_committed_key` compares the pages with the committed key.
#
# The pages mark what they quote (docs/labs/README.md, "For the teacher"): `<!-- key: NAME -->`
# right after a number names the figure NAME of the page's lab (`NAME (lab NN)` for another
# lab's), and `<!-- key-table: PREFIX -->` before a table makes each cell the figure
# PREFIX/ROW/COLUMN (row and column labels lower-cased, runs of other characters as `_`,
# numbers as numbers: `2.0` is `2`).
#
# No step waits a fixed time for another process: every wait is for a condition (a file, a
# line in a report), with a generous deadline.
set -euo pipefail
REPO=$(cd "$(dirname "${BASH_SOURCE[0]}")/../../.." && pwd)
SELF=$REPO/docs/labs/key/make.sh
OUT=$(mkdir -p "${1:-$REPO/docs/labs/key}" && cd "${1:-$REPO/docs/labs/key}" && pwd)
export PATH="$REPO/target/release:$PATH"
export RCCAR_CONFIG=$REPO/config/car.toml
command -v rccar >/dev/null || { echo "make.sh: rccar not found (cargo build --release --features serial)" >&2; exit 2; }
command -v rccar-train >/dev/null || { echo "make.sh: rccar-train not found (cargo build --release -p rccar-train)" >&2; exit 2; }
command -v jq >/dev/null || { echo "make.sh: needs jq (apt-get install jq)" >&2; exit 2; }
W=$(mktemp -d -t rccar-key-XXXXXX)
trap 'kill $(jobs -p) 2>/dev/null || true; rm -rf "$W"' EXIT
cd "$W"
FIGS=$W/figs.jsonl
: > "$FIGS"
want() { [ -z "${LABS:-}" ] || [[ ",$LABS," == *",$1,"* ]]; }

# fig LAB NAME VALUE TOL UNIT COMMAND — one figure of the key (a number)
fig() {
  [[ "$3" =~ ^-?[0-9]+(\.[0-9]+)?([eE][-+]?[0-9]+)?$ ]] || { echo "make.sh: lab $1 $2: not a number: '$3' ($6)" >&2; exit 1; }
  jq -cn --arg lab "$1" --arg name "$2" --argjson value "$3" --argjson tol "$4" --arg unit "$5" --arg cmd "$6" \
    '{lab: $lab, name: $name, value: $value, tol: $tol, unit: $unit, command: $cmd}' >> "$FIGS"
  printf '%-4s %-40s %14s  (±%s %s)\n' "$1" "$2" "$3" "$4" "$5"
}
# word LAB NAME WORD COMMAND — a figure that is a word (how a run ended); compared exactly,
# ignoring case and `_` (laps_done = LapsDone)
word() {
  [ -n "$3" ] || { echo "make.sh: lab $1 $2: empty ($4)" >&2; exit 1; }
  jq -cn --arg lab "$1" --arg name "$2" --arg value "$3" --arg cmd "$4" \
    '{lab: $lab, name: $name, value: $value, tol: 0, unit: "", command: $cmd}' >> "$FIGS"
  printf '%-4s %-40s %14s\n' "$1" "$2" "$3"
}
# timing LAB NAME VALUE TOL UNIT COMMAND — a wall-clock time of this machine (see the top)
timing() {
  fig "$@"
  jq -c 'if .name == $n and .lab == $l then .timing = true else . end' --arg n "$2" --arg l "$1" "$FIGS" > "$FIGS.t" && mv "$FIGS.t" "$FIGS"
}
# sweep LAB PREFIX DIR COMMAND — every run of DIR/sweep.csv as figures PREFIX/VALUE/QUANTITY
# (VALUE: the swept value, VALUE1/VALUE2 for a grid; QUANTITY: laps, lap_time_s, rms_m, max_m,
# departures, reversals_s, steer_diff_rms, lost_frames, end)
sweep() {
  local lab=$1 prefix=$2 csv=$3/sweep.csv cmd=$4 label col val
  awk -F, 'NR == 1 { for (i = 1; i <= NF; i++) { h[i] = $i; if ($i == "laps") nk = i - 1 }; next }
           { label = sprintf("%.6g", $1); for (i = 2; i <= nk; i++) label = label "/" sprintf("%.6g", $i)
             for (i = nk + 1; i <= NF; i++) print label "\t" h[i] "\t" $i }' "$csv" |
  while IFS=$'\t' read -r label col val; do
    case $col in
      laps) fig "$lab" "$prefix/$label/laps" "$val" 0 laps "$cmd" ;;
      lap_time_s) [ -z "$val" ] || fig "$lab" "$prefix/$label/lap_time_s" "$val" 0.1 s "$cmd" ;;
      xte_rms_m) fig "$lab" "$prefix/$label/rms_m" "$val" 0.001 m "$cmd" ;;
      xte_max_m) fig "$lab" "$prefix/$label/max_m" "$val" 0.002 m "$cmd" ;;
      departures) fig "$lab" "$prefix/$label/departures" "$val" 1 departures "$cmd" ;;
      reversals_per_s) fig "$lab" "$prefix/$label/reversals_s" "$val" 0.05 1/s "$cmd" ;;
      steer_diff_rms) fig "$lab" "$prefix/$label/steer_diff_rms" "$val" 0.005 1 "$cmd" ;;
      lost_frames) fig "$lab" "$prefix/$label/lost_frames" "$val" 5 frames "$cmd" ;;
      end) word "$lab" "$prefix/$label/end" "$val" "$cmd" ;;
    esac
  done
}
# num STRING PATTERN — the number after PATTERN (a regex) in STRING
num() { grep -oE "$2 *-?[0-9.]+" <<< "$1" | head -1 | grep -oE -- '-?[0-9.]+$'; }
# until_ok COMMAND... — retry COMMAND every 0.1 s until it succeeds (at most 60 s)
until_ok() { for _ in $(seq 600); do "$@" 2>/dev/null && return 0; sleep 0.1; done; echo "make.sh: timed out: $*" >&2; return 1; }
SIM="rccar sim --no-local --no-timing --set detect.enabled=false"
# chatter (labs 13, 16): RMS of the frame-to-frame change of the steering command of a telemetry.jsonl
CHAT='[.[].steer] as $s | [range(1; $s | length) | ($s[.] - $s[. - 1]) | . * .] | (add / length) | sqrt'

# Whole key, KEY_JOBS labs at a time (default 2; 1 = one after the other): each lab runs as its
# own `LABS=NN make.sh` in a folder of its own (the labs share no files), the longest first, and
# the figures are put together in lab order, so the key is the same as a serial run's. Lab 11
# runs alone, first: its emulator keeps the firmware's clock on the wall clock.
LAB_LIST="11 16 13 02 15 07 01 08 03 04 14 12 06 10 05 09"
if [ -z "${LABS:-}" ] && [ "${KEY_JOBS:-2}" -gt 1 ]; then
  # (each lab's wall and CPU seconds go to stderr: what the key costs, lab by lab)
  part() {
    local rc=0 t0=$SECONDS me=$BASHPID c0 c1   # (this shell's pid: $BASHPID inside $(...) is not)
    c0=$(awk '{print $14 + $15 + $16 + $17}' /proc/$me/stat 2>/dev/null || echo 0)
    LABS=$1 KEY_JOBS=1 bash "$SELF" "$W/p$1" > "$W/p$1.log" 2>&1 || rc=$?; echo $rc > "$W/p$1.rc"
    c1=$(awk '{print $14 + $15 + $16 + $17}' /proc/$me/stat 2>/dev/null || echo 0)
    echo "make.sh: lab $1 took $((SECONDS - t0)) s, $(( (c1 - c0) / $(getconf CLK_TCK) )) s of CPU" >&2
  }
  first=1
  for l in $LAB_LIST; do
    [ -n "$(sed -n "/^if want $l; then/p" "$SELF")" ] || continue
    if [ "$first" = 1 ]; then part "$l"; first=0; continue; fi
    while [ "$(jobs -rp | wc -l)" -ge "${KEY_JOBS:-2}" ]; do wait -n || true; done
    part "$l" &
  done
  wait
  failed=
  for l in $(tr ' ' '\n' <<< "$LAB_LIST" | sort); do
    [ -f "$W/p$l.rc" ] || continue
    cat "$W/p$l.log"
    [ "$(cat "$W/p$l.rc")" = 0 ] || failed="$failed $l"
  done
  [ -z "$failed" ] || { echo "make.sh: lab(s)$failed failed (their output above)" >&2; exit 1; }
  for l in $(tr ' ' '\n' <<< "$LAB_LIST" | sort); do
    [ -f "$W/p$l/key.json" ] && jq -c '.figures[]' "$W/p$l/key.json"
  done > "$FIGS"
  LABS=none   # every figure is in; the sections below are skipped
fi

# ---- lab 1: P steering ---------------------------------------------------------------------
if want 01; then
  C="rccar sim --laps 1 --no-timing --set detect.enabled=false --set steering.kd=0 --sweep steering.kp=0.5:8:6"
  $SIM --laps 1 --set steering.kd=0 --sweep steering.kp=0.5:8:6 -o l01 >/dev/null
  sweep 01 kp l01 "$C"
  C="rccar sim --laps 1 --no-timing --set detect.enabled=false (the shipped gains)"
  $SIM --laps 1 -o l01_shipped >/dev/null
  fig 01 shipped_rms_m "$(jq .xte_rms_m l01_shipped/summary.json)" 0.0005 m "$C"
  fig 01 shipped_lap_time_s "$(jq '.lap_times_s[0]' l01_shipped/summary.json)" 0.2 s "$C"
  C="rccar sim --laps 1 --no-timing --set detect.enabled=false --set steering.kd=0 --set steering.kp=5"
  $SIM --laps 1 --set steering.kd=0 --set steering.kp=5 -o l01_kp5 >/dev/null || [ $? -eq 1 ]
  fig 01 kp5_offset_max_m "$(jq -s 'map(.truth.offset_m) | max' l01_kp5/telemetry.jsonl)" 0.005 m "$C; the largest truth.offset_m (left curves)"
  fig 01 kp5_offset_min_m "$(jq -s 'map(.truth.offset_m) | min' l01_kp5/telemetry.jsonl)" 0.005 m "$C; the smallest truth.offset_m (the right curve)"
  fig 01 kp5_departures "$(jq .lane_departures l01_kp5/summary.json)" 1 departures "$C"
  fig 01 kp5_time_outside_s "$(jq .time_outside_s l01_kp5/summary.json)" 1 s "$C"
fi

# ---- lab 2: PD ---------------------------------------------------------------------------------
if want 02; then
  C="rccar sim --laps 0 --seconds 40 --no-timing --set detect.enabled=false --set vehicle.servo_delay_s=0.3 --set vehicle.servo_rate_dps=60 --set steering.kp=4 --sweep steering.kd=0:0.6:4"
  $SIM --laps 0 --seconds 40 --set vehicle.servo_delay_s=0.3 --set vehicle.servo_rate_dps=60 --set steering.kp=4 \
    --sweep steering.kd=0:0.6:4 -o l02_slow >/dev/null
  sweep 02 slow_servo l02_slow "$C"
  C="rccar sim --laps 1 --no-timing --set detect.enabled=false --sweep steering.kd=0:0.3:4 --sweep steering.derivative_tau=0:0.2:3"
  $SIM --laps 1 --sweep steering.kd=0:0.3:4 --sweep steering.derivative_tau=0:0.2:3 -o l02_grid >/dev/null
  sweep 02 grid l02_grid "$C"
fi

# ---- lab 3: PID ---------------------------------------------------------------------------------
if want 03; then
  C="rccar sim --laps 1 --no-timing --set detect.enabled=false --sweep steering.ki=0:0.6:4"
  $SIM --laps 1 --sweep steering.ki=0:0.6:4 -o l03_ki >/dev/null
  sweep 03 ki l03_ki "$C"
  C="rccar sim --laps 1 --no-timing --set detect.enabled=false --set steering.ki=0.6 --sweep steering.integral_limit=0.05:1:3"
  $SIM --laps 1 --set steering.ki=0.6 --sweep steering.integral_limit=0.05:1:3 -o l03_limit >/dev/null
  sweep 03 limit l03_limit "$C"
fi

# ---- lab 4: speed ---------------------------------------------------------------------------------
if want 04; then
  C="rccar sim --laps 1 --no-timing --set detect.enabled=false --sweep throttle.base=0.4:1:4"
  $SIM --laps 1 --sweep throttle.base=0.4:1:4 -o l04_base >/dev/null
  sweep 04 base l04_base "$C"
  C="rccar sim --laps 1 --no-timing --set detect.enabled=false --set vehicle.max_speed_mps=4 --sweep throttle.base=0.25:1:4"
  $SIM --laps 1 --set vehicle.max_speed_mps=4 --sweep throttle.base=0.25:1:4 -o l04_fast >/dev/null
  sweep 04 fast l04_fast "$C"
  C="rccar sim --laps 1 --no-timing --set detect.enabled=false --set vehicle.max_speed_mps=4 --set throttle.base=1"
  $SIM --laps 1 --set vehicle.max_speed_mps=4 --set throttle.base=1 -o l04_fastest >/dev/null
  fig 04 fastest_lap_time_s "$(jq '.lap_times_s[0]' l04_fastest/summary.json)" 0.1 s "$C"
  C="rccar sim --laps 1 --no-timing --set detect.enabled=false --set vehicle.max_speed_mps=4 --set camera.fps=10 --set vehicle.servo_delay_s=0.1 --sweep throttle.base=0.25:1:4"
  $SIM --laps 1 --set vehicle.max_speed_mps=4 --set camera.fps=10 --set vehicle.servo_delay_s=0.1 \
    --sweep throttle.base=0.25:1:4 -o l04_slow >/dev/null
  sweep 04 slow_camera l04_slow "$C"
fi

# ---- lab 5: step response -------------------------------------------------------------------------
if want 05; then
  for kp in 1 2.5; do
    C="rccar sim --laps 0 --seconds 10 --no-timing --set detect.enabled=false --start-offset 0.05 --set steering.kp=$kp"
    $SIM --laps 0 --seconds 10 --start-offset 0.05 --set steering.kp=$kp -o l05_$kp >/dev/null
    fig 05 "step/$kp/rise_time_10_90" "$(jq .step.rise_time_s l05_$kp/summary.json)" 0.1 s "$C"
    fig 05 "step/$kp/overshoot" "$(jq .step.overshoot_pct l05_$kp/summary.json)" 1 % "$C"
    fig 05 "step/$kp/settling_2_5_mm" "$(jq .step.settling_time_s l05_$kp/summary.json)" 0.2 s "$C"
    fig 05 "kp_${kp}_peak_steer" "$(jq -s 'map(select(.time_s < 0.5) | .steer) | max' l05_$kp/telemetry.jsonl)" 0.02 1 "$C; the largest steer of the first 0.5 s"
    fig 05 "kp_${kp}_half_offset_s" "$(jq -s 'map(select(.truth.offset_m <= 0.025)) | .[0].time_s' l05_$kp/telemetry.jsonl)" 0.1 s "$C; first time the true offset is half the start's"
  done
  fig 05 kp_1_overshoot_mm "$(jq '.step.overshoot_pct * .step.initial_offset_m * 10' l05_1/summary.json)" 0.3 mm \
    "rccar sim --laps 0 --seconds 10 --no-timing --set detect.enabled=false --start-offset 0.05 --set steering.kp=1"
  C="rccar sim --laps 0 --seconds 12 --no-timing --set detect.enabled=false --kick 5:0.05"
  $SIM --laps 0 --seconds 12 --kick 5:0.05 -o l05_kick >/dev/null
  fig 05 kick_rise_time_s "$(jq .step.rise_time_s l05_kick/summary.json)" 0.1 s "$C"
  fig 05 kick_overshoot_pct "$(jq .step.overshoot_pct l05_kick/summary.json)" 1 % "$C"
  fig 05 kick_settling_time_s "$(jq .step.settling_time_s l05_kick/summary.json)" 0.2 s "$C"
fi

# ---- lab 6: the camera model ------------------------------------------------------------------------
if want 06; then
  roi() { rccar config roi --no-local "$@"; }
  corners() { grep -oE -- '-?[0-9]+\.[0-9]+' <<< "$1" | sed -n "$2p"; }
  C="rccar config roi --near 0.4 --far 1.0 --half-width 0.25"
  R0=$(roi --near 0.4 --far 1.0 --half-width 0.25)
  R=$R0
  for i in 1 2 3 4 5 6 7 8; do fig 06 "roi_shipped_$i" "$(corners "$R" $i)" 0.01 px "$C; the i-th number of src"; done
  fig 06 px_per_m_across "$(num "$R" 'scale:')" 0.1 px/m "$C"
  fig 06 px_per_m_along "$(num "$R" 'across,')" 0.1 px/m "$C"
  C="rccar config roi --near 0.3 --far 0.8 --half-width 0.25"
  R=$(roi --near 0.3 --far 0.8 --half-width 0.25)
  for i in 1 2 3 4 5 6 7 8; do fig 06 "roi_near_$i" "$(corners "$R" $i)" 0.01 px "$C; the i-th number of src"; done
  C="rccar config roi --near 0.4 --far 1.0 --half-width 0.25 --set camera.tilt_deg=25"
  R25=$(roi --near 0.4 --far 1.0 --half-width 0.25 --set camera.tilt_deg=25)
  fig 06 roi_up_at_tilt25_px "$(awk -v a="$(corners "$R0" 2)" -v b="$(corners "$R25" 2)" 'BEGIN {print a - b}')" 0.5 px "$C; top edge, against the shipped ROI"
  C="rccar sim --laps 1 --no-timing --set detect.enabled=false --sweep lane.band=0.1:0.9:5"
  $SIM --laps 1 --sweep lane.band=0.1:0.9:5 -o l06_band >/dev/null
  sweep 06 band l06_band "$C"
fi

# ---- lab 7: vision under changing light -----------------------------------------------------------------
if want 07; then
  C="rccar sim --seconds 8 --laps 0 --set detect.enabled=false --set sim.light_variation=0.6 --record frames; rccar stages frames/frame_000075.png frames/frame_000225.png [--set lane.threshold_mode=fixed|otsu --set lane.opening=0]"
  rccar sim --no-local --seconds 8 --laps 0 --set detect.enabled=false --set sim.light_variation=0.6 --record l07f -o l07r >/dev/null
  rccar stages --no-local l07f/frame_000075.png l07f/frame_000225.png -o l07fixed --set lane.threshold_mode=fixed --set lane.opening=0 >/dev/null
  rccar stages --no-local l07f/frame_000075.png l07f/frame_000225.png -o l07otsu --set lane.threshold_mode=otsu --set lane.opening=0 >/dev/null
  rccar stages --no-local l07f/frame_000075.png l07f/frame_000225.png -o l07adaptive >/dev/null
  for m in fixed otsu; do
    fig 07 "${m}_level_bright" "$(sed -n 1p l07$m/stages.jsonl | jq .level)" 2 grey "$C"
    fig 07 "${m}_level_dark" "$(sed -n 2p l07$m/stages.jsonl | jq .level)" 2 grey "$C"
  done
  for m in fixed otsu adaptive; do
    word 07 "${m}_status_bright" "$(sed -n 1p l07$m/stages.jsonl | jq -r .lane.status)" "$C"
    word 07 "${m}_status_dark" "$(sed -n 2p l07$m/stages.jsonl | jq -r .lane.status)" "$C"
  done
  for m in fixed otsu adaptive; do
    o=0; [ $m = adaptive ] && o=3
    C="rccar sim --laps 1 --no-timing --set detect.enabled=false --set sim.light_variation=0.6 --set lane.threshold_mode=$m --set lane.opening=$o"
    $SIM --laps 1 --set sim.light_variation=0.6 --set lane.threshold_mode=$m --set lane.opening=$o -o l07$m-lap >/dev/null || [ $? -eq 1 ]
    fig 07 "drive_${m}_lost_frames" "$(jq .lane_lost_frames l07$m-lap/summary.json)" 10 frames "$C"
    fig 07 "drive_${m}_frames" "$(jq .frames l07$m-lap/summary.json)" 10 frames "$C"
    fig 07 "drive_${m}_seconds" "$(jq .seconds l07$m-lap/summary.json)" 0.5 s "$C"
    word 07 "drive_${m}_end" "$(jq -r .end l07$m-lap/summary.json)" "$C"
  done
  fig 07 drive_otsu_rms_m "$(jq .xte_rms_m l07otsu-lap/summary.json)" 0.0005 m "$C"
  fig 07 drive_adaptive_rms_m "$(jq .xte_rms_m l07adaptive-lap/summary.json)" 0.0005 m "$C"
  C="rccar sim --laps 1 --no-timing --set detect.enabled=false --set lane.threshold_mode=fixed --set lane.opening=0 --sweep sim.exposure=0.4:1.8:8"
  $SIM --laps 1 --set lane.threshold_mode=fixed --set lane.opening=0 --sweep sim.exposure=0.4:1.8:8 -o l07_exposure >/dev/null
  sweep 07 exposure l07_exposure "$C"
  C="rccar sim --laps 1 --no-timing --set detect.enabled=false --sweep sim.light_level=0:3:4 [--set lane.threshold_mode=fixed --set lane.opening=0]"
  $SIM --laps 1 --sweep sim.light_level=0:3:4 -o l07_light >/dev/null
  sweep 07 light l07_light "$C"
  $SIM --laps 1 --set lane.threshold_mode=fixed --set lane.opening=0 --sweep sim.light_level=0:3:4 -o l07_light_fixed >/dev/null
  sweep 07 light_fixed l07_light_fixed "$C"
  C="rccar stages \$RCCAR/tests/data/lane_sample/frame_029.png [--set lane.opening=0]"
  rccar stages --no-local "$REPO/tests/data/lane_sample/frame_029.png" -o l07open0 --set lane.opening=0 >/dev/null
  rccar stages --no-local "$REPO/tests/data/lane_sample/frame_029.png" -o l07open3 >/dev/null
  word 07 open0_status "$(jq -r .lane.status l07open0/stages.jsonl)" "$C"
  word 07 open3_status "$(jq -r .lane.status l07open3/stages.jsonl)" "$C"
  truth=$(jq -r 'select(.file == "frame_029.png") | .truth_center' "$REPO/tests/data/lane_sample/truth.jsonl")
  fig 07 open0_center_error_px "$(jq -r --argjson t "$truth" '.lane.lane_center - $t | fabs' l07open0/stages.jsonl)" 0.1 px "$C; |L_c - truth|"
fi

# ---- lab 8: detection -----------------------------------------------------------------------------------
if want 08; then
  T=$REPO/config/tracks/default.toml
  rccar-train gen --kind stop_sign --split positives --count 300 --seed 1 --track "$T" --out pos >/dev/null
  rccar-train gen --kind stop_sign --split negatives --count 100 --seed 2 --track "$T" --out neg >/dev/null
  rccar-train gen --kind stop_sign --split eval --count 40 --seed 3 --track "$T" --out eval >/dev/null
  C="rccar-train train --pos pos/info.dat (300, seed 1) --bg neg/bg.txt (100, seed 2) --num-stages 6 --num-neg 300; rccar-train evaluate --cascade model/cascade.xml --info eval/info.dat (40, seed 3)"
  t0=$(date +%s.%N)
  rccar-train train --pos pos/info.dat --bg neg/bg.txt --num-stages 6 --num-neg 300 --out model >/dev/null 2>&1
  timing 08 training_s "$(awk -v a="$t0" -v b="$(date +%s.%N)" 'BEGIN {printf "%.0f", b - a}')" 60 s "$C (wall-clock)"
  rccar-train evaluate --cascade model/cascade.xml --info eval/info.dat --out ev_mine >/dev/null
  for mn in 0 1 3 5 8; do
    fig 08 "mn/$mn/recall_40_signs" "$(jq ".points[] | select(.min_neighbors==$mn) | .recall" ev_mine/report.json)" 0.0001 1 "$C"
    fig 08 "mn/$mn/fp_per_frame_mine" "$(jq ".points[] | select(.min_neighbors==$mn) | .fp_per_frame" ev_mine/report.json)" 0.05 1/frame "$C"
  done
  C="rccar-train evaluate --cascade config/cascades/stop_sign.xml --info eval/info.dat"
  rccar-train evaluate --cascade "$REPO/config/cascades/stop_sign.xml" --info eval/info.dat --out ev_shipped >/dev/null
  fig 08 shipped_recall_mn3 "$(jq '.points[] | select(.min_neighbors==3) | .recall' ev_shipped/report.json)" 0.0001 1 "$C"
  fig 08 shipped_fp_mn3 "$(jq '.points[] | select(.min_neighbors==3) | .false_positives' ev_shipped/report.json)" 0 boxes "$C"
  for sf in 1.05 1.3; do
    C="rccar-train evaluate --cascade config/cascades/stop_sign.xml --info eval/info.dat --scale-factor $sf"
    rccar-train evaluate --cascade "$REPO/config/cascades/stop_sign.xml" --info eval/info.dat --scale-factor $sf --out ev_$sf >/dev/null
    fig 08 "sf${sf}_recall_mn3" "$(jq '.points[] | select(.min_neighbors==3) | .recall' ev_$sf/report.json)" 0.0001 1 "$C"
    fig 08 "sf${sf}_misses_mn3" "$(jq '.points[] | select(.min_neighbors==3) | .misses' ev_$sf/report.json)" 0 signs "$C"
    timing 08 "sf${sf}_ms_median" "$(jq .ms_median ev_$sf/report.json)" "$([ $sf = 1.3 ] && echo 3 || echo 20)" ms "$C (wall-clock, median per frame)"
  done
fi

# ---- lab 9: monocular ranging ------------------------------------------------------------------------------
if want 09; then
  C="rccar calibrate ranging --from-sim 10 --sim-tilt-error-deg 2 --sim-pairs-out pairs.csv --dry-run"
  rccar calibrate ranging --no-local --from-sim 10 --sim-tilt-error-deg 2 --sim-pairs-out pairs.csv --dry-run > l09.txt
  fig 09 fitted_tilt_deg "$(num "$(cat l09.txt)" 'fit: tilt')" 0.005 deg "$C"
  fig 09 fitted_v0_px "$(num "$(cat l09.txt)" 'v0')" 0.05 px "$C"
  fig 09 rms_row_error_px "$(num "$(cat l09.txt)" 'rms row error')" 0.02 px "$C"
  # the residuals: the largest |resid %| of the pairs nearer than 1.3 m, and the one at ~1.36 m
  fig 09 resid_max_pct_below_1_3_m "$(awk '$1 ~ /^[0-9.]+$/ && $2 < 1.3 {r = $5 < 0 ? -$5 : $5 + 0; if (r > m) m = r} END {print m + 0}' l09.txt)" 0.1 % "$C"
  fig 09 resid_near_1_3_m "$(awk '$1 ~ /^[0-9.]+$/ && $2 < 1.3 {d = $2} END {print d}' l09.txt)" 0.01 m "$C; the farthest pair nearer than 1.3 m"
  fig 09 resid_pct_at_1_36_m "$(awk '$1 ~ /^[0-9.]+$/ && $2 > 1.3 && $2 < 1.4 {print $5 + 0}' l09.txt)" 0.1 % "$C"
  fig 09 resid_far_pair_m "$(awk '$1 ~ /^[0-9.]+$/ && $2 > 1.3 && $2 < 1.4 {print $2 + 0}' l09.txt)" 0.01 m "$C; the pair between 1.3 and 1.4 m"
  # part 2: the pairs' rows in Eq. 5 with the configured camera (tilt 20 deg, h 0.2 m, a_y, v0)
  C="Eq. 5 on pairs.csv with the configured tilt, v0 = 119.5, a_y = 265.235 px, h = 0.2 m"
  while IFS=, read -r row d _; do
    case $row in 198.5|113.5|81.5|65.5|51.5) ;; *) continue ;; esac
    eq5=$(awk -v v="$row" 'BEGIN {pi = atan2(0, -1); a = 20 * pi / 180 + atan2(v - 119.5, 265.235); print 0.2 * cos(a) / sin(a)}')
    fig 09 "eq5/$row/true_m" "$d" 0.001 m "$C"
    fig 09 "eq5/$row/eq_5_at_20" "$eq5" 0.001 m "$C"
    fig 09 "eq5/$row/error" "$(awk -v e="$eq5" -v d="$d" 'BEGIN {print (e / d - 1) * 100}')" 0.2 % "$C"
  done < <(tail -n +2 pairs.csv)
  C="rccar calibrate ranging --from-sim 10 --sim-tilt-error-deg 2 --sim-tape-sigma-m 0.03 --sim-seed 2 --dry-run"
  O=$(rccar calibrate ranging --no-local --from-sim 10 --sim-tilt-error-deg 2 --sim-tape-sigma-m 0.03 --sim-seed 2 --dry-run)
  fig 09 tape3cm_tilt_deg "$(num "$O" 'fit: tilt')" 0.005 deg "$C"
  fig 09 tape3cm_rms_px "$(num "$O" 'rms row error')" 0.02 px "$C"
  fig 09 tape3cm_tilt_error_deg "$(awk -v t="$(num "$O" 'fit: tilt')" 'BEGIN {print 22 - t}')" 0.005 deg "$C; 22 deg (the truth) minus the fit"
  C="rccar calibrate ranging --from-sim 4 --sim-tilt-error-deg 2 --dry-run"
  O=$(rccar calibrate ranging --no-local --from-sim 4 --sim-tilt-error-deg 2 --dry-run)
  fig 09 pairs4_tilt_deg "$(num "$O" 'fit: tilt')" 0.005 deg "$C"
  fig 09 pairs4_rms_px "$(num "$O" 'rms row error')" 0.02 px "$C"
  C="rccar calibrate ranging pairs.csv --fit-ay --dry-run"
  O=$(rccar calibrate ranging --no-local pairs.csv --fit-ay --dry-run)
  fig 09 fit_ay_tilt_deg "$(num "$O" 'fit: tilt')" 0.005 deg "$C"
  fig 09 fit_ay_scale "$(num "$O" '\(scale')" 0.0005 1 "$C"
fi

# ---- lab 10: stereo ---------------------------------------------------------------------------------------
if want 10; then
  D=/usr/share/doc/opencv-doc/examples/data
  C="rccar calibrate stereo --board 9x6 --square 0.025 --left \$D/left[0-9]*.jpg --right \$D/right[0-9]*.jpg --corners-out corners.json"
  O=$(rccar calibrate stereo --board 9x6 --square 0.025 --left $D/left[0-9]*.jpg --right $D/right[0-9]*.jpg \
    --corners-out corners.json -o stereo.json)
  T=$(grep -oE 'T = \[[^]]*\]' <<< "$O" | grep -oE -- '-?[0-9.]+')
  for i in 1 2 3; do fig 10 "t_$i" "$(sed -n ${i}p <<< "$T")" 0.0002 m "$C; T = [x, y, z]"; done
  fig 10 baseline_m "$(jq '.stereo.baseline_m' stereo.json)" 0.0002 m "$C"
  fig 10 stereo_rms_px "$(jq '.stereo.rms_px' stereo.json)" 0.002 px "$C"
  fig 10 rectified_f_px "$(num "$O" 'rectified f')" 0.05 px "$C"
  fig 10 left_fx_px "$(jq '.stereo.left.intrinsics.fx' stereo.json)" 0.05 px "$C"
  SPACING=$(jq --arg k "$D/left01.jpg" '.[$k] as $c
      | [range(0; 6) as $r | range(0; 8) as $i | [$c[$r*9+$i], $c[$r*9+$i+1]]]
      + [range(0; 5) as $r | range(0; 9) as $i | [$c[$r*9+$i], $c[($r+1)*9+$i]]]
      | map(((.[1][0] - .[0][0]) | . * .) + ((.[1][1] - .[0][1]) | . * .) | sqrt) | sort | .[length / 2 | floor]' corners.json)
  fig 10 left01_corner_spacing_px "$SPACING" 0.05 px "$C; the median distance between neighbouring corners in left01"
  fig 10 left01_mono_depth_m "$(jq -n --argjson f "$(jq '.stereo.left.intrinsics.fx' stereo.json)" --argjson s "$SPACING" '$f * 0.025 / $s')" \
    0.002 m "$C; the left camera's fx * 0.025 m / the corner spacing"
  C="rccar stereo \$D/left01.jpg \$D/right01.jpg --box 240,80,280,190 --set stereo.calibration=stereo_calib.json"
  rccar stereo --no-local $D/left01.jpg $D/right01.jpg --box 240,80,280,190 --set stereo.calibration="$PWD/stereo.json" > l10.json
  fig 10 disparity_px "$(jq '.disparity_px' l10.json)" 0.2 px "$C"
  fig 10 ncc "$(jq '.ncc' l10.json)" 0.005 1 "$C"
  fig 10 board_depth_bfd_m "$(jq '.depth_m.bfd' l10.json)" 0.002 m "$C"
  fig 10 board_depth_exact_m "$(jq '.depth_m.exact' l10.json)" 0.002 m "$C"
  fig 10 board_depth_eq16_m "$(jq '.depth_m.eq16' l10.json)" 0.002 m "$C"
  fig 10 eq16_long_pct "$(jq '(.depth_m.eq16 / .depth_m.bfd - 1) * 100' l10.json)" 0.2 % "$C"
  C="$C --set stereo.min_ncc=0.9"
  rccar stereo --no-local $D/left01.jpg $D/right01.jpg --box 240,80,280,190 --set stereo.calibration="$PWD/stereo.json" \
    --set stereo.min_ncc=0.9 > l10b.json
  fig 10 best_ncc "$(jq -r '.no_range' l10b.json | grep -oE 'best match [0-9.]+' | grep -oE '[0-9.]+$')" 0.005 1 "$C"
  # part 3: the simulator, one camera and a pair, up to the stop sign (x = 4.5 m on the track;
  # the lens vehicle.camera_x_m = 0.24 m ahead of the rear axle)
  setting() { rccar config check --no-local 2>/dev/null | awk -v k="$1" '$1 == k {print $3; exit}'; }
  CAMX=$(setting camera_x_m)
  STILL=$(setting standstill_mps)
  for m in mono stereo; do
    if [ $m = mono ]; then
      C="rccar sim --seconds 10 --no-timing"
      rccar sim --no-local --seconds 10 --no-timing -o sim_$m >/dev/null
    else
      C="rccar sim --seconds 10 --no-timing --set ranging.method=stereo --record L --record-right R"
      rccar sim --no-local --seconds 10 --no-timing --set ranging.method=stereo --record L --record-right R -o sim_$m > sim_$m.txt
    fi
    S=$(jq -c --argjson cx "$CAMX" 'select(.transition.to == "stop_sign")
          | {t: .time_s, d: (.objects[] | select(.class == "stop_sign") | .distance_m), truth: (4.5 - .truth.pose[0] - $cx)}' \
          sim_$m/telemetry.jsonl | head -1)
    fig 10 "sim_${m}_decides_s" "$(jq .t <<< "$S")" 0.07 s "$C"
    fig 10 "sim_${m}_range_m" "$(jq .d <<< "$S")" 0.005 m "$C"
    fig 10 "sim_${m}_true_m" "$(jq .truth <<< "$S")" 0.005 m "$C; 4.5 - x - camera_x_m"
    fig 10 "sim_${m}_error_pct" "$(jq '(.d / .truth - 1) * 100' <<< "$S")" 0.3 % "$C"
    E=$(jq -s --argjson cx "$CAMX" '[.[] | (4.5 - .truth.pose[0] - $cx) as $d | select($d >= 0.3 and $d <= 1.5)
          | .objects[]? | select(.class == "stop_sign" and .measured_m != null) | ((.measured_m / $d - 1) | fabs * 100)] | sort' \
          sim_$m/telemetry.jsonl)
    fig 10 "sim_${m}_single_median_pct" "$(jq '.[length / 2 | floor]' <<< "$E")" 0.1 % "$C; single-box ranges 0.3-1.5 m"
    fig 10 "sim_${m}_single_max_pct" "$(jq '.[-1]' <<< "$E")" 0.3 % "$C; single-box ranges 0.3-1.5 m"
    fig 10 "sim_${m}_rest_m" "$(jq -s --argjson cx "$CAMX" --argjson still "$STILL" '
          [foreach .[] as $r ({moved: false}; .moved = (.moved or $r.truth.speed_mps > 0.2);
             if .moved and ($r.truth.speed_mps | fabs) < $still then 4.5 - $r.truth.pose[0] - $cx else empty end)] | .[0]' \
          sim_$m/telemetry.jsonl)" 0.005 m "$C; true distance when the car first stands still"
  done
  fig 10 sim_stereo_boxes_ranged "$(num "$(cat sim_stereo.txt)" 'ranged by stereo')" 3 boxes "$C"
  fig 10 sim_stereo_boxes_unmatched "$(num "$(cat sim_stereo.txt)" 'without a match')" 0 boxes "$C"
fi

# ---- lab 11: the serial link, with the real firmware in the emulator --------------------------------------
if want 11; then
  if grep -q "built without the serial link" <<< "$(rccar link --port /nonexistent 2>&1 || true)"; then
    echo "make.sh: lab 11 needs rccar with the serial link: cargo build --release --features serial" >&2; exit 2
  fi
  make -s -C "$REPO/firmware" all sim >/dev/null
  EMU_CMD=("$REPO/firmware/build/rccar_sim" "$REPO/firmware/build/rccar_fw.elf" --no-stdin)
  "${EMU_CMD[@]}" --link "$W/tty" --sniff > pins.log 2>/dev/null &
  EMU=$!
  until_ok grep -q '^PULSE esc' pins.log            # the firmware runs: its first ESC pulse
  C="rccar link --port tty --latency 50"
  O=$(rccar link --port "$W/tty" --latency 50)
  timing 11 rtt_median_ms "$(num "$O" 'median')" 2 ms "$C (wall-clock)"
  timing 11 rtt_max_ms "$(num "$O" 'max')" 20 ms "$C (wall-clock)"
  # part 2: a PING with a bad CRC and a header with length 33, while rccar link shows telemetry
  C="rccar link --port tty (live) + printf a bad PING and a too-long header into the pty"
  rccar link --port "$W/tty" --seconds 60 > live.txt 2>/dev/null &
  LINK=$!
  until_ok grep -q '^#' live.txt
  printf '\xa5\x00\x05\x07\x00\x00' > "$W/tty"
  printf '\xa5\x21\x05\x07' > "$W/tty"
  until_ok grep -q 'framing [1-9]' live.txt
  kill -INT $LINK; wait $LINK || true
  L=$(grep '^#' live.txt | tail -1)
  for k in crc framing overrun lost failsafe; do fig 11 "corrupt_$k" "$(num "$L" "$k")" 0 frames "$C"; done
  # part 3: rccar drive through the firmware, killed with SIGKILL after 90 DRIVE frames
  C="rccar drive --camera sim --port tty --pwm-log pins.log --arm --set detect.enabled=false; kill -9 after 90 DRIVEs"
  rccar drive --no-local --camera sim --port "$W/tty" --pwm-log pins.log --arm --set detect.enabled=false -o crash > crash.txt &
  DRIVE=$!
  until_ok awk '$1 == "RX" && $2 == 2 {n++} END {exit n < 90}' pins.log
  { kill -9 $DRIVE; wait $DRIVE; } 2>/dev/null || true
  until_ok awk '$1 == "RX" && $2 == 2 {t = $4} $1 == "PULSE" && $2 == "esc" && $3 < 1510 && t {f = 1} END {exit !f}' pins.log
  fig 11 esc_driving_us "$(awk '$1 == "PULSE" && $2 == "esc" && $3 > 1600 {print $3; exit}' pins.log)" 1 us "$C; the first ESC width above 1600 µs"
  fig 11 failsafe_ms "$(awk '$1 == "RX" && $2 == 2 {t = $4} $1 == "PULSE" && $2 == "esc" && $3 < 1510 && t {printf "%.1f", ($4 - t) / 1000; exit}' pins.log)" 21 ms "$C; from the last DRIVE to the ESC's neutral pulse, firmware clock: failsafe_ms 250 + up to one 20 ms PWM period"
  fig 11 drives_per_s "$(awk '$1 == "RX" && $2 == 2 {n++; if (!a) a = $4; b = $4} END {printf "%.1f", (n - 1) / (b - a) * 1e6}' pins.log)" 2 1/s "$C; DRIVE frames per second of the firmware's clock"
  L=$(rccar link --port "$W/tty" --seconds 1 | grep '^#' | tail -1)
  word 11 state_after_kill "$(awk '{print $2}' <<< "$L")" "rccar link --port tty --seconds 1 (after the kill)"
  fig 11 failsafe_trips_after_kill "$(num "$L" 'failsafe')" 0 trips "rccar link --port tty --seconds 1 (after the kill)"
  kill $EMU; wait $EMU 2>/dev/null || true
  # part 4: a fresh emulator, drive 4 s (the page's --laps 1 takes two minutes of wall clock)
  C="rccar drive --camera sim --port tty2 --pwm-log pins2.log --arm --laps 0 --seconds 4 --set detect.enabled=false"
  "${EMU_CMD[@]}" --link "$W/tty2" > pins2.log 2>/dev/null &
  EMU=$!
  until_ok grep -q '^PULSE esc' pins2.log
  O=$(rccar drive --no-local --camera sim --port "$W/tty2" --pwm-log pins2.log --arm --laps 0 --seconds 4 --set detect.enabled=false -o lap)
  timing 11 drive_latency_median_ms "$(num "$(grep 'capture->command' <<< "$O")" 'median')" 5 ms "$C (wall-clock)"
  timing 11 drive_latency_max_ms "$(num "$(grep 'capture->command' <<< "$O")" 'max')" 20 ms "$C (wall-clock)"
  kill $EMU; wait $EMU 2>/dev/null || true
fi

# ---- lab 12: behaviours ---------------------------------------------------------------------------------------
if want 12; then
  TR=$REPO/config/tracks/scenarios.toml
  C="rccar sim --track config/tracks/scenarios.toml --laps 1 --truth-boxes --no-timing --set behaviour.pass_enabled=true"
  rccar sim --no-local --track "$TR" --laps 1 --truth-boxes --no-timing --set behaviour.pass_enabled=true -o l12 >/dev/null
  fig 12 lap_s "$(jq '.lap_times_s[0]' l12/summary.json)" 0.2 s "$C"
  fig 12 lap_departures "$(jq .lane_departures l12/summary.json)" 0 departures "$C"
  while IFS=$'\t' read -r k t d; do
    fig 12 "lap/$k/t_s" "$t" 0.07 s "$C"
    [ -z "$d" ] || fig 12 "lap/$k/reason" "$d" 0.02 "m or s" "$C; the number in the transition's reason"
  done < <(jq -r 'select(.transition) | [(.transition.from + "_" + .transition.to), .time_s,
      (.transition.reason | (capture("(?<d>[0-9]+(\\.[0-9]+)?)").d // ""))] | @tsv' l12/telemetry.jsonl)
  C="rccar sim --track config/tracks/scenarios.toml --laps 0 --seconds 16 --truth-boxes --no-timing --set behaviour.stop_trigger_m=0.6"
  rccar sim --no-local --track "$TR" --laps 0 --seconds 16 --truth-boxes --no-timing --set behaviour.stop_trigger_m=0.6 -o l12late >/dev/null
  S=$(jq -c 'select(.transition.to == "stop_sign") | [.time_s, (.transition.reason | capture("(?<d>[0-9.]+) m").d | tonumber)]' l12late/telemetry.jsonl | head -1)
  fig 12 late_stop_begins_s "$(jq '.[0]' <<< "$S")" 0.07 s "$C"
  fig 12 late_stop_distance_m "$(jq '.[1]' <<< "$S")" 0.02 m "$C"
  fig 12 late_stop_resume_s "$(jq -c 'select(.transition.from == "stop_sign") | .time_s' l12late/telemetry.jsonl | head -1)" 0.07 s "$C"
fi

# ---- lab 13: pure pursuit against the PID ----------------------------------------------------------------------
# chatter: RMS of the frame-to-frame change of the steering command (steer units per frame),
# the same measure as sweep.csv's steer_diff_rms
if want 13; then
  for m in pid pure_pursuit; do
    C="rccar sim --laps 3 --no-timing --set steering.method=$m"
    rccar sim --no-local --laps 3 --no-timing --set steering.method=$m -o l13_$m >/dev/null
    fig 13 "cmp/$m/laps" "$(jq .laps l13_$m/summary.json)" 0 laps "$C"
    fig 13 "cmp/$m/departures" "$(jq .lane_departures l13_$m/summary.json)" 0 departures "$C"
    fig 13 "cmp/$m/rms_m" "$(jq .xte_rms_m l13_$m/summary.json)" 0.0005 m "$C"
    fig 13 "cmp/$m/max_m" "$(jq .xte_max_m l13_$m/summary.json)" 0.002 m "$C"
    fig 13 "cmp/$m/chatter" "$(jq -s "$CHAT" l13_$m/telemetry.jsonl)" 0.001 "steer/frame" "$C; RMS of the frame-to-frame steer change"
    fig 13 "cmp/$m/lap_time_s" "$(jq '.lap_times_s[1]' l13_$m/summary.json)" 0.2 s "$C; the second lap"
  done
  C="rccar sim --laps 1 --no-timing --set detect.enabled=false --set steering.method=pure_pursuit --sweep steering.lookahead_m=0.75:1.15:5"
  $SIM --laps 1 --set steering.method=pure_pursuit --sweep steering.lookahead_m=0.75:1.15:5 -o l13_ld >/dev/null || [ $? -eq 1 ]
  sweep 13 ld l13_ld "$C"
fi

# ---- lab 14: routes ------------------------------------------------------------------------
if want 14; then
  ROUTE=straight,left,left,left,straight,right
  C="rccar sim --track town --laps 3 --route $ROUTE --no-timing"
  rccar sim --no-local --track "$REPO/config/tracks/town.toml" --laps 3 --route $ROUTE --no-timing -o l14 >/dev/null
  fig 14 "tour/laps" "$(jq .laps l14/summary.json)" 0 laps "$C"
  fig 14 "tour/departures" "$(jq .lane_departures l14/summary.json)" 0 departures "$C"
  fig 14 "tour/forks" "$(jq '[.junctions[] | select(.kind == "fork")] | length' l14/summary.json)" 0 forks "$C; fork passages driven"
  fig 14 "tour/crossings" "$(jq '[.junctions[] | select(.kind == "crossing")] | length' l14/summary.json)" 0 crossings "$C; the crossing, crossed"
  fig 14 "tour/rms_m" "$(jq .xte_rms_m l14/summary.json)" 0.0005 m "$C"
fi

# ---- lab 15: data balance ----------------------------------------------------------------------
if want 15; then
  C="rccar sim --laps 1 --no-timing --set detect.enabled=false --record F -o R; rccar data ls F --telemetry R/telemetry.jsonl --json"
  $SIM --laps 1 --record l15_frames -o l15_run >/dev/null
  rccar data ls l15_frames --telemetry l15_run/telemetry.jsonl --json > l15_ls.json
  rm -rf l15_frames   # about 450 MB of PNG
  share() { jq "100 * $1 / .stats.frames" l15_ls.json; }
  fig 15 "lap/frames" "$(jq .stats.frames l15_ls.json)" 5 frames "$C"
  fig 15 "lap/left_pct" "$(share '.stats.steer_left_straight_right[0]')" 0.5 % "$C; steer < -0.05"
  fig 15 "lap/straight_pct" "$(share '.stats.steer_left_straight_right[1]')" 0.5 % "$C; -0.05 <= steer < 0.05"
  fig 15 "lap/right_pct" "$(share '.stats.steer_left_straight_right[2]')" 0.5 % "$C; steer >= 0.05"
  fig 15 "lap/turning_left_pct" "$(jq '.stats.steer_left_straight_right as $s | 100 * $s[0] / ($s[0] + $s[2])' l15_ls.json)" 0.5 % "$C; of the turning frames"
fi

# ---- lab 16: the learned pilot against the classical one ----------------------------------------------------
if want 16; then
  for m in pid learned; do
    C="rccar sim --laps 1 --no-timing --set detect.enabled=false --set steering.method=$m"
    $SIM --laps 1 --set steering.method=$m -o l16_$m >/dev/null
    fig 16 "cmp/$m/laps" "$(jq .laps l16_$m/summary.json)" 0 laps "$C"
    fig 16 "cmp/$m/departures" "$(jq .lane_departures l16_$m/summary.json)" 0 departures "$C"
    fig 16 "cmp/$m/rms_m" "$(jq .xte_rms_m l16_$m/summary.json)" 0.0005 m "$C"
    fig 16 "cmp/$m/max_m" "$(jq .xte_max_m l16_$m/summary.json)" 0.002 m "$C"
    fig 16 "cmp/$m/chatter" "$(jq -s "$CHAT" l16_$m/telemetry.jsonl)" 0.001 "steer/frame" "$C; RMS of the frame-to-frame steer change"
    fig 16 "cmp/$m/lap_time_s" "$(jq '.lap_times_s[0]' l16_$m/summary.json)" 0.2 s "$C"
  done
  for m in pid learned; do
    C="rccar sim --laps 1 --no-timing --set detect.enabled=false --set lane.threshold_mode=adaptive --set steering.method=$m --sweep sim.light_level=0:3:4"
    $SIM --laps 1 --set lane.threshold_mode=adaptive --set steering.method=$m --sweep sim.light_level=0:3:4 \
      -o l16_light_$m >/dev/null || [ $? -eq 1 ]
    # sweep.csv: light level, laps, lap time, RMS, max, departures, ...
    while IFS=, read -r level laps _ rms _ dep _; do
      level=$(printf '%.0f' "$level")
      fig 16 "light/$level/${m}_laps" "$laps" 0 laps "$C"
      fig 16 "light/$level/${m}_rms_m" "$rms" 0.001 m "$C"
      fig 16 "light/$level/${m}_departures" "$dep" 0 departures "$C"
    done < <(tail -n +2 l16_light_$m/sweep.csv)
  done
  # §3: one noisy lap in each failing light, cut, trained on (one thread: the same weights on
  # every machine), the sweep again with the new weights
  for l in 2 3; do
    $SIM --laps 1 --set lane.threshold_mode=adaptive --set sim.light_level=$l --set sim.steer_noise=0.1 \
      --record l16_frames$l -o l16_noisy$l >/dev/null
    rccar data cut l16_frames$l --telemetry l16_noisy$l/telemetry.jsonl --drop ..30 -o l16_rec$l >/dev/null
    rm -rf l16_frames$l   # about 450 MB of PNG
  done
  C="rccar sim --laps 1 --no-timing --set detect.enabled=false --set lane.threshold_mode=adaptive --set sim.light_level=L --set sim.steer_noise=0.1 --record F (L = 2, 3); rccar data cut --drop ..30; rccar-train pilot --recording rec2 --recording rec3 --epochs 20 --patience 5 --threads 1"
  rccar-train pilot --recording l16_rec2 --recording l16_rec3 --epochs 20 --patience 5 --threads 1 \
    --out l16_light.safetensors >/dev/null 2>&1
  fig 16 retrained_val_rmse "$(awk '/^learned pilot/ {print $(NF-1)}' l16_light.report.txt)" 0.002 1 "$C; light.report.txt, held-out RMSE"
  fig 16 retrained_mean_rmse "$(awk '/^training mean/ {print $(NF-1)}' l16_light.report.txt)" 0.002 1 "$C; light.report.txt, the training mean's RMSE"
  C="$C; rccar sim --laps 1 --no-timing --set detect.enabled=false --set lane.threshold_mode=adaptive --set steering.method=learned --set steering.model=light.safetensors --sweep sim.light_level=0:3:4"
  $SIM --laps 1 --set lane.threshold_mode=adaptive --set steering.method=learned --set steering.model="$PWD/l16_light.safetensors" \
    --sweep sim.light_level=0:3:4 -o l16_retrained >/dev/null || [ $? -eq 1 ]
  sweep 16 retrained l16_retrained "$C"
fi

# ---- write the key ------------------------------------------------------------------------------------------------
# one figure per line, so that a regenerated key diffs figure by figure
{
  echo '{"generated_by": "bash docs/labs/key/make.sh", "figures": ['
  jq -c . "$FIGS" | sed '$!s/$/,/'
  echo ']}'
} > "$OUT/key.json"
jq -e '.figures | length > 0' "$OUT/key.json" >/dev/null
{
  echo "# The labs' key (generated by \`bash docs/labs/key/make.sh\`; do not edit)"
  echo
  echo "Every figure a lab page quotes, with the command that produced it and the tolerance within"
  echo "which a rerun must agree (\`cargo test --release --features serial --test car labs::key_matches_committed\`"
  echo "regenerates the key and compares; \`labs::pages_quote_the_committed_key\` checks the pages against"
  echo "this table). Figures marked *timing* are wall-clock times of the machine that made the key: a"
  echo "rerun only checks that they are produced."
  echo
  echo "| lab | figure | value | tolerance | command |"
  echo "|---|---|---|---|---|"
  jq -r '.figures[] | "| \(.lab) | \(.name) | \(.value) \(.unit)\(if .timing then " *timing*" else "" end) | ±\(.tol) | `\(.command)` |"' "$OUT/key.json"
} > "$OUT/key.md"
echo "wrote $OUT/key.json and $OUT/key.md ($(jq '.figures | length' "$OUT/key.json") figures)"
