#!/usr/bin/env bash
# The running service's own figures, beside the benchmark's: stereod, as the packages build
# it (build/, the README's tree), replays the real rig's 13 chessboard pairs in lockstep
# (as fast as its worker takes them) with the default configuration, and then again with
# OpenCV's SGBM 3-way as its matcher. After a warm-up, `stereoctl status --json` gives each
# stage's mean time over the last frames (`pipeline.stage_ms`). The service's other threads
# (the replay's decoding, the calibration health check, the socket) share the cores, as
# they do on a robot.
#
# Per round: census-sgm's whole frame (the sum of its stages) and SGBM 3-way's match stage
# alone; then the medians of the rounds and their ratio.
#
#   bench/service_compare.sh [ROUNDS] [SECONDS]     (default 3 rounds of 12 s per matcher)
#
# The recording is the demo's: run scripts/demo.sh once first.
set -euo pipefail
source "$(dirname "$0")/../scripts/common.sh"

rounds="${1:-3}"
seconds="${2:-12}"
stereod="$STEREOD_BUILD_DIR/daemon/stereod"
stereoctl="$STEREOD_BUILD_DIR/ctl/stereoctl"
recording="$STEREOD_BUILD_DIR/demo/chessboard"
for f in "$stereod" "$stereoctl" "$recording/calibration.yaml"; do
  [ -e "$f" ] || { echo "service_compare: $f is missing: run scripts/demo.sh first" >&2; exit 1; }
done

work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT

# Starts the service with `algorithm`, waits, and writes its status to $work/ALGO.ROUND.json.
measure() {
  local algorithm="$1" round="$2"
  cat > "$work/$algorithm.yaml" <<EOF
source:
  type: replay
  replay:
    path: $recording
    pacing: lockstep
    loop: true
calibration: ""
matcher:
  algorithm: $algorithm
socket:
  path: $work/$algorithm.sock
log_level: warn
EOF
  "$stereod" --config "$work/$algorithm.yaml" > "$work/$algorithm.log" 2>&1 &
  local pid=$!
  sleep "$seconds"
  if ! "$stereoctl" --socket "$work/$algorithm.sock" status --json > "$work/$algorithm.$round.json"; then
    echo "service_compare: no status from the $algorithm service; its log:" >&2
    cat "$work/$algorithm.log" >&2
    kill "$pid" 2>/dev/null || true
    exit 1
  fi
  kill "$pid"
  wait "$pid" 2>/dev/null || true
}

for round in $(seq 1 "$rounds"); do
  echo "service_compare: round $round of $rounds (census-sgm, then sgbm-3way, ${seconds} s each)" >&2
  measure census-sgm "$round"
  measure sgbm-3way "$round"
done

python3 - "$work" "$rounds" <<'EOF'
import json
import statistics
import sys

work, rounds = sys.argv[1], int(sys.argv[2])
ours, theirs = [], []
print("| round | census-sgm frame, ms (stages) | SGBM 3-way match, ms | fps, census-sgm / SGBM 3-way |")
print("|---|---|---:|---:|")
for r in range(1, rounds + 1):
    a = json.load(open(f"{work}/census-sgm.{r}.json"))["pipeline"]
    b = json.load(open(f"{work}/sgbm-3way.{r}.json"))["pipeline"]
    frame = sum(a["stage_ms"].values())
    stages = ", ".join(f"{k} {v:.2f}" for k, v in a["stage_ms"].items() if v > 0)
    ours.append(frame)
    theirs.append(b["stage_ms"]["match"])
    print(f"| {r} | {frame:.2f} ({stages}) | {theirs[-1]:.2f} | {a['fps']:.1f} / {b['fps']:.1f} |")
print()
print(f"{a['num_disparities']} disparities, extended range {'on' if a.get('extended_range') else 'off'}: "
      f"census-sgm's frame {statistics.median(ours):.2f} ms, SGBM 3-way's match "
      f"{statistics.median(theirs):.2f} ms (medians): "
      f"{statistics.median(ours) / statistics.median(theirs):.2f}x")
EOF
