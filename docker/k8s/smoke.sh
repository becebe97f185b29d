#!/usr/bin/env bash
# The Kubernetes Deployment of docker/k8s, smoke-run with `podman kube play` (no cluster runs
# here): the runtime image built from the programs of --bin-dir and the HAProxy image, the
# Deployment with its ConfigMaps at one replica (validate/kube-play.js says what the variant
# changes for podman's host networking), then checks that the pod
#   - runs the server and the proxy as the non-root user 10001 with read-only root filesystems,
#   - gets POD_NAME from the downward API (fieldRef metadata.name),
#   - serves with the ConfigMap's config mounted (--config: 2 workers, 20 s shutdown grace),
#   - becomes healthy through the proxy and our gRPC health service (cloudcast-load --probe),
#   - answers a short lossless load through the proxy and serves /metrics,
#   - keeps a 2 s rapid reset at its gRPC port from reaching the server (cloudcast-attack),
#   - drains on SIGTERM (podman pod stop) and exits 0;
# and removes the pod and its image tags whatever happened. It checks nothing of the cluster
# itself: Services, probes, the PDB, the HPA, the NetworkPolicy and scheduling are not run by
# podman (docker/k8s/README.md).
#
#   docker/k8s/smoke.sh [--bin-dir DIR] [--work DIR]
#
# Exit 77 (a skip for ctest) only when podman cannot run containers here.
set -euo pipefail
repo=$(cd "$(dirname "$0")/../.." && pwd)
here=$repo/docker/k8s
. "$repo/docker/podman-env.sh"

bin_dir=$repo/build/bin
work=$repo/build/k8s-validate
while [ $# -gt 0 ]; do
  case "$1" in
    --bin-dir) bin_dir=$2; shift ;;
    --work) work=$2; shift ;;
    -h|--help) sed -n '2,18p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "smoke.sh: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
  shift
done
bin_dir=$(cd "$bin_dir" && pwd)

# Every podman call is bounded. A podman process killed while it held one of libpod's locks
# leaves that lock taken, and each later call that needs it waits forever: here `podman kube play`
# once hung until ctest's 900 s timeout with an empty log, and the killed run left its pod
# behind. Bounded, the smoke fails in minutes, says why, and still removes what it made.
podman_budget=${CLOUDCAST_PODMAN_TIMEOUT:-120}
podman() {
  local rc=0
  timeout -k 10 "$podman_budget" podman "$@" || rc=$?
  if [ "$rc" = 124 ] || [ "$rc" = 137 ]; then
    echo "smoke.sh: 'podman $*' did not return in $podman_budget s: a libpod lock is probably held" \
      "by a podman process that was killed; with no other podman running, 'podman system" \
      "renumber' frees it" >&2
  fi
  return "$rc"
}

command -v podman >/dev/null || { echo "smoke.sh: SKIPPED: podman is not installed" >&2; exit 77; }
info_rc=0
podman info >/dev/null 2>&1 || info_rc=$?
if [ "$info_rc" = 124 ] || [ "$info_rc" = 137 ]; then exit 1; fi  # hung: a failure, not a skip
if [ "$info_rc" != 0 ]; then
  echo "smoke.sh: SKIPPED: podman cannot run here (scripts/setup installs it)" >&2
  exit 77
fi
for c in catatonit debootstrap curl python3; do
  command -v "$c" >/dev/null ||
    { echo "smoke.sh: $c is not installed (scripts/setup installs it)" >&2; exit 1; }
done

started=$(date +%s)
step() { echo "smoke [$(( $(date +%s) - started )) s] $*"; }
passed=0 failed=0
check() {  # check WHAT COMMAND...
  local what=$1
  shift
  if "$@"; then
    passed=$((passed + 1)); echo "ok    $what"
  else
    failed=$((failed + 1)); echo "FAIL  $what"
  fi
}

name=cloudcast-smoke-$$
pod=$name-pod-0  # podman's name for the Deployment's one pod
container=$pod-server
proxy=$pod-proxy
tag=localhost/cloudcast:k8s-smoke-$$
proxy_tag=localhost/cloudcast-haproxy:k8s-smoke-$$
run=$(mktemp -d "${TMPDIR:-/tmp}/cloudcast-k8s-smoke.XXXXXX")
cleanup() {
  local code=$?
  set +e
  if [ -f "$run/play.yaml" ]; then podman kube down "$run/play.yaml" >/dev/null 2>&1; fi
  podman pod rm -f "$pod" >/dev/null 2>&1
  podman rmi "$tag" "$proxy_tag" >/dev/null 2>&1
  if podman pod exists "$pod" 2>/dev/null; then
    echo "smoke.sh: pod $pod could not be removed" >&2
    code=1
  fi
  rm -rf "$run"
  step "done (exit $code)"
  exit "$code"
}
trap cleanup EXIT
trap 'exit 130' INT TERM

step "npm packages (js-yaml) in $work"
"$here/validate/install.sh" "$work" >/dev/null
step "runtime image $tag from $bin_dir"
"$repo/docker/runtime-image.sh" --bin-dir "$bin_dir" --tag "$tag" --log "$run/build.log"
step "HAProxy image $proxy_tag (Containerfile.tools)"
podman_budget=900 podman build --network host --format docker -f "$repo/docker/Containerfile.tools" --target haproxy \
  -t "$proxy_tag" "$repo/docker" >"$run/build-haproxy.log" 2>&1 ||
  { tail -30 "$run/build-haproxy.log" >&2; exit 1; }

# A loopback address and two ports free on it, picked now.
read -r ip grpc_port backend_port metrics_port < <(python3 - <<'PY'
import random, socket, sys
rng = random.Random()
def free(ip, port):
    s = socket.socket()
    try:
        s.bind((ip, port)); return True
    except OSError:
        return False
    finally:
        s.close()
for _ in range(200):
    ip = "127.0.%d.%d" % (rng.randrange(1, 250), rng.randrange(20, 250))
    ports = [rng.randrange(20000, 60000) for _ in range(3)]
    if len(set(ports)) == 3 and all(free(ip, p) for p in ports):
        print(ip, *ports)
        sys.exit(0)
sys.exit("no free ports found")
PY
)
grpc=$ip:$grpc_port
backend=$ip:$backend_port
metrics=$ip:$metrics_port
(cd "$work" && node kube-play.js "$here" "$run/play.yaml" "$name" "$tag" "$proxy_tag" "$grpc" \
  "$backend" "$metrics")
step "podman kube play (gRPC $grpc through the proxy to $backend, metrics $metrics)"
podman kube play --network host "$run/play.yaml" >"$run/play.log" 2>&1 ||
  { cat "$run/play.log" >&2; exit 1; }

# The probe waits for the server (wait-for-ready, bounded by its timeout): no sleep needed.
check "the pod becomes healthy: gRPC health of cloudcast.v1.CloudCast is SERVING" \
  "$bin_dir/cloudcast-load" --probe --server "$grpc" --connect-timeout 60
check "the pod is running" \
  test "$(podman pod inspect "$pod" --format '{{.State}}')" = Running
check "the server runs as uid 10001 (runAsUser, runAsNonRoot)" \
  test "$(podman exec "$container" id -u)" = 10001
check "the root filesystem is read-only (readOnlyRootFilesystem)" \
  test "$(podman inspect "$container" --format '{{.HostConfig.ReadonlyRootfs}}')" = true
check "POD_NAME comes from the downward API (fieldRef metadata.name)" \
  test "$(podman exec "$container" printenv POD_NAME)" = "$pod"
check "the ConfigMap is mounted and in effect (--config: threads = 2)" \
  grep -q "listening on $backend (2 workers" <(podman logs "$container" 2>&1)
check "the proxy runs as uid 10001 on a read-only root filesystem" \
  test "$(podman exec "$proxy" id -u)" = 10001 -a \
    "$(podman inspect "$proxy" --format '{{.HostConfig.ReadonlyRootfs}}')" = true

"$bin_dir/cloudcast-load" --server "$grpc" --synthetic 64x48 --streams 2 --frames 20 --fps 20 \
  --lossless -q --json "$run/load.json" >"$run/load.txt" 2>&1 || true
answered() {
  (cd "$work" && node -e '
    const r = JSON.parse(require("fs").readFileSync(process.argv[1], "utf8"));
    process.exit(r.frames.sent === 20 && r.frames.answered === 20 ? 0 : 1);' "$run/load.json")
}
check "a short lossless load is answered: 20 of 20 frames" answered
check "/metrics serves the server's counters" \
  grep -q '^cloudcast_frames_processed_total' <(curl -fsS --max-time 10 "http://$metrics/metrics")
# The proxy in front: a rapid reset (CVE-2023-44487) at the Pod's gRPC port, from another
# address (the proxy limits each address' request rate), never reaches the server, whose count of
# Stream calls stays where the load left it.
streams() { curl -fsS --max-time 10 "http://$metrics/metrics" | awk '/^cloudcast_streams_accepted_total/ {print $2}'; }
before=$(streams)
"$bin_dir/cloudcast-attack" rapid-reset --target "$grpc" --source 127.0.0.2 \
  --path /cloudcast.v1.CloudCast/Stream --seconds 2 >"$run/attack.json" 2>&1 || true
check "a 2 s rapid reset through the proxy opens no stream on the server ($(grep -o '"pairs":[0-9]*' "$run/attack.json"))" \
  test "$(streams)" = "$before"
check "and the server still answers through the proxy" \
  "$bin_dir/cloudcast-load" --probe --server "$grpc" --connect-timeout 10

step "podman pod stop: SIGTERM, the drain"
podman pod stop -t 40 "$pod" >/dev/null
check "the server drained on SIGTERM and exited 0" \
  test "$(podman inspect "$container" --format '{{.State.ExitCode}}')" = 0
check "with the ConfigMap's 20 s shutdown grace" \
  grep -q "shutting down (grace 20000 ms)" <(podman logs "$container" 2>&1)
if [ "$failed" -gt 0 ]; then
  echo "--- server log:"; podman logs "$container" 2>&1 | tail -20
  echo "--- proxy log:"; podman logs "$proxy" 2>&1 | tail -20
  echo "--- load:"; cat "$run/load.txt"
fi
echo "$passed passed, $failed failed"
[ "$failed" = 0 ]
