// cloudcast-load's prepared requests (load::FrameStore), parsed back as the server would read
// them: the tests check what a send puts on the wire.
#pragma once

#include <grpcpp/support/byte_buffer.h>
#include <gtest/gtest.h>

#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "cloudcast/core/camera.h"
#include "cloudcast/load/frame_store.h"
#include "cloudcast/proto/convert.h"
#include "cloudcast/v1/cloudcast.pb.h"

namespace cloudcast::testing {

// The request FrameStore::Request makes for these arguments, parsed (a test failure when the
// bytes do not parse as a StreamRequest).
inline v1::StreamRequest ParsedRequest(const load::FrameStore& store, std::size_t index,
                                       std::uint64_t sequence, std::int64_t capture_time_unix_ns,
                                       std::size_t level = 0) {
  grpc::ByteBuffer buffer = store.Request(index, sequence, capture_time_unix_ns, level);
  std::vector<grpc::Slice> slices;
  EXPECT_TRUE(buffer.Dump(&slices).ok());
  std::string bytes;
  for (auto& s : slices) bytes.append(reinterpret_cast<const char*>(s.begin()), s.size());
  v1::StreamRequest request;
  EXPECT_TRUE(request.ParseFromString(bytes)) << "frame " << index << " level " << level;
  return request;
}

// The stream camera cloudcast-load sends for a source camera without flags: the source's,
// principal point unset (each frame's centre).
inline absl::StatusOr<v1::CameraModel> LoadStreamCamera(const CameraModel& camera) {
  v1::StreamConfig config;
  convert::SetCamera(camera, &config);
  config.mutable_camera()->clear_cx();
  config.mutable_camera()->clear_cy();
  return config.camera();
}

}  // namespace cloudcast::testing
