#pragma once
/// @brief Progress bar and messages on stderr.
///
/// The bar is drawn only when stderr is a terminal and the program is not quiet; it appears once a
/// step has run for about a second. Warnings always go to stderr unless quiet.

#include <chrono>
#include <string>

namespace caps {

/// Process-wide verbosity, set once by the CLI (--quiet).
void set_quiet(bool quiet);
bool is_quiet();

/// Prints "caps: warning: <msg>" on stderr unless quiet.
void warn(const std::string& msg);

/// Prints "caps: <msg>" on stderr unless quiet.
void inform(const std::string& msg);

/// A progress bar for one named step. update() may be called from one thread at a time.
class Progress {
 public:
  Progress(std::string step, double total = 1.0);
  ~Progress();
  Progress(const Progress&) = delete;
  Progress& operator=(const Progress&) = delete;
  /// Sets the amount done, 0..total.
  void update(double done);
  /// Marks the step finished and clears the bar.
  void done();

 private:
  std::string step_;
  double total_;
  std::chrono::steady_clock::time_point start_;
  bool drawn_ = false;
  bool finished_ = false;
  int last_percent_ = -1;
};

}  // namespace caps
