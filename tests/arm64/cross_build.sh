#!/usr/bin/env bash
# The arm64 client, as a robot builds and uses it (tests/arm64_client_test.cc drives this):
#  1. scripts/build-arm64: the client-only cross build with its unit tests (warm through ccache);
#  2. those unit tests under qemu-user (ctest uses the toolchain's CMAKE_CROSSCOMPILING_EMULATOR);
#  3. `cmake --install` into a scratch prefix: an arm64 install tree, without the x86-64 engine;
#  4. tests/package, a robot's own project, cross-built against it with find_package(cloudcast);
#  and the ROS 2 and ROS 1 bridges, when their arm64 libraries are there (cyclonedds-dev:arm64;
#  libroscpp4d:arm64 and the rest): built, their unit tests among those of step 2, their --help run
#  under qemu-user; and the robot example when OpenCV's arm64 libraries are unpacked.
# The test then runs that robot under qemu-user against an amd64 cloudcast-server.
#   cross_build.sh SOURCE_DIR SCRATCH_DIR
# Exit 77 (the test skips) when the cross toolchain, qemu-user or the arm64 packages are missing.
set -euo pipefail
src=$1 scratch=$2
missing=()
for tool in aarch64-linux-gnu-g++ aarch64-linux-gnu-pkg-config qemu-aarch64-static; do
  command -v "$tool" >/dev/null || missing+=("$tool")
done
for pkg in libgrpc++-dev:arm64 libprotobuf-dev:arm64 libdraco-dev:arm64 libzstd-dev:arm64 \
           libgtest-dev:arm64; do
  dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" ||
    missing+=("$pkg")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "missing ${missing[*]} (scripts/setup --arm64 installs them)" >&2
  exit 77
fi
mkdir -p "$scratch"

echo "== cross build (scripts/build-arm64)"
start=$SECONDS
"$src/scripts/build-arm64" "$scratch/cloudcast" >"$scratch/build.log" 2>&1 ||
  { tail -50 "$scratch/build.log" >&2; exit 1; }
echo "cross build: $((SECONDS - start)) s"
# None of the server's or the benchmarks' dependencies, and none of the x86-64 engine. (OpenCV,
# PCL, GL, FFmpeg and CLI11, when scripts/setup provided them, only for the robot example,
# cloudcast-client and the bridges' encoders: the installed client library is checked below.)
if grep -qiE "open3d|prometheus" "$scratch/cloudcast/build.ninja"; then
  echo "the arm64 client build references Open3D or prometheus-cpp" >&2
  exit 1
fi
if grep -qE "draco_sequential_encoder|voxel_grid\.cc|pipeline\.cc|filters\.cc" \
     "$scratch/cloudcast/build.ninja"; then
  echo "the arm64 client build compiles the engine's SIMD stages or the Draco encoder" >&2
  exit 1
fi

echo "== the client's unit tests under qemu-user"
grep -ho "qemu-aarch64[a-z-]*" "$scratch"/cloudcast/tests/client_only/*_tests.cmake | sort -u
# Once per build: arm64_client_test runs this script before each of its tests, and the unit tests
# under qemu-user are most of its time (5 s); they run again when a test program changed.
stamp=$(find "$scratch/cloudcast/bin" -type f -printf '%P %s %T@\n' | sort | md5sum)
if [ "$(cat "$scratch/ctest.stamp" 2>/dev/null)" != "$stamp" ]; then
  rm -f "$scratch/ctest.stamp"
  # On every core: the test that runs this is SERIAL, and each unit test is a qemu-user process.
  ctest --test-dir "$scratch/cloudcast" --output-on-failure --timeout 120 -j "$(nproc)" \
    >"$scratch/ctest.log" 2>&1 ||
    { cat "$scratch/ctest.log" >&2; exit 1; }
  echo "$stamp" >"$scratch/ctest.stamp"
else
  echo "(the same test programs as the last run, which passed: its log)"
fi
grep "tests passed" "$scratch/ctest.log"

# A ROS bridge, a robot program: AArch64 code, its unit tests among those that passed above (by
# their label, tests/client_only/), and the program starting under qemu-user (--help).
#   report_bridge KEY PROGRAM TEST_LABEL WHAT_INSTALLS_IT
report_bridge() {
  local key=$1 bridge="$scratch/cloudcast/bin/$2" label=$3 needs=$4
  echo "== the $key bridge, a robot program (built when $needs is installed)"
  if [ ! -x "$bridge" ]; then
    echo "$key bridge: not built (scripts/setup --arm64 installs $needs)"
    return
  fi
  echo "$key bridge: $(aarch64-linux-gnu-readelf -h "$bridge" | awk '/Machine:/ {print $2}')"
  echo "$key unit tests under qemu-user: $(ctest --test-dir "$scratch/cloudcast" -N -L "$label" |
    sed -n 's/^Total Tests: //p') passed"
  echo "$key bridge --help under qemu-user: $("$qemu" "$bridge" --help 2>&1 | head -1)"
}
# qemu-user as the build runs its tests: with the unpacked arm64 libraries (cmake/qemu-wrapper.cmake).
qemu=$scratch/cloudcast/qemu-aarch64
report_bridge ros2 cloudcast-ros2-bridge 'unit/ros2_' "cyclonedds-dev:arm64"
report_bridge ros1 cloudcast-ros-bridge 'unit/ros_bridge' "libroscpp4d:arm64 (roscpp's runtime)"

echo "== install, and a robot project finds it with find_package(cloudcast)"
rm -rf "$scratch/prefix" "$scratch/robot"
cmake --install "$scratch/cloudcast" --prefix "$scratch/prefix" >/dev/null
launcher=()
command -v ccache >/dev/null && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
cmake -S "$src/tests/package" -B "$scratch/robot" -G Ninja -DCMAKE_BUILD_TYPE=Release \
  -DCMAKE_TOOLCHAIN_FILE="$src/cmake/toolchain-aarch64-linux-gnu.cmake" \
  -DCMAKE_PREFIX_PATH="$scratch/prefix" "${launcher[@]}" >"$scratch/robot-configure.log" 2>&1 ||
  { cat "$scratch/robot-configure.log" >&2; exit 1; }
cmake --build "$scratch/robot" >"$scratch/robot-build.log" 2>&1 ||
  { cat "$scratch/robot-build.log" >&2; exit 1; }
echo "robot: $(aarch64-linux-gnu-readelf -h "$scratch/robot/robot" | awk '/Machine:/ {print $2}')"
# The client library alone: gRPC, Protobuf, Draco, Abseil and zstd.
if grep -rqiE "opencv|pcl|glfw|epoxy|avcodec|CLI11|spdlog" "$scratch/prefix/lib/cmake/cloudcast" ||
   aarch64-linux-gnu-readelf -d "$scratch/robot/robot" | grep -qiE "opencv|pcl|glfw|epoxy|avcodec"; then
  echo "the installed arm64 client library's package, or the robot linked against it, needs" \
       "more than the client library's own dependencies" >&2
  exit 1
fi

# A robot program beyond the library: AArch64 code, starting under qemu-user (--help).
#   report_program KEY PROGRAM WHAT_PROVIDES_ITS_LIBRARIES
report_program() {
  local key=$1 program="$scratch/cloudcast/bin/$2" needs=$3
  echo "== $key (built when $needs)"
  if [ ! -x "$program" ]; then
    echo "$key: not built (scripts/setup --arm64 provides its arm64 libraries)"
    return
  fi
  echo "$key: $(aarch64-linux-gnu-readelf -h "$program" | awk '/Machine:/ {print $2}')"
  echo "$key --help under qemu-user: $("$qemu" "$program" --help 2>&1 | head -1)"
}
# The README's robot example (cv::Mat frames, PNG folders through OpenCV's imgcodecs), and
# cloudcast-client (run without a window on a robot).
report_program "robot example" cloudcast-robot-example "OpenCV's arm64 libraries are unpacked"
report_program cloudcast-client cloudcast-client "PCL's and OpenCV's arm64 libraries are unpacked"
