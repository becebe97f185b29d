// ROS 2's type descriptions and type hashes (REP 2016, "RIHS01"): what Iron and later put in each
// endpoint's USER_DATA ("typehash=RIHS01_<sha256>;") and compare when they match topics. The hash
// is the SHA-256 of rosidl_generator_type_description's JSON of the type and of every type it
// refers to (sorted by name), without default values.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

namespace cloudcast::ros2_bridge {

// type_description_interfaces/msg/FieldType: a scalar's id; + kArray for T[N], + kUnboundedSequence
// for T[].
enum FieldTypeId : std::uint8_t {
  kNestedType = 1,
  kInt32Type = 6,
  kUint8Type = 3,
  kUint32Type = 7,
  kFloatType = 10,
  kDoubleType = 11,
  kBooleanType = 15,
  kByteType = 16,
  kStringType = 17,
  kBoundedStringType = 21,  // string<=N
};
inline constexpr std::uint8_t kArray = 48;
inline constexpr std::uint8_t kUnboundedSequence = 144;

struct FieldDescription {
  std::string name;
  std::uint8_t type_id = 0;
  std::uint64_t capacity = 0;         // T[N]: N
  std::uint64_t string_capacity = 0;  // string<=N: N
  std::string nested_type_name;       // "std_msgs/msg/Header" for kNestedType (+ array kinds)
};

struct TypeDescription {
  std::string type_name;  // "sensor_msgs/msg/PointCloud2"
  std::vector<FieldDescription> fields;
};

// The description of one of the bridge's types ("builtin_interfaces/msg/Time",
// "std_msgs/msg/Header", "sensor_msgs/msg/{RegionOfInterest,PointField,PointCloud2,Image,
// CameraInfo}", "stereo_msgs/msg/DisparityImage", "diagnostic_msgs/msg/{KeyValue,
// DiagnosticStatus,DiagnosticArray}", "rmw_dds_common/msg/{Gid,NodeEntitiesInfo,
// ParticipantEntitiesInfo}" (Iron's and later); nullptr for any other name.
const TypeDescription* FindTypeDescription(std::string_view type_name);

// The JSON that is hashed: {"type_description": ..., "referenced_type_descriptions": [...]}, in
// Python's json.dumps layout (", " and ": "), as rosidl writes it. Empty for an unknown type.
std::string HashableTypeJson(std::string_view type_name);

// "RIHS01_" + the lowercase hex SHA-256 of HashableTypeJson; empty for an unknown type.
std::string TypeHash(std::string_view type_name);

}  // namespace cloudcast::ros2_bridge
