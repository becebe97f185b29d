#!/usr/bin/env bash
# The soak of README.md: one cloudcast-server on 127.0.0.1 and cloudcast-load with 4 DELIVERY_ALL
# streams at 30 fps, the server's resident memory sampled from its /metrics every 5 s. It fails
# (exit 3) when any frame is lost, unsent, answered with an error or not answered, or when the
# memory after the warm-up rises more than the bound above its value at the warm-up's end.
# The table (with the memory series) goes to stdout and OUT/soak.txt, the reports (the memory
# chart among them) to OUT/report.{json,html}, the server's log to OUT/server.log.
#
#   load/soak.sh [--duration S] [--streams N] [--fps F] [--warmup S] [--max-growth-mb MB]
#                [--interval S] [--bin-dir DIR] [--out DIR] [-- extra cloudcast-load flags]
#
# Defaults: 600 s (CI runs 60), 4 streams at 30 fps, 15 s warm-up, +64 MB, samples every 5 s,
# build/bin, out/soak. Frames: New Tsukuba when ../shared/data/new_tsukuba is there, else the
# synthetic 640x480 scene. Only loopback; the server is stopped at the end (SIGTERM, and its exit
# status must be 0).
set -euo pipefail
repo=$(cd "$(dirname "$0")/.." && pwd)
duration=600 streams=4 fps=30 warmup=15 growth=64 interval=5 bin_dir=$repo/build/bin out=""
extra=()
while [ $# -gt 0 ]; do
  case "$1" in
    --duration) duration=$2; shift ;;
    --streams) streams=$2; shift ;;
    --fps) fps=$2; shift ;;
    --warmup) warmup=$2; shift ;;
    --max-growth-mb) growth=$2; shift ;;
    --interval) interval=$2; shift ;;
    --bin-dir) bin_dir=$2; shift ;;
    --out) out=$2; shift ;;
    -h|--help) sed -n '2,15p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    --) shift; extra=("$@"); break ;;
    *) echo "soak.sh: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
  shift
done
out=${out:-$repo/out/soak}
mkdir -p "$out"
free_port() {
  python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])'
}
port=$(free_port) metrics_port=$(free_port)
server=""
cleanup() { [ -n "$server" ] && kill -KILL "$server" 2>/dev/null || true; }
trap cleanup EXIT
"$bin_dir/cloudcast-server" --listen "127.0.0.1:$port" --metrics-listen "127.0.0.1:$metrics_port" \
  --instance soak --log-level info >"$out/server.log" 2>&1 &
server=$!
"$bin_dir/cloudcast-load" --probe --server "127.0.0.1:$port" --connect-timeout 20 >/dev/null
data=${CLOUDCAST_DATA:-$repo/../shared/data/new_tsukuba}
# The paper's setting, stated (the server assumes no passthrough): both sources are 640x480 with
# its camera.
source_args=(--synthetic 640x480 --camera-preset new_tsukuba)
[ -d "$data/groundtruth" ] && source_args=(--tsukuba "$data" --camera-preset new_tsukuba)
status=0
"$bin_dir/cloudcast-load" --server "127.0.0.1:$port" --streams "$streams" --fps "$fps" \
  --duration "$duration" --lossless "${source_args[@]}" \
  --watch-memory "http://127.0.0.1:$metrics_port/metrics" --memory-interval "$interval" \
  --soak --soak-warmup "$warmup" --soak-max-growth-mb "$growth" --progress 0 \
  --json "$out/report.json" --html "$out/report.html" "${extra[@]}" >"$out/soak.txt" ||
  status=$?
cat "$out/soak.txt"
kill -TERM "$server"
server_status=0
wait "$server" || server_status=$?
server=""
if [ "$server_status" != 0 ]; then
  echo "soak.sh: the server exited with status $server_status on SIGTERM (see $out/server.log)" >&2
  [ "$status" = 0 ] && status=1
fi
exit "$status"
