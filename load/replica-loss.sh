#!/usr/bin/env bash
# The replica-loss run of README.md: three cloudcast-server processes on 127.0.0.1, 127.0.0.2 and
# 127.0.0.3 (one free port), cloudcast-load with resilient DELIVERY_ALL streams over one
# round_robin channel, and one replica stopped mid-run with SIGKILL (killed) or SIGTERM (drained).
# The table (per stream: sent, answered, resent, lost, reconnects and their times; per replica:
# streams and frames) goes to stdout and OUT/load.txt, the reports to OUT/report.{json,html}.
# Only loopback addresses; every process it started is stopped at the end.
#
#   load/replica-loss.sh [--signal KILL|TERM] [--at S] [--duration S] [--streams N] [--fps F]
#                        [--threads N] [--bin-dir DIR] [--out DIR] [-- extra cloudcast-load flags]
#
# Defaults: KILL at 8 s of a 20 s run, 6 streams at 15 fps, 1 worker per replica, build/bin,
# out/replica-loss-<signal>. Frames: New Tsukuba when ../shared/data/new_tsukuba is there.
set -euo pipefail
repo=$(cd "$(dirname "$0")/.." && pwd)
signal=KILL at=8 duration=20 streams=6 fps=15 threads=1 bin_dir=$repo/build/bin out="" extra=()
while [ $# -gt 0 ]; do
  case "$1" in
    --signal) signal=$2; shift ;;
    --at) at=$2; shift ;;
    --duration) duration=$2; shift ;;
    --streams) streams=$2; shift ;;
    --fps) fps=$2; shift ;;
    --threads) threads=$2; shift ;;
    --bin-dir) bin_dir=$2; shift ;;
    --out) out=$2; shift ;;
    -h|--help) sed -n '2,14p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    --) shift; extra=("$@"); break ;;
    *) echo "replica-loss.sh: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
  shift
done
case "$signal" in KILL|TERM) ;; *) echo "replica-loss.sh: --signal KILL or TERM" >&2; exit 2 ;; esac
out=${out:-$repo/out/replica-loss-$(echo "$signal" | tr A-Z a-z)}
mkdir -p "$out"
port=$(python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
pids=()
cleanup() {
  for p in "${pids[@]}"; do kill -KILL "$p" 2>/dev/null || true; done
  wait 2>/dev/null || true
}
trap cleanup EXIT
target=ipv4:
for i in 1 2 3; do
  "$bin_dir/cloudcast-server" --listen "127.0.0.$i:$port" --metrics-listen "" \
    --instance "replica-$i" --threads "$threads" --log-level info >"$out/replica-$i.log" 2>&1 &
  pids+=($!)
  target+="$([ "$i" = 1 ] || echo ,)127.0.0.$i:$port"
done
for i in 1 2 3; do
  "$bin_dir/cloudcast-load" --probe --server "127.0.0.$i:$port" --connect-timeout 20 >/dev/null
done
data=${CLOUDCAST_DATA:-$repo/../shared/data/new_tsukuba}
# The paper's setting, stated (the server assumes no passthrough): both sources are 640x480.
source_args=(--synthetic 640x480 --camera-preset new_tsukuba)
[ -d "$data/groundtruth" ] && source_args=(--tsukuba "$data" --camera-preset new_tsukuba)
"$bin_dir/cloudcast-load" --server "$target" --connections 1 --streams "$streams" --fps "$fps" \
  --duration "$duration" --lossless --resilient "${source_args[@]}" --json "$out/report.json" \
  --html "$out/report.html" "${extra[@]}" >"$out/load.txt" 2>"$out/progress.txt" &
load=$!
# The load prepares its frames and connects first: the stop is timed from its first progress
# line (one second into the schedule).
for _ in $(seq 600); do
  grep -q "frames/s" "$out/progress.txt" 2>/dev/null && break
  sleep 0.1
done
sleep "$(python3 -c "print(max(0, $at - 1))")"
echo "replica-loss: SIG$signal replica-2 at about $at s" | tee "$out/event.txt"
kill "-$signal" "${pids[1]}"
wait "$load"
wait "${pids[1]}" && status=0 || status=$?
echo "replica-2 exit status: $status" | tee -a "$out/event.txt"
cat "$out/load.txt"
