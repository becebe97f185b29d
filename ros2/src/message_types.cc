#include "message_types.h"

#include <dds/ddsi/ddsi_cdrstream.h>

#include <cstring>
#include <map>
#include <mutex>

#include "absl/strings/str_cat.h"
#include "type_hash.h"

namespace cloudcast::ros2_bridge {

const MessageType kTimeType{"builtin_interfaces/msg/Time", &builtin_interfaces_msg_dds__Time__desc};
const MessageType kHeaderType{"std_msgs/msg/Header", &std_msgs_msg_dds__Header__desc};
const MessageType kRegionOfInterestType{"sensor_msgs/msg/RegionOfInterest",
                                        &sensor_msgs_msg_dds__RegionOfInterest__desc};
const MessageType kPointFieldType{"sensor_msgs/msg/PointField",
                                  &sensor_msgs_msg_dds__PointField__desc};
const MessageType kPointCloud2Type{"sensor_msgs/msg/PointCloud2",
                                   &sensor_msgs_msg_dds__PointCloud2__desc};
const MessageType kImageType{"sensor_msgs/msg/Image", &sensor_msgs_msg_dds__Image__desc};
const MessageType kCameraInfoType{"sensor_msgs/msg/CameraInfo",
                                  &sensor_msgs_msg_dds__CameraInfo__desc};
const MessageType kDisparityImageType{"stereo_msgs/msg/DisparityImage",
                                      &stereo_msgs_msg_dds__DisparityImage__desc};
const MessageType kKeyValueType{"diagnostic_msgs/msg/KeyValue",
                                &diagnostic_msgs_msg_dds__KeyValue__desc};
const MessageType kDiagnosticStatusType{"diagnostic_msgs/msg/DiagnosticStatus",
                                        &diagnostic_msgs_msg_dds__DiagnosticStatus__desc};
const MessageType kDiagnosticArrayType{"diagnostic_msgs/msg/DiagnosticArray",
                                       &diagnostic_msgs_msg_dds__DiagnosticArray__desc};

const std::vector<const MessageType*>& AllMessageTypes() {
  static const std::vector<const MessageType*> all = {
      &kTimeType,       &kHeaderType,          &kRegionOfInterestType, &kPointFieldType,
      &kPointCloud2Type, &kImageType,          &kCameraInfoType,       &kDisparityImageType,
      &kKeyValueType,   &kDiagnosticStatusType, &kDiagnosticArrayType};
  return all;
}

const std::string& MessageType::type_hash() const {
  static std::mutex mu;
  static std::map<const MessageType*, std::string> hashes;
  std::lock_guard<std::mutex> lock(mu);
  auto it = hashes.find(this);
  if (it == hashes.end()) it = hashes.emplace(this, TypeHash(ros_name)).first;
  return it->second;
}

namespace {
// The encapsulation identifiers of RTPS 2.3 10.5: plain CDR (XCDR1), big and little endian.
constexpr std::uint8_t kCdrBe = 0x00, kCdrLe = 0x01;
}  // namespace

std::vector<std::uint8_t> SerializeCdr(const MessageType& type, const void* sample) {
  dds_ostream_t os;
  dds_ostream_init(&os, 0, CDR_ENC_VERSION_1);
  // Little endian on this machine's byte order (x86-64, arm64): the plain stream writer.
  dds_stream_write(&os, static_cast<const char*>(sample), type.descriptor->m_ops);
  std::vector<std::uint8_t> out(4 + os.m_index, 0);
  out[1] = kCdrLe;
  if (os.m_index > 0) std::memcpy(out.data() + 4, os.m_buffer, os.m_index);
  dds_ostream_fini(&os);
  return out;
}

absl::Status DeserializeCdr(const MessageType& type, absl::Span<const std::uint8_t> bytes,
                            void* sample) {
  if (bytes.size() < 4) {
    return absl::InvalidArgumentError(absl::StrCat(type.ros_name, ": ", bytes.size(),
                                                   " bytes, shorter than the encapsulation header"));
  }
  if (bytes[0] != 0x00 || (bytes[1] != kCdrLe && bytes[1] != kCdrBe)) {
    return absl::InvalidArgumentError(absl::StrCat(
        type.ros_name, ": encapsulation ", static_cast<int>(bytes[0]), ",",
        static_cast<int>(bytes[1]), " is not CDR_LE or CDR_BE (an XCDR2 writer?)"));
  }
  const bool bswap = (bytes[1] == kCdrLe) != (DDSRT_ENDIAN == DDSRT_LITTLE_ENDIAN);
  // Normalization checks and byte-swaps in place: a copy, 8-aligned as the reader expects.
  const std::size_t size = bytes.size() - 4;
  std::vector<std::uint64_t> buffer((size + 7) / 8 + 1);
  char* data = reinterpret_cast<char*>(buffer.data());
  if (size > 0) std::memcpy(data, bytes.data() + 4, size);
  std::uint32_t offset = 0;
  if (size > UINT32_MAX ||
      dds_stream_normalize_data(data, &offset, static_cast<std::uint32_t>(size), bswap,
                                CDR_ENC_VERSION_1, type.descriptor->m_ops) == nullptr) {
    return absl::InvalidArgumentError(
        absl::StrCat(type.ros_name, ": ", size, " bytes that are no valid CDR of the type"));
  }
  dds_istream_t is;
  dds_istream_init(&is, static_cast<std::uint32_t>(size), data, CDR_ENC_VERSION_1);
  dds_stream_read(&is, static_cast<char*>(sample), type.descriptor->m_ops);
  dds_istream_fini(&is);
  return absl::OkStatus();
}

void FreeSample(const MessageType& type, void* sample) {
  dds_stream_free_sample(sample, type.descriptor->m_ops);
}

}  // namespace cloudcast::ros2_bridge
