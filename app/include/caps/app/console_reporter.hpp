#pragma once
/// @brief The command line's reporter: a progress bar on stderr (only on a terminal, and only
/// for steps that run for more than about a second), warnings and notes on stderr unless quiet.

#include <chrono>
#include <string>

#include "caps/core/reporter.hpp"

namespace caps::app {

class ConsoleReporter : public Reporter {
 public:
  explicit ConsoleReporter(bool quiet) : quiet_(quiet) {}
  ~ConsoleReporter() override;

 protected:
  void on_warning(const std::string& message) override;
  void on_note(const std::string& message) override;
  void on_progress(const std::string& step, double fraction) override;
  void on_step_done(const std::string& step) override;

 private:
  void clear_bar();

  bool quiet_;
  std::string step_;
  std::chrono::steady_clock::time_point start_;
  bool drawn_ = false;
  int last_percent_ = -1;
};

}  // namespace caps::app
