#include "type_hash.h"

#include <openssl/sha.h>

#include <map>
#include <set>

namespace cloudcast::ros2_bridge {
namespace {

FieldDescription Scalar(std::string name, std::uint8_t id) { return {std::move(name), id, 0, 0, ""}; }
FieldDescription Nested(std::string name, std::string type, std::uint8_t kind = 0) {
  return {std::move(name), static_cast<std::uint8_t>(kNestedType + kind), 0, 0, std::move(type)};
}

// The fields of ROS 2's definitions (Humble and Jazzy; the same as ros2/idl/ros2_messages.idl).
const std::map<std::string, TypeDescription, std::less<>>& Descriptions() {
  static const auto* table = [] {
    const std::string kTime = "builtin_interfaces/msg/Time";
    const std::string kHeader = "std_msgs/msg/Header";
    const std::string kRoi = "sensor_msgs/msg/RegionOfInterest";
    const std::string kImage = "sensor_msgs/msg/Image";
    const std::string kGid = "rmw_dds_common/msg/Gid";
    const std::string kNodeEntitiesInfo = "rmw_dds_common/msg/NodeEntitiesInfo";
    std::vector<TypeDescription> types = {
        {kTime, {Scalar("sec", kInt32Type), Scalar("nanosec", kUint32Type)}},
        {kHeader, {Nested("stamp", kTime), Scalar("frame_id", kStringType)}},
        {kRoi,
         {Scalar("x_offset", kUint32Type), Scalar("y_offset", kUint32Type),
          Scalar("height", kUint32Type), Scalar("width", kUint32Type),
          Scalar("do_rectify", kBooleanType)}},
        {"sensor_msgs/msg/PointField",
         {Scalar("name", kStringType), Scalar("offset", kUint32Type),
          Scalar("datatype", kUint8Type), Scalar("count", kUint32Type)}},
        {"sensor_msgs/msg/PointCloud2",
         {Nested("header", kHeader), Scalar("height", kUint32Type), Scalar("width", kUint32Type),
          Nested("fields", "sensor_msgs/msg/PointField", kUnboundedSequence),
          Scalar("is_bigendian", kBooleanType), Scalar("point_step", kUint32Type),
          Scalar("row_step", kUint32Type), Scalar("data", kUint8Type + kUnboundedSequence),
          Scalar("is_dense", kBooleanType)}},
        {kImage,
         {Nested("header", kHeader), Scalar("height", kUint32Type), Scalar("width", kUint32Type),
          Scalar("encoding", kStringType), Scalar("is_bigendian", kUint8Type),
          Scalar("step", kUint32Type), Scalar("data", kUint8Type + kUnboundedSequence)}},
        {"sensor_msgs/msg/CameraInfo",
         {Nested("header", kHeader), Scalar("height", kUint32Type), Scalar("width", kUint32Type),
          Scalar("distortion_model", kStringType),
          Scalar("d", kDoubleType + kUnboundedSequence), {"k", kDoubleType + kArray, 9, 0, ""},
          {"r", kDoubleType + kArray, 9, 0, ""}, {"p", kDoubleType + kArray, 12, 0, ""},
          Scalar("binning_x", kUint32Type), Scalar("binning_y", kUint32Type),
          Nested("roi", kRoi)}},
        {"stereo_msgs/msg/DisparityImage",
         {Nested("header", kHeader), Nested("image", kImage), Scalar("f", kFloatType),
          Scalar("t", kFloatType), Nested("valid_window", kRoi),
          Scalar("min_disparity", kFloatType), Scalar("max_disparity", kFloatType),
          Scalar("delta_d", kFloatType)}},
        {"diagnostic_msgs/msg/KeyValue", {Scalar("key", kStringType), Scalar("value", kStringType)}},
        {"diagnostic_msgs/msg/DiagnosticStatus",
         {Scalar("level", kByteType), Scalar("name", kStringType), Scalar("message", kStringType),
          Scalar("hardware_id", kStringType),
          Nested("values", "diagnostic_msgs/msg/KeyValue", kUnboundedSequence)}},
        {"diagnostic_msgs/msg/DiagnosticArray",
         {Nested("header", kHeader),
          Nested("status", "diagnostic_msgs/msg/DiagnosticStatus", kUnboundedSequence)}},
        // rmw_dds_common's, Iron and later (ros2/idl/ros_discovery_info.idl): the .msg's char is
        // rosidl's uint8.
        {kGid, {{"data", kUint8Type + kArray, 16, 0, ""}}},
        {kNodeEntitiesInfo,
         {{"node_namespace", kBoundedStringType, 0, 256, ""},
          {"node_name", kBoundedStringType, 0, 256, ""},
          Nested("reader_gid_seq", kGid, kUnboundedSequence),
          Nested("writer_gid_seq", kGid, kUnboundedSequence)}},
        {"rmw_dds_common/msg/ParticipantEntitiesInfo",
         {Nested("gid", kGid),
          Nested("node_entities_info_seq", kNodeEntitiesInfo, kUnboundedSequence)}},
    };
    auto* out = new std::map<std::string, TypeDescription, std::less<>>();
    for (auto& t : types) {
      std::string name = t.type_name;
      out->emplace(std::move(name), std::move(t));
    }
    return out;
  }();
  return *table;
}

// Every type `type` refers to, directly or not (a std::set: sorted by name, as rosidl sorts them).
void CollectReferenced(const TypeDescription& type, std::set<std::string>* out) {
  for (const FieldDescription& f : type.fields) {
    if (f.nested_type_name.empty() || !out->insert(f.nested_type_name).second) continue;
    if (const TypeDescription* nested = FindTypeDescription(f.nested_type_name)) {
      CollectReferenced(*nested, out);
    }
  }
}

// The names here are plain identifiers and package paths: no character needs JSON escaping.
void AppendType(const TypeDescription& type, std::string* out) {
  *out += "{\"type_name\": \"" + type.type_name + "\", \"fields\": [";
  for (std::size_t i = 0; i < type.fields.size(); ++i) {
    const FieldDescription& f = type.fields[i];
    if (i > 0) *out += ", ";
    *out += "{\"name\": \"" + f.name + "\", \"type\": {\"type_id\": " +
            std::to_string(f.type_id) + ", \"capacity\": " + std::to_string(f.capacity) +
            ", \"string_capacity\": " + std::to_string(f.string_capacity) +
            ", \"nested_type_name\": \"" + f.nested_type_name + "\"}}";
  }
  *out += "]}";
}

}  // namespace

const TypeDescription* FindTypeDescription(std::string_view type_name) {
  auto it = Descriptions().find(type_name);
  return it == Descriptions().end() ? nullptr : &it->second;
}

std::string HashableTypeJson(std::string_view type_name) {
  const TypeDescription* type = FindTypeDescription(type_name);
  if (type == nullptr) return "";
  std::set<std::string> referenced;
  CollectReferenced(*type, &referenced);
  std::string out = "{\"type_description\": ";
  AppendType(*type, &out);
  out += ", \"referenced_type_descriptions\": [";
  bool first = true;
  for (const std::string& name : referenced) {
    if (!first) out += ", ";
    first = false;
    AppendType(*FindTypeDescription(name), &out);
  }
  out += "]}";
  return out;
}

std::string TypeHash(std::string_view type_name) {
  const std::string json = HashableTypeJson(type_name);
  if (json.empty()) return "";
  unsigned char digest[SHA256_DIGEST_LENGTH];
  SHA256(reinterpret_cast<const unsigned char*>(json.data()), json.size(), digest);
  static const char kHex[] = "0123456789abcdef";
  std::string out = "RIHS01_";
  for (unsigned char b : digest) {
    out += kHex[b >> 4];
    out += kHex[b & 15];
  }
  return out;
}

}  // namespace cloudcast::ros2_bridge
