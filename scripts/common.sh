# Shared by the scripts: where things are. Sourced, not run.
STEREOD_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
STEREOD_JOBS="${STEREOD_JOBS:-$(nproc)}"

# The directory of opencv-doc's sample data (see setup.sh for why it may move).
opencv_samples_dir() {
  local system=/usr/share/doc/opencv-doc/examples/data
  if [ -f "$system/aloeL.jpg" ]; then echo "$system"; else echo "$STEREOD_ROOT/.deps/opencv-doc$system"; fi
}

# build/, the tree the README's two commands share, and the options both configure it
# with, whatever its cache holds: tests and benchmarks on, warnings as errors in CI. The
# demo builds only its targets, so neither command undoes the other's configuration and
# the second reuses the first's objects (a demo that turned the tests off left a later
# test.sh with no test to run).
STEREOD_BUILD_DIR="$STEREOD_ROOT/build"
main_tree_options=(-DSTEREOD_BUILD_TESTS=ON -DSTEREOD_BUILD_BENCH=ON)
if [ "${CI:-}" = "true" ]; then
  main_tree_options+=(-DSTEREOD_WERROR=ON)
fi

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

# Runs a command as root: directly when root, else through sudo.
as_root() {
  if [ "$(id -u)" -eq 0 ]; then "$@"; else sudo "$@"; fi
}

# ensure_packages TAG PACKAGE...: installs the Debian packages that are missing (apt-get,
# as root), saying so under TAG; says "all packages present" when nothing is missing.
ensure_packages() {
  local tag="$1"; shift
  local missing=() p
  for p in "$@"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  if [ ${#missing[@]} -gt 0 ]; then
    echo "$tag: installing ${missing[*]}"
    as_root apt-get update -q
    as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends "${missing[@]}"
  else
    echo "$tag: all packages present"
  fi
}
