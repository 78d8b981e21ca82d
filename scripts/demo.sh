#!/usr/bin/env bash
# Sets up, builds, and runs the classical stereo pipeline end to end on real data, with
# no camera: the 13 stereo chessboard pairs of Debian's opencv-doc package are used to
# calibrate the rig (stereoctl calibrate), then replayed as a recording through stereod
# with that calibration, and stereoctl asks for the nearest-object distance as a robot
# would, next to what the board's pose says it is.
#
#   scripts/demo.sh          the chessboard flow above
#   scripts/demo.sh --aloe   Middlebury 2006 "Aloe" (rectified, with ground truth)
set -euo pipefail
source "$(dirname "$0")/common.sh"

scene=chessboard
case "${1:-}" in
  "") ;;
  --aloe) scene=aloe ;;
  -h|--help) sed -n '2,9p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
  *) echo "demo.sh: unknown option '$1' (try --help)" >&2; exit 2 ;;
esac

"$STEREOD_ROOT/scripts/setup.sh"
build="$STEREOD_BUILD_DIR"
echo "== build ($build: stereod, stereoctl)"
build_tree "$build" "${main_tree_options[@]}" -- stereod stereoctl

demo="$build/demo"
samples="$(opencv_samples_dir)"
socket="$demo/stereod.sock"
stereod="$build/daemon/stereod"
stereoctl="$build/ctl/stereoctl"
mkdir -p "$demo"

# Starts stereod on recording $1 with config $2 and waits (up to $3 half-seconds) for a
# valid reading; the service is stopped when the script ends.
start_service() {
  echo "== stereod (socket $socket)"
  rm -f "$socket"
  "$stereod" --config "$2" --replay "$1" --socket "$socket" > "$demo/stereod.log" 2>&1 &
  pid=$!
  trap 'kill -TERM $pid 2>/dev/null; wait $pid 2>/dev/null || true' EXIT
  local status=1
  for _ in $(seq 1 "$3"); do
    if ! kill -0 "$pid" 2>/dev/null; then
      echo "stereod exited early; its log:" >&2; cat "$demo/stereod.log" >&2; exit 1
    fi
    set +e; "$stereoctl" distance --socket "$socket" >/dev/null 2>&1; status=$?; set -e
    [ "$status" -eq 0 ] && break
    sleep 0.5
  done
}

# json_number KEY JSON: the number under "KEY" in a one-line JSON object (empty when
# absent or null).
json_number() {
  printf '%s' "$2" | tr -d ' \n' | sed -n "s/.*\"$1\":\([-0-9.eE+]*\).*/\1/p"
}

show_service() {
  echo "== stereoctl status"
  "$stereoctl" status --socket "$socket" || true
  echo "== stereoctl snapshot"
  "$stereoctl" snapshot --socket "$socket" --colormap "$demo/depth-colormap.png" \
    --depth "$demo/depth.png" --left "$demo/left.png" || true
}

if [ "$scene" = chessboard ]; then
  recording="$demo/chessboard"
  echo "== calibration from the 13 stereo chessboard pairs ($samples)"
  rm -rf "$recording"
  mkdir -p "$recording/left" "$recording/right"
  # 9x6 inner corners; the square size is not in the images: 25 mm is assumed, and it
  # sets the scale of the baseline and so of every distance below.
  "$stereoctl" calibrate --left "$samples/left[0-9][0-9].jpg" \
    --right "$samples/right[0-9][0-9].jpg" --board 9x6 --square-m 0.025 \
    --out "$recording/calibration.yaml" --preview "$demo/rectified-preview.png"

  # The recording: the raw pairs, two a second, in the recording format (frames.csv +
  # left/ + right/ + calibration.yaml). The frames link to the packaged images.
  echo "== recording ($recording)"
  lefts=()
  i=0
  {
    echo "index,left_stamp_ns,right_stamp_ns,left,right"
    for left in "$samples"/left[0-9][0-9].jpg; do
      right="$samples/right${left##*/left}"
      name=$(printf '%06d.jpg' "$i")
      ln -s "$left" "$recording/left/$name"
      ln -s "$right" "$recording/right/$name"
      stamp=$((i * 500000000))
      echo "$i,$stamp,$stamp,left/$name,right/$name"
      lefts+=("$left")
      i=$((i + 1))
    done
  } > "$recording/frames.csv"

  config="$STEREOD_ROOT/config/examples/chessboard-demo.yaml"
  start_service "$recording" "$config" 60
  show_service
  # One reading, and the board's pose in that reading's own frame: the frame index the
  # service reports names the recorded pair (frame % pairs: the recording loops). A second
  # `stereoctl distance` could answer for a later frame, so there is none. Every pair gives
  # a reading with the demo's settings; should one give none (a slower machine, other
  # settings), the demo shows that answer and its reason, and asks again at a later pair.
  echo "== stereoctl distance --json"
  for _ in $(seq 1 20); do
    set +e; reading=$("$stereoctl" distance --socket "$socket" --json); status=$?; set -e
    echo "$reading"
    frame=$(json_number frame "$reading")
    measured=$(json_number distance_m "$reading")
    [ "$status" -eq 0 ] && break
    [ -n "$frame" ] && echo "demo: frame $frame gave no reading; asking again at a later pair"
    sleep 0.5
  done
  if [ "$status" -ne 0 ] || [ -z "$frame" ] || [ -z "$measured" ]; then
    echo "demo: stereod gave no reading (stereoctl distance exit $status)" >&2
    [ "$status" -ne 0 ] && exit "$status"
    exit 1
  fi
  pair="${lefts[$((frame % ${#lefts[@]}))]}"
  echo "== frame $frame (${pair##*/}): stereod's reading and the board's pose"
  board_distance=("$stereoctl" board-distance "$pair" --calib "$recording/calibration.yaml"
                  --config "$config")
  set +e
  posed_text=$("${board_distance[@]}")
  posed=$("${board_distance[@]}" --json)
  set -e
  board=$(json_number distance_m "$posed")
  awk -v m="$measured" 'BEGIN { printf "stereoctl distance        %.3f m\n", m }'
  echo "stereoctl board-distance  $posed_text"
  if [ -z "$board" ]; then
    awk -v frame="$frame" -v name="${pair##*/}" -v m="$measured" 'BEGIN {
      printf "demo: frame %s (%s): stereod %.3f m; the board is not in the region\n",
             frame, name, m }'
  else
    awk -v frame="$frame" -v name="${pair##*/}" -v m="$measured" -v b="$board" 'BEGIN {
      printf "demo: frame %s (%s): stereod %.3f m, the board'"'"'s pose %.3f m (%+.1f %%)\n",
             frame, name, m, b, 100 * (m - b) / b }'
  fi
  exit "$status"
fi

recording="$demo/aloe"

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

start_service "$recording" "$STEREOD_ROOT/config/examples/aloe-demo.yaml" 120
show_service
echo "== stereoctl distance --json"
"$stereoctl" distance --socket "$socket" --json || true
echo "== stereoctl distance"
set +e; "$stereoctl" distance --socket "$socket"; status=$?; set -e
exit "$status"
