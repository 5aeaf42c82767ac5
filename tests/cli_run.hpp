#pragma once
// Runs the caps program (CAPS_EXE) as a user would, for the test_cli*.cpp programs.

#include <sys/wait.h>

#include <array>
#include <cstdio>
#include <string>

namespace caps_test {

struct CliRun {
  int code;         ///< the exit code (-1 if the program did not exit normally)
  std::string out;  ///< stdout and stderr together
};

inline CliRun caps(const std::string& args) {
  const std::string cmd = std::string(CAPS_EXE) + " " + args + " 2>&1 </dev/null";
  FILE* p = popen(cmd.c_str(), "r");
  if (!p) return {-1, "popen failed"};
  std::string out;
  std::array<char, 4096> buf{};
  while (fgets(buf.data(), buf.size(), p)) out += buf.data();
  const int status = pclose(p);
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, out};
}

}  // namespace caps_test
