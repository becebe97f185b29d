# OpenCV in the arm64 cross build (scripts/build-arm64), for the robot example and
# cloudcast-client: they read images with imgcodecs, whose arm64 package cannot be installed
# beside the host's (it pulls GDAL, whose arm64 dependencies replace the host's). scripts/setup --arm64 unpacks it, its runtime
# closure and the arm64 headers into build-arm64-deps/ instead. Imported targets named as
# OpenCV's own from there; the libraries behind them are found by the linker through
# -rpath-link, and under qemu-user by the loader through LD_LIBRARY_PATH
# (tests/arm64/cross_build.sh prints the folders).
set(CLOUDCAST_ARM64_DEPS "${CMAKE_SOURCE_DIR}/build-arm64-deps" CACHE PATH
    "Where scripts/setup --arm64 unpacked the arm64 packages that cannot be installed")
set(_opencv_lib ${CLOUDCAST_ARM64_DEPS}/usr/lib/${CMAKE_LIBRARY_ARCHITECTURE})
set(OpenCV_INCLUDE_DIRS ${CLOUDCAST_ARM64_DEPS}/usr/include/opencv4
    ${CLOUDCAST_ARM64_DEPS}/usr/include/${CMAKE_LIBRARY_ARCHITECTURE}/opencv4)
set(OpenCV_LIBS)
# videoio (video files) only for cloudcast-client's sources (sources/), unpacked with PCL's.
set(_opencv_modules core imgproc imgcodecs)
if(CLOUDCAST_BUILD_VIEWER)
  list(APPEND _opencv_modules videoio)
endif()
foreach(module ${_opencv_modules})
  set(_so ${_opencv_lib}/libopencv_${module}.so.406)  # Debian 12's OpenCV 4.6
  if(NOT EXISTS ${_so})
    message(FATAL_ERROR "${_so} is missing: scripts/setup --arm64 unpacks OpenCV's arm64 "
                        "packages, or build without CLOUDCAST_WITH_OPENCV")
  endif()
  add_library(opencv_${module} SHARED IMPORTED)
  set_target_properties(opencv_${module} PROPERTIES IMPORTED_LOCATION ${_so}
    INTERFACE_INCLUDE_DIRECTORIES "${OpenCV_INCLUDE_DIRS}")
  list(APPEND OpenCV_LIBS opencv_${module})
endforeach()
# Every folder of the unpacked tree that holds shared libraries (GDAL's and the rest of
# imgcodecs' dependencies, BLAS behind Debian's alternatives), for the linker.
file(GLOB_RECURSE _deps_libs LIST_DIRECTORIES false ${CLOUDCAST_ARM64_DEPS}/*.so.*)
set(CLOUDCAST_ARM64_DEPS_LIBRARY_DIRS)
foreach(lib ${_deps_libs})
  get_filename_component(dir ${lib} DIRECTORY)
  list(APPEND CLOUDCAST_ARM64_DEPS_LIBRARY_DIRS ${dir})
endforeach()
list(REMOVE_DUPLICATES CLOUDCAST_ARM64_DEPS_LIBRARY_DIRS)
foreach(dir ${CLOUDCAST_ARM64_DEPS_LIBRARY_DIRS})
  add_link_options(LINKER:-rpath-link,${dir})
endforeach()
