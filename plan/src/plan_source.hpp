#pragma once
// Internal: the plan's file in front of the errors its checks throw (Plan::source).

#include <string>
#include <utility>

#include "caps/core/error.hpp"
#include "caps/plan/check.hpp"
#include "caps/plan/plan.hpp"

namespace caps::plan::detail {

// The exception being handled, `e`, again as an E with the plan's file in front.
template <typename E>
[[noreturn]] void throw_naming_plan_file(const Plan& plan, const E& e) {
  const std::string what = e.what();
  if (what.rfind(plan.source + ": ", 0) == 0) throw;
  throw E(cat(plan.source, ": ", what));
}

/// Runs f(); an InvalidInput it throws is thrown again with `plan.source` (the plan's file) in
/// front, unless the message already starts with it or the plan was not read from a file.
/// InvalidParameter (a procedure's named parameters, not a file's fault) passes unchanged;
/// SkinNotHeld stays SkinNotHeld.
template <typename F>
auto naming_plan_file(const Plan& plan, F&& f) -> decltype(f()) {
  if (plan.source.empty()) return std::forward<F>(f)();
  try {
    return std::forward<F>(f)();
  } catch (const InvalidParameter&) {
    throw;
  } catch (const SkinNotHeld& e) {  // kept as what it is: a chart would hold this skin
    throw_naming_plan_file(plan, e);
  } catch (const InvalidInput& e) {
    throw_naming_plan_file(plan, e);
  }
}

}  // namespace caps::plan::detail
