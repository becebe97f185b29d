# `cmake --install` puts the client library where a robot project finds it with
#   find_package(cloudcast REQUIRED)
#   target_link_libraries(robot PRIVATE cloudcast::client)
# Installed: the engine (cloudcast::core, x86-64 only; cloudcast::core_portable, the part the
# client uses) and its uplink codec (cloudcast::frame_codec), the contract and its boundary
# (cloudcast::proto, cloudcast::convert), the client (cloudcast::client), their headers, the
# .proto file, and cloudcast-config.cmake, which finds gRPC, Protobuf, Abseil, Draco and zstd for the user.
include(GNUInstallDirs)
include(CMakePackageConfigHelpers)

set(CLOUDCAST_INSTALL_CMAKEDIR ${CMAKE_INSTALL_LIBDIR}/cmake/cloudcast)
set(_cloudcast_installed cloudcast_core_portable cloudcast_frame_codec cloudcast_proto
  cloudcast_convert cloudcast_client)
# The engine's stages and encoder exist only where they build (x86-64, core/CMakeLists.txt).
if(TARGET cloudcast_core)
  list(PREPEND _cloudcast_installed cloudcast_core cloudcast_draco_encode)
endif()
foreach(target ${_cloudcast_installed})
  string(REPLACE "cloudcast_" "" export_name ${target})
  set_target_properties(${target} PROPERTIES EXPORT_NAME ${export_name})
endforeach()

install(TARGETS ${_cloudcast_installed}
  EXPORT cloudcastTargets
  ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
  LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR}
  INCLUDES DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
install(DIRECTORY
    ${CMAKE_SOURCE_DIR}/core/include/cloudcast
    ${CMAKE_SOURCE_DIR}/proto/include/cloudcast
    ${CMAKE_SOURCE_DIR}/client/include/cloudcast
  DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}
  # opencv.h needs cloudcast_client_opencv, which is not installed.
  PATTERN opencv.h EXCLUDE)
install(DIRECTORY ${CMAKE_BINARY_DIR}/proto/gen/cloudcast
  DESTINATION ${CMAKE_INSTALL_INCLUDEDIR} FILES_MATCHING PATTERN "*.h")
install(FILES ${CMAKE_SOURCE_DIR}/proto/cloudcast/v1/cloudcast.proto
  DESTINATION ${CMAKE_INSTALL_DATADIR}/cloudcast/proto/cloudcast/v1)

install(EXPORT cloudcastTargets NAMESPACE cloudcast:: DESTINATION ${CLOUDCAST_INSTALL_CMAKEDIR})
configure_package_config_file(${CMAKE_SOURCE_DIR}/cmake/cloudcast-config.cmake.in
  ${CMAKE_BINARY_DIR}/cloudcast-config.cmake INSTALL_DESTINATION ${CLOUDCAST_INSTALL_CMAKEDIR})
write_basic_package_version_file(${CMAKE_BINARY_DIR}/cloudcast-config-version.cmake
  VERSION ${PROJECT_VERSION} COMPATIBILITY SameMinorVersion)
install(FILES ${CMAKE_BINARY_DIR}/cloudcast-config.cmake
  ${CMAKE_BINARY_DIR}/cloudcast-config-version.cmake DESTINATION ${CLOUDCAST_INSTALL_CMAKEDIR})
