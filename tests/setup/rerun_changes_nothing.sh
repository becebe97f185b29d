#!/usr/bin/env bash
# scripts/setup on a configured, built tree neither configures nor builds anything: tests call it
# (scripts/bench-against does), and a second configure rebuilt and relinked every target under
# the running suite, so tests whose binary was being linked failed with "permission denied".
#   tests/setup/rerun_changes_nothing.sh SOURCE_DIR BUILD_DIR
set -euo pipefail
src=$1 build=$2
# The build's own -Werror setting, as CI (CLOUDCAST_WERROR=1) or a user (unset) configured it.
werror=$(sed -n 's/^CLOUDCAST_WERROR:BOOL=//p' "$build/CMakeCache.txt")
flag=0
[ "$werror" = ON ] && flag=1
before=$(stat -c %y "$build/build.ninja")
log=$(mktemp)
trap 'rm -f "$log"' EXIT
(cd "$src" && CLOUDCAST_WERROR=$flag CLOUDCAST_BUILD_DIR="$build" ./scripts/setup) >"$log" 2>&1 || {
  cat "$log"; echo "FAIL: scripts/setup failed"; exit 1; }
after=$(stat -c %y "$build/build.ninja")
if [ "$before" != "$after" ]; then
  echo "FAIL: scripts/setup (CLOUDCAST_WERROR=$flag) configured the build again (build.ninja rewritten)"
  exit 1
fi
if grep -qE '^\[[0-9]+/[0-9]+\] (Building|Linking)' "$log"; then
  grep -E '^\[[0-9]+/[0-9]+\]' "$log" | head -5
  echo "FAIL: scripts/setup rebuilt targets of an up-to-date build"
  exit 1
fi
echo "ok: scripts/setup (CLOUDCAST_WERROR=$flag) left the build as it was"
