#include "caps/core/progress.hpp"

#include <unistd.h>

#include <atomic>
#include <cstdio>

namespace caps {
namespace {
std::atomic<bool> g_quiet{false};

bool bar_enabled() { return !g_quiet.load() && isatty(STDERR_FILENO); }
}  // namespace

void set_quiet(bool quiet) { g_quiet = quiet; }
bool is_quiet() { return g_quiet.load(); }

void warn(const std::string& msg) {
  if (!g_quiet) std::fprintf(stderr, "caps: warning: %s\n", msg.c_str());
}

void inform(const std::string& msg) {
  if (!g_quiet) std::fprintf(stderr, "caps: %s\n", msg.c_str());
}

Progress::Progress(std::string step, double total)
    : step_(std::move(step)), total_(total > 0 ? total : 1.0),
      start_(std::chrono::steady_clock::now()) {}

Progress::~Progress() { done(); }

void Progress::update(double done) {
  if (finished_ || !bar_enabled()) return;
  const double elapsed =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  if (elapsed < 1.0) return;  // short steps stay silent
  int percent = static_cast<int>(100.0 * done / total_);
  percent = percent < 0 ? 0 : (percent > 100 ? 100 : percent);
  if (percent == last_percent_) return;
  last_percent_ = percent;
  constexpr int kWidth = 30;
  const int filled = percent * kWidth / 100;
  std::string bar(static_cast<size_t>(filled), '#');
  bar.append(static_cast<size_t>(kWidth - filled), '.');
  std::fprintf(stderr, "\r%-28s [%s] %3d%%", step_.c_str(), bar.c_str(), percent);
  std::fflush(stderr);
  drawn_ = true;
}

void Progress::done() {
  if (finished_) return;
  finished_ = true;
  if (drawn_) {
    std::fprintf(stderr, "\r%-70s\r", "");
    std::fflush(stderr);
  }
}

}  // namespace caps
