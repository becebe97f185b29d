#!/bin/bash
# The runtime image's entrypoint. With no arguments, or arguments starting with '-', it runs one
# cloudcast-server replica; any other command runs as given (e.g. cloudcast-load ...).
#
# Replicas share the host's network (podman here allows nothing else), so each claims the first
# free address of CLOUDCAST_REPLICA_ADDRESSES ("IP ..."; gRPC on CLOUDCAST_GRPC_PORT, metrics on
# CLOUDCAST_METRICS_PORT): a replica that cannot bind tries the next. The server refuses a busy
# port (it turns SO_REUSEPORT off), so two replicas never share one. The address goes to
# /tmp/cloudcast-listen for the HEALTHCHECK. SIGTERM drains the server gracefully.
set -u
if [ $# -gt 0 ] && [ "${1#-}" = "$1" ]; then exec "$@"; fi
addresses=${CLOUDCAST_REPLICA_ADDRESSES:-0.0.0.0}
grpc_port=${CLOUDCAST_GRPC_PORT:-50051}
metrics_port=${CLOUDCAST_METRICS_PORT:-9464}
pid=""
# Whether process $1 owns a TCP socket listening on IPv4 $2:$3, from /proc (no tools needed).
# gRPC listens on a dual-stack socket, so the address may be IPv4-mapped in /proc/net/tcp6.
listening() {
  local ip port inodes
  ip=$(printf '%02X%02X%02X%02X' $(echo "$2" | awk -F. '{print $4, $3, $2, $1}'))
  port=$(printf '%04X' "$3")
  inodes=$(ls -l "/proc/$1/fd" 2>/dev/null | sed -n 's/.*socket:\[\([0-9]*\)\].*/\1/p')
  [ -n "$inodes" ] || return 1
  cat /proc/net/tcp /proc/net/tcp6 2>/dev/null |
    awk -v a="$ip:$port" -v b="0000000000000000FFFF0000$ip:$port" \
      '($2 == a || $2 == b) && $4 == "0A" {print $10}' | grep -qxF "$inodes"
}
trap '[ -n "$pid" ] && kill -TERM "$pid"' TERM INT
for ip in $addresses; do
  log=/tmp/cloudcast-server.$ip.log
  cloudcast-server --listen "$ip:$grpc_port" --metrics-listen "$ip:$metrics_port" \
    --instance "cloudcast-$ip" "$@" >"$log" 2>&1 &
  pid=$!
  # Up to 20 s: either it exits (the address is taken: try the next) or it holds the listening
  # socket itself (another replica may answer on the address meanwhile, so no probe can tell).
  ours=0
  for _ in $(seq 200); do
    kill -0 "$pid" 2>/dev/null || break
    if listening "$pid" "$ip" "$grpc_port"; then
      ours=1
      break
    fi
    sleep 0.1
  done
  if [ "$ours" = 1 ]; then
    echo "$ip:$grpc_port" >/tmp/cloudcast-listen
    cat "$log"
    tail -f -n 0 "$log" &
    wait "$pid"
    status=$?
    # A signal interrupts the first wait; the second one waits for the drain to finish.
    kill -0 "$pid" 2>/dev/null && wait "$pid" && status=$?
    exit "$status"
  fi
  kill -KILL "$pid" 2>/dev/null  # neither bound nor gone within 20 s
  wait "$pid" 2>/dev/null
  cat "$log" >&2
  pid=""
done
echo "serve.sh: no free address among '$addresses' (ports $grpc_port, $metrics_port)" >&2
exit 1
