// The ROS 2 bridge's command line in ROS 2's style (rcl's arguments): everything after
// --ros-args up to "--" or the end:
//   -p name:=value | --param name:=value       a parameter (value in YAML: 1, 0.5, true, text)
//   --params-file FILE                          a YAML parameters file (node: ros__parameters:)
//   -r from:=to | --remap from:=to              a topic remapping (both sides resolved)
//   -r __ns:=/namespace, -r __node:=name        the node's namespace and name
//   --log-level LEVEL                           accepted (the bridge logs at info)
// Later settings of a parameter win over earlier ones, as in rcl.
#pragma once

#include <map>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "bridge_options.h"
#include "ros_names.h"

namespace cloudcast::ros2_bridge {

// A parameter's value as YAML typed it.
struct ParamValue {
  enum Type { kBool, kInt, kDouble, kString } type = kString;
  bool b = false;
  long long i = 0;
  double d = 0;
  std::string s;
  std::string Text() const;  // for errors: "true", "3", "0.5", "'text'"
};

struct RosArgs {
  bool help = false;
  NodeNames node;  // namespace, name, remappings (resolved)
  std::map<std::string, ParamValue> params;  // by ROS 2 name: "voxel.leaf"
};

// Parses argv (argv[0] excluded). `default_node_name` names the node unless __node remaps it.
// Errors say which argument is wrong ("-p voxel.leaf: expected name:=value").
absl::StatusOr<RosArgs> ParseRosArgs(const std::vector<std::string>& args,
                                     const std::string& default_node_name);

// The parameters of node `node` in a YAML parameters file's text: the sections "/**", "name",
// "/name", "/ns/name" and "ns/name" that match, each "ros__parameters:" map flattened with "."
// ("voxel: {leaf: 0.01}" is "voxel.leaf"). Errors name the file (`source`) and the key.
absl::Status ReadParamsYaml(const std::string& yaml_text, const std::string& source,
                            const NodeNames& node, std::map<std::string, ParamValue>* params);

// The ROS 2 bridge's own parameters, beyond the shared core's (ParamDocs): the `extra` of its
// Ros2ParamReader.
inline const std::vector<std::string>& Ros2BridgeParameters() {
  static const std::vector<std::string> names = {"input_qos", "ros_discovery_info",
                                                 "use_sim_time"};
  return names;
}

// The parameters as the shared core reads them: "voxel.leaf" is ParamDocs' "voxel/leaf".
// Parameters outside ParamDocs that are ROS 2's own or the ROS 2 bridge's (`extra`, e.g.
// "input_qos") are not reported by Names().
class Ros2ParamReader : public ros_bridge::ParamReader {
 public:
  Ros2ParamReader(const std::map<std::string, ParamValue>& params,
                  std::vector<std::string> extra)
      : params_(params), extra_(std::move(extra)) {}
  absl::StatusOr<std::optional<std::string>> String(const std::string& name) const override;
  absl::StatusOr<std::optional<bool>> Bool(const std::string& name) const override;
  absl::StatusOr<std::optional<int>> Int(const std::string& name) const override;
  absl::StatusOr<std::optional<double>> Double(const std::string& name) const override;
  std::vector<std::string> Names() const override;
  std::string Display(const std::string& name) const override;

 private:
  const ParamValue* Find(const std::string& name) const;
  absl::Status WrongType(const std::string& name, const ParamValue& v, const char* wanted) const;
  const std::map<std::string, ParamValue>& params_;
  std::vector<std::string> extra_;
};

}  // namespace cloudcast::ros2_bridge
