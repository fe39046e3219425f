#!/usr/bin/env bash
# Cross-build check for the Raspberry Pi (issue 10): builds `rccar` for aarch64-unknown-linux-gnu
# with Debian's own Rust (rustc-web 1.96 + libstd-rust-web-dev:arm64) and linker
# (gcc-aarch64-linux-gnu), runs `rccar replay` of the shipped sample, a short lane-only
# `rccar sim` and the same with the learned pilot steering (issue 29) under qemu-aarch64,
# and checks that every decision is the one the native build makes (tests/cross/compare.py);
# then reads a camera program's frames through a pipe (the
# native simulator as the camera). Closes with "N passed, N failed".
#
#   bash tests/cross/run.sh                     the check (tests/all.sh runs it)
#   RCCAR_CROSS_SIM_SECONDS=60 bash ...         a longer simulated drive (default 20 s)
#   RCCAR_CROSS_CAMERA=0 bash ...               skip the library build with `--features camera`
#   RCCAR_NATIVE_FEATURES=serial,... bash ...   the native build's features (default: none)
#   RCCAR_CROSS_BUILD_ONLY=1 bash ...           only the aarch64 build (tests/all.sh runs it in the
#                                               background at nice 19 while the FIL laps run on the
#                                               wall clock, then this whole check on a warm build)
#
# Packages (tests/all.sh installs them; arm64 must be a foreign architecture first):
#   dpkg --add-architecture arm64 && apt-get update
#   apt-get install rustc-web cargo-web libstd-rust-web-dev:arm64 gcc-aarch64-linux-gnu \
#                   libc6-dev-arm64-cross qemu-user libclang-dev
# `camera` cross-builds with nothing more: bindgen (v4l2-sys-mit) passes the target to
# libclang, which finds the arm64 kernel headers of libc6-dev-arm64-cross, and mozjpeg-sys's C
# goes through CC_aarch64_unknown_linux_gnu.
# The build goes to target/cross (its own target dir: a different compiler than rustup's, so it
# would otherwise rebuild target/release every time) with the `car` profile the Pi uses.
set -uo pipefail
cd "$(dirname "$0")/../.."
ROOT=$PWD
TARGET=aarch64-unknown-linux-gnu
PROFILE=car
CROSS_DIR=$ROOT/target/cross
OUT=$ROOT/target/cross-check
SIM_SECONDS=${RCCAR_CROSS_SIM_SECONDS:-20}
PASSED=0; FAILED=0
pass() { PASSED=$((PASSED + 1)); echo "ok   $*"; }
fail() { FAILED=$((FAILED + 1)); echo "FAIL $*"; }
finish() { echo "cross: $PASSED passed, $FAILED failed"; [ "$FAILED" -eq 0 ]; exit $?; }

# ---- tools ------------------------------------------------------------------------------
missing=()
[ -x /usr/bin/rustc ] || missing+=("rustc-web (/usr/bin/rustc)")
[ -x /usr/bin/cargo ] || missing+=("cargo-web (/usr/bin/cargo)")
ls /usr/lib/rustlib/$TARGET/lib/libstd-*.rlib >/dev/null 2>&1 || missing+=("libstd-rust-web-dev:arm64")
command -v aarch64-linux-gnu-gcc >/dev/null || missing+=("gcc-aarch64-linux-gnu")
[ -e /usr/aarch64-linux-gnu/lib/libc.so.6 ] || missing+=("libc6-dev-arm64-cross")
command -v qemu-aarch64 >/dev/null || missing+=("qemu-user")
if [ ${#missing[@]} -gt 0 ]; then
  fail "missing: ${missing[*]} (see the top of tests/cross/run.sh)"
  finish
fi
echo "toolchain: $(/usr/bin/rustc --version), $(aarch64-linux-gnu-gcc --version | head -1), $(qemu-aarch64 --version | head -1)"

# ---- features: the car's (serial, gpio, the dashboard's axum/hyper/tokio server, the gamepad) -----
# `camera` is built apart below (libclang). The default features come too: `jpeg-turbo` (issue
# 28) cross-compiles libjpeg-turbo's C (and its NEON code) with aarch64-linux-gnu-gcc, so the car
# decodes its recordings and a class's photos as cv2.imread does (checked in 4 below).
FEATURES=serial,gpio,dashboard,gamepad
CAMERA=${RCCAR_CROSS_CAMERA:-1}
if [ "$CAMERA" != 0 ] && ! ls /usr/lib/llvm-*/lib/libclang*.so* >/dev/null 2>&1; then
  fail "missing: libclang-dev (bindgen, for --features camera)"; CAMERA=0
fi
CROSS_ENV=(env RUSTC=/usr/bin/rustc CARGO_TARGET_DIR="$CROSS_DIR"
  CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_LINKER=aarch64-linux-gnu-gcc
  CC_aarch64_unknown_linux_gnu=aarch64-linux-gnu-gcc)

# ---- 0. the library with the camera (nokhwa: bindgen + mozjpeg-sys cross-compiled) -------
# Built apart from the binary below so that a camera problem does not hide the decision checks.
if [ "$CAMERA" != 0 ]; then
  echo "== cross build (library with the camera): --features $FEATURES,camera --lib"
  t0=$(date +%s)
  if "${CROSS_ENV[@]}" /usr/bin/cargo build --locked --profile "$PROFILE" --target "$TARGET" -p rccar --lib \
      --features "$FEATURES,camera" 2>&1 | grep -vE '^\s+(Compiling|Downloaded|Downloading) ' ; [ "${PIPESTATUS[0]}" -eq 0 ]; then
    pass "cross build of the library with --features $FEATURES,camera in $(( $(date +%s) - t0 )) s"
  else
    fail "cross build of the library with --features $FEATURES,camera after $(( $(date +%s) - t0 )) s (see above)"
  fi
fi

# ---- the cross build -------------------------------------------------------------------
echo "== cross build: cargo build --locked --profile $PROFILE --target $TARGET -p rccar --bin rccar --features $FEATURES"
t0=$(date +%s)
if "${CROSS_ENV[@]}" /usr/bin/cargo build --locked --profile "$PROFILE" --target "$TARGET" -p rccar --bin rccar \
      --features "$FEATURES" 2>&1 | grep -vE '^\s+(Compiling|Downloaded|Downloading) ' ; [ "${PIPESTATUS[0]}" -eq 0 ]; then
  BIN=$CROSS_DIR/$TARGET/$PROFILE/rccar
  size=$(stat -c %s "$BIN")
  arch=$(file -b "$BIN" 2>/dev/null | cut -d, -f1-2)
  pass "cross build ($FEATURES) in $(( $(date +%s) - t0 )) s: $BIN, $(awk -v s="$size" 'BEGIN{printf "%.1f MB", s/1e6}') ${arch:+($arch)}"
else
  fail "cross build ($FEATURES) after $(( $(date +%s) - t0 )) s"
  finish
fi
[ "${RCCAR_CROSS_BUILD_ONLY:-0}" = 1 ] && finish

# ---- the native reference -------------------------------------------------------------
# The build of tests/all.sh's first stage, with its features (it sets RCCAR_NATIVE_FEATURES), so
# nothing is compiled again here (`-p rccar --bin rccar` alone resolves the dependencies'
# features differently and recompiles the library).
NATIVE_FEATURES=${RCCAR_NATIVE_FEATURES:-}
echo "== native build: cargo build --release --workspace --all-targets ${NATIVE_FEATURES:+--features $NATIVE_FEATURES}"
if cargo build --release --workspace --all-targets ${NATIVE_FEATURES:+--features "$NATIVE_FEATURES"} 2>&1 | grep -vE '^\s+(Compiling|Downloaded|Downloading) '; [ "${PIPESTATUS[0]}" -eq 0 ]; then
  NATIVE=$ROOT/target/release/rccar
else
  fail "native build"
  finish
fi
# The guest's glibc must be ONE glibc. `-L /usr/aarch64-linux-gnu` alone gives the loader of
# libc6-arm64-cross (2.36-8cross1) but not its libc: the guest's ld.so reads the host's
# /etc/ld.so.cache and the multiarch path, and finds /lib/aarch64-linux-gnu/libc.so.6 of
# libc6:arm64 (2.36-9+deb12uN, pulled in by libstd-rust-web-dev:arm64). The two disagree on
# the layout of the loader's private _rtld_global, so the first pthread_create walked a
# stack-cache list that never ends: 100 % CPU, no frame, after the drive loop (signal
# thread) and the link (I/O thread) started threads. LD_LIBRARY_PATH puts the cross libc
# (and libgcc_s) beside its own loader.
QEMU_RUN=(qemu-aarch64 -L /usr/aarch64-linux-gnu -E LD_LIBRARY_PATH=/usr/aarch64-linux-gnu/lib)
# A run under qemu that hangs still fails the check instead of hanging the suite.
QEMU=(timeout -k 5 "${RCCAR_CROSS_TIMEOUT:-600}" "${QEMU_RUN[@]}")
# The guest's C library must sit beside the loader qemu starts (/usr/aarch64-linux-gnu/lib).
libs=$("${QEMU_RUN[@]}" -strace "$BIN" --version 2>&1 | sed -nE 's/.*openat\([^,]*,"([^"]*lib(c|m|gcc_s)\.so[^"]*)".*= [0-9]+$/\1/p' | tr '\n' ' ')
if [[ "$libs" == */usr/aarch64-linux-gnu/lib/libc.so.6* ]] && ! grep -qE '(^| )/lib/' <<<"$libs"; then
  pass "qemu guest loads the loader's own glibc: ${libs% }"
else
  fail "qemu guest glibc not the loader's (libc6-arm64-cross): '${libs% }'"
fi

# run LABEL OUTDIR COMMAND...: runs it, keeps its output in OUTDIR.log, prints time and exit code.
run() {
  local label=$1 dir=$2; shift 2
  rm -rf "$dir"; mkdir -p "$dir"
  local t0 rc
  t0=${EPOCHREALTIME/./}
  "$@" >"$dir.log" 2>&1; rc=$?
  local ms=$(( (${EPOCHREALTIME/./} - t0) / 1000 ))
  printf '   %-8s exit %d in %d.%d s\n' "$label" "$rc" $((ms / 1000)) $((ms % 1000 / 100))
  return $rc
}

# ---- 1. replay of the shipped sample frames --------------------------------------------
echo "== replay tests/data/lane_sample --no-timing (native, then aarch64 under qemu)"
run native "$OUT/native/replay" "$NATIVE" replay tests/data/lane_sample --no-timing --no-annotate --out "$OUT/native/replay"; rn=$?
run aarch64 "$OUT/aarch64/replay" "${QEMU[@]}" "$BIN" replay tests/data/lane_sample --no-timing --no-annotate --out "$OUT/aarch64/replay"; ra=$?
if [ $rn -ne 0 ] || [ $ra -ne 0 ]; then
  fail "replay exit codes: native $rn, aarch64 $ra (logs $OUT/*/replay.log)"
  tail -3 "$OUT/aarch64/replay.log"
elif out=$(python3 tests/cross/compare.py replay "$OUT/native/replay/telemetry.jsonl" "$OUT/aarch64/replay/telemetry.jsonl"); then
  PASSED=$((PASSED + 1)); echo "$out"
else
  FAILED=$((FAILED + 1)); echo "$out"
fi

# ---- 2. a short lane-only drive in the simulator ---------------------------------------
SIM=(sim --laps 1 --seconds "$SIM_SECONDS" --set detect.enabled=false --no-timing)
echo "== sim ${SIM[*]:1} (native, then aarch64 under qemu)"
run native "$OUT/native/sim" "$NATIVE" "${SIM[@]}" --out "$OUT/native/sim"; rn=$?
run aarch64 "$OUT/aarch64/sim" "${QEMU[@]}" "$BIN" "${SIM[@]}" --out "$OUT/aarch64/sim"; ra=$?
# `sim` exits 1 when the lap was not finished in time; both builds must end the same way.
if [ $rn -ne $ra ] || [ $rn -gt 1 ]; then
  fail "sim exit codes: native $rn, aarch64 $ra (logs $OUT/*/sim.log)"
  tail -3 "$OUT/aarch64/sim.log"
elif out=$(python3 tests/cross/compare.py sim "$OUT/native/sim/telemetry.jsonl" "$OUT/aarch64/sim/telemetry.jsonl" \
            --summary "$OUT/native/sim/summary.json" "$OUT/aarch64/sim/summary.json"); then
  PASSED=$((PASSED + 1)); echo "$out"
  grep -E 'laps completed|cross-track|departures' "$OUT/aarch64/sim.log" | sed 's/^/     aarch64 /'
else
  FAILED=$((FAILED + 1)); echo "$out"
fi

# ---- 2b. the learned pilot (issue 29): the network's own kernels, built for aarch64 --------
# steering.method = learned with the shipped weights (config/pilot.safetensors): the same frames
# must give the same steering bit for bit (f32 sums in a fixed order, no fused multiply-add).
LSIM=(sim --laps 1 --seconds "$SIM_SECONDS" --set detect.enabled=false --set steering.method=learned --no-timing)
echo "== sim ${LSIM[*]:1} (native, then aarch64 under qemu)"
run native "$OUT/native/learned" "$NATIVE" "${LSIM[@]}" --out "$OUT/native/learned"; rn=$?
run aarch64 "$OUT/aarch64/learned" "${QEMU[@]}" "$BIN" "${LSIM[@]}" --out "$OUT/aarch64/learned"; ra=$?
if [ $rn -ne $ra ] || [ $rn -gt 1 ]; then
  fail "learned sim exit codes: native $rn, aarch64 $ra (logs $OUT/*/learned.log)"
  tail -3 "$OUT/aarch64/learned.log"
elif out=$(python3 tests/cross/compare.py learned "$OUT/native/learned/telemetry.jsonl" "$OUT/aarch64/learned/telemetry.jsonl" \
            --summary "$OUT/native/learned/summary.json" "$OUT/aarch64/learned/summary.json"); then
  PASSED=$((PASSED + 1)); echo "$out"
  grep -E 'cross-track|departures' "$OUT/aarch64/learned.log" | sed 's/^/     aarch64 /'
else
  FAILED=$((FAILED + 1)); echo "$out"
fi

# ---- 3. a camera program on a pipe (src/pipecam/) -----------------------------------------
# The aarch64 rccar starts a child (its own process group, the parent-death signal set in the
# child before exec, under qemu) and reads its raw frames: the native simulator writing 10 s
# of frames to stdout. Both builds must make the same decisions from them.
PSIM=(sim --seconds 10 --no-timing --set detect.enabled=false --frames-to -)
echo "== replay 'pipe:rgb24:rccar ${PSIM[*]}' (native, then aarch64 under qemu)"
rm -rf "$OUT/native/pipe-sim" "$OUT/aarch64/pipe-sim"
run native "$OUT/native/pipe" "$NATIVE" replay "pipe:rgb24:$NATIVE ${PSIM[*]} -o $OUT/native/pipe-sim" \
  --no-annotate --no-timing --set detect.enabled=false --out "$OUT/native/pipe"; rn=$?
run aarch64 "$OUT/aarch64/pipe" "${QEMU[@]}" "$BIN" replay "pipe:rgb24:$NATIVE ${PSIM[*]} -o $OUT/aarch64/pipe-sim" \
  --no-annotate --no-timing --set detect.enabled=false --out "$OUT/aarch64/pipe"; ra=$?
if [ $rn -ne 0 ] || [ $ra -ne 0 ]; then
  fail "pipe replay exit codes: native $rn, aarch64 $ra (logs $OUT/*/pipe.log)"
  tail -3 "$OUT/aarch64/pipe.log"
elif out=$(python3 tests/cross/compare.py pipe "$OUT/native/pipe/telemetry.jsonl" "$OUT/aarch64/pipe/telemetry.jsonl"); then
  PASSED=$((PASSED + 1)); echo "$out"
else
  FAILED=$((FAILED + 1)); echo "$out"
fi

# ---- 4. JPEG decoded on aarch64 as natively (libjpeg-turbo, a default feature) ----------
# `rccar detect` on OpenCV's sample JPEGs (Debian opencv-doc): the boxes and the annotated
# copies (the decoded pixels with the boxes drawn, as PNG) of the aarch64 build must be the
# native build's, byte for byte; the native build's are cv2.imread's (jpeg-parity stage). The
# aarch64 libjpeg-turbo runs its NEON code, the native one its C code (no nasm).
DOC=${RCCAR_OPENCV_DOC:-/usr/share/doc/opencv-doc/examples/data}
JPEGS=()
for f in baboon building fruits home lena left01 messi5 orange; do [ -f "$DOC/$f.jpg" ] && JPEGS+=("$DOC/$f.jpg"); done
if [ ${#JPEGS[@]} -lt 4 ]; then
  if [ -n "${RCCAR_OPENCV_DOC:-}" ]; then fail "OpenCV's sample JPEGs missing in $DOC (opencv-doc)"
  else echo "skip JPEG check: no OpenCV sample JPEGs in $DOC (apt-get install opencv-doc)"; fi
else
  DET=(detect --cascade config/cascades/stop_sign.xml --cascade config/cascades/traffic_light.xml)
  echo "== ${DET[*]} on ${#JPEGS[@]} of OpenCV's sample JPEGs (native, then aarch64 under qemu)"
  run native "$OUT/native/jpeg" "$NATIVE" "${DET[@]}" --out "$OUT/native/jpeg" "${JPEGS[@]}"; rn=$?
  run aarch64 "$OUT/aarch64/jpeg" "${QEMU[@]}" "$BIN" "${DET[@]}" --out "$OUT/aarch64/jpeg" "${JPEGS[@]}"; ra=$?
  nb=$(grep -o '"x"' "$OUT/native/jpeg.log" | wc -l)
  if [ $rn -ne 0 ] || [ $ra -ne 0 ]; then
    fail "JPEG detect exit codes: native $rn, aarch64 $ra (logs $OUT/*/jpeg.log)"
  elif ! cmp -s "$OUT/native/jpeg.log" "$OUT/aarch64/jpeg.log"; then
    fail "JPEG detect: the aarch64 boxes differ from the native ones ($OUT/*/jpeg.log)"
  elif ! diff -rq "$OUT/native/jpeg" "$OUT/aarch64/jpeg" >/dev/null; then
    fail "JPEG detect: the aarch64 decoded pixels differ: $(diff -rq "$OUT/native/jpeg" "$OUT/aarch64/jpeg" | head -3 | tr '\n' ' ')"
  else
    pass "JPEG: ${#JPEGS[@]} OpenCV sample JPEGs decoded identically on aarch64 (annotated copies byte for byte) and the same $nb boxes"
  fi
fi

# ---- 5. the wiring picture of docs/pi.md follows config/car.toml [gpio] ----------------
if out=$(python3 docs/img/wiring.py --check 2>&1); then pass "$out"; else fail "$out"; fi

echo "note: the camera (V4L2) and the GPIO are compiled, not opened: no device under qemu."
echo "note: the serial port is not exercised under qemu-user 7.2: it does not implement the"
echo "      TCGETS2 ioctl serialport uses (ENOSYS, aarch64 as armv7); the link is tested"
echo "      natively (link-hil stage, real firmware in simavr); 'serial' is only compiled here."
finish
