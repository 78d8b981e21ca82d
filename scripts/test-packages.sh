#!/usr/bin/env bash
# The Debian packages tested as installed software, on this machine (CI's Debian 12
# container, as root): installs build/packages/*.deb with apt-get (dependencies resolve
# from the archive), checks what the maintainer scripts made (user, group, socket
# directory, configuration, nothing enabled) and the installed units (systemd-analyze
# verify), runs the installed stereod as the stereod user with the installed unit's
# command line on a recording made by the installed stereoctl, asks it for a distance
# with stereoctl and with the Python client, then removes and purges both packages and
# checks that nothing of them is left: no file under /etc, /usr, /run or /var/lib that was
# not there before, no user, no group. Build the packages first (scripts/package.sh).
#
# It changes the system it runs on, so it refuses to run where stereod is already
# installed or its user exists: it would remove them.
set -euo pipefail
source "$(dirname "$0")/common.sh"

fail() { echo "test-packages: $*" >&2; exit 1; }

[ "$(id -u)" -eq 0 ] || fail "installs and purges system packages: run it as root (CI does)"
packages_dir="$STEREOD_BUILD_DIR/packages"
debs=("$packages_dir"/stereod_*.deb "$packages_dir"/python3-stereod_*.deb)
for deb in "${debs[@]}"; do
  [ -f "$deb" ] || fail "no package $deb: build them with scripts/package.sh"
done
for package in stereod python3-stereod; do
  if dpkg-query -W -f='${Status}' "$package" 2>/dev/null | grep -q "installed"; then
    fail "$package is installed on this machine already; this test would purge it"
  fi
done
if getent passwd stereod >/dev/null || getent group stereod >/dev/null || [ -e /etc/stereod ]; then
  fail "the stereod user, group or /etc/stereod exists already; this test would remove it"
fi

# What the system holds before, to compare with after the purge: file names under the
# directories a package or its scripts write to (apt's and dpkg's own state aside), users
# and groups.
system_state() {
  find /etc /usr /run /var/lib -xdev \
    \( -path /var/lib/dpkg -o -path /var/lib/apt -o -path /var/lib/ucf -o -path /run/user \
       -o -path /var/lib/systemd/deb-systemd-helper-enabled -o -path /var/lib/systemd/deb-systemd-user-helper-enabled \
       -o -path /etc/ld.so.cache \) -prune -o -print 2>/dev/null | LC_ALL=C sort
  getent passwd | cut -d: -f1 | LC_ALL=C sort | sed 's/^/user:/'
  getent group | cut -d: -f1 | LC_ALL=C sort | sed 's/^/group:/'
}
work="$(mktemp -d)"
service_pid=""
installed=false
# On failure too: the service stopped, and the packages this test installed purged.
cleanup() {
  if [ -n "$service_pid" ]; then kill "$service_pid" 2>/dev/null || true; wait "$service_pid" 2>/dev/null || true; fi
  if $installed; then
    DEBIAN_FRONTEND=noninteractive apt-get purge -y -q stereod python3-stereod > /dev/null 2>&1 || true
  fi
  rm -rf "$work"
}
trap cleanup EXIT
system_state > "$work/before"

echo "== apt-get install ${debs[*]##*/}"
installed=true
DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends "${debs[@]}" > "$work/apt.log" 2>&1 \
  || { cat "$work/apt.log" >&2; fail "apt-get install failed"; }

echo "== what the maintainer scripts made"
getent passwd stereod >/dev/null || fail "no stereod user after install"
id -nG stereod | tr ' ' '\n' | grep -qx video || fail "the stereod user is not in the video group"
[ "$(stat -c %U:%G /run/stereod)" = "stereod:stereod" ] || fail "/run/stereod missing or not stereod's"
[ -f /etc/stereod/stereod.yaml ] || fail "no /etc/stereod/stereod.yaml from the example"
enabled="$(find /etc/systemd/system -name 'stereod*' 2>/dev/null)"
[ -z "$enabled" ] || fail "the package enabled units: $enabled"
stereod --check-config /etc/stereod/stereod.yaml
man_dir=/usr/share/man/man1
[ -f "$man_dir/stereod.1.gz" ] && [ -f "$man_dir/stereoctl.1.gz" ] || fail "man pages missing from $man_dir"

echo "== systemd-analyze verify (the installed units)"
unit_dir="$(dirname "$(dpkg -L stereod | grep '/stereod\.service$')")"
verify="$(systemd-analyze verify "$unit_dir/stereod.service" "$unit_dir/stereod.socket" 2>&1)" \
  || fail "systemd-analyze verify failed: $verify"
[ -z "$verify" ] || fail "systemd-analyze verify reports: $verify"

# A recording the stereod user can read: Middlebury 2005 "Books" at third size (463x370,
# rectified, colour; the shared data), ten frames at 10 fps, with a rectified calibration
# written by the installed stereoctl: f 3740 / 3 px, B 160 mm, doffs its dmin 200 / 3 px.
echo "== a recording, calibrated by the installed stereoctl"
scene="$STEREOD_ROOT/../shared/data/middlebury2005/Books"
[ -f "$scene/view1.png" ] || fail "no $scene/view1.png (the shared data beside the checkout)"
recording="$work/books"
mkdir -p "$recording/left" "$recording/right"
cp "$scene/view1.png" "$recording/left/000000.png"
cp "$scene/view5.png" "$recording/right/000000.png"
{
  echo "index,left_stamp_ns,right_stamp_ns,left,right"
  for i in $(seq 0 9); do
    echo "$i,$((i * 100000000)),$((i * 100000000)),left/000000.png,right/000000.png"
  done
} > "$recording/frames.csv"
stereoctl calibrate --rectified --focal-px 1246.667 --baseline-m 0.160 --size 463x370 \
  --doffs-px 66.667 --out "$recording/calibration.yaml" > /dev/null
chmod -R a+rX "$work"

# The installed unit's command line, as its user (systemd adds the sandbox, which needs
# systemd as PID 1; docs/service.md says what only such a machine shows).
exec_start="$(sed -n 's/^ExecStart=//p' "$unit_dir/stereod.service")"
[ -n "$exec_start" ] || fail "no ExecStart= in $unit_dir/stereod.service"
echo "== $exec_start --replay $recording (as stereod)"
read -r -a command <<< "$exec_start"
# setpriv executes it in place (runuser would stay between and answer SIGTERM itself).
setpriv --reuid=stereod --regid=stereod --init-groups -- "${command[@]}" --replay "$recording" > "$work/stereod.log" 2>&1 &
service_pid=$!

echo "== stereoctl distance"
distance=""
for _ in $(seq 1 120); do
  kill -0 "$service_pid" 2>/dev/null || { cat "$work/stereod.log" >&2; fail "stereod exited early"; }
  if distance="$(stereoctl distance 2>/dev/null)"; then break; fi
  distance=""
  sleep 0.5
done
[ -n "$distance" ] || { tail -20 "$work/stereod.log" >&2; stereoctl distance || true; fail "no valid distance within 60 s"; }
echo "stereoctl distance: $distance"
echo "== the installed Python client"
# Debian's python3, the one the package depends on (not a python3 earlier in PATH).
/usr/bin/python3 - <<'EOF'
import importlib.metadata
from stereod import Client
with Client() as client:
    reading = client.distance()
assert reading.valid, f"no reading: {reading.reason} {reading.message}"
print(f"python3-stereod {importlib.metadata.version('stereod')}: {reading.distance_m:.3f} m")
EOF

kill -TERM "$service_pid"
status=0; wait "$service_pid" || status=$?
service_pid=""
[ "$status" -eq 0 ] || { cat "$work/stereod.log" >&2; fail "stereod exited $status on SIGTERM"; }

echo "== apt-get remove: the configuration and the user stay"
DEBIAN_FRONTEND=noninteractive apt-get remove -y -q stereod python3-stereod > "$work/apt.log" 2>&1 \
  || { cat "$work/apt.log" >&2; fail "apt-get remove failed"; }
[ ! -e /usr/bin/stereod ] || fail "/usr/bin/stereod is still there after remove"
[ -f /etc/stereod/stereod.yaml ] || fail "remove took /etc/stereod/stereod.yaml (only purge may)"
getent passwd stereod >/dev/null || fail "remove took the stereod user (only purge may)"

echo "== apt-get purge: nothing is left"
DEBIAN_FRONTEND=noninteractive apt-get purge -y -q stereod python3-stereod > "$work/apt.log" 2>&1 \
  || { cat "$work/apt.log" >&2; fail "apt-get purge failed"; }
for package in stereod python3-stereod; do
  if dpkg-query -W -f='${Status}' "$package" 2>/dev/null | grep -qv "not-installed"; then
    fail "$package is still known to dpkg: $(dpkg-query -W -f='${Status}' "$package")"
  fi
done
system_state > "$work/after"
# Files that appeared and belong to another package came with a dependency apt-get
# installed; the rest were left by ours. The shadow tools keep their backups (passwd-).
left="$(LC_ALL=C comm -13 "$work/before" "$work/after" | while read -r path; do
  case "$path" in
    /etc/passwd- | /etc/group- | /etc/shadow- | /etc/gshadow-) continue ;;
  esac
  if [ -e "$path" ] && dpkg -S "$path" > /dev/null 2>&1; then continue; fi
  echo "$path"
done)"
installed=false
[ -z "$left" ] || fail "left after purge: $left"
gone="$(LC_ALL=C comm -23 "$work/before" "$work/after")"
[ -z "$gone" ] || fail "gone after purge (was there before the install): $gone"
echo "test-packages: installed, ran, removed and purged; nothing left"
