#!/usr/bin/env bash
# Installs the pinned npm packages (package-lock.json) into WORK_DIR/node_modules with `npm ci`,
# the first time and whenever the lock changes, and copies serialize.js there. Nothing global,
# nothing in the source tree. Run by ros2_serializer_test (ros2/tests/serializer_test.cc).
#
#   ros2/tests/serializer/install.sh WORK_DIR
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
work=${1:?usage: install.sh WORK_DIR}
for c in node npm; do
  command -v "$c" >/dev/null ||
    { echo "install.sh: $c is not installed (scripts/setup installs nodejs and npm)" >&2; exit 1; }
done
mkdir -p "$work"
# One install at a time: the tests run side by side, and npm ci empties node_modules first. A file
# is copied only when it changed, so a test running serialize.js meanwhile never reads half of it.
exec 9>"$work/.install.lock"
flock 9
for f in package.json package-lock.json serialize.js; do
  cmp -s "$here/$f" "$work/$f" || cp "$here/$f" "$work/$f"
done
if [ ! -d "$work/node_modules" ] || ! cmp -s "$here/package-lock.json" "$work/installed-lock.json"; then
  echo "install.sh: npm ci in $work (node $(node --version), npm $(npm --version))" >&2
  rm -f "$work/installed-lock.json"
  (cd "$work" && timeout 600 npm ci --no-audit --no-fund --prefer-offline --loglevel=error >&2)
  cp "$here/package-lock.json" "$work/installed-lock.json"
fi
