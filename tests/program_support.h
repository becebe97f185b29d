// Running the project's programs from tests: the real binaries in CLOUDCAST_BIN_DIR, with their
// stdout and stderr captured through files.
#pragma once

#include <sys/wait.h>

#include <cstdlib>
#include <fstream>
#include <ostream>
#include <sstream>
#include <string>
#include <vector>

namespace cloudcast::testing {

inline std::string BinDir() { return CLOUDCAST_BIN_DIR; }

inline std::string ShellQuote(const std::string& s) {
  std::string out = "'";
  for (char c : s) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return out + "'";
}

inline std::string ReadText(const std::string& path) {
  std::ifstream file(path, std::ios::binary);
  std::stringstream ss;
  ss << file.rdbuf();
  return ss.str();
}

struct RunResult {
  bool exited = false;  // false: killed by a signal (a crash)
  int code = -1;
  std::string out, err;

  // 128 + signal: the shell reports a crashed child this way.
  bool crashed() const { return !exited || code >= 128; }
};

inline std::ostream& operator<<(std::ostream& os, const RunResult& r) {
  return os << "exit " << r.code << "\n--- stdout:\n" << r.out << "--- stderr:\n" << r.err;
}

// Runs `binary args...` with stdin from /dev/null; stdout and stderr go through files in
// `scratch_dir`. `env` prefixes the command (e.g. "env -u DISPLAY").
inline RunResult RunProgram(const std::string& binary, const std::vector<std::string>& args,
                            const std::string& scratch_dir, const std::string& env = "") {
  const std::string out = scratch_dir + "/stdout.txt", err = scratch_dir + "/stderr.txt";
  std::string command = env.empty() ? "" : env + " ";
  command += ShellQuote(binary);
  for (const std::string& a : args) command += " " + ShellQuote(a);
  command += " </dev/null >" + ShellQuote(out) + " 2>" + ShellQuote(err);
  const int status = std::system(command.c_str());
  RunResult r;
  if (status != -1 && WIFEXITED(status)) {
    r.exited = true;
    r.code = WEXITSTATUS(status);
  }
  r.out = ReadText(out);
  r.err = ReadText(err);
  return r;
}

}  // namespace cloudcast::testing
