#include "ros_names.h"

#include <cctype>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"

namespace cloudcast::ros2_bridge {
namespace {

bool IsTokenChar(char c) { return std::isalnum(static_cast<unsigned char>(c)) || c == '_'; }

// One token of a name: not empty, [A-Za-z0-9_], not starting with a digit.
bool ValidToken(std::string_view token) {
  if (token.empty() || std::isdigit(static_cast<unsigned char>(token[0]))) return false;
  for (char c : token) {
    if (!IsTokenChar(c)) return false;
  }
  return true;
}

// An absolute name: "/" and tokens separated by single slashes, no trailing slash.
absl::Status ValidateAbsolute(std::string_view name_view, std::string_view what_view) {
  const std::string name(name_view), what(what_view);
  if (name.empty() || name[0] != '/') {
    return absl::InvalidArgumentError(absl::StrCat(what, " '", name, "' must start with '/'"));
  }
  if (name == "/") return absl::OkStatus();
  const std::vector<std::string> tokens = absl::StrSplit(name.substr(1), '/');
  for (const std::string& token : tokens) {
    if (!ValidToken(token)) {
      return absl::InvalidArgumentError(absl::StrCat(
          what, " '", name, "' has the token '", token,
          "'; tokens are letters, digits and '_', not empty and not starting with a digit"));
    }
  }
  return absl::OkStatus();
}

}  // namespace

absl::Status ValidateNodeName(std::string_view name) {
  if (!ValidToken(name)) {
    return absl::InvalidArgumentError(
        absl::StrCat("node name '", std::string(name),
                     "' must be letters, digits and '_', not empty and not starting with a digit"));
  }
  return absl::OkStatus();
}

absl::Status ValidateNamespace(std::string_view ns) { return ValidateAbsolute(ns, "namespace"); }

absl::StatusOr<std::string> ExpandTopicName(std::string_view name_view, const NodeNames& node) {
  const std::string name(name_view);
  std::string expanded;
  if (name.empty()) return absl::InvalidArgumentError("a topic name is empty");
  const std::string ns = node.node_namespace == "/" ? "" : node.node_namespace;
  if (name[0] == '/') {
    expanded = name;
  } else if (name[0] == '~') {
    if (name.size() > 1 && name[1] != '/') {
      return absl::InvalidArgumentError(
          absl::StrCat("topic '", name, "': '~' must be followed by '/' or nothing"));
    }
    expanded = absl::StrCat(ns, "/", node.node_name, name.substr(1));
  } else {
    expanded = absl::StrCat(ns, "/", name);
  }
  if (absl::Status s = ValidateAbsolute(expanded, "topic"); !s.ok()) return s;
  if (expanded == "/") return absl::InvalidArgumentError("topic '/' names no topic");
  return expanded;
}

absl::StatusOr<std::string> ResolveTopicName(std::string_view name, const NodeNames& node) {
  auto expanded = ExpandTopicName(name, node);
  if (!expanded.ok()) return expanded.status();
  auto it = node.remaps.find(*expanded);
  if (it != node.remaps.end()) return it->second;
  return expanded;
}

std::string DdsTopicName(std::string_view fully_qualified_name) {
  return "rt" + std::string(fully_qualified_name);
}

std::string DdsTypeName(std::string_view ros_type_name) {
  std::vector<std::string> parts = absl::StrSplit(std::string(ros_type_name), '/');
  if (parts.size() != 3) return "";
  return absl::StrCat(parts[0], "::", parts[1], "::dds_::", parts[2], "_");
}

}  // namespace cloudcast::ros2_bridge
