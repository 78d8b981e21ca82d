#!/usr/bin/env bash
# Installs what stereod needs to build, test and run, from the distribution's packages
# (Debian 12 / Ubuntu 22.04 or newer). Safe to run again: it installs only what is missing.
set -euo pipefail
source "$(dirname "$0")/common.sh"

packages=(
  build-essential cmake ninja-build pkg-config git
  lld   # the linker the build prefers (CMakeLists.txt): five times GNU ld's speed
  libopencv-dev libv4l-dev libturbojpeg0-dev libeigen3-dev libyaml-cpp-dev libspdlog-dev libsystemd-dev
  nlohmann-json3-dev libcli11-dev
  libzstd-dev zlib1g-dev   # MCAP recordings: zstd chunks, CRC-32
  libpng-dev libjpeg62-turbo-dev   # replay: PNG and JPEG decoded by the libraries themselves (replay/image_codecs.hpp)
  libwebsocketpp-dev libasio-dev libjs-three   # the live view: Foxglove WebSocket server, the page's 3D view
  chromium   # the live view's page tested in a real browser (headless, tests/live_view/page.mjs)
  cyclonedds-dev cyclonedds-tools   # ROS 2 on DDS: Eclipse Cyclone DDS and its IDL compiler (idlc)
  libfastrtps-dev fastddsgen   # the ROS 2 interop test's peer: eProsima Fast DDS and its type generator
  libhwy-dev   # Highway: portable SIMD with run-time dispatch, for the census-sgm matcher
  libgtest-dev libgmock-dev libbenchmark-dev
  clang libclang-rt-dev   # scripts/fuzz.sh: clang with libFuzzer and its sanitizer runtimes
  opencv-doc
  camera-calibration-parsers-tools python3-camera-calibration-parsers   # ROS's own calibration parsers: the ROS format tests
  python3-numpy python3-pytest python3-setuptools python3-venv   # python/: the Python client and its tests
  systemd   # systemd-analyze, systemd-sysusers, systemd-tmpfiles: the unit checks (tests/daemon)
  help2man lintian   # scripts/package.sh: man pages from --help, the packages checked
)

ensure_packages setup "${packages[@]}"

# Minimal container images tell dpkg to skip /usr/share/doc, which drops opencv-doc's
# sample data (the real stereo pairs the demo and tests use). Unpack it beside the
# project instead when that happened.
here="$(cd "$(dirname "$0")/.." && pwd)"
samples=/usr/share/doc/opencv-doc/examples/data
if [ ! -f "$samples/aloeL.jpg" ]; then
  dest="$here/.deps/opencv-doc"
  if [ ! -f "$dest/usr/share/doc/opencv-doc/examples/data/aloeL.jpg" ]; then
    echo "setup: $samples is missing (dpkg path exclusion?); unpacking opencv-doc into $dest"
    tmp="$(mktemp -d)"
    (cd "$tmp" && apt-get download opencv-doc >/dev/null)
    mkdir -p "$dest"
    dpkg-deb -x "$tmp"/opencv-doc_*.deb "$dest"
    rm -rf "$tmp"
  fi
fi
