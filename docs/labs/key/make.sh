#!/usr/bin/env bash
# The teacher's key of the labs (docs/labs/*.md): reruns a short version of each lab's
# experiment and writes the expected figures, each with the command that produced it and the
# tolerance within which a rerun must agree, to OUT/key.json and OUT/key.md.
#
#   bash docs/labs/key/make.sh [OUT]      OUT defaults to docs/labs/key (the committed key)
#
# Needs: rccar and rccar-train on PATH, or built in target/release (cargo build --release &&
# cargo build --release -p rccar-train); jq; the firmware toolchain and simavr for lab 11
# (make -C firmware all sim). Every run is seeded and uses --no-local and --no-timing, so the
# figures are the same on every machine up to floating point; the tolerances allow for that
# and, for lab 11, for the emulator's wall-clock pacing. tests/labs.rs (key_matches_committed)
# regenerates the key into a temporary folder and compares it with the committed one.
set -euo pipefail
REPO=$(cd "$(dirname "${BASH_SOURCE[0]}")/../../.." && pwd)
OUT=$(mkdir -p "${1:-$REPO/docs/labs/key}" && cd "${1:-$REPO/docs/labs/key}" && pwd)
export PATH="$REPO/target/release:$PATH"
export RCCAR_CONFIG=$REPO/config/car.toml
command -v rccar >/dev/null || { echo "make.sh: rccar not found (cargo build --release)" >&2; exit 2; }
command -v rccar-train >/dev/null || { echo "make.sh: rccar-train not found (cargo build --release -p rccar-train)" >&2; exit 2; }
command -v jq >/dev/null || { echo "make.sh: needs jq (apt-get install jq)" >&2; exit 2; }
W=$(mktemp -d -t rccar-key-XXXXXX)
trap 'kill $(jobs -p) 2>/dev/null || true; rm -rf "$W"' EXIT
cd "$W"
FIGS=$W/figs.jsonl
: > "$FIGS"
# fig LAB NAME VALUE TOL UNIT COMMAND  — one figure of the key
fig() {
  jq -cn --arg lab "$1" --arg name "$2" --argjson value "$3" --argjson tol "$4" --arg unit "$5" --arg cmd "$6" \
    '{lab: $lab, name: $name, value: $value, tol: $tol, unit: $unit, command: $cmd}' >> "$FIGS"
  printf '%-4s %-34s %12s  (±%s %s)\n' "$1" "$2" "$3" "$4" "$5"
}
# csv_at FILE VALUE COLUMN — the COLUMN of the sweep.csv row whose value is VALUE
csv_at() { awk -F, -v v="$2" -v c="$3" 'NR==1 {for (i=1;i<=NF;i++) h[$i]=i; next} ($1+0)==(v+0) {print $h[c]}' "$1"; }
SIM="rccar sim --no-local --no-timing --set detect.enabled=false"

# ---- lab 1: P steering, Kp sweep (kd = 0), 40 s: the first two curves -------------------
C="$SIM --laps 0 --seconds 40 --set steering.kd=0 --sweep steering.kp=0.5:3.5:3"
$C -o l01 >/dev/null
for kp in 0.5 2 3.5; do
  fig 01 "xte_rms_kp_$kp" "$(csv_at l01/sweep.csv $kp xte_rms_m)" 0.001 m "$C"
done
fig 01 "lost_frames_kp_0.5" "$(csv_at l01/sweep.csv 0.5 lost_frames)" 5 frames "$C"

# ---- lab 2: derivative chatter with and without the low-pass, 30 s (the first curve) -----
for tau in 0 0.2; do
  C="$SIM --laps 0 --seconds 30 --set steering.kd=0.1 --set steering.derivative_tau=$tau"
  $C -o l02_$tau >/dev/null
  fig 02 "reversals_per_s_kd0.1_tau$tau" "$(jq '.steer_reversals_per_s' l02_$tau/summary.json)" 0.05 1/s "$C"
  fig 02 "xte_rms_kd0.1_tau$tau" "$(jq '.xte_rms_m' l02_$tau/summary.json)" 0.001 m "$C"
done

# ---- lab 5: step response from a 5 cm start offset ---------------------------------------
C="$SIM --laps 0 --seconds 10 --start-offset 0.05"
$C -o l05 >/dev/null
fig 05 offset_rise_time_s "$(jq '.step.rise_time_s' l05/summary.json)" 0.1 s "$C"
fig 05 offset_overshoot_pct "$(jq '.step.overshoot_pct' l05/summary.json)" 1 % "$C"
fig 05 offset_settling_time_s "$(jq '.step.settling_time_s' l05/summary.json)" 0.2 s "$C"

# ---- lab 6: camera model ------------------------------------------------------------------
C="rccar config roi --no-local --near 0.3 --far 0.8 --half-width 0.25"
fig 06 roi_near03_bottom_left_x "$($C | grep -o '\[-\?[0-9.]*, [0-9.]*\]\]' | grep -o '^\[-\?[0-9.]*' | tr -d '[')" 0.01 px "$C"
C="$SIM --laps 0 --seconds 40 --sweep lane.band=0.3:0.7:2"
$C -o l06 >/dev/null
fig 06 band_0.3_lost_frames "$(csv_at l06/sweep.csv 0.3 lost_frames)" 5 frames "$C"
fig 06 band_0.7_lost_frames "$(csv_at l06/sweep.csv 0.7 lost_frames)" 5 frames "$C"
fig 06 band_0.3_xte_rms "$(csv_at l06/sweep.csv 0.3 xte_rms_m)" 0.001 m "$C"

# ---- lab 7: vision under changing light ---------------------------------------------------
C="$SIM --laps 0 --seconds 8 --set sim.light_variation=0.6 --record frames; rccar stages --no-local frames/frame_000225.png --set lane.threshold_mode=otsu"
$SIM --laps 0 --seconds 8 --set sim.light_variation=0.6 --record l07f -o l07 >/dev/null
rccar stages --no-local l07f/frame_000225.png --set lane.threshold_mode=otsu -o l07s >/dev/null
fig 07 otsu_level_dark_frame "$(jq '.level' l07s/stages.jsonl)" 2 grey "$C"
for m in fixed otsu; do
  C="$SIM --laps 0 --seconds 30 --set sim.light_variation=0.6 --set lane.threshold_mode=$m"
  $C -o l07$m >/dev/null || true
  fig 07 "lost_frames_${m}_30s" "$(jq '.lane_lost_frames' l07$m/summary.json)" 10 frames "$C"
done

# ---- lab 8: detection -----------------------------------------------------------------------
T=$REPO/config/tracks/default.toml
rccar-train gen --kind stop_sign --split positives --count 60 --seed 1 --track "$T" --out pos >/dev/null
rccar-train gen --kind stop_sign --split negatives --count 20 --seed 2 --track "$T" --out neg >/dev/null
rccar-train gen --kind stop_sign --split eval --count 12 --seed 3 --track "$T" --out eval >/dev/null
C="rccar-train evaluate --cascade config/cascades/stop_sign.xml --info eval/info.dat (12 frames of gen --split eval --seed 3)"
rccar-train evaluate --cascade "$REPO/config/cascades/stop_sign.xml" --info eval/info.dat --out ev_shipped >/dev/null
fig 08 shipped_recall_mn3 "$(jq '.points[] | select(.min_neighbors==3) | .recall' ev_shipped/report.json)" 0.0001 1 "$C"
fig 08 shipped_fp_per_frame_mn3 "$(jq '.points[] | select(.min_neighbors==3) | .fp_per_frame' ev_shipped/report.json)" 0.0001 1/frame "$C"
rccar-train evaluate --cascade "$REPO/config/cascades/stop_sign.xml" --info eval/info.dat --scale-factor 1.3 --out ev_13 >/dev/null
fig 08 shipped_recall_mn3_sf1.3 "$(jq '.points[] | select(.min_neighbors==3) | .recall' ev_13/report.json)" 0.0001 1 "$C --scale-factor 1.3"
C="rccar-train train --pos pos/info.dat (60, seed 1) --bg neg/bg.txt (20, seed 2) --num-stages 2 --num-neg 60 --threads 1; evaluate as above"
rccar-train train --pos pos/info.dat --bg neg/bg.txt --num-stages 2 --num-neg 60 --threads 1 --out model >/dev/null 2>&1
rccar-train evaluate --cascade model/cascade.xml --info eval/info.dat --out ev_mine >/dev/null
fig 08 trained_2stage_recall_mn3 "$(jq '.points[] | select(.min_neighbors==3) | .recall' ev_mine/report.json)" 0.0001 1 "$C"
fig 08 trained_2stage_fp_per_frame_mn0 "$(jq '.points[] | select(.min_neighbors==0) | .fp_per_frame' ev_mine/report.json)" 0.5 1/frame "$C"

# ---- lab 9: monocular ranging ----------------------------------------------------------------
C="rccar calibrate ranging --no-local --from-sim 10 --sim-tilt-error-deg 2 --dry-run"
$C > l09.txt
fig 09 fitted_tilt_deg "$(grep -o 'fit: tilt [0-9.]*' l09.txt | grep -o '[0-9.]*$')" 0.005 deg "$C"
fig 09 rms_row_error_px "$(grep -o 'rms row error [0-9.]*' l09.txt | grep -o '[0-9.]*$')" 0.02 px "$C"

# ---- lab 10: stereo ----------------------------------------------------------------------------
D=/usr/share/doc/opencv-doc/examples/data
C="rccar calibrate stereo --board 9x6 --square 0.025 --left $D/left[0-9]*.jpg --right $D/right[0-9]*.jpg"
rccar calibrate stereo --board 9x6 --square 0.025 --left $D/left[0-9]*.jpg --right $D/right[0-9]*.jpg -o stereo.json >/dev/null
fig 10 baseline_m "$(jq '.stereo.baseline_m' stereo.json)" 0.0002 m "$C"
fig 10 stereo_rms_px "$(jq '.stereo.rms_px' stereo.json)" 0.002 px "$C"
C="rccar stereo --no-local $D/left01.jpg $D/right01.jpg --box 240,80,280,190 --set stereo.calibration=stereo.json"
rccar stereo --no-local $D/left01.jpg $D/right01.jpg --box 240,80,280,190 --set stereo.calibration="$PWD/stereo.json" > l10.json
fig 10 board_depth_bfd_m "$(jq '.depth_m.bfd' l10.json)" 0.002 m "$C"
fig 10 board_depth_eq16_m "$(jq '.depth_m.eq16' l10.json)" 0.002 m "$C"
fig 10 disparity_px "$(jq '.disparity_px' l10.json)" 0.2 px "$C"

# ---- lab 11: the firmware's failsafe (the emulator, raw frames; no serial feature needed) ------
make -s -C "$REPO/firmware" all sim >/dev/null
"$REPO/firmware/build/rccar_sim" "$REPO/firmware/build/rccar_fw.elf" --link "$W/tty" --sniff --no-stdin > pins.log 2>/dev/null &
for _ in $(seq 50); do [ -e "$W/tty" ] && break; sleep 0.1; done
exec 3<>"$W/tty"
printf '\xa5\x01\x01\x00\x01\x65\xd5' >&3               # HELLO v1, seq 0
sleep 0.2; printf '\xa5\x00\x03\x01\xee\x89' >&3        # ARM, seq 1
sleep 0.2; printf '\xa5\x04\x02\x02\x00\x00\xf4\x01\xef\x30' >&3  # DRIVE steer 0, throttle +500 per mille
sleep 1
exec 3>&-
kill %1 2>/dev/null || true
C="rccar_sim --sniff; HELLO, ARM, one DRIVE (throttle 0.5) by printf; time from the DRIVE to the ESC's neutral pulse"
fig 11 esc_us_throttle_0.5 "$(awk '$1=="PULSE" && $2=="esc" && $3>1600 {print $3; exit}' pins.log)" 1 us "$C"
fig 11 failsafe_ms "$(awk '$1=="RX" && $2==2 {t=$4} $1=="PULSE" && $2=="esc" && $3<1510 && t {printf "%.1f", ($4-t)/1000; exit}' pins.log)" 25 ms "$C"

# ---- lab 12: behaviours --------------------------------------------------------------------------
C="rccar sim --no-local --no-timing --track config/tracks/scenarios.toml --laps 0 --seconds 16 --truth-boxes"
rccar sim --no-local --no-timing --track "$REPO/config/tracks/scenarios.toml" --laps 0 --seconds 16 --truth-boxes -o l12 >/dev/null
STOP=$(jq -c 'select(.transition.to=="stop_sign") | [.time_s, (.transition.reason | capture("(?<d>[0-9.]+) m").d | tonumber)]' l12/telemetry.jsonl | head -1)
fig 12 stop_sign_stop_begins_s "$(echo "$STOP" | jq '.[0]')" 0.07 s "$C"
fig 12 stop_sign_distance_m "$(echo "$STOP" | jq '.[1]')" 0.02 m "$C"
RESUME=$(jq -c 'select(.transition.from=="stop_sign") | .time_s' l12/telemetry.jsonl | head -1)
fig 12 stop_sign_resume_s "$RESUME" 0.07 s "$C"

# ---- write the key ---------------------------------------------------------------------------------
jq -s '{generated_by: "bash docs/labs/key/make.sh", figures: .}' "$FIGS" > "$OUT/key.json"
{
  echo "# The labs' key (generated by \`bash docs/labs/key/make.sh\`; do not edit)"
  echo
  echo "Each figure is rerun by \`cargo test --release --test car labs::key_matches_committed\` and must"
  echo "agree with this table within its tolerance. The labs' own pages quote longer runs (whole"
  echo "laps, more samples); these are the short versions."
  echo
  echo "| lab | figure | value | tolerance | command |"
  echo "|---|---|---|---|---|"
  jq -r '.figures[] | "| \(.lab) | \(.name) | \(.value) \(.unit) | ±\(.tol) | `\(.command)` |"' "$OUT/key.json"
} > "$OUT/key.md"
echo "wrote $OUT/key.json and $OUT/key.md ($(jq '.figures | length' "$OUT/key.json") figures)"
