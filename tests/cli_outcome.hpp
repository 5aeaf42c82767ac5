#pragma once
// Runs the caps program (CAPS_EXE) with stdout and stderr apart, for the test_cli*.cpp programs
// that check messages and files: the outcome, file helpers and a small phantom CT.

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

namespace caps_test {

struct Outcome {
  int code;  ///< the exit code (-1 if the program did not exit normally)
  std::string out, err;
};

inline std::string slurp(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

inline void write_file(const std::filesystem::path& p, const std::string& bytes) {
  std::ofstream(p, std::ios::binary) << bytes;
}

/// A new empty folder `prefix` + the process id under the temporary folder.
inline std::filesystem::path fresh_temp_dir(const std::string& prefix) {
  const std::filesystem::path d =
      std::filesystem::temp_directory_path() / (prefix + std::to_string(::getpid()));
  std::filesystem::remove_all(d);
  std::filesystem::create_directories(d);
  return d;
}

/// Runs `caps args`, its stdout and stderr captured in files under `dir`; `env`: variable
/// assignments for the shell to put before the program ("NAME=value ...").
inline Outcome run_caps(const std::filesystem::path& dir, const std::string& args,
                        const std::string& env = "") {
  const std::filesystem::path out = dir / "stdout.txt", err = dir / "stderr.txt";
  const std::string cmd = (env.empty() ? "" : env + " ") + std::string(CAPS_EXE) + " " + args +
                          " >" + out.string() + " 2>" + err.string() + " </dev/null";
  const int status = std::system(cmd.c_str());
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, slurp(out), slurp(err)};
}

/// A small phantom CT (80 x 80 x 72 voxels of 3.2 mm) in `dir`, written once.
inline std::filesystem::path small_phantom(const std::filesystem::path& dir) {
  const std::filesystem::path p = dir / "phantom.nii.gz";
  if (!std::filesystem::exists(p)) {
    const Outcome r =
        run_caps(dir, "phantom -o " + p.string() + " --size 80,80,72 --spacing 3.2,3.2,3.2 -q");
    EXPECT_EQ(r.code, 0) << r.err;
  }
  return p;
}

/// A suite of caps runs sharing one temporary folder `dir`, which the suite's SetUpTestSuite
/// creates (fresh_temp_dir) and which is removed after the suite.
class CliTest : public ::testing::Test {
 protected:
  static inline std::filesystem::path dir;
  static void TearDownTestSuite() { std::filesystem::remove_all(dir); }
  static Outcome run(const std::string& args) { return run_caps(dir, args); }
  // A small phantom CT, written once.
  static std::filesystem::path phantom() { return small_phantom(dir); }
};

}  // namespace caps_test
