#!/usr/bin/env bash
# rccar's one test command (README, .ci/run): installs what is missing on a Debian machine,
# then runs every test suite and closes with one "N passed, N failed" line over all of them.
#
#   bash tests/all.sh            everything
#   RCCAR_SKIP_INSTALL=1 ...     don't touch apt/pip (you installed things yourself)
#   RCCAR_CROSS=0 ...            skip the Pi cross-build stage (tests/cross/run.sh)
#   RCCAR_CROSS_CAMERA=1 ...     cross-build the camera too (another ~5 min of CPU when cold)
set -uo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
LOG_DIR=$ROOT/target/test-logs
mkdir -p "$LOG_DIR"

# ---- 1. Debian packages (each stage lists what it needs) -------------------------------
DEB_PACKAGES=(
  python3-venv python3-pip fonts-dejavu-core   # OpenCV reference scripts, plot fonts
  gcc-avr avr-libc arduino-core-avr            # firmware (make -C firmware)
  simavr libsimavr-dev libsimavrparts1 libelf-dev  # hardware-in-the-loop harness
  libclang-dev                                 # the `camera` feature (nokhwa's V4L2 bindings)
  opencv-data                                  # stock Haar/LBP cascades for the detect parity stage
  chromium chromium-driver                     # the dashboard's headless-browser stage
  socat                                        # a silent pty pair for rccar drive's bad-port test
  jq                                           # the labs' key (docs/labs/key/make.sh)
  opencv-doc                                   # OpenCV's stereo chessboard pairs (calib parity stage)
  ffmpeg                                       # testsrc as a camera for the pipe source (tests/pipe_camera.rs)
)
# The Pi cross-build stage (tests/cross/run.sh) and its packages (skip with RCCAR_CROSS=0). Cold
# it compiles every dependency for aarch64: ~6 min of CPU with `serial,gpio` (axum, hyper and
# tokio of the suite's default `serial,gpio,dashboard,gamepad` add a few minutes), ~11 min with the
# camera (RCCAR_CROSS_CAMERA=1). With target/cross kept: 21 s when
# nothing changed, a few minutes after a source change (rccar itself recompiled for aarch64).
if [ "${RCCAR_CROSS:-1}" = 1 ]; then
  DEB_PACKAGES+=(rustc-web cargo-web libstd-rust-web-dev:arm64 gcc-aarch64-linux-gnu libc6-dev-arm64-cross qemu-user)
fi
if [ -z "${RCCAR_SKIP_INSTALL:-}" ]; then
  missing=()
  for p in "${DEB_PACKAGES[@]}"; do dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p"); done
  if [ ${#missing[@]} -gt 0 ]; then
    echo "== installing Debian packages: ${missing[*]}"
    SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO=sudo
    # :arm64 packages need arm64 as a foreign architecture (only arm64: armhf broke apt once)
    case " ${missing[*]}" in *:arm64*) dpkg --print-foreign-architectures | grep -qx arm64 || $SUDO dpkg --add-architecture arm64 ;; esac
    $SUDO apt-get update -qq && $SUDO env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}" >/dev/null \
      || { echo "apt-get install failed"; exit 1; }
  fi
  # ---- 2. the OpenCV 4.x reference, in a virtualenv of its own -------------------------
  if ! .venv/bin/python -c "import cv2, numpy, skimage, onnx, onnxruntime" >/dev/null 2>&1; then
    echo "== installing the OpenCV reference into .venv (tests/parity/requirements.txt)"
    python3 -m venv .venv && .venv/bin/pip install -q -r tests/parity/requirements.txt || { echo "pip install failed"; exit 1; }
  fi
fi
export RCCAR_PYTHON=$ROOT/.venv/bin/python
# OpenCV's sample photos (opencv-doc, installed above): tests that read them fail, not skip,
# when this is set and a photo is missing (tests/stereo_photos.rs).
export RCCAR_OPENCV_DOC=/usr/share/doc/opencv-doc/examples/data

# ---- 3. the suites ------------------------------------------------------------------
PASSED=0; FAILED=0; FAILED_STAGES=(); TIMES=(); SUITE_START=$SECONDS
# stage NAME COMMAND...: runs it, shows its output, adds up its "N passed / N failed".
stage() {
  local name=$1; shift
  echo; echo "== $name: $*"
  local log=$LOG_DIR/$name.log t0=$SECONDS
  "$@" 2>&1 | tee "$log"
  count_stage "$name" "$log" "${PIPESTATUS[0]}" "$t0" ""
}
# count_stage NAME LOG RC T0 NOTE: adds a finished stage's tests, time and failure.
count_stage() {
  local name=$1 log=$2 rc=$3 t0=$4 note=$5
  TIMES+=("$(printf '%5d s  %s%s' $((SECONDS - t0)) "$name" "$note")")
  # cargo: "test result: ok. 12 passed; 0 failed"; others: "N passed, N failed"
  local p f
  if grep -aq '^test result:' "$log"; then
    # cargo: add up every test binary's "test result" line
    p=$(grep -a '^test result:' "$log" | grep -aoE '[0-9]+ passed' | awk '{s+=$1} END {print s+0}')
    f=$(grep -a '^test result:' "$log" | grep -aoE '[0-9]+ failed' | awk '{s+=$1} END {print s+0}')
  else
    # scripts: their closing "N passed, N failed" line
    local last
    last=$(grep -aE '[0-9]+ passed, [0-9]+ failed' "$log" | tail -1)
    p=$(echo "$last" | grep -aoE '[0-9]+ passed' | awk '{print $1+0}'); p=${p:-0}
    f=$(echo "$last" | grep -aoE '[0-9]+ failed' | awk '{print $1+0}'); f=${f:-0}
  fi
  if [ "$rc" -ne 0 ] && [ "$f" -eq 0 ]; then f=1; fi
  PASSED=$((PASSED + p)); FAILED=$((FAILED + f))
  [ "$rc" -ne 0 ] && FAILED_STAGES+=("$name")
  return 0
}
# bg_stage NAME COMMAND...: starts a stage in the background at nice 19, its output to its log
# (shown by bg_wait). For CPU work that may overlap the wall-clock stages: those run at the
# suite's priority and take the cores whenever they want them; the stage gets what they leave.
# COMMAND must not be cargo (its lock would hold up the stages in front): a test binary.
BG_PID=
bg_stage() {
  BG_NAME=$1; shift
  echo; echo "== $BG_NAME: started in the background at nice 19 (its output when it ends): $*"
  BG_T0=$SECONDS
  nice -n 19 "$@" > "$LOG_DIR/$BG_NAME.log" 2>&1 &
  BG_PID=$!
}
# bg_wait: waits for the background stage, shows its output and adds it up like `stage`.
bg_wait() {
  echo; echo "== $BG_NAME (in the background since $((SECONDS - BG_T0)) s; waiting for it)"
  local t1=$SECONDS rc=0
  wait "$BG_PID" || rc=$?
  BG_PID=
  cat "$LOG_DIR/$BG_NAME.log"
  TIMES+=("$(printf '%5d s  %s' $((SECONDS - t1)) "$BG_NAME: waited for at its end")")
  count_stage "$BG_NAME" "$LOG_DIR/$BG_NAME.log" "$rc" "$BG_T0" " (in the background, overlapping the stages above)"
}

# The Pi cross-build (its own target dir and compiler) compiles in the background at nice 19
# from the start: it gets the cores whenever the stages leave them idle (test threads waiting
# on subprocesses, the wall-clock firmware-in-the-loop laps); the cross stage at the end finishes
# whatever is left of it in the foreground. (Started after the feature build, a cold run still
# waited ~60 s for it.)
CROSS_BG=
if [ "${RCCAR_CROSS:-1}" = 1 ]; then
  # setsid: its own process group (the trap below kills it whole). A new session is also a new
  # scheduler autogroup (Linux, kernel.sched_autogroup_enabled), which shares the CPU equally
  # with the suite's group whatever its nice: so the group's own nice is set to 19 as well.
  RCCAR_CROSS_BUILD_ONLY=1 RCCAR_CROSS_CAMERA="${RCCAR_CROSS_CAMERA:-0}" setsid bash -c \
    'echo 19 > /proc/self/autogroup 2>/dev/null; exec nice -n 19 bash tests/cross/run.sh' \
    > "$LOG_DIR/cross-build.log" 2>&1 &
  CROSS_BG=$!
  trap 'kill -- -$CROSS_BG 2>/dev/null; [ -z "$BG_PID" ] || kill "$BG_PID" 2>/dev/null' EXIT   # an interrupted suite leaves no compiler behind
fi
# Everything is built and tested in ONE feature set, the car's and the dashboard's (libjpeg-turbo
# decoding and `parallel` are default features): the library, its unit tests and every test
# binary are compiled once. (Compiling them once without and once with the features took 379 s +
# 249 s of wall time from a clean clone, 2026-11-29.) The stages below then only run, and the
# machine is quiet for the wall-clock ones.
FEAT=serial,camera,gpio,dashboard,jpeg-turbo,gamepad
stage build cargo build --release --workspace --all-targets --features $FEAT
# rccar-train is built: the tests that run it need not call cargo themselves (tests/pilot_round_trip.rs)
export RCCAR_TRAINER_BUILT=1
# The main job's build (`cargo run --release -- sim`: default features) still compiles, with the
# code that only exists without a feature (the "built without the serial link" answers): checked,
# not built (a fraction of the CPU).
stage default-check cargo check --workspace --all-targets
# The tests that run on the wall clock or drive the firmware in simavr get stages of their own
# below, one at a time; drive_cli:: runs with them (stage drive-fil).
ALONE=(--skip drive_cli:: --skip drive_fil:: --skip link_hil:: --skip session_fil:: --skip dashboard_security::
  --skip labs::lab11 --skip labs::key_matches_committed)
stage cargo-test cargo test --release --workspace --features $FEAT --no-fail-fast -- "${ALONE[@]}"
stage lane-parity "$RCCAR_PYTHON" tests/parity/lane_parity.py
stage detect-parity "$RCCAR_PYTHON" tests/parity/detect_parity.py --quick
# JPEG as cv2.imread decodes it with the default features (libjpeg-turbo's C code via mozjpeg, a
# default feature; issue 28): pixels and `rccar detect`'s boxes on OpenCV's sample JPEGs. Run on
# the suite's build (the hardware features touch no decoding): without RCCAR_JPEG_CARGO it would
# compile everything again without them (211 s, 2026-11-29).
stage jpeg-parity env RCCAR_JPEG_CARGO="--features $FEAT" "$RCCAR_PYTHON" tests/parity/jpeg_parity.py
stage train-parity "$RCCAR_PYTHON" tests/parity/train_parity.py --quick
stage calib-parity "$RCCAR_PYTHON" tests/parity/calib_parity.py
stage firmware make -C firmware all sim
stage protocol-c make -C firmware test
stage protocol-c-fuzz make -C firmware fuzz FUZZ_ITERS=200000
stage link-decoder-fuzz env RCCAR_FUZZ_CASES=1000000 cargo test --release --features $FEAT --lib decoder_survives_arbitrary_bytes
# the link to the firmware in simavr, one test at a time (each waits on the emulator's clock;
# two emulators side by side on a machine whose cores are busy fell behind it), and the
# library's session driving the firmware in-process (session_fil)
stage link-hil cargo test --release --features $FEAT --test car -- --test-threads 1 link_hil:: session_fil::
# lab 11 and the labs' key (it reruns every figure the lab pages quote, lab 11's with the firmware;
# ~6 min of CPU) in the background at nice 19 while the wall-clock firmware-in-the-loop stages
# below leave most of the two cores idle. The key's lab 11 runs first and alone (make.sh), so
# its emulator has a core, as have the laps' at the suite's priority. The car's test binary is
# run directly: a `cargo test` holding cargo's lock would stop the stages below.
CAR_TESTS=$(cargo test --release --features $FEAT --test car --no-run --message-format=json 2>/dev/null |
  jq -r 'select(.executable != null and .target.name == "car") | .executable' | tail -1)
if [ -x "$CAR_TESTS" ]; then
  bg_stage labs-link "$CAR_TESTS" --nocapture labs::lab11 labs::key_matches_committed
else
  stage labs-link cargo test --release --features $FEAT --test car -- labs::lab11 labs::key_matches_committed
fi
# the firmware in the loop: rccar drive + the simulator as camera + the real firmware in simavr,
# on the wall clock. The two whole laps (closed loop; 1e-3 bit errors) one after the other (~4.5
# min; side by side, on a machine whose cores were already busy, they fell behind real time),
# then the timed faults (kill -9, Ctrl-C, stall, vanished pty) and drive_cli (~2 min).
stage drive-fil-laps cargo test --release --features $FEAT --test car -- --test-threads 1 \
  drive_fil::firmware_in_the_loop_drives_a_lap drive_fil::bit_errors_at_1e_3_for_a_lap
stage drive-fil cargo test --release --features $FEAT --test car -- --test-threads 1 drive_fil:: drive_cli:: \
  --skip firmware_in_the_loop_drives_a_lap --skip bit_errors_at_1e_3_for_a_lap
stage dashboard-security cargo test --release --features $FEAT --test car -- --test-threads 1 dashboard_security::
# the browser test runs target/release/rccar, built by the build stage with the dashboard
stage dashboard-browser "$RCCAR_PYTHON" tests/dashboard/browser_test.py
[ -z "$BG_PID" ] || bg_wait
# The Pi cross-build check: aarch64 build (Debian's rustc-web), replay and a 20 s sim under
# qemu-aarch64, decisions compared with the native run (see the top for the switches).
if [ "${RCCAR_CROSS:-1}" = 1 ]; then
  # A background build still running here is finished in the foreground, at the suite's own
  # priority: on a machine kept busy by something else (a CPU hog, another build) nice 19 gets
  # almost nothing, and a cold build waited on at nice 19 took longer than the whole suite.
  # cargo resumes from what the background build finished.
  t0=$SECONDS
  if [ -n "$CROSS_BG" ] && kill -0 "$CROSS_BG" 2>/dev/null; then
    echo; echo "== cross: the background build is not done; finishing it in the foreground"
    kill -- -"$CROSS_BG" 2>/dev/null; wait "$CROSS_BG" 2>/dev/null
  fi
  TIMES+=("$(printf '%5d s  %s' $((SECONDS - t0)) "cross (stopping the background build, log: $LOG_DIR/cross-build.log)")")
  stage cross env RCCAR_CROSS_CAMERA="${RCCAR_CROSS_CAMERA:-0}" RCCAR_NATIVE_FEATURES=$FEAT bash tests/cross/run.sh
else
  echo; echo "== cross: skipped (RCCAR_CROSS=0)"
fi

echo
echo "wall time: set-up $SUITE_START s (packages, .venv), stages $((SECONDS - SUITE_START)) s:"; printf '  %s\n' "${TIMES[@]}"
if [ ${#FAILED_STAGES[@]} -gt 0 ]; then echo "failed stages: ${FAILED_STAGES[*]} (logs in target/test-logs/)"; fi
echo "rccar: $PASSED passed, $FAILED failed"
[ "$FAILED" -eq 0 ] && [ ${#FAILED_STAGES[@]} -eq 0 ]
