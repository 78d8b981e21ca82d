#!/usr/bin/env bash
# Builds stereod_bench in Release and runs it: Google Benchmark's table on the terminal,
# its JSON in bench/results.json (untracked), and a markdown summary at the end: stage
# times, latency, census-sgm against OpenCV's SGBM as ratios, allocations, memory.
#
#   bench/run.sh                                   everything (about 2 minutes on 2 shared cores)
#   bench/run.sh --benchmark_filter='scene:aloe'   any extra flags go to the benchmark
#
# Environment: BUILD_DIR (default: build-bench in the source tree), JOBS (default 2),
# MIN_TIME (seconds per repetition, default 0.1), REPETITIONS (default 5).
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
BUILD_DIR="${BUILD_DIR:-$ROOT/build-bench}"
JOBS="${JOBS:-2}"
MIN_TIME="${MIN_TIME:-0.1}"
REPETITIONS="${REPETITIONS:-5}"
RESULTS="$ROOT/bench/results.json"

generator=()
if command -v ninja >/dev/null 2>&1; then
    generator=(-G Ninja)
fi
if [[ ! -f "$BUILD_DIR/CMakeCache.txt" ]]; then
    cmake -S "$ROOT" -B "$BUILD_DIR" "${generator[@]}" -DCMAKE_BUILD_TYPE=Release \
        -DSTEREOD_BUILD_TESTS=OFF >/dev/null
else
    cmake -S "$ROOT" -B "$BUILD_DIR" -DCMAKE_BUILD_TYPE=Release >/dev/null
fi
cmake --build "$BUILD_DIR" --target stereod_bench -j "$JOBS"

"$BUILD_DIR/bench/stereod_bench" \
    --benchmark_min_time="$MIN_TIME" \
    --benchmark_repetitions="$REPETITIONS" \
    --benchmark_display_aggregates_only=true \
    --benchmark_out="$RESULTS" \
    --benchmark_out_format=json \
    "$@"
echo "JSON: $RESULTS"
