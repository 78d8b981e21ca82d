#!/usr/bin/env bash
# Builds the census + semi-global matcher core (pipeline/sgm) and its unit tests
# (tests/pipeline/sgm) for 64-bit Arm with Debian's cross compiler, and runs the tests
# under qemu-user: the SIMD kernels on Highway's Arm target, held to the scalar reference.
#   scripts/cross-aarch64.sh      install what is missing, build into build-aarch64/, test
# Only the core is built (tests/pipeline/sgm/cross): it needs nothing but the standard
# library, Highway and GoogleTest, the only arm64 packages installed; the rest of stereod
# needs OpenCV and more. Safe to run again: it installs only what is missing.
set -euo pipefail
source "$(dirname "$0")/common.sh"

dir="$STEREOD_ROOT/build-aarch64"
packages=(g++-aarch64-linux-gnu qemu-user-static libhwy-dev:arm64 libgtest-dev:arm64)

start=$(date +%s)
phase_start=$start
phase() {   # phase NAME: prints how long the previous phase took
  local now; now=$(date +%s)
  [ -n "${current_phase:-}" ] && echo "cross-aarch64: $current_phase took $(( now - phase_start )) s"
  current_phase="$1"; phase_start=$now
  [ -n "$1" ] && echo "== $1"
  return 0
}

phase "packages"
if ! dpkg --print-foreign-architectures | grep -qx arm64; then
  echo "cross-aarch64: adding the arm64 architecture to dpkg"
  as_root dpkg --add-architecture arm64
fi
ensure_packages cross-aarch64 "${packages[@]}"

phase "build ($dir)"
cmake_args=()
[ "${CI:-}" = "true" ] && cmake_args+=(-DSTEREOD_WERROR=ON)
cmake -S "$STEREOD_ROOT/tests/pipeline/sgm/cross" -B "$dir" -G Ninja \
  -DCMAKE_TOOLCHAIN_FILE="$STEREOD_ROOT/cmake/aarch64-linux-gnu.cmake" "${cmake_args[@]}" >/dev/null
cmake --build "$dir" -j "$STEREOD_JOBS"

# Twice: as a Cortex-A72 (NEON only, what most robot computers have) and as qemu's
# "max" processor (SVE and SVE2, which Highway prefers when present). Each run must
# exercise its SIMD target: a fallback to Highway's scalar emulation would leave the
# SIMD code untested.
for cpu in cortex-a72 max; do
  phase "test under qemu-aarch64, cpu $cpu ($dir)"
  QEMU_CPU=$cpu ctest --test-dir "$dir" --no-tests=error --output-on-failure --timeout 600 -j "$STEREOD_JOBS"
  target=$(QEMU_CPU=$cpu qemu-aarch64-static -L / "$dir/tests/pipeline/sgm/pipeline_sgm_test" \
             --gtest_filter='SgmKernelsTest.SimdTargetIsNamed' | sed -n 's/^simd target: //p')
  echo "cross-aarch64: cpu $cpu: SIMD kernels' target ${target:-unknown}"
  case "$target" in
    ""|EMU128|SCALAR)
      echo "cross-aarch64: on cpu $cpu the SIMD kernels fell back to ${target:-nothing}" >&2
      exit 1 ;;
  esac
done
phase ""
echo "cross-aarch64: done in $(( $(date +%s) - start )) s"
