# Shared by the scripts: where things are. Sourced, not run.
STEREOD_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
STEREOD_JOBS="${STEREOD_JOBS:-$(nproc)}"

# The directory of opencv-doc's sample data (see setup.sh for why it may move).
opencv_samples_dir() {
  local system=/usr/share/doc/opencv-doc/examples/data
  if [ -f "$system/aloeL.jpg" ]; then echo "$system"; else echo "$STEREOD_ROOT/.deps/opencv-doc$system"; fi
}

# build_tree DIR [cmake args...] [-- TARGET...]: configure and build into DIR (all
# targets unless some are named after --).
build_tree() {
  local dir="$1"; shift
  local args=() targets=()
  while [ $# -gt 0 ]; do
    if [ "$1" = "--" ]; then shift; targets=("$@"); break; fi
    args+=("$1"); shift
  done
  cmake -S "$STEREOD_ROOT" -B "$dir" -G Ninja -DSTEREOD_OPENCV_SAMPLES_DIR="$(opencv_samples_dir)" "${args[@]}" >/dev/null
  if [ ${#targets[@]} -gt 0 ]; then
    cmake --build "$dir" -j "$STEREOD_JOBS" --target "${targets[@]}"
  else
    cmake --build "$dir" -j "$STEREOD_JOBS"
  fi
}
