#!/usr/bin/env bash
# Builds the Debian 12 base image that docker/Containerfile starts FROM, for machines that reach no
# image registry: debootstrap --variant=minbase bookworm with this machine's apt mirror, then
# podman import under the FROM name. On a machine with a registry, skip this: FROM pulls
# debian:bookworm-slim as usual (build with --build-arg BASE=docker.io/library/debian:bookworm-slim).
#
#   docker/base-image.sh [--force] [--tag NAME]
#
# An image already present under NAME is kept (debootstrap takes about 35 s) unless --force.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
. "$here/podman-env.sh"

tag=localhost/cloudcast-base:bookworm
force=0
while [ $# -gt 0 ]; do
  case "$1" in
    --force) force=1 ;;
    --tag) tag=$2; shift ;;
    -h|--help) sed -n '2,9p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "base-image.sh: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
  shift
done

if [ "$force" = 0 ] && podman image exists "$tag"; then
  echo "base-image: $tag already present (use --force to rebuild)"
  exit 0
fi
command -v debootstrap >/dev/null || { echo "base-image: debootstrap is not installed" >&2; exit 1; }
mirror=$(apt_mirror)
root=$(mktemp -d "${TMPDIR:-/tmp}/cloudcast-base.XXXXXX")
trap 'rm -rf "$root"' EXIT
echo "base-image: debootstrap --variant=minbase bookworm from $mirror"
start=$(date +%s)
debootstrap --variant=minbase bookworm "$root" "$mirror" >"$root.log" 2>&1 ||
  { tail -20 "$root.log" >&2; rm -f "$root.log"; exit 1; }
rm -f "$root.log"
# Smaller image: no package lists or caches (apt-get update in a later layer fetches them anew).
rm -rf "$root"/var/cache/apt/archives/*.deb "$root"/var/lib/apt/lists/* "$root"/usr/share/doc/* \
  "$root"/usr/share/man/*
tar -C "$root" -c . | podman import --change 'CMD ["/bin/bash"]' - "$tag" >/dev/null
echo "base-image: $tag built in $(( $(date +%s) - start )) s"
podman image ls "$tag"
