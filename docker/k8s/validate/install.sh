#!/usr/bin/env bash
# Installs the pinned npm packages (package-lock.json) into WORK_DIR/node_modules with `npm ci`,
# the first time and whenever the lock changes, and copies the scripts there. Nothing global,
# nothing in the source tree. Used by run.sh and ../smoke.sh.
#
#   docker/k8s/validate/install.sh WORK_DIR
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
work=${1:?usage: install.sh WORK_DIR}
for c in node npm; do
  command -v "$c" >/dev/null ||
    { echo "install.sh: $c is not installed (scripts/setup installs Debian's nodejs and npm)" >&2; exit 1; }
done
mkdir -p "$work"
cp "$here/package.json" "$here/package-lock.json" "$here"/*.js "$work/"
if [ ! -d "$work/node_modules" ] || ! cmp -s "$here/package-lock.json" "$work/installed-lock.json"; then
  echo "install.sh: npm ci in $work (node $(node --version), npm $(npm --version))"
  rm -f "$work/installed-lock.json"
  (cd "$work" && timeout 600 npm ci --no-audit --no-fund --prefer-offline --loglevel=error)
  cp "$here/package-lock.json" "$work/installed-lock.json"
fi
