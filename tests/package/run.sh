#!/usr/bin/env bash
# The installable client library, end to end: a client-only build of cloudcast (what a robot
# builds: engine, contract, client; gRPC, Protobuf, Draco and Abseil only), `cmake --install`
# into a scratch prefix, a separate project that finds it with find_package(cloudcast), and that
# project's program streaming one frame to a real cloudcast-server on loopback.
#   run.sh SOURCE_DIR BUILD_DIR SERVER_BINARY
# BUILD_DIR is the client-only build folder; the install prefix, the robot project and the logs
# go in its robot-side/. Make it a sibling of the main build folder (ctest passes <build>-package):
# ccache takes paths relative to the folder a compiler runs in, so at the same depth the client's
# sources hit the main build's cache entries (a cold CI run compiled them twice).
set -euo pipefail
src=$1 build=$2 server=$3
scratch=$build/robot-side
launcher=()
if command -v ccache >/dev/null; then
  # Paths relative to the checkout, as scripts/setup: a clean clone elsewhere (CI's) finds what
  # an earlier run compiled (76 s cold, 2 s warm).
  export CCACHE_BASEDIR=$src CCACHE_NOHASHDIR=1
  launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
fi
werror=OFF
[ "${CLOUDCAST_WERROR:-0}" = 1 ] && werror=ON  # as scripts/setup: CI's builds judge warnings
rm -rf "$build" && mkdir -p "$scratch"

echo "== client-only build of cloudcast"
cmake -S "$src" -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=Release \
  -DCLOUDCAST_CLIENT_ONLY=ON -DCLOUDCAST_WERROR=$werror "${launcher[@]}" >"$scratch/configure.log" ||
  { cat "$scratch/configure.log"; exit 1; }
grep -q "CLOUDCAST_WITH_PCL:BOOL=OFF" "$build/CMakeCache.txt"
cmake --build "$build" -j "$(nproc)" >"$scratch/build.log" ||
  { tail -50 "$scratch/build.log"; exit 1; }
# Nothing beyond the client's own dependencies may have been built or linked.
if grep -qiE "opencv|pcl_|open3d|prometheus|CLI11" "$build/build.ninja"; then
  echo "the client-only build references OpenCV, PCL, Open3D, prometheus-cpp or CLI11"; exit 1
fi
cmake --install "$build" --prefix "$scratch/prefix" >/dev/null

echo "== a robot project finds it with find_package(cloudcast)"
cmake -S "$src/tests/package" -B "$scratch/robot" -G Ninja -DCMAKE_BUILD_TYPE=Release \
  -DCMAKE_PREFIX_PATH="$scratch/prefix" "${launcher[@]}" >"$scratch/robot-configure.log" ||
  { cat "$scratch/robot-configure.log"; exit 1; }
cmake --build "$scratch/robot" >"$scratch/robot-build.log" || { cat "$scratch/robot-build.log"; exit 1; }

echo "== and streams one frame to a real server"
# The server's log comes through a pipe, read line by line until it names its port: each read
# blocks until the next line (or the server's exit), so nothing polls. A background cat drains
# the rest, so that the server never blocks on a full pipe.
mkfifo "$scratch/server.pipe"
: >"$scratch/server.log"
"$server" --listen 127.0.0.1:0 --metrics-listen "" --instance package-test \
  >"$scratch/server.pipe" 2>&1 &
pid=$!
trap 'kill -TERM $pid 2>/dev/null || true; wait $pid 2>/dev/null || true' EXIT
exec 3<"$scratch/server.pipe"
port=""
# -t 60 only turns a hang into a failure.
while [ -z "$port" ] && IFS= read -r -t 60 line <&3; do
  printf '%s\n' "$line" >>"$scratch/server.log"
  port=$(printf '%s\n' "$line" | sed -n 's/.*listening on 127\.0\.0\.1:\([0-9]*\).*/\1/p')
done
cat <&3 >>"$scratch/server.log" &
exec 3<&-
[ -n "$port" ] || { cat "$scratch/server.log"; echo "the server reported no port"; exit 1; }
"$scratch/robot/robot" "127.0.0.1:$port" | tee "$scratch/robot.out"
grep -q "from package-test" "$scratch/robot.out"
