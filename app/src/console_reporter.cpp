#include "caps/app/console_reporter.hpp"

#include <unistd.h>

#include <cstdio>

namespace caps::app {

ConsoleReporter::~ConsoleReporter() { clear_bar(); }

void ConsoleReporter::clear_bar() {
  if (!drawn_) return;
  std::fprintf(stderr, "\r%-70s\r", "");
  std::fflush(stderr);
  drawn_ = false;
}

void ConsoleReporter::on_warning(const std::string& message) {
  if (quiet_) return;
  clear_bar();
  std::fprintf(stderr, "caps: warning: %s\n", message.c_str());
}

void ConsoleReporter::on_note(const std::string& message) {
  if (quiet_) return;
  clear_bar();
  std::fprintf(stderr, "caps: %s\n", message.c_str());
}

void ConsoleReporter::on_progress(const std::string& step, double fraction) {
  if (quiet_ || !isatty(STDERR_FILENO)) return;
  const auto now = std::chrono::steady_clock::now();
  if (step != step_) {
    clear_bar();
    step_ = step;
    start_ = now;
    last_percent_ = -1;
  }
  if (std::chrono::duration<double>(now - start_).count() < 1.0) return;  // short steps stay silent
  const int percent = static_cast<int>(100.0 * fraction);
  if (percent == last_percent_) return;
  last_percent_ = percent;
  constexpr int kWidth = 30;
  const int filled = percent * kWidth / 100;
  std::string bar(static_cast<size_t>(filled), '#');
  bar.append(static_cast<size_t>(kWidth - filled), '.');
  std::fprintf(stderr, "\r%-28s [%s] %3d%%", step.c_str(), bar.c_str(), percent);
  std::fflush(stderr);
  drawn_ = true;
}

void ConsoleReporter::on_step_done(const std::string& step) {
  if (step == step_) {
    clear_bar();
    step_.clear();
  }
}

}  // namespace caps::app
