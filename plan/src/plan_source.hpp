#pragma once
// Internal: the plan's file in front of the errors its checks throw (Plan::source).

#include <string>
#include <utility>

#include "caps/core/error.hpp"
#include "caps/plan/plan.hpp"

namespace caps::plan::detail {

/// Runs f(); an InvalidInput it throws is thrown again with `plan.source` (the plan's file) in
/// front, unless the message already starts with it or the plan was not read from a file.
/// InvalidParameter (a procedure's named parameters, not a file's fault) passes unchanged.
template <typename F>
auto naming_plan_file(const Plan& plan, F&& f) -> decltype(f()) {
  if (plan.source.empty()) return std::forward<F>(f)();
  try {
    return std::forward<F>(f)();
  } catch (const InvalidParameter&) {
    throw;
  } catch (const InvalidInput& e) {
    const std::string what = e.what();
    if (what.rfind(plan.source + ": ", 0) == 0) throw;
    throw InvalidInput(cat(plan.source, ": ", what));
  }
}

}  // namespace caps::plan::detail
