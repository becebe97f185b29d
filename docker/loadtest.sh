#!/usr/bin/env bash
# The containerised load test: builds the images, starts N cloudcast-server replicas behind
# HAProxy with Prometheus scraping them (docker/compose.yaml, podman-compose), runs cloudcast-load
# through the balancer, and collects its ghz-shaped JSON, its HTML page and Prometheus' frames per
# replica into the output folder. Everything it started is removed at the end, on success and on
# failure alike. Only loopback addresses are used, with free ports probed at start.
#
#   docker/loadtest.sh [options] [-- extra cloudcast-load flags]
#
#   --replicas N        server replicas (default 2)
#   --streams N         concurrent streams (default 16)
#   --fps F             frames per second per stream (default 30)
#   --duration S        seconds of load (default 20)
#   --lossless          DELIVERY_ALL (every frame answered); default DELIVERY_LATEST
#   --server-threads N  worker threads per replica (default 1: N replicas share the 2 cores)
#   --out DIR           output folder (default out/loadtest)
#   --bin-dir DIR       programs for the runtime image, built beforehand (default build/bin);
#                       the image is then built from them (Containerfile.prebuilt)
#   --full-build        build the runtime image from source (docker/Containerfile, ~6 min more)
#   --ci                CI's short run: 2 replicas, 4 streams at 30 fps for 4 s, lossless; fails
#                       if any frame is lost or any replica answered none
#   -h, --help          this text
#
# Needs podman, podman-compose, runc and debootstrap (scripts/setup --long installs them).
set -euo pipefail
repo=$(cd "$(dirname "$0")/.." && pwd)
here=$repo/docker
. "$here/podman-env.sh"

replicas=2 streams=16 fps=30 duration=20 lossless=0 server_threads=1 ci=0 full=0
out=$repo/out/loadtest
bin_dir=$repo/build/bin
extra=()
while [ $# -gt 0 ]; do
  case "$1" in
    --replicas) replicas=$2; shift ;;
    --streams) streams=$2; shift ;;
    --fps) fps=$2; shift ;;
    --duration) duration=$2; shift ;;
    --lossless) lossless=1 ;;
    --server-threads) server_threads=$2; shift ;;
    --out) out=$2; shift ;;
    --bin-dir) bin_dir=$2; shift ;;
    --full-build) full=1 ;;
    --ci) ci=1 ;;
    -h|--help) sed -n '2,27p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    --) shift; extra=("$@"); break ;;
    *) echo "loadtest.sh: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
  shift
done
if [ "$ci" = 1 ]; then replicas=2 streams=4 fps=30 duration=4 lossless=1; fi
for v in replicas streams duration server_threads; do
  [[ ${!v} =~ ^[0-9]+$ ]] && [ "${!v}" -ge 1 ] ||
    { echo "loadtest.sh: --${v//_/-} must be a whole number >= 1, got '${!v}'" >&2; exit 2; }
done
[ "$replicas" -le 32 ] || { echo "loadtest.sh: --replicas is at most 32" >&2; exit 2; }
[ "$duration" -le 600 ] || { echo "loadtest.sh: --duration is at most 600 s" >&2; exit 2; }
for c in podman podman-compose python3 curl debootstrap; do
  if ! command -v "$c" >/dev/null; then
    echo "loadtest.sh: $c is not installed (scripts/setup --long installs it)" >&2
    [ "$ci" = 1 ] && { echo "loadtest.sh: SKIPPED: the containerised test cannot run here" >&2; exit 77; }
    exit 1
  fi
done
# Installed is not enough: inside a container podman may not run at all ("overlay is not supported
# over overlayfs"), which `podman info` tells in a second (k8s/smoke.sh checks the same way).
if ! podman info >/dev/null 2>&1; then
  echo "loadtest.sh: podman cannot run here: $(podman info 2>&1 | tail -1)" >&2
  [ "$ci" = 1 ] && { echo "loadtest.sh: SKIPPED: the containerised test cannot run here" >&2; exit 77; }
  exit 1
fi

started=$(date +%s)
step() { echo "loadtest [$(( $(date +%s) - started )) s] $*"; }
mkdir -p "$out"
out=$(cd "$out" && pwd)
rm -f "$out/report.json" "$out/report.html" "$out/prometheus-frames.json"
run=$(mktemp -d "${TMPDIR:-/tmp}/cloudcast-loadtest.XXXXXX")
chmod 0777 "$run" "$out"  # the containers' users (cloudcast, prometheus) write here
project=cloudcast-loadtest-$$

cleanup() {
  local code=$?
  set +e
  if [ -f "$run/compose.env" ]; then
    step "stopping the stack"
    (cd "$here" && podman-compose --podman-path "$here/podman-hostnet" -p "$project" -f compose.yaml \
      down -t 10 >"$run/down.log" 2>&1)
  fi
  # Whatever compose left (a failed start, a run container): by its project label, then its pod
  # and networks.
  ids=$(podman ps -aq --filter "label=io.podman.compose.project=$project" 2>/dev/null)
  [ -n "$ids" ] && podman rm -f -t 5 $ids >/dev/null 2>&1
  podman pod rm -f "pod_$project" >/dev/null 2>&1
  for n in $(podman network ls -q --filter "label=io.podman.compose.project=$project" 2>/dev/null); do
    podman network rm -f "$n" >/dev/null 2>&1
  done
  left=$(podman ps -aq --filter "label=io.podman.compose.project=$project" 2>/dev/null | wc -l)
  [ "$left" = 0 ] || { echo "loadtest.sh: $left containers could not be removed" >&2; code=1; }
  cp "$run"/*.log "$out/" 2>/dev/null
  rm -rf "$run"
  step "done (exit $code)"
  exit "$code"
}
trap cleanup EXIT
trap 'exit 130' INT TERM

# --- images -------------------------------------------------------------------------------------
step "runtime image ($([ "$full" = 1 ] && echo "from source" || echo "from $bin_dir"))"
image_args=(--bin-dir "$bin_dir" --log "$run/build-runtime.log")
[ "$full" = 1 ] && image_args=(--full-build --log "$run/build-runtime.log")
"$here/runtime-image.sh" "${image_args[@]}"
step "load balancer and Prometheus images"
for target in haproxy prometheus; do
  podman build --network host --format docker -f "$here/Containerfile.tools" --target "$target" \
    -t "localhost/cloudcast-$target:latest" "$here" >"$run/build-$target.log" 2>&1 ||
    { tail -30 "$run/build-$target.log" >&2; exit 1; }
done
podman image ls --format '{{.Repository}}:{{.Tag}} {{.Size}}' | grep 'localhost/cloudcast' |
  tee "$out/image-sizes.txt"

# --- addresses: one loopback address per replica, ports free on all of them -----------------------
read -r grpc_port metrics_port lb_port prom_port ips < <(python3 - "$replicas" <<'PY'
import random, socket, sys
n = int(sys.argv[1])
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
    block = rng.randrange(1, 250)  # 127.0.<block>.x
    ips = ["127.0.%d.%d" % (block, 10 + i) for i in range(n)]
    ports = [rng.randrange(20000, 60000) for _ in range(4)]
    if len(set(ports)) == 4 and all(free(ip, p) for ip in ips for p in ports[:2]) and \
       all(free("127.0.0.1", p) for p in ports[2:]):
        print(*ports, " ".join(ips).replace(" ", ","))
        sys.exit(0)
sys.exit("no free ports found")
PY
)
ips=${ips//,/ }
lb=127.0.0.1:$lb_port
prom=127.0.0.1:$prom_port
step "replicas on ${ips// /, } (gRPC :$grpc_port, metrics :$metrics_port), balancer $lb, Prometheus $prom"

{
  # The shipped front (docker/haproxy/cloudcast.cfg: the limits that keep HTTP/2 floods from the
  # servers), and a backend of the replicas.
  cat "$here/haproxy/cloudcast.cfg"
  echo
  echo "backend cloudcast"
  echo "  # Each Stream call (an h2 stream) goes to the next replica."
  echo "  balance roundrobin"
  echo "  # Backend connections of its own for each client connection (issue 30: a shared one froze"
  echo "  # every client behind one whose stream could not drain; docker/haproxy/backend-local.cfg)."
  echo "  http-reuse never"
  i=1
  for ip in $ips; do
    echo "  server replica$i $ip:$grpc_port proto h2 check inter 1s"
    i=$((i + 1))
  done
} >"$run/haproxy.cfg"
{
  echo "global:"
  echo "  scrape_interval: 1s"
  echo "scrape_configs:"
  echo "  - job_name: cloudcast"
  echo "    static_configs:"
  echo "      - targets: [$(for ip in $ips; do printf "'%s:%s'," "$ip" "$metrics_port"; done | sed 's/,$//')]"
} >"$run/prometheus.yml"
cp "$run/haproxy.cfg" "$run/prometheus.yml" "$out/"

data_dir=${CLOUDCAST_DATA:-$repo/../shared/data/new_tsukuba}
if [ -f "$data_dir/groundtruth/disparity_maps/left/tsukuba_disparity_L_00001.png" ]; then
  data_dir=$(cd "$data_dir" && pwd)
  source_args=(--tsukuba /data)
else
  data_dir=$run
  source_args=(--synthetic 640x480)
fi

export CLOUDCAST_REPLICAS=$replicas CLOUDCAST_REPLICA_ADDRESSES=$ips CLOUDCAST_GRPC_PORT=$grpc_port \
  CLOUDCAST_METRICS_PORT=$metrics_port CLOUDCAST_LB_ADDRESS=$lb CLOUDCAST_PROMETHEUS_LISTEN=$prom \
  CLOUDCAST_RUN_DIR=$run CLOUDCAST_OUT_DIR=$out CLOUDCAST_DATA_DIR=$data_dir CLOUDCAST_SERVER_THREADS=$server_threads
env | grep '^CLOUDCAST_' >"$run/compose.env"
compose() {
  (cd "$here" && podman-compose --podman-path "$here/podman-hostnet" -p "$project" -f compose.yaml "$@")
}

# --- the stack ----------------------------------------------------------------------------------
step "starting $replicas replicas, the balancer and Prometheus"
compose up -d server lb prometheus >"$run/up.log" 2>&1 || { tail -30 "$run/up.log" >&2; exit 1; }
servers=$(podman ps -aq --filter "label=io.podman.compose.project=$project" \
  --filter "label=com.docker.compose.service=server")
[ "$(echo "$servers" | wc -w)" = "$replicas" ] ||
  { echo "loadtest.sh: $(echo "$servers" | wc -w) of $replicas replicas were created" >&2; exit 1; }
# The HEALTHCHECK itself (gRPC health of each replica), run by hand: podman runs it on systemd
# timers, and there is no systemd here. Up to 30 s per replica.
for c in $servers; do
  for i in $(seq 60); do
    podman healthcheck run "$c" >/dev/null 2>&1 && break
    if [ "$i" = 60 ] || [ "$(podman inspect -f '{{.State.Running}}' "$c")" != true ]; then
      echo "loadtest.sh: replica $c is not healthy:" >&2
      podman logs "$c" >&2
      exit 1
    fi
    sleep 0.5
  done
done
step "replicas healthy; probing through the balancer"
for i in $(seq 40); do
  compose run --rm --no-deps load cloudcast-load --probe --server "$lb" --connect-timeout 2 \
    >"$run/probe.log" 2>&1 && break
  [ "$i" = 40 ] && { cat "$run/probe.log" >&2; exit 1; }
  sleep 0.5
done

# --- the load -------------------------------------------------------------------------------------
load_args=(--server "$lb" --streams "$streams" --fps "$fps" --duration "$duration"
  --json /out/report.json --html /out/report.html "${source_args[@]}")
[ "$lossless" = 1 ] && load_args+=(--lossless)
step "cloudcast-load ${load_args[*]} ${extra[*]:-}"
compose run --rm --no-deps load cloudcast-load "${load_args[@]}" "${extra[@]}" \
  2>&1 | tee "$out/load.txt"
# podman-compose 1.0.3 exits 0 whatever its container did: the report tells.
[ "${PIPESTATUS[0]}" = 0 ] && [ -s "$out/report.json" ] ||
  { echo "loadtest.sh: cloudcast-load failed (no $out/report.json)" >&2; exit 1; }

# Prometheus: the replicas' counters after one more scrape.
sleep 2.5
curl -fsS "http://$prom/api/v1/query" --data-urlencode \
  'query=sum by (instance) (cloudcast_frames_processed_total)' >"$out/prometheus-frames.json"
python3 - "$out" "$ci" "$replicas" <<'PY'
import json, sys
out, ci, replicas = sys.argv[1], sys.argv[2] == "1", int(sys.argv[3])
prom = json.load(open(out + "/prometheus-frames.json"))["data"]["result"]
per = {r["metric"]["instance"]: float(r["value"][1]) for r in prom}
print("Prometheus, cloudcast_frames_processed_total per replica:")
for k in sorted(per):
    print("  %-24s %8.0f" % (k, per[k]))
rep = json.load(open(out + "/report.json"))
f = rep["frames"]
print("report: %d sent, %d answered, %d lost, %d unsent, %d errors, %d dropped; replies per replica: %s"
      % (f["sent"], f["answered"], f["lost"], f["unsent"], f["frameErrors"], f["dropped"],
         rep["framesPerReplica"]))
if ci:
    problems = []
    if f["sent"] == 0 or f["answered"] != f["sent"] or f["lost"] or f["unsent"] or f["frameErrors"] or f["dropped"]:
        problems.append("frames were lost: %s" % f)
    if len(rep["framesPerReplica"]) != replicas or min(rep["framesPerReplica"].values()) == 0:
        problems.append("a replica answered nothing: %s" % rep["framesPerReplica"])
    if len(per) != replicas or min(per.values()) == 0:
        problems.append("Prometheus saw a replica with no frames: %s" % per)
    if problems:
        sys.exit("loadtest --ci FAILED: " + "; ".join(problems))
    print("loadtest --ci: every frame answered, every replica busy")
PY
step "report in $out (report.json, report.html, prometheus-frames.json, load.txt)"
