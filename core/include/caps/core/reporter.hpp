#pragma once
/// @brief Progress, warnings and cancellation, reported to whoever called (after OpenVDB's
/// interrupter): a library function that takes long or can warn takes a `Reporter*`; nullptr is
/// silent. The command line's reporter draws a progress bar on stderr, a server's sends events,
/// and every warning is also recorded so that it lands in the result JSON and the reports.

#include <mutex>
#include <string>
#include <vector>

#include "caps/core/error.hpp"

namespace caps {

/// Thrown by Progress::update() (or Reporter::check_cancelled()) once the caller has cancelled.
class Cancelled : public Error {
 public:
  using Error::Error;
};

/// Receives progress, warnings and notes; may cancel. Thread-safe: warnings may come from any
/// thread; progress of one step comes from one thread at a time.
class Reporter {
 public:
  virtual ~Reporter() = default;

  /// Records a warning (see warnings()) and passes it on to on_warning().
  void warning(const std::string& message);
  /// Information that is not a warning (how a file was read, what was assumed).
  void note(const std::string& message);
  /// `fraction` (0..1) of the step named `step` is done.
  void progress(const std::string& step, double fraction);
  /// The step named `step` is finished.
  void step_done(const std::string& step);
  /// True once the caller wants the work stopped.
  virtual bool is_cancelled() const { return false; }
  /// Throws Cancelled if is_cancelled().
  void check_cancelled() const;
  /// Every warning so far, in order.
  std::vector<std::string> warnings() const;

 protected:
  virtual void on_warning(const std::string& /*message*/) {}
  virtual void on_note(const std::string& /*message*/) {}
  virtual void on_progress(const std::string& /*step*/, double /*fraction*/) {}
  virtual void on_step_done(const std::string& /*step*/) {}

 private:
  mutable std::mutex mutex_;
  std::vector<std::string> warnings_;
};

/// reporter->warning(message), or nothing when `reporter` is null.
void warn(Reporter* reporter, const std::string& message);
/// reporter->note(message), or nothing when `reporter` is null.
void note(Reporter* reporter, const std::string& message);

/// One named step of a long computation, reported to a Reporter (or to nobody).
class Progress {
 public:
  Progress(Reporter* reporter, std::string step, double total = 1.0);
  ~Progress();
  Progress(const Progress&) = delete;
  Progress& operator=(const Progress&) = delete;
  /// Sets the amount done, 0..total. Throws Cancelled if the reporter has been cancelled.
  void update(double done);
  /// Marks the step finished.
  void done();

 private:
  Reporter* reporter_;
  std::string step_;
  double total_;
  bool finished_ = false;
};

}  // namespace caps
