# Every program and test links with lld where the compiler can use it (scripts/setup installs it;
# the compiler's default linker otherwise). A cold CI run links about 400 programs in five builds
# (main, ASan, TSan, fuzz, arm64) and a warm one links them all again, since ccache keeps objects,
# not programs: client_test links in 0.22 s with lld against 0.80 with GNU ld (0.31 with gold).
# Only our own targets get it: the installed package's users keep their own linker.
set(CLOUDCAST_LINKER "lld" CACHE STRING
    "Linker for -fuse-ld= (lld, gold, bfd; empty: the compiler's default)")
if(CLOUDCAST_LINKER)
  include(CheckLinkerFlag)
  # One cache entry per linker and compiler, so that changing either checks again.
  string(MAKE_C_IDENTIFIER "CLOUDCAST_LINKS_WITH_${CLOUDCAST_LINKER}_${CMAKE_CXX_COMPILER_ID}"
         _cloudcast_linker_ok)
  check_linker_flag(CXX "-fuse-ld=${CLOUDCAST_LINKER}" ${_cloudcast_linker_ok})
  if(${_cloudcast_linker_ok})
    add_link_options(-fuse-ld=${CLOUDCAST_LINKER})
  else()
    message(STATUS "cloudcast: ${CMAKE_CXX_COMPILER} cannot link with -fuse-ld=${CLOUDCAST_LINKER} "
                   "(scripts/setup installs lld); linking with its default linker")
  endif()
endif()
