#include "caps/core/error.hpp"

namespace caps::detail {

void assertion_failed(const char* cond, const std::string& msg, const char* file, int line) {
  throw Error(cat("internal error: assertion '", cond, "' failed at ", file, ":", line, ": ", msg,
                  " (please report this as a bug)"));
}

}  // namespace caps::detail
