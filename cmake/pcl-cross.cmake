# PCL in the arm64 cross build (scripts/build-arm64), for cloudcast-client's .pcd and .ply files
# (io/src/cloud_io.cc): libpcl-io1.13:arm64 pulls VTK, whose arm64 packages replace the host's, so
# scripts/setup --arm64 unpacks it and its runtime closure into build-arm64-deps/ (as OpenCV's,
# cmake/opencv-cross.cmake, whose -rpath-link folders serve it too). The headers are the host's:
# PCL's, Eigen's and Boost's are the same for every architecture. The variables are those
# find_package(PCL) sets, with what cloud_io needs.
set(_pcl_lib ${CLOUDCAST_ARM64_DEPS}/usr/lib/${CMAKE_LIBRARY_ARCHITECTURE})
set(PCL_LIBRARIES)
foreach(name pcl_common pcl_io pcl_io_ply)
  if(NOT EXISTS ${_pcl_lib}/lib${name}.so.1.13)
    message(FATAL_ERROR "${_pcl_lib}/lib${name}.so.1.13 is missing: scripts/setup --arm64 unpacks "
                        "PCL's arm64 packages, or build without CLOUDCAST_WITH_PCL")
  endif()
  list(APPEND PCL_LIBRARIES ${_pcl_lib}/lib${name}.so.1.13)
endforeach()
foreach(dir /usr/include/pcl-1.13 /usr/include/eigen3)
  if(NOT EXISTS ${dir})
    message(FATAL_ERROR "${dir} (the host's PCL and Eigen headers) is missing: ./scripts/setup")
  endif()
endforeach()
set(PCL_INCLUDE_DIRS /usr/include/pcl-1.13 /usr/include/eigen3)
# What Debian's PCLConfig.cmake gives cloud_io on the host (Boost as shared libraries; PCL built
# without pcap and png).
set(PCL_DEFINITIONS -DBOOST_ALL_NO_LIB -DBOOST_FILESYSTEM_DYN_LINK -DBOOST_IOSTREAMS_DYN_LINK
    -DBOOST_SYSTEM_DYN_LINK -DDISABLE_PCAP -DDISABLE_PNG)
