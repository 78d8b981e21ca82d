#!/usr/bin/env bash
# Sets up, builds and runs the test suite.
#   scripts/test.sh                      the whole suite (build/)
#   scripts/test.sh --sanitize address   the whole suite under ASan+UBSan (build-asan/)
#   scripts/test.sh --sanitize thread    the threaded tests under TSan (build-tsan/)
#   scripts/test.sh --target NAME ...    build only these targets (repeatable), for a
#                                        quick check with a ctest filter
# Extra arguments after `--` go to ctest (e.g. -- -R Ring). A run in which no test runs
# fails.
set -euo pipefail
source "$(dirname "$0")/common.sh"

sanitize=""
ctest_args=()
targets=()
only=()
while [ $# -gt 0 ]; do
  case "$1" in
    --sanitize) sanitize="${2:?--sanitize needs address or thread}"; shift 2 ;;
    --target) only+=("${2:?--target needs a target name}"); shift 2 ;;
    --) shift; ctest_args+=("$@"); break ;;
    *) echo "test.sh: unknown argument '$1' (expected --sanitize address|thread, --target NAME, or -- CTEST-ARGS)" >&2; exit 2 ;;
  esac
done

"$STEREOD_ROOT/scripts/setup.sh"
"$STEREOD_ROOT/scripts/setup-node.sh"   # the MCAP interop tests' Node.js packages

# Every tree is configured with its tests on, whatever its cache says (the demo shares
# build/ and builds only its own targets there).
cmake_args=(-DSTEREOD_BUILD_TESTS=ON)
[ "${CI:-}" = "true" ] && cmake_args+=(-DSTEREOD_WERROR=ON)
# The sanitizer builds use clang: it builds them in two thirds of gcc's time (measured:
# 449 s against 667 s for the ASan+UBSan tree on two cores).
sanitizer_compiler=(-DCMAKE_CXX_COMPILER=clang++)
# The health monitor's long runs: one pair checked 40 times (its cost stays flat), and the
# demo's pairs 300 times (ten minutes of the service's checks, no false alarm).
long_health_runs='^CalibrationHealthMonitor\.(RepeatedChecksOfOnePairCostTheSame|DemoRigStaysOkForTenMinutesOfChecks)$'
case "$sanitize" in
  "")
    dir="$STEREOD_BUILD_DIR"
    cmake_args=("${main_tree_options[@]}") ;;
  address)
    dir="$STEREOD_ROOT/build-asan"
    cmake_args+=("${sanitizer_compiler[@]}" "-DSTEREOD_SANITIZE=address;undefined" -DSTEREOD_BUILD_BENCH=OFF)
    export ASAN_OPTIONS="detect_leaks=1:abort_on_error=1:strict_string_checks=1"
    export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1"
    export LSAN_OPTIONS="suppressions=$STEREOD_ROOT/tests/sanitizers/lsan.supp"
    # The 60 s soak runs in the normal pass only, and so do the sweeps that run the
    # matcher over every scene, range and tuning (about 280 s of the ASan run's test time
    # on two cores: the same code paths some fifty times over, which the one-scene tests
    # keep under ASan) and the health monitor's runs of 40 and 300 checks. So do the
    # live view page's tests in Chromium (a browser beside an ASan service on two cores,
    # about 60 s of test time): what they ask of the service, the page and its WebSocket,
    # the other live view tests ask under ASan too.
    ctest_args=(-LE soak
                -E "^(RealRig|SharedScenes|ChessboardCalibrationTest|CensusSgmAccuracy|LiveViewPage)\\.|$long_health_runs"
                "${ctest_args[@]}")
    ;;
  thread)
    dir="$STEREOD_ROOT/build-tsan"
    cmake_args+=("${sanitizer_compiler[@]}" -DSTEREOD_SANITIZE=thread -DSTEREOD_BUILD_BENCH=OFF)
    export TSAN_OPTIONS="halt_on_error=1:second_deadlock_stack=1:suppressions=$STEREOD_ROOT/tests/sanitizers/tsan.supp"
    # The health monitor's runs of 40 and 300 checks hand over between the same two
    # threads each time (300 s of the TSan run's test time); its other tests keep that
    # handover under TSan.
    ctest_args=(-L threaded -E "$long_health_runs" "${ctest_args[@]}")
    targets=(-- stereod_threaded_tests)
    ;;
  *) echo "test.sh: --sanitize takes address or thread, not '$sanitize'" >&2; exit 2 ;;
esac

# A tree configured with another compiler cannot switch to this one: start it afresh.
if [ -n "$sanitize" ] && [ -f "$dir/CMakeCache.txt" ] &&
   ! grep -q '^CMAKE_CXX_COMPILER:[A-Z]*=.*clang++' "$dir/CMakeCache.txt"; then
  rm -rf "$dir"
fi

[ ${#only[@]} -gt 0 ] && targets=(-- "${only[@]}")
echo "== build ($dir)"
build_tree "$dir" "${cmake_args[@]}" "${targets[@]}"
echo "== test ($dir)"
cd "$dir"
# A run in which no test ran (none built, or a filter that matches none) fails.
ctest --no-tests=error --output-on-failure --timeout 600 -j "$STEREOD_JOBS" "${ctest_args[@]}"
