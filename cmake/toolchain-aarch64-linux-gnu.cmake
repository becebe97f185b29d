# Cross-compiling for 64-bit ARM (Jetson, Raspberry Pi 4/5, most robot SoCs) with Debian's cross
# toolchain (g++-aarch64-linux-gnu) against Debian's arm64 packages installed beside the amd64
# ones (multiarch: libraries in /usr/lib/aarch64-linux-gnu, headers shared in /usr/include).
#   cmake -S . -B build-arm64 -DCMAKE_TOOLCHAIN_FILE=cmake/toolchain-aarch64-linux-gnu.cmake \
#     -DCLOUDCAST_CLIENT_ONLY=ON
# scripts/setup --arm64 installs what this needs and builds so (docs/client.md, arm64).
set(CMAKE_SYSTEM_NAME Linux)
set(CMAKE_SYSTEM_PROCESSOR aarch64)
set(CMAKE_C_COMPILER aarch64-linux-gnu-gcc)
set(CMAKE_CXX_COMPILER aarch64-linux-gnu-g++)
# Multiarch: find_library and find_package look in lib/aarch64-linux-gnu, never in the host's
# lib/x86_64-linux-gnu. The sysroot is / (Debian's cross gcc searches the multiarch paths).
set(CMAKE_LIBRARY_ARCHITECTURE aarch64-linux-gnu)
# pkg-config (gRPC's package finds RE2 and OpenSSL with it): the cross wrapper, which reads the
# arm64 .pc files only; the host's would hand the linker /usr/lib/x86_64-linux-gnu.
set(PKG_CONFIG_EXECUTABLE aarch64-linux-gnu-pkg-config CACHE FILEPATH "pkg-config for arm64")
# Programs (protoc, grpc_cpp_plugin) are the host's: they generate code, they are not linked.
set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)
# Test programs run under qemu-user (qemu-user-static): ctest, gtest_discover_tests and
# try_run use it. Debian's arm64 loader and libraries are where qemu looks for them (/lib,
# /usr/lib/aarch64-linux-gnu), so no -L prefix is needed.
find_program(CLOUDCAST_QEMU_AARCH64 qemu-aarch64-static qemu-aarch64)
if(CLOUDCAST_QEMU_AARCH64)
  set(CMAKE_CROSSCOMPILING_EMULATOR ${CLOUDCAST_QEMU_AARCH64})
endif()
