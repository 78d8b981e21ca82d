#!/usr/bin/env bash
# Installs what stereod needs to build, test and run, from the distribution's packages
# (Debian 12 / Ubuntu 22.04 or newer). Safe to run again: it installs only what is missing.
set -euo pipefail

packages=(
  build-essential cmake ninja-build pkg-config git
  libopencv-dev libv4l-dev libturbojpeg0-dev libeigen3-dev libyaml-cpp-dev libspdlog-dev libsystemd-dev
  nlohmann-json3-dev libcli11-dev
  libgtest-dev libgmock-dev libbenchmark-dev
  clang libclang-rt-dev   # scripts/fuzz.sh: clang with libFuzzer and its sanitizer runtimes
  opencv-doc
  systemd   # systemd-analyze, systemd-sysusers, systemd-tmpfiles: the unit checks (tests/daemon)
)

as_root() {
  if [ "$(id -u)" -eq 0 ]; then "$@"; else sudo "$@"; fi
}

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done

if [ ${#missing[@]} -gt 0 ]; then
  echo "setup: installing ${missing[*]}"
  as_root apt-get update -q
  as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends "${missing[@]}"
else
  echo "setup: all packages present"
fi

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
