// core/atomic_output.hpp: an output is claimed while it is written (a second writer is refused),
// moved into place without replacing what another program put there meanwhile unless --force,
// and --force replaces only a regular file or a folder caps wrote; an interrupted run's
// temporaries and claims are removed.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <csignal>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

#include "caps/core/atomic_output.hpp"
#include "caps/core/crash_report.hpp"
#include "caps/core/error.hpp"
#include "caps/core/reporter.hpp"

namespace fs = std::filesystem;
using namespace caps;

namespace {

class Output : public ::testing::Test {
 protected:
  void SetUp() override {
    dir = fs::temp_directory_path() / ("caps_test_core_output_" + std::to_string(::getpid()));
    fs::remove_all(dir);
    fs::create_directories(dir);
  }
  void TearDown() override { fs::remove_all(dir); }
  static std::string slurp(const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
  }
  // Names in `dir` other than `keep`.
  int others(const std::string& keep) const {
    int n = 0;
    for (const auto& e : fs::directory_iterator(dir)) n += e.path().filename() != keep;
    return n;
  }
  fs::path dir;
};

TEST_F(Output, AFileMadeMeanwhileIsNotReplacedWithoutForce) {
  const fs::path out = dir / "plan.json";
  {
    const OutputClaim claim(out, false);
    std::ofstream(out) << "another program's";
    EXPECT_THROW(write_text_atomic(out, "caps' plan"), InvalidInput);
  }
  EXPECT_EQ(slurp(out), "another program's");
  EXPECT_EQ(others("plan.json"), 0) << "a temporary or the claim was left";
  // With --force it is replaced; with no claim (a file rewritten in place) too.
  {
    const OutputClaim claim(out, true);
    write_text_atomic(out, "caps' plan");
  }
  EXPECT_EQ(slurp(out), "caps' plan");
  write_text_atomic(out, "rewritten");
  EXPECT_EQ(slurp(out), "rewritten");
}

TEST_F(Output, AFolderMadeMeanwhileIsNotReplacedWithoutForce) {
  const fs::path out = dir / "result";
  OutputDirectory d(out, false);
  write_text_atomic(d.path() / "summary.json", "{}");
  fs::create_directories(out);  // empty: rename() would silently replace it
  EXPECT_THROW(d.commit(), InvalidInput);
  EXPECT_TRUE(fs::is_empty(out));
}

TEST_F(Output, ForceReplacesOnlyARegularFileOrACapsFolder) {
  const fs::path fifo = dir / "fifo", link = dir / "link", target = dir / "target.txt";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0644), 0);
  std::ofstream(target) << "kept";
  fs::create_symlink(target, link);
  for (const fs::path& p : {fifo, link}) {
    EXPECT_THROW(check_replaceable(p, true), InvalidInput) << p;
    EXPECT_THROW(OutputClaim(p, true), InvalidInput) << p;
  }
  EXPECT_THROW(OutputDirectory(link, true), InvalidInput);
  EXPECT_THROW(check_replaceable(target, false), InvalidInput);  // exists, no --force
  EXPECT_NO_THROW(check_replaceable(target, true));
  EXPECT_NO_THROW(check_replaceable(dir / "missing", false));
  const fs::path mine = dir / "model", theirs = dir / "documents";
  fs::create_directories(mine);
  fs::create_directories(theirs);
  std::ofstream(mine / "model.json") << "{}";
  std::ofstream(theirs / "letter.txt") << "keep me";
  EXPECT_NO_THROW(check_replaceable(mine, true));
  EXPECT_THROW(check_replaceable(theirs, true), InvalidInput);
  EXPECT_TRUE(fs::is_fifo(fs::symlink_status(fifo)));
  EXPECT_EQ(slurp(target), "kept");
}

TEST_F(Output, AClaimIsRefusedToAnotherProcessAndNestsWithinOne) {
  const fs::path out = dir / "out";
  const OutputClaim claim(out, false);
  EXPECT_NO_THROW(OutputClaim(out, false));  // this process again: nested
  EXPECT_TRUE(fs::exists(dir / "out.caps-claim"));
  const pid_t child = ::fork();
  if (child == 0) {
    try {
      const OutputClaim again(out, false);
      ::_exit(0);
    } catch (const InvalidInput& e) {
      ::_exit(std::string(e.what()).find(std::to_string(::getppid())) != std::string::npos ? 2 : 3);
    }
  }
  int status = 0;
  ::waitpid(child, &status, 0);
  EXPECT_EQ(WEXITSTATUS(status), 2) << "the second process was not refused, naming the first";
}

TEST_F(Output, AnAbandonedRunLeavesNothingAndMovesNothingIntoPlace) {
  const fs::path out = dir / "result";
  {
    const OutputClaim claim(out, false);
    OutputDirectory d(out, false);
    write_text_atomic(d.path() / "summary.json", "{}");
    const auto outputs = abandon_unfinished_outputs();
    ASSERT_EQ(outputs.size(), 1u);
    EXPECT_NE(outputs[0].find("result"), std::string::npos);
    EXPECT_EQ(others(""), 0) << "the temporary or the claim is still there";
    EXPECT_THROW(d.commit(), Cancelled);
  }
  EXPECT_FALSE(fs::exists(out));
}

}  // namespace

// A fault is reported before the process dies of it (core/crash_report.hpp): the signal named and
// a call stack on stderr, then the same signal ends the process (ctest and shells see it as
// before: exit status 128 + signal). The handlers are not installed under AddressSanitizer.
#if defined(__has_feature)
#if __has_feature(address_sanitizer)
#define CAPS_TEST_ASAN 1
#endif
#endif
#if !defined(__SANITIZE_ADDRESS__) && !defined(CAPS_TEST_ASAN)
TEST(CrashReport, AFaultSaysWhatAndWhereThenEndsTheProcessWithItsSignal) {
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  EXPECT_EXIT(
      {
        caps::install_crash_report();
        caps::install_crash_report();  // once is enough; a second call changes nothing
        std::raise(SIGFPE);
      },
      ::testing::KilledBySignal(SIGFPE),
      "caps: internal error: arithmetic fault \\(SIGFPE\\); please report it with this call "
      "stack:\n.*test_core_output");
  EXPECT_EXIT(
      {
        caps::install_crash_report();
        std::raise(SIGSEGV);
      },
      ::testing::KilledBySignal(SIGSEGV), "invalid memory access \\(SIGSEGV\\)");
}
#endif

