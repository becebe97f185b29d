# The cross build's emulator as one program, ${CMAKE_BINARY_DIR}/qemu-aarch64: qemu-user with the
# guest's LD_LIBRARY_PATH set to the arm64 libraries scripts/setup unpacked rather than installed
# (cmake/opencv-cross.cmake lists their folders), so that ctest, gtest_discover_tests and the
# tests that start arm64 programs (tests/arm64/) run them the same way. Only the guest sees the
# path (qemu's -E): the host's programs never load an arm64 library by mistake.
if(NOT CLOUDCAST_QEMU_AARCH64)
  return()
endif()
set(_qemu_args)
if(CLOUDCAST_ARM64_DEPS_LIBRARY_DIRS)
  string(JOIN ":" _ld_path ${CLOUDCAST_ARM64_DEPS_LIBRARY_DIRS})
  set(_qemu_args "-E LD_LIBRARY_PATH=${_ld_path} ")
endif()
file(WRITE ${CMAKE_BINARY_DIR}/qemu-aarch64
  "#!/bin/sh\n# Written by cmake/qemu-wrapper.cmake.\nexec ${CLOUDCAST_QEMU_AARCH64} ${_qemu_args}\"$@\"\n")
file(CHMOD ${CMAKE_BINARY_DIR}/qemu-aarch64 FILE_PERMISSIONS OWNER_READ OWNER_WRITE OWNER_EXECUTE
  GROUP_READ GROUP_EXECUTE WORLD_READ WORLD_EXECUTE)
set(CMAKE_CROSSCOMPILING_EMULATOR ${CMAKE_BINARY_DIR}/qemu-aarch64)
