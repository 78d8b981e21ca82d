#!/usr/bin/env bash
# Builds the libFuzzer targets (tests/fuzz/: the protocol parser, the configuration
# loader, the live view's WebSocket message parser, a bag's Image messages and its zstd
# chunks) with clang and runs them side by side for a bounded time, each from its
# checked-in seed corpus.
#   scripts/fuzz.sh [SECONDS] [TARGET...]    SECONDS of the run (default 60);
#                                            TARGET: fuzz_protocol, fuzz_config,
#                                            fuzz_foxglove, fuzz_image_message,
#                                            fuzz_mcap_chunk (default all)
# Fails when a target crashes, hangs (one input over 10 s), leaks or runs out of memory;
# the input that did it is kept under the build directory (artifacts/) and its path
# printed. New inputs found go to the build directory's working corpus, never into the
# checked-in seeds. Build directory: $STEREOD_FUZZ_BUILD_DIR, default build-fuzz/.
set -euo pipefail
source "$(dirname "$0")/common.sh"

seconds="${1:-60}"
[ $# -gt 0 ] && shift
case "$seconds" in
  ''|*[!0-9]*) echo "fuzz.sh: SECONDS must be a whole number, not '$seconds'" >&2; exit 2 ;;
esac
targets=("$@")
[ ${#targets[@]} -eq 0 ] && targets=(fuzz_protocol fuzz_config fuzz_foxglove fuzz_image_message fuzz_mcap_chunk)

declare -A corpus=([fuzz_protocol]=protocol [fuzz_config]=config [fuzz_foxglove]=foxglove
                   [fuzz_image_message]=image_message [fuzz_mcap_chunk]=mcap_chunk)
declare -A dict=([fuzz_protocol]=tests/protocol/fuzz_protocol.dict [fuzz_config]=tests/config/fuzz_config.dict
                 [fuzz_foxglove]=tests/daemon/fuzz_foxglove.dict
                 [fuzz_image_message]=tests/replay/fuzz_image_message.dict
                 [fuzz_mcap_chunk]=tests/replay/fuzz_mcap_chunk.dict)
for target in "${targets[@]}"; do
  if [ -z "${corpus[$target]:-}" ]; then
    echo "fuzz.sh: unknown target '$target' (expected fuzz_protocol, fuzz_config, fuzz_foxglove," \
         "fuzz_image_message or fuzz_mcap_chunk)" >&2
    exit 2
  fi
done

"$STEREOD_ROOT/scripts/setup.sh"

dir="${STEREOD_FUZZ_BUILD_DIR:-$STEREOD_ROOT/build-fuzz}"
echo "== build ($dir)"
cmake -S "$STEREOD_ROOT/tests/fuzz" -B "$dir" -G Ninja -DCMAKE_CXX_COMPILER=clang++ >/dev/null
cmake --build "$dir" -j "$STEREOD_JOBS" --target "${targets[@]}"

# Leaks fail the run like crashes; UBSan findings abort (built with -fno-sanitize-recover).
export ASAN_OPTIONS="detect_leaks=1:abort_on_error=1"
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1"

# The targets run side by side, one process each, so that the run takes SECONDS on a
# machine with as many cores as targets (on fewer, each gets a share of them).
start=$(date +%s)
declare -A pid
for target in "${targets[@]}"; do
  work="$dir/corpus/${corpus[$target]}"
  mkdir -p "$work" "$dir/artifacts/$target/"
  echo "== $target: ${seconds} s from tests/fuzz/corpus/${corpus[$target]}"
  # The first corpus directory receives new inputs; the seeds are only read.
  "$dir/$target" -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 -max_len=4096 \
    -dict="$STEREOD_ROOT/${dict[$target]}" -artifact_prefix="$dir/artifacts/$target/" \
    -print_final_stats=1 "$work" "$STEREOD_ROOT/tests/fuzz/corpus/${corpus[$target]}" \
    >"$dir/$target.log" 2>&1 &
  pid[$target]=$!
done

failed=0
for target in "${targets[@]}"; do
  status=0
  wait "${pid[$target]}" || status=$?
  elapsed=$(( $(date +%s) - start ))
  log="$dir/$target.log"
  runs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -n 1)
  rate=$(sed -n 's/^stat::average_exec_per_sec: *//p' "$log" | tail -n 1)
  inputs=$(find "$dir/corpus/${corpus[$target]}" -type f | wc -l)
  if [ "$status" -ne 0 ]; then
    failed=1
    echo "fuzz $target: FAILED (exit $status) within ${elapsed} s; log: $log"
    grep -E "^(==[0-9]+==ERROR|SUMMARY|.*runtime error|artifact_prefix|Test unit written|ALARM|==[0-9]+== ERROR)" "$log" | head -n 20 || true
    tail -n 40 "$log"
  else
    echo "fuzz $target: ${runs:-?} executions within ${elapsed} s (${rate:-?}/s), no crash; working corpus: $inputs inputs"
  fi
done
exit "$failed"
