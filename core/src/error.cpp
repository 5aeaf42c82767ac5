#include "caps/core/error.hpp"

namespace caps {
namespace {

// "element 3, Gauss point 0: " for the parts that are known; nothing if none is.
std::string located(const std::string& what, int element, int gauss_point, int iteration) {
  std::string where;
  const auto add = [&](const char* name, int value) {
    if (value >= 0) where += cat(where.empty() ? "" : ", ", name, " ", value);
  };
  add("element", element);
  add("Gauss point", gauss_point);
  add("iteration", iteration);
  return where.empty() ? what : cat(where, ": ", what);
}

}  // namespace

SolverError::SolverError(const std::string& what, int element, int gauss_point, int iteration)
    : Error(located(what, element, gauss_point, iteration)),
      element(element),
      gauss_point(gauss_point),
      iteration(iteration) {}

namespace detail {

void assertion_failed(const char* cond, const std::string& msg, const char* file, int line) {
  throw Error(cat("internal error: assertion '", cond, "' failed at ", file, ":", line, ": ", msg,
                  " (please report this as a bug)"));
}

}  // namespace detail
}  // namespace caps
