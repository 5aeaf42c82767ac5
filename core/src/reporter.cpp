#include "caps/core/reporter.hpp"

namespace caps {

void Reporter::warning(const std::string& message) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    warnings_.push_back(message);
  }
  on_warning(message);
}

void Reporter::note(const std::string& message) { on_note(message); }

void Reporter::progress(const std::string& step, double fraction) {
  on_progress(step, fraction < 0 ? 0.0 : (fraction > 1 ? 1.0 : fraction));
}

void Reporter::step_done(const std::string& step) { on_step_done(step); }

void Reporter::check_cancelled() const {
  if (is_cancelled()) throw Cancelled("cancelled by the caller");
}

std::vector<std::string> Reporter::warnings() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return warnings_;
}

void warn(Reporter* reporter, const std::string& message) {
  if (reporter) reporter->warning(message);
}

void note(Reporter* reporter, const std::string& message) {
  if (reporter) reporter->note(message);
}

Progress::Progress(Reporter* reporter, std::string step, double total)
    : reporter_(reporter), step_(std::move(step)), total_(total > 0 ? total : 1.0) {
  if (reporter_) {
    reporter_->check_cancelled();
    reporter_->progress(step_, 0.0);
  }
}

Progress::~Progress() {
  if (!finished_ && reporter_) reporter_->step_done(step_);
}

void Progress::update(double done) {
  if (finished_ || !reporter_) return;
  reporter_->check_cancelled();
  reporter_->progress(step_, done / total_);
}

void Progress::done() {
  if (finished_) return;
  finished_ = true;
  if (reporter_) reporter_->step_done(step_);
}

}  // namespace caps
