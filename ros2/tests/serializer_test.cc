// The bytes the bridge writes for every message type, against an independent ROS 2 serializer:
// @foxglove/rosmsg2-serialization over the definitions of @foxglove/rosmsg-msgs-common (npm, run
// by node). Each message is filled with values that make every field's alignment and length
// matter (odd string lengths, empty and non-empty sequences, negative seconds).
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "discovery_info.h"
#include "message_types.h"
#include "nlohmann/json.hpp"

namespace cloudcast::ros2_bridge {
namespace {

using json = nlohmann::json;

std::string Hex(const std::vector<std::uint8_t>& bytes) {
  static const char kHex[] = "0123456789abcdef";
  std::string out;
  for (std::uint8_t b : bytes) {
    out += kHex[b >> 4];
    out += kHex[b & 15];
  }
  return out;
}

char* Str(const char* s) { return const_cast<char*>(s); }

template <typename Seq, typename T>
void Point(Seq* seq, std::vector<T>& storage) {
  seq->_buffer = storage.data();
  seq->_length = seq->_maximum = static_cast<std::uint32_t>(storage.size());
  seq->_release = false;
}

// One message of each type, as a C struct (serialized by the bridge's code) and as JSON (for the
// foxglove writer), kept alive together.
struct Samples {
  std::vector<std::uint8_t> bytes3 = {1, 2, 3};
  std::vector<std::uint8_t> pixels = {10, 20, 30, 40, 50, 60, 70, 80, 90};
  std::vector<double> distortion = {0.1, -0.25, 0.001, -0.002, 0.0};
  std::vector<sensor_msgs_msg_dds__PointField_> fields;
  std::vector<diagnostic_msgs_msg_dds__KeyValue_> values;
  std::vector<diagnostic_msgs_msg_dds__DiagnosticStatus_> statuses;

  builtin_interfaces_msg_dds__Time_ time{-3, 999999999};
  std_msgs_msg_dds__Header_ header{};
  sensor_msgs_msg_dds__RegionOfInterest_ roi{1, 2, 3, 4, true};
  sensor_msgs_msg_dds__PointField_ field{};
  sensor_msgs_msg_dds__PointCloud2_ cloud{};
  sensor_msgs_msg_dds__Image_ image{};
  sensor_msgs_msg_dds__CameraInfo_ info{};
  stereo_msgs_msg_dds__DisparityImage_ disparity{};
  diagnostic_msgs_msg_dds__KeyValue_ kv{};
  diagnostic_msgs_msg_dds__DiagnosticStatus_ status{};
  diagnostic_msgs_msg_dds__DiagnosticArray_ array{};

  std::vector<std::pair<const MessageType*, const void*>> c;
  std::vector<std::pair<std::string, json>> js;  // foxglove's type name, the message

  static json Hexed(const std::vector<std::uint8_t>& b) { return json{{"hex", Hex(b)}}; }

  Samples() {
    const json jtime = {{"sec", -3}, {"nanosec", 999999999}};
    header.stamp = time;
    header.frame_id = Str("cam");
    const json jheader = {{"stamp", jtime}, {"frame_id", "cam"}};
    const json jroi = {{"x_offset", 1}, {"y_offset", 2}, {"height", 3}, {"width", 4},
                       {"do_rectify", true}};
    field = {Str("rgb"), 12, 7, 1};
    const json jfield = {{"name", "rgb"}, {"offset", 12}, {"datatype", 7}, {"count", 1}};

    fields = {{Str("x"), 0, 7, 1}, field};
    cloud.header = header;
    cloud.height = 1;
    cloud.width = 3;
    Point(&cloud.fields, fields);
    cloud.is_bigendian = false;
    cloud.point_step = 1;
    cloud.row_step = 3;
    Point(&cloud.data, bytes3);
    cloud.is_dense = true;
    const json jcloud = {{"header", jheader},     {"height", 1},
                         {"width", 3},            {"fields", json::array({{{"name", "x"}, {"offset", 0}, {"datatype", 7}, {"count", 1}}, jfield})},
                         {"is_bigendian", false}, {"point_step", 1},
                         {"row_step", 3},         {"data", Hexed(bytes3)},
                         {"is_dense", true}};

    image.header = header;
    image.height = 3;
    image.width = 3;
    image.encoding = Str("mono8");
    image.is_bigendian = 0;
    image.step = 3;
    Point(&image.data, pixels);
    const json jimage = {{"header", jheader}, {"height", 3},      {"width", 3},
                         {"encoding", "mono8"}, {"is_bigendian", 0}, {"step", 3},
                         {"data", Hexed(pixels)}};

    info.header = header;
    info.height = 480;
    info.width = 640;
    info.distortion_model = Str("plumb_bob");
    Point(&info.d, distortion);
    json jk = json::array(), jr = json::array(), jp = json::array();
    for (int i = 0; i < 9; ++i) {
      info.k[i] = 100.5 + i;
      info.r[i] = i % 4 == 0 ? 1.0 : 0.0;
      jk.push_back(info.k[i]);
      jr.push_back(info.r[i]);
    }
    for (int i = 0; i < 12; ++i) {
      info.p[i] = -0.125 * i;
      jp.push_back(info.p[i]);
    }
    info.binning_x = 0;
    info.binning_y = 2;
    info.roi = roi;
    const json jinfo = {{"header", jheader}, {"height", 480},   {"width", 640},
                        {"distortion_model", "plumb_bob"},
                        {"d", distortion},   {"k", jk},         {"r", jr},
                        {"p", jp},           {"binning_x", 0},  {"binning_y", 2},
                        {"roi", jroi}};

    disparity.header = header;
    disparity.image = image;
    disparity.f = 615.5f;
    disparity.t = 0.1f;
    disparity.valid_window = roi;
    disparity.min_disparity = 0.0f;
    disparity.max_disparity = 127.0f;
    disparity.delta_d = 0.0625f;
    const json jdisparity = {{"header", jheader},     {"image", jimage},
                             {"f", 615.5},            {"t", static_cast<double>(0.1f)},
                             {"valid_window", jroi},  {"min_disparity", 0.0},
                             {"max_disparity", 127.0}, {"delta_d", 0.0625}};

    kv = {Str("round_trip_ms_mean"), Str("12.5")};
    const json jkv = {{"key", "round_trip_ms_mean"}, {"value", "12.5"}};
    values = {kv, {Str("k"), Str("")}};
    status.level = 2;
    status.name = Str("cloudcast_bridge: cloudcast stream");
    status.message = Str("left/image_rect_color.encoding is 'yuv422'");
    status.hardware_id = Str("127.0.0.1:50051");
    Point(&status.values, values);
    const json jstatus = {{"level", 2},
                          {"name", "cloudcast_bridge: cloudcast stream"},
                          {"message", "left/image_rect_color.encoding is 'yuv422'"},
                          {"hardware_id", "127.0.0.1:50051"},
                          {"values", json::array({jkv, {{"key", "k"}, {"value", ""}}})}};
    statuses = {status, {0, Str("x"), Str(""), Str(""), {}}};
    array.header = header;
    Point(&array.status, statuses);
    const json jarray = {
        {"header", jheader},
        {"status", json::array({jstatus, {{"level", 0}, {"name", "x"}, {"message", ""},
                                          {"hardware_id", ""}, {"values", json::array()}}})}};

    Add(&kTimeType, &time, "builtin_interfaces/Time", jtime);
    Add(&kHeaderType, &header, "std_msgs/Header", jheader);
    Add(&kRegionOfInterestType, &roi, "sensor_msgs/RegionOfInterest", jroi);
    Add(&kPointFieldType, &field, "sensor_msgs/PointField", jfield);
    Add(&kPointCloud2Type, &cloud, "sensor_msgs/PointCloud2", jcloud);
    Add(&kImageType, &image, "sensor_msgs/Image", jimage);
    Add(&kCameraInfoType, &info, "sensor_msgs/CameraInfo", jinfo);
    Add(&kDisparityImageType, &disparity, "stereo_msgs/DisparityImage", jdisparity);
    Add(&kKeyValueType, &kv, "diagnostic_msgs/KeyValue", jkv);
    Add(&kDiagnosticStatusType, &status, "diagnostic_msgs/DiagnosticStatus", jstatus);
    Add(&kDiagnosticArrayType, &array, "diagnostic_msgs/DiagnosticArray", jarray);
  }
  void Add(const MessageType* t, const void* sample, std::string name, json message) {
    c.emplace_back(t, sample);
    js.emplace_back(std::move(name), std::move(message));
  }
};

// Runs foxglove's writer (installing the pinned npm packages the first time) over `request`.
// ctest runs this binary's tests as processes side by side: the request and reply files are
// this process's own (shared ones let one test read the other's reply), and install.sh installs
// under a lock.
json RunFoxglove(const json& request) {
  const std::string dir = CLOUDCAST_ROS2_NPM_DIR;
  const std::string install = std::string(CLOUDCAST_ROS2_NPM_INSTALL) + " " + dir;
  if (std::system(install.c_str()) != 0) {
    ADD_FAILURE() << "'" << install << "' failed (node and npm: scripts/setup)";
    return json();
  }
  const std::string id = std::to_string(getpid());
  const std::string in = dir + "/request-" + id + ".json", out = dir + "/reply-" + id + ".json";
  std::ofstream(in) << request.dump();
  const std::string cmd = "node " + dir + "/serialize.js < " + in + " > " + out;
  const int status = std::system(cmd.c_str());
  std::ifstream reply(out);
  std::stringstream ss;
  ss << reply.rdbuf();
  std::remove(in.c_str());
  std::remove(out.c_str());
  if (status != 0) {
    ADD_FAILURE() << "'" << cmd << "' failed";
    return json();
  }
  return json::parse(ss.str());
}

TEST(Ros2Serializer, EveryTypeEqualsFoxglovesBytes) {
  Samples s;
  ASSERT_EQ(s.c.size(), AllMessageTypes().size());
  for (const char* distro : {"ros2humble", "ros2jazzy"}) {
    json request = {{"distro", distro}, {"messages", json::array()}};
    for (const auto& [name, message] : s.js) {
      request["messages"].push_back({{"type", name}, {"message", message}});
    }
    const json reply = RunFoxglove(request);
    ASSERT_TRUE(reply.is_array()) << distro;
    ASSERT_EQ(reply.size(), s.c.size());
    for (std::size_t i = 0; i < s.c.size(); ++i) {
      const MessageType& type = *s.c[i].first;
      const std::string ours = Hex(SerializeCdr(type, s.c[i].second));
      EXPECT_EQ(ours, reply[i]["hex"].get<std::string>()) << distro << " " << type.ros_name;
    }
  }
}

// ros_discovery_info's entry in both Gid layouts, against foxglove's writer over rmw_dds_common's
// .msg definitions (humble branch: char[24], jazzy: char[16]), given as text: two nodes, odd name
// lengths, an empty and non-empty GID sequence, GID bytes above 127 (char is one byte).
TEST(Ros2Serializer, DiscoveryInfoEqualsFoxglovesBytesInBothLayouts) {
  for (GidLayout layout : {GidLayout::kHumble, GidLayout::kIronAndLater}) {
    const std::size_t n = GidSize(layout);
    auto gid = [&](std::uint8_t first) {
      std::vector<std::uint8_t> g(n);
      for (std::size_t i = 0; i < n; ++i) g[i] = static_cast<std::uint8_t>(first + 17 * i);
      return g;
    };
    ParticipantEntities e;
    e.gid = gid(200);
    NodeEntities a;
    a.node_namespace = "/stereo";
    a.node_name = "cloudcast_bridge";
    a.reader_gids = {gid(1), gid(2), gid(3)};
    a.writer_gids = {gid(250)};
    NodeEntities b;
    b.node_namespace = "/";
    b.node_name = "x";
    b.writer_gids = {gid(7), gid(9)};
    e.nodes = {a, b};
    auto jgid = [](const std::vector<std::uint8_t>& g) {
      return json{{"data", Samples::Hexed(g)}};
    };
    auto jnode = [&](const NodeEntities& node) {
      json readers = json::array(), writers = json::array();
      for (const auto& g : node.reader_gids) readers.push_back(jgid(g));
      for (const auto& g : node.writer_gids) writers.push_back(jgid(g));
      return json{{"node_namespace", node.node_namespace},
                  {"node_name", node.node_name},
                  {"reader_gid_seq", readers},
                  {"writer_gid_seq", writers}};
    };
    const json jentry = {{"gid", jgid(e.gid)},
                         {"node_entities_info_seq", json::array({jnode(a), jnode(b)})}};
    const json request = {
        {"distro", layout == GidLayout::kHumble ? "ros2humble" : "ros2jazzy"},
        {"definitions",
         {{"rmw_dds_common/ParticipantEntitiesInfo",
           "Gid gid\nNodeEntitiesInfo[] node_entities_info_seq\n"},
          {"rmw_dds_common/NodeEntitiesInfo",
           "string<=256 node_namespace\nstring<=256 node_name\nGid[] reader_gid_seq\n"
           "Gid[] writer_gid_seq\n"},
          {"rmw_dds_common/Gid", layout == GidLayout::kHumble ? "char[24] data\n"
                                                              : "char[16] data\n"}}},
        {"messages", json::array({{{"type", "rmw_dds_common/ParticipantEntitiesInfo"},
                                   {"message", jentry}}})}};
    const json reply = RunFoxglove(request);
    ASSERT_TRUE(reply.is_array() && reply.size() == 1) << Name(layout);
    ParticipantEntitiesInfoSample sample(layout, e);
    EXPECT_EQ(Hex(SerializeCdr(sample.type(), sample.sample())), reply[0]["hex"].get<std::string>())
        << Name(layout);
  }
}

}  // namespace
}  // namespace cloudcast::ros2_bridge
