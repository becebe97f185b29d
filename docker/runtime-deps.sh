#!/usr/bin/env bash
# Prints the Debian packages that hold the shared libraries the given programs load (ldd, then
# dpkg -S), one per line: what a runtime image must install, and nothing more. Run where the
# programs were built (the packages must be installed there).
#   docker/runtime-deps.sh build/bin/cloudcast-server build/bin/cloudcast-load
set -euo pipefail
[ $# -gt 0 ] || { echo "usage: $0 PROGRAM..." >&2; exit 2; }
libs=$(for p in "$@"; do ldd "$p"; done | awk '/=> \// {print $3}' | sort -u)
# usrmerge: ldd may say /lib/... where dpkg recorded /usr/lib/... (or the other way round), so
# every spelling is asked for, in one dpkg call (it is slow to start).
candidates=$(for lib in $libs; do
  echo "$lib"; readlink -f "$lib"; echo "/usr$lib"; echo "${lib#/usr}"
done | sort -u)
# shellcheck disable=SC2086
found=$(dpkg -S $candidates 2>/dev/null | cut -d: -f1 | sort -u || true)
[ -n "$found" ] || { echo "runtime-deps.sh: dpkg knows none of the libraries" >&2; exit 1; }
echo "$found"
