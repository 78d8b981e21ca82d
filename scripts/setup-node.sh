#!/usr/bin/env bash
# Installs the Node.js packages of the tests that run real clients: the MCAP
# interoperability tests (tests/mcap_interop: @mcap/core, @foxglove/rosmsg2-serialization,
# @foxglove/rosmsg, fzstd) and the live view's (tests/live_view: @foxglove/ws-protocol, ws,
# @foxglove/rosmsg2-serialization), exactly as each package-lock.json pins them, into
# each folder's node_modules (ignored by git). The
# npm cache lives outside the repository: $STEREOD_NPM_CACHE, or ~/.cache/stereod-npm.
# Safe to run again: it does nothing when the installed tree matches the lock file.
# Installs the distribution's nodejs and npm when there is no node; if that fails, it says
# so and succeeds: the interop tests then skip.
set -euo pipefail
source "$(dirname "$0")/common.sh"

if ! command -v npm >/dev/null || ! command -v node >/dev/null; then
  # The distribution's Node.js (Debian 12: 18, which the packages run on although
  # rosmsg2-serialization asks for 20). Only when none is there: a Node.js from elsewhere
  # (NodeSource, nvm) is used as it is.
  ensure_packages setup-node nodejs npm || true
fi
if ! command -v npm >/dev/null || ! command -v node >/dev/null; then
  echo "setup-node: node/npm not installed; the MCAP interop tests will skip"
  exit 0
fi
cache="${STEREOD_NPM_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/stereod-npm}"
# npm keeps a copy of what it installed in node_modules/.package-lock.json: the tree is
# current when its versions are those of the lock file.
versions() {
  node -e 'const p = require(process.argv[1]).packages; delete p[""];
           console.log(Object.keys(p).sort().map((k) => k + "@" + p[k].version).join("\n"))' "$1"
}
for dir in "$STEREOD_ROOT/tests/mcap_interop" "$STEREOD_ROOT/tests/live_view"; do
  name="${dir#"$STEREOD_ROOT"/}"
  stamp="$dir/node_modules/.package-lock.json"
  if [ -f "$stamp" ] && [ "$(versions "$dir/package-lock.json")" = "$(versions "$stamp")" ]; then
    echo "setup-node: $name packages present"
    continue
  fi
  echo "setup-node: installing the $name packages (npm ci, cache $cache)"
  npm ci --prefix "$dir" --cache "$cache" --no-audit --no-fund --loglevel=error
done
