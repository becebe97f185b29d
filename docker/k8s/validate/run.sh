#!/usr/bin/env bash
# ctest's k8s.manifests_validate: validates docker/k8s/*.yaml offline (validate.js says what it
# checks), with the npm packages install.sh puts into WORK_DIR.
#
#   docker/k8s/validate/run.sh WORK_DIR [PATH/cloudcast-server]
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
work=${1:?usage: run.sh WORK_DIR [PATH/cloudcast-server]}
"$here/install.sh" "$work"
cd "$work"
if [ -n "${2:-}" ]; then exec node validate.js "$here/.." --server "$2"; fi
exec node validate.js "$here/.."
