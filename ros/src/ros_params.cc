#include "ros_params.h"

#include <sstream>

#include "absl/strings/str_cat.h"

namespace cloudcast::ros_bridge {
namespace {

// The private parameters of a node, as XmlRpc values from the parameter server.
class RosParamReader : public ParamReader {
 public:
  explicit RosParamReader(const ros::NodeHandle& nh) : nh_(nh) {}

  absl::StatusOr<std::optional<std::string>> String(const std::string& name) const override {
    XmlRpc::XmlRpcValue v;
    if (!nh_.getParam(name, v)) return std::optional<std::string>();
    if (v.getType() != XmlRpc::XmlRpcValue::TypeString) return WrongType(name, v, "a string");
    return std::optional<std::string>(static_cast<std::string&>(v));
  }
  absl::StatusOr<std::optional<bool>> Bool(const std::string& name) const override {
    XmlRpc::XmlRpcValue v;
    if (!nh_.getParam(name, v)) return std::optional<bool>();
    if (v.getType() != XmlRpc::XmlRpcValue::TypeBoolean) return WrongType(name, v, "true or false");
    return std::optional<bool>(static_cast<bool&>(v));
  }
  absl::StatusOr<std::optional<int>> Int(const std::string& name) const override {
    XmlRpc::XmlRpcValue v;
    if (!nh_.getParam(name, v)) return std::optional<int>();
    if (v.getType() != XmlRpc::XmlRpcValue::TypeInt) return WrongType(name, v, "an integer");
    return std::optional<int>(static_cast<int&>(v));
  }
  absl::StatusOr<std::optional<double>> Double(const std::string& name) const override {
    XmlRpc::XmlRpcValue v;
    if (!nh_.getParam(name, v)) return std::optional<double>();
    if (v.getType() == XmlRpc::XmlRpcValue::TypeInt) {
      return std::optional<double>(static_cast<int&>(v));
    }
    if (v.getType() != XmlRpc::XmlRpcValue::TypeDouble) return WrongType(name, v, "a number");
    return std::optional<double>(static_cast<double&>(v));
  }
  // The parameters under the node's private namespace, relative to it ("voxel/leaf").
  std::vector<std::string> Names() const override {
    std::vector<std::string> all, out;
    if (!nh_.getParamNames(all)) return out;  // the master will fail louder
    const std::string prefix = nh_.getNamespace() + "/";
    for (const std::string& full : all) {
      if (full.rfind(prefix, 0) == 0) out.push_back(full.substr(prefix.size()));
    }
    return out;
  }
  std::string Display(const std::string& name) const override { return "~" + name; }

 private:
  static absl::Status WrongType(const std::string& name, XmlRpc::XmlRpcValue& v,
                                const char* wanted) {
    return absl::InvalidArgumentError(
        absl::StrCat("~", name, " is ", v.toXml(), "; must be ", wanted));
  }
  const ros::NodeHandle& nh_;
};

}  // namespace

absl::StatusOr<BridgeOptions> ReadBridgeOptions(const ros::NodeHandle& private_nh) {
  return ReadBridgeOptions(RosParamReader(private_nh), "cloudcast-ros-bridge");
}

std::string HelpText() {
  std::ostringstream os;
  os << "cloudcast-ros-bridge: turns a ROS camera's disparity, depth image or stereo pair into\n"
        "point clouds on a cloudcast server and publishes them as sensor_msgs/PointCloud2.\n\n"
        "Usage: cloudcast-ros-bridge [ROS remappings, e.g. disparity:=/stereo/disparity]\n"
        "                            [_param:=value ...]\n\n"
        "Subscribes, ~input disparity (the names of stereo_image_proc's point_cloud2 nodelet):\n"
        "  disparity               stereo_msgs/DisparityImage (32FC1; z = f T / d; d below\n"
        "                          min_disparity, NaN or inf: no point)\n"
        "  left/image_rect_color   sensor_msgs/Image, rgb8 bgr8 rgba8 bgra8 or mono8, same size\n"
        "  left/camera_info        sensor_msgs/CameraInfo (P gives fx, fy, cx, cy)\n"
        "~input depth (the names of depth_image_proc's point_cloud_xyzrgb nodelet):\n"
        "  depth_registered/image_rect\n"
        "                          sensor_msgs/Image, 16UC1 (mm) or 32FC1 (m), REP 118; 0, NaN,\n"
        "                          inf: no point; registered to the colour camera\n"
        "  rgb/image_rect_color    sensor_msgs/Image, the colour encodings above, same size\n"
        "  rgb/camera_info         sensor_msgs/CameraInfo of the depth's pixels (P, or K)\n"
        "~input stereo (rectified pairs; the server matches them, ~stereo/...):\n"
        "  left/image_rect_color   sensor_msgs/Image, the colour encodings above (the points'\n"
        "                          colour; the matcher uses its grey)\n"
        "  right/image_rect        sensor_msgs/Image, same size (mono8 is enough)\n"
        "  left/camera_info        sensor_msgs/CameraInfo: P gives fx, fy, cx, cy\n"
        "  right/camera_info       sensor_msgs/CameraInfo: P[3] = -fx * baseline\n"
        "Publishes:\n"
        "  points2                 sensor_msgs/PointCloud2: x y z rgb (FLOAT32 at 0 4 8 12, PCL's\n"
        "                          packed rgb), unorganized, dense, the input's header\n"
        "  disparity               (~input stereo, ~stereo/publish_disparity) stereo_msgs/\n"
        "                          DisparityImage: the server's disparities, 1/16 pixel steps\n"
        "  /diagnostics            diagnostic_msgs/DiagnosticArray: per-stage times (decode,\n"
        "                          rectify, match, pipeline, encode, queue, round trip),\n"
        "                          frames, drops, reconnects\n\n"
        "Parameters (private, e.g. _server:=10.0.0.2:50051 or <param name=\"server\"> in a "
        "launch file):\n";
  for (const ParamDoc& d : ParamDocs()) {
    std::string head = "  ~" + d.name + " (" + d.type + ", default " +
                       (d.default_value.empty() ? "none" : d.default_value) + ")";
    os << head << "\n" << WrapText(d.help, 84, "      ");
  }
  os << "\nExamples:\n"
        "  cloudcast-ros-bridge _server:=127.0.0.1:50051 disparity:=/stereo/disparity \\\n"
        "      left/image_rect_color:=/stereo/left/image_rect_color \\\n"
        "      left/camera_info:=/stereo/left/camera_info\n"
        "  cloudcast-ros-bridge _input:=depth __ns:=/camera points2:=/camera/cloudcast/points\n"
        "  cloudcast-ros-bridge _input:=stereo _stereo/matcher:=sgm _stereo/num_disparities:=160 "
        "\\\n"
        "      __ns:=/stereo\n"
        "  roslaunch cloudcast_ros cloudcast_bridge.launch camera:=/stereo server:=robot-pc:50051\n"
        "  roslaunch cloudcast_ros cloudcast_depth.launch camera:=/camera\n"
        "  roslaunch cloudcast_ros cloudcast_stereo.launch camera:=/stereo\n"
        "Documentation: docs/ros.md\n";
  return os.str();
}

}  // namespace cloudcast::ros_bridge
