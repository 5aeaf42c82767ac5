#include "caps/core/error.hpp"

namespace caps {

namespace {

// Replaces every {name} of `text` by spell(name).
std::string fill(const std::string& text, const std::function<std::string(const std::string&)>& spell) {
  std::string out;
  for (std::size_t i = 0; i < text.size();) {
    const std::size_t open = text.find('{', i);
    const std::size_t close = open == std::string::npos ? open : text.find('}', open);
    if (close == std::string::npos) {
      out += text.substr(i);
      break;
    }
    out += text.substr(i, open - i) + spell(text.substr(open + 1, close - open - 1));
    i = close + 1;
  }
  return out;
}

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

InvalidParameter::InvalidParameter(const std::string& message_template)
    : InvalidInput(fill(message_template, [](const std::string& name) { return name; })),
      template_(message_template) {}

std::string InvalidParameter::spelled(
    const std::function<std::string(const std::string&)>& spell) const {
  return fill(template_, spell);
}

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
