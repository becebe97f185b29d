#include "ros_args.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <fstream>
#include <sstream>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_replace.h"

namespace cloudcast::ros2_bridge {
namespace {

absl::Status Invalid(const std::string& m) { return absl::InvalidArgumentError(m); }

// A YAML scalar's type, as rclcpp types parameters: a quoted scalar is a string; a plain one is a
// bool (true/false), an integer, a floating point number, or else a string.
ParamValue FromScalar(const YAML::Node& node) {
  ParamValue v;
  const std::string text = node.Scalar();
  v.s = text;
  if (node.Tag() == "!") return v;  // quoted
  if (text == "true" || text == "True" || text == "TRUE") {
    v.type = ParamValue::kBool;
    v.b = true;
  } else if (text == "false" || text == "False" || text == "FALSE") {
    v.type = ParamValue::kBool;
    v.b = false;
  } else if (long long i; absl::SimpleAtoi(text, &i)) {
    v.type = ParamValue::kInt;
    v.i = i;
  } else if (double d; text.find_first_of(".eE") != std::string::npos && absl::SimpleAtod(text, &d)) {
    v.type = ParamValue::kDouble;
    v.d = d;
  }
  return v;
}

absl::Status Flatten(const YAML::Node& node, const std::string& prefix, const std::string& source,
                     std::map<std::string, ParamValue>* out) {
  for (const auto& kv : node) {
    const std::string key = kv.first.as<std::string>();
    const std::string name = prefix.empty() ? key : prefix + "." + key;
    if (kv.second.IsMap()) {
      if (absl::Status s = Flatten(kv.second, name, source, out); !s.ok()) return s;
    } else if (kv.second.IsScalar()) {
      (*out)[name] = FromScalar(kv.second);
    } else {
      return Invalid(absl::StrCat(source, ": parameter ", name,
                                  " is a list or null; the bridge's parameters are scalars"));
    }
  }
  return absl::OkStatus();
}

// Does a parameters file's top-level key select this node?
bool Selects(const std::string& key, const NodeNames& node) {
  if (key == "/**" || key == node.node_name || key == "/**/" + node.node_name) return true;
  const std::string ns = node.node_namespace == "/" ? "" : node.node_namespace;
  const std::string fq = ns + "/" + node.node_name;
  return key == fq || "/" + key == fq;
}

std::pair<std::string, std::string> SplitAssign(const std::string& arg) {
  const auto pos = arg.find(":=");
  if (pos == std::string::npos) return {"", ""};
  return {arg.substr(0, pos), arg.substr(pos + 2)};
}

}  // namespace

std::string ParamValue::Text() const {
  switch (type) {
    case kBool:
      return b ? "true" : "false";
    case kInt:
      return std::to_string(i);
    case kDouble: {
      std::ostringstream os;
      os << d;
      return os.str();
    }
    case kString:
      break;
  }
  return "'" + s + "'";
}

absl::Status ReadParamsYaml(const std::string& yaml_text, const std::string& source,
                            const NodeNames& node, std::map<std::string, ParamValue>* params) {
  YAML::Node root;
  try {
    root = YAML::Load(yaml_text);
  } catch (const YAML::Exception& e) {
    return Invalid(absl::StrCat(source, ": not YAML: ", e.what()));
  }
  if (root.IsNull()) return absl::OkStatus();
  if (!root.IsMap()) return Invalid(absl::StrCat(source, ": must be a map of node names"));
  try {
    for (const auto& section : root) {
      const std::string key = section.first.as<std::string>();
      if (!Selects(key, node)) continue;
      const YAML::Node p = section.second["ros__parameters"];
      if (!p || !p.IsMap()) {
        return Invalid(absl::StrCat(source, ": '", key, "' has no ros__parameters map"));
      }
      if (absl::Status s = Flatten(p, "", source, params); !s.ok()) return s;
    }
  } catch (const YAML::Exception& e) {
    return Invalid(absl::StrCat(source, ": ", e.what()));
  }
  return absl::OkStatus();
}

absl::StatusOr<RosArgs> ParseRosArgs(const std::vector<std::string>& args,
                                     const std::string& default_node_name) {
  RosArgs out;
  out.node.node_name = default_node_name;
  std::vector<std::pair<std::string, std::string>> remaps;
  // Parameters and files in order (files are read once the node's name is known).
  std::vector<std::pair<bool, std::string>> param_sources;  // (is_file, text)
  bool in_ros_args = false;
  for (std::size_t i = 0; i < args.size(); ++i) {
    const std::string& a = args[i];
    if (a == "--help" || a == "-h") {
      out.help = true;
      continue;
    }
    if (a == "--ros-args") {
      in_ros_args = true;
      continue;
    }
    if (!in_ros_args) {
      return Invalid(absl::StrCat("unexpected argument '", a,
                                  "'; parameters and remappings go after --ros-args (see --help)"));
    }
    if (a == "--") {
      in_ros_args = false;
      continue;
    }
    auto value_of = [&](const char* what) -> absl::StatusOr<std::string> {
      if (i + 1 >= args.size()) return Invalid(absl::StrCat(a, " needs ", what));
      return args[++i];
    };
    if (a == "-p" || a == "--param") {
      auto v = value_of("name:=value");
      if (!v.ok()) return v.status();
      param_sources.emplace_back(false, *v);
    } else if (a == "--params-file") {
      auto v = value_of("a file");
      if (!v.ok()) return v.status();
      param_sources.emplace_back(true, *v);
    } else if (a == "-r" || a == "--remap") {
      auto v = value_of("from:=to");
      if (!v.ok()) return v.status();
      auto [from, to] = SplitAssign(*v);
      if (from.empty() || to.empty()) {
        return Invalid(absl::StrCat(a, " ", *v, ": expected from:=to"));
      }
      if (from == "__ns") {
        out.node.node_namespace = to;
      } else if (from == "__node" || from == "__name") {
        out.node.node_name = to;
      } else {
        remaps.emplace_back(from, to);
      }
    } else if (a == "--log-level") {
      if (auto v = value_of("a level"); !v.ok()) return v.status();
    } else {
      return Invalid(absl::StrCat("unknown ROS argument '", a,
                                  "' (the bridge takes -p, --params-file, -r, --log-level)"));
    }
  }
  if (absl::Status s = ValidateNamespace(out.node.node_namespace); !s.ok()) return s;
  if (absl::Status s = ValidateNodeName(out.node.node_name); !s.ok()) return s;
  for (const auto& [from, to] : remaps) {
    NodeNames plain = out.node;
    plain.remaps.clear();
    auto f = ExpandTopicName(from, plain);
    if (!f.ok()) return Invalid(absl::StrCat("-r ", from, ":=", to, ": ", f.status().message()));
    auto t = ExpandTopicName(to, plain);
    if (!t.ok()) return Invalid(absl::StrCat("-r ", from, ":=", to, ": ", t.status().message()));
    out.node.remaps[*f] = *t;
  }
  for (const auto& [is_file, text] : param_sources) {
    if (is_file) {
      std::ifstream in(text);
      if (!in) return Invalid(absl::StrCat("--params-file ", text, ": cannot be read"));
      std::stringstream ss;
      ss << in.rdbuf();
      if (absl::Status s = ReadParamsYaml(ss.str(), text, out.node, &out.params); !s.ok()) {
        return s;
      }
      continue;
    }
    auto [name, value] = SplitAssign(text);
    if (name.empty()) return Invalid(absl::StrCat("-p ", text, ": expected name:=value"));
    YAML::Node node;
    try {
      node = YAML::Load(value);
    } catch (const YAML::Exception& e) {
      return Invalid(absl::StrCat("-p ", text, ": the value is not YAML: ", e.what()));
    }
    if (value.empty()) {
      ParamValue empty;
      out.params[name] = empty;
    } else if (!node.IsScalar()) {
      return Invalid(absl::StrCat("-p ", text, ": the bridge's parameters are scalars"));
    } else {
      out.params[name] = FromScalar(node);
    }
  }
  return out;
}

const ParamValue* Ros2ParamReader::Find(const std::string& name) const {
  auto it = params_.find(absl::StrReplaceAll(name, {{"/", "."}}));
  return it == params_.end() ? nullptr : &it->second;
}

absl::Status Ros2ParamReader::WrongType(const std::string& name, const ParamValue& v,
                                        const char* wanted) const {
  return Invalid(absl::StrCat(Display(name), " is ", v.Text(), "; must be ", wanted));
}

absl::StatusOr<std::optional<std::string>> Ros2ParamReader::String(const std::string& name) const {
  const ParamValue* v = Find(name);
  if (v == nullptr) return std::optional<std::string>();
  if (v->type != ParamValue::kString) return WrongType(name, *v, "a string");
  return std::optional<std::string>(v->s);
}

absl::StatusOr<std::optional<bool>> Ros2ParamReader::Bool(const std::string& name) const {
  const ParamValue* v = Find(name);
  if (v == nullptr) return std::optional<bool>();
  if (v->type != ParamValue::kBool) return WrongType(name, *v, "true or false");
  return std::optional<bool>(v->b);
}

absl::StatusOr<std::optional<int>> Ros2ParamReader::Int(const std::string& name) const {
  const ParamValue* v = Find(name);
  if (v == nullptr) return std::optional<int>();
  if (v->type != ParamValue::kInt || v->i < INT32_MIN || v->i > INT32_MAX) {
    return WrongType(name, *v, "an integer");
  }
  return std::optional<int>(static_cast<int>(v->i));
}

absl::StatusOr<std::optional<double>> Ros2ParamReader::Double(const std::string& name) const {
  const ParamValue* v = Find(name);
  if (v == nullptr) return std::optional<double>();
  if (v->type == ParamValue::kInt) return std::optional<double>(static_cast<double>(v->i));
  if (v->type != ParamValue::kDouble) return WrongType(name, *v, "a number");
  return std::optional<double>(v->d);
}

std::vector<std::string> Ros2ParamReader::Names() const {
  std::vector<std::string> out;
  for (const auto& [name, value] : params_) {
    if (std::find(extra_.begin(), extra_.end(), name) != extra_.end()) continue;
    out.push_back(absl::StrReplaceAll(name, {{".", "/"}}));
  }
  return out;
}

std::string Ros2ParamReader::Display(const std::string& name) const {
  // "stereo/..." (a group, in the core's errors) is "stereo.*".
  if (name.size() > 4 && name.compare(name.size() - 4, 4, "/...") == 0) {
    return absl::StrReplaceAll(name.substr(0, name.size() - 4), {{"/", "."}}) + ".*";
  }
  return absl::StrReplaceAll(name, {{"/", "."}});
}

}  // namespace cloudcast::ros2_bridge
