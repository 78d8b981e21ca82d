#!/usr/bin/env bash
# Builds the Debian packages into build/packages/ (docs/packages.md):
#   stereod_VERSION-1_ARCH.deb         daemon, stereoctl, man pages, systemd units, docs
#   python3-stereod_VERSION-1_all.deb  the Python client
# from build/, the tree the README's commands share (only the targets the packages hold
# are built), then checks them with lintian: an error or a warning fails. Install them
# with `sudo apt-get install ./build/packages/*.deb`; scripts/test-packages.sh tests them
# as installed software.
set -euo pipefail
source "$(dirname "$0")/common.sh"

"$STEREOD_ROOT/scripts/setup.sh"
build_tree "$STEREOD_BUILD_DIR" "${main_tree_options[@]}" -- stereod stereoctl stereod_man

out="$STEREOD_BUILD_DIR/packages"
rm -rf "$out"
(cd "$STEREOD_BUILD_DIR" && cpack -G DEB > cpack.log 2>&1) \
  || { cat "$STEREOD_BUILD_DIR/cpack.log" >&2; echo "package: cpack failed" >&2; exit 1; }

debs=("$out"/*.deb)
for deb in "${debs[@]}"; do
  printf '%-40s %6d KiB  installed %6s KiB\n' "${deb##*/}" "$(( $(stat -c %s "$deb") / 1024 ))" \
    "$(dpkg-deb -f "$deb" Installed-Size)"
done
echo "== lintian"
# Root is how CI and package builds in containers run; lintian only reads the files.
lintian --allow-root --fail-on error,warning "${debs[@]}"
echo "package: lintian clean (no error, no warning)"
