# Shared by the scripts: where things are. Sourced, not run.
STEREOD_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
STEREOD_JOBS="${STEREOD_JOBS:-$(nproc)}"

# The directory of opencv-doc's sample data (see setup.sh for why it may move).
opencv_samples_dir() {
  local system=/usr/share/doc/opencv-doc/examples/data
  if [ -f "$system/aloeL.jpg" ]; then echo "$system"; else echo "$STEREOD_ROOT/.deps/opencv-doc$system"; fi
}

# build_tree DIR [cmake args...]: configure (once) and build everything into DIR.
build_tree() {
  local dir="$1"; shift
  cmake -S "$STEREOD_ROOT" -B "$dir" -G Ninja -DSTEREOD_OPENCV_SAMPLES_DIR="$(opencv_samples_dir)" "$@" >/dev/null
  cmake --build "$dir" -j "$STEREOD_JOBS"
}
