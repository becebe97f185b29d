# Sanitizer and fuzzer builds. Each lives in its own build folder (scripts/fuzz, scripts/sanitize):
#   CLOUDCAST_SANITIZE=address  the test suite under ASan + UBSan (gcc or clang).
#   CLOUDCAST_BUILD_FUZZERS=ON  clang: every target with -fsanitize=fuzzer-no-link,address,undefined,
#                               the libFuzzer harnesses of fuzz/ linked with -fsanitize=fuzzer.
#                               With CLOUDCAST_SANITIZE=address it is the same build: the harnesses
#                               and the suite share every library object (scripts/sanitize asan and
#                               scripts/fuzz use one folder, build-asan/, configured as
#                               scripts/lib/asan-build.sh says: a cold CI run compiled the
#                               libraries twice, 191 s more).
#   CLOUDCAST_SANITIZE=thread   the test suite under TSan (build only the server and client tests).
# Debian's own libraries (gRPC, protobuf, OpenCV, PCL, Draco, zstd) are not instrumented: ASan
# still checks every access our code makes and intercepts their malloc/free and memcpy; MSan,
# which needs everything instrumented, is not offered.
option(CLOUDCAST_BUILD_FUZZERS "Build the libFuzzer harnesses (fuzz/; needs clang)" OFF)
set(CLOUDCAST_SANITIZE "" CACHE STRING "Sanitize everything: '', 'address' (+undefined), 'thread'")
set_property(CACHE CLOUDCAST_SANITIZE PROPERTY STRINGS "" address thread)

if(CLOUDCAST_BUILD_FUZZERS AND CLOUDCAST_SANITIZE STREQUAL "thread")
  message(FATAL_ERROR "CLOUDCAST_BUILD_FUZZERS=ON sanitizes with address,undefined: "
                      "CLOUDCAST_SANITIZE must be empty or 'address'")
endif()

set(_cloudcast_san_flags "")
if(CLOUDCAST_BUILD_FUZZERS)
  if(NOT CMAKE_CXX_COMPILER_ID STREQUAL "Clang")
    message(FATAL_ERROR "CLOUDCAST_BUILD_FUZZERS=ON needs clang (libFuzzer), e.g. "
                        "-DCMAKE_CXX_COMPILER=clang++-14 -DCMAKE_C_COMPILER=clang-14")
  endif()
  # fuzzer-no-link: coverage instrumentation everywhere; only the harnesses link libFuzzer's main.
  set(_cloudcast_san_flags -fsanitize=fuzzer-no-link,address,undefined)
  set(_cloudcast_san_link -fsanitize=address,undefined)
elseif(CLOUDCAST_SANITIZE STREQUAL "address")
  set(_cloudcast_san_flags -fsanitize=address,undefined)
  set(_cloudcast_san_link -fsanitize=address,undefined)
elseif(CLOUDCAST_SANITIZE STREQUAL "thread")
  set(_cloudcast_san_flags -fsanitize=thread)
  set(_cloudcast_san_link -fsanitize=thread)
  # gRPC's C++ API is half headers (grpcpp/: call ops, callback tags, byte buffers) and half
  # libgrpc, whose synchronisation TSan cannot see since Debian's build is not instrumented. The
  # header half, inlined into our objects, then races against itself across gRPC's threads. clang
  # leaves what tests/sanitizers/tsan.ignorelist names uninstrumented, like the library it belongs
  # to; our own code, even when gRPC calls it, stays checked.
  if(CMAKE_CXX_COMPILER_ID STREQUAL "Clang")
    set(_cloudcast_ignorelist ${CMAKE_SOURCE_DIR}/tests/sanitizers/tsan.ignorelist)
    # Relative to the build folder, where Ninja runs every compile: ccache takes CCACHE_BASEDIR's
    # paths relative in -I and the sources but not here, so an absolute path made every clean
    # clone elsewhere (CI's) build TSan cold (163 s in a warm run; now 27 s).
    file(RELATIVE_PATH _cloudcast_ignorelist_rel ${CMAKE_BINARY_DIR} ${_cloudcast_ignorelist})
    list(APPEND _cloudcast_san_flags -fsanitize-ignorelist=${_cloudcast_ignorelist_rel})
    # ccache 4.7 hashes the file of -fsanitize-blacklist but not of -fsanitize-ignorelist: the
    # file's digest on the command line makes an edit to it recompile everything.
    set_property(DIRECTORY APPEND PROPERTY CMAKE_CONFIGURE_DEPENDS ${_cloudcast_ignorelist})
    file(MD5 ${_cloudcast_ignorelist} _cloudcast_ignorelist_md5)
    add_compile_definitions(CLOUDCAST_TSAN_IGNORELIST_MD5=${_cloudcast_ignorelist_md5})
  else()
    message(WARNING "CLOUDCAST_SANITIZE=thread with ${CMAKE_CXX_COMPILER_ID}: grpcpp's headers "
                    "stay instrumented and report races inside gRPC; use clang (scripts/sanitize)")
  endif()
elseif(NOT CLOUDCAST_SANITIZE STREQUAL "")
  message(FATAL_ERROR "CLOUDCAST_SANITIZE must be '', 'address' or 'thread', not "
                      "'${CLOUDCAST_SANITIZE}'")
endif()

if(_cloudcast_san_flags)
  # An undefined-behaviour report is a failure, not a warning: the program stops at the first.
  if(NOT CLOUDCAST_SANITIZE STREQUAL "thread")
    list(APPEND _cloudcast_san_flags -fno-sanitize-recover=undefined)
  endif()
  # Every sanitized build at -O1, as OSS-Fuzz builds its sanitized targets; ASan and the fuzzers
  # with line tables only: reports keep every frame's file and line, and clang compiles faster
  # (issue 29's cold CI: server_limits_test.cc 17.8 s against 15.1 at -O2 -g, pipeline.cc 39.1
  # against 32.1). TSan keeps full -g: with line tables only the std::function members that
  # grpcpp's headers call are instrumented outside tsan.ignorelist's reach, and TSan reports
  # gRPC's own unsynchronised calls as races (seen: 42 of ClientTest's 93 tests). At -O1 -g it
  # builds cold in 134 s against about 150 at -O2 -g, and its 93 tests and the canary pass alike.
  # gcc has no line-tables-only level, and its -g costs it nothing measurable.
  set(_cloudcast_san_codegen -O1 -g)
  if(NOT CLOUDCAST_SANITIZE STREQUAL "thread" AND CMAKE_CXX_COMPILER_ID STREQUAL "Clang")
    set(_cloudcast_san_codegen -O1 -gline-tables-only)
  endif()
  add_compile_options(${_cloudcast_san_flags} -fno-omit-frame-pointer ${_cloudcast_san_codegen})
  add_link_options(${_cloudcast_san_link})
  # Eigen (inside PCL's headers) switches to its own aligned malloc when it sees
  # __SANITIZE_ADDRESS__ (gcc defines it under ASan; clang 14 does not), while Debian's libpcl was
  # built with plain malloc: a PointCloud allocated in our code and freed in libpcl then crashes in
  # free(). glibc's and ASan's malloc both return 16-byte aligned blocks on x86-64, so telling Eigen
  # so keeps both sides on malloc/free, as in the normal build.
  add_compile_definitions(EIGEN_MALLOC_ALREADY_ALIGNED=1)
endif()
