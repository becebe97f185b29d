# Sourced by scripts/sanitize and scripts/fuzz: configures the one ASan + UBSan build folder both
# use. With clang-14 (the default) it also builds the libFuzzer harnesses
# (CLOUDCAST_BUILD_FUZZERS=ON: every object with -fsanitize=fuzzer-no-link,address,undefined), so
# that the suite under ASan and the fuzzers share every library object: apart, a cold CI run
# compiled the libraries twice (the fuzz build took 191 s, most of it the ASan build's work again).
#
#   configure_asan_build BUILD_DIR   run from the checkout's root; configures once (the folder
#                                    keeps what it was configured with: compiler, fuzzers)
#   asan_build_has_fuzzers BUILD_DIR true when that folder builds the harnesses
#
# CLOUDCAST_ASAN_COMPILER: clang (clang-14, the default: a cold build in 548 s against gcc's
# 1,435, docs/testing.md) or gcc (no fuzzers: libFuzzer is clang's). Without clang-14 and without
# that variable: gcc, saying so.
configure_asan_build() {
  local build_dir=$1
  [ -f "$build_dir/build.ninja" ] && return 0
  local launcher=() compiler=() fuzzers=OFF
  command -v ccache >/dev/null && launcher=(-DCMAKE_C_COMPILER_LAUNCHER=ccache
                                           -DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
  local asan_compiler=${CLOUDCAST_ASAN_COMPILER:-clang}
  case "$asan_compiler" in
    gcc|clang) ;;
    *) echo "asan build: CLOUDCAST_ASAN_COMPILER is '$asan_compiler'; must be gcc or clang" >&2
       return 2 ;;
  esac
  if [ "$asan_compiler" = clang ]; then
    if command -v clang++-14 >/dev/null; then
      compiler=(-DCMAKE_C_COMPILER=clang-14 -DCMAKE_CXX_COMPILER=clang++-14)
      # libFuzzer's runtime comes with libclang-rt-14-dev (scripts/setup --long).
      ls /usr/lib/llvm-14/lib/clang/*/lib/linux/libclang_rt.fuzzer-x86_64.a >/dev/null 2>&1 &&
        fuzzers=ON
    elif [ -n "${CLOUDCAST_ASAN_COMPILER:-}" ]; then
      echo "asan build: CLOUDCAST_ASAN_COMPILER=clang needs clang-14 (scripts/setup --long)" >&2
      return 77
    else
      echo "asan build: clang-14 is not installed (scripts/setup --long); building with gcc"
    fi
  fi
  cmake -S . -B "$build_dir" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo "${launcher[@]}" \
    "${compiler[@]}" -DCLOUDCAST_SANITIZE=address -DCLOUDCAST_BUILD_FUZZERS=$fuzzers \
    -DCLOUDCAST_BUILD_BENCH=OFF >/dev/null
}

asan_build_has_fuzzers() {
  grep -q '^CLOUDCAST_BUILD_FUZZERS:BOOL=ON$' "$1/CMakeCache.txt" 2>/dev/null
}
