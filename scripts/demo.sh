#!/usr/bin/env bash
# Sets up, builds, and runs stereod on the built-in default: a replay of a real stereo
# recording (Middlebury 2006 "Aloe", shipped by Debian's opencv-doc package), then asks
# it for the nearest-object distance with stereoctl, as a robot would.
set -euo pipefail
source "$(dirname "$0")/common.sh"

"$STEREOD_ROOT/scripts/setup.sh"
build="$STEREOD_ROOT/build"
echo "== build ($build)"
build_tree "$build" -DSTEREOD_BUILD_TESTS=OFF -DSTEREOD_BUILD_BENCH=OFF

demo="$build/demo"
recording="$demo/aloe"
samples="$(opencv_samples_dir)"
socket="$demo/stereod.sock"
stereod="$build/daemon/stereod"
stereoctl="$build/ctl/stereoctl"

# The recording: a static scene seen for one second at 10 fps, in the recording format
# (frames.csv + left/ + right/). The frames link to the packaged images; nothing is copied.
echo "== recording ($recording)"
rm -rf "$recording"
mkdir -p "$recording/left" "$recording/right"
{
  echo "index,left_stamp_ns,right_stamp_ns,left,right"
  for i in $(seq 0 9); do
    name=$(printf '%06d.jpg' "$i")
    ln -s "$samples/aloeL.jpg" "$recording/left/$name"
    ln -s "$samples/aloeR.jpg" "$recording/right/$name"
    stamp=$((i * 100000000))
    echo "$i,$stamp,$stamp,left/$name,right/$name"
  done
} > "$recording/frames.csv"

# Middlebury 2006 full-size geometry (see README): f = 3740 px, B = 160 mm, and Aloe's
# principal-point offset doffs = 270 px, so Z = f*B / (d + doffs).
"$stereoctl" calibrate --rectified --focal-px 3740 --baseline-m 0.160 --size 1282x1110 \
  --doffs-px 270 --out "$recording/calibration.yaml"

echo "== stereod (socket $socket)"
rm -f "$socket"
"$stereod" --config "$STEREOD_ROOT/config/examples/aloe-demo.yaml" --replay "$recording" \
  --socket "$socket" > "$demo/stereod.log" 2>&1 &
pid=$!
trap 'kill -TERM $pid 2>/dev/null; wait $pid 2>/dev/null || true' EXIT

# The first frames take a moment (full-size SGBM); wait for a valid reading.
status=1
for _ in $(seq 1 120); do
  if ! kill -0 "$pid" 2>/dev/null; then
    echo "stereod exited early; its log:" >&2; cat "$demo/stereod.log" >&2; exit 1
  fi
  set +e; "$stereoctl" distance --socket "$socket" >/dev/null 2>&1; status=$?; set -e
  [ "$status" -eq 0 ] && break
  sleep 0.5
done

echo "== stereoctl status"
"$stereoctl" status --socket "$socket" || true
echo "== stereoctl snapshot"
"$stereoctl" snapshot --socket "$socket" --colormap "$demo/depth-colormap.png" \
  --depth "$demo/depth.png" --left "$demo/left.png" || true
echo "== stereoctl distance --json"
"$stereoctl" distance --socket "$socket" --json || true
echo "== stereoctl distance"
set +e; "$stereoctl" distance --socket "$socket"; status=$?; set -e
exit "$status"
