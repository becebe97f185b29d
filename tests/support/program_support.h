// Running the project's programs from tests: the real binaries in CLOUDCAST_BIN_DIR, with their
// stdout and stderr captured through files.
#pragma once

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
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

// A test with a fresh scratch folder of its own (named after the test and the process, so that
// parallel ctest runs never share one), removed afterwards.
class ScratchDirTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    std::string name = std::string(info->test_suite_name()) + "_" + info->name();
    std::replace(name.begin(), name.end(), '/', '_');
    dir_ = std::filesystem::path(::testing::TempDir()) /
           ("cloudcast_" + name + "_" + std::to_string(::getpid()));
    std::filesystem::remove_all(dir_);
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override {
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }
  std::string Path(const std::string& name) const { return (dir_ / name).string(); }

  std::filesystem::path dir_;
};

}  // namespace cloudcast::testing
