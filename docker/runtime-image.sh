#!/usr/bin/env bash
# Builds the runtime image localhost/cloudcast:latest: the Debian base (base-image.sh, kept
# between runs), then either the runtime stage alone from programs built beforehand
# (Containerfile.prebuilt; what CI and the tests use) or the whole multi-stage build from source
# (Containerfile, about 6 minutes more). Used by loadtest.sh and k8s/smoke.sh.
#
#   docker/runtime-image.sh [--bin-dir DIR | --full-build] [--tag NAME] [--log FILE]
#
#   --bin-dir DIR   the programs to put in the image (default build/bin)
#   --full-build    build from source instead
#   --tag NAME      the image's name (default localhost/cloudcast:latest)
#   --log FILE      podman build's output (default: a temporary file, shown on failure)
set -euo pipefail
repo=$(cd "$(dirname "$0")/.." && pwd)
here=$repo/docker
. "$here/podman-env.sh"

bin_dir=$repo/build/bin full=0 log="" tag=localhost/cloudcast:latest
while [ $# -gt 0 ]; do
  case "$1" in
    --bin-dir) bin_dir=$2; shift ;;
    --full-build) full=1 ;;
    --tag) tag=$2; shift ;;
    --log) log=$2; shift ;;
    -h|--help) sed -n '2,12p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "runtime-image.sh: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
  shift
done
work=$(mktemp -d "${TMPDIR:-/tmp}/cloudcast-image.XXXXXX")
trap 'rm -rf "$work"' EXIT
[ -n "$log" ] || log=$work/build.log

"$here/base-image.sh"
if [ "$full" = 1 ]; then
  echo "runtime-image: from source (docker/Containerfile)"
  podman build --network host --format docker -f "$here/Containerfile" -t "$tag" "$repo" \
    >"$log" 2>&1 || { tail -30 "$log" >&2; exit 1; }
  exit 0
fi
echo "runtime-image: from $bin_dir (docker/Containerfile.prebuilt)"
ctx=$work/context
mkdir -p "$ctx/bin"
for p in cloudcast-server cloudcast-load cloudcast-null-server; do
  [ -x "$bin_dir/$p" ] || { echo "runtime-image.sh: $bin_dir/$p is missing: build first" >&2; exit 1; }
  cp "$bin_dir/$p" "$ctx/bin/"
done
"$here/runtime-deps.sh" "$ctx"/bin/* >"$ctx/runtime-packages.txt"
cp "$here/runtime-setup.sh" "$here/serve.sh" "$here/healthcheck.sh" "$ctx/"
podman build --network host --format docker -f "$here/Containerfile.prebuilt" \
  -t "$tag" "$ctx" >"$log" 2>&1 || { tail -30 "$log" >&2; exit 1; }
