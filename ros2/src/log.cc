#include "log.h"

#include <chrono>
#include <cstdio>
#include <map>
#include <mutex>

namespace cloudcast::ros2_bridge {
namespace {

void Print(const char* level, const NodeNames& node, const std::string& message) {
  const double now =
      std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
  const std::string fq = (node.node_namespace == "/" ? "" : node.node_namespace.substr(1) + ".") +
                         node.node_name;
  std::fprintf(stderr, "[%s] [%.9f] [%s]: %s\n", level, now, fq.c_str(), message.c_str());
}

}  // namespace

void LogInfo(const NodeNames& node, const std::string& message) { Print("INFO", node, message); }
void LogWarn(const NodeNames& node, const std::string& message) { Print("WARN", node, message); }

void LogError(const NodeNames& node, const std::string& message) {
  static std::mutex mu;
  static std::map<std::string, std::chrono::steady_clock::time_point> last;
  const auto now = std::chrono::steady_clock::now();
  {
    std::lock_guard<std::mutex> lock(mu);
    auto it = last.find(message);
    if (it != last.end() && now - it->second < std::chrono::seconds(5)) return;
    last[message] = now;
    if (last.size() > 1000) last.clear();
  }
  Print("ERROR", node, message);
}

}  // namespace cloudcast::ros2_bridge
