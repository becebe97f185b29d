#!/bin/sh
# Inside the runtime image: installs the packages listed in runtime-packages.txt (made by
# runtime-deps.sh from the programs' ldd), adds the non-root user, and leaves no package lists.
set -eu
apt-get update -q
# shellcheck disable=SC2046
apt-get install -y -q --no-install-recommends $(cat /opt/cloudcast/runtime-packages.txt)
rm -rf /var/lib/apt/lists/* /var/cache/apt/archives/*.deb /usr/share/doc/* /usr/share/man/*
useradd --system --uid 10001 --create-home --shell /usr/sbin/nologin cloudcast
