#pragma once
// Test helper: the message of the InvalidInput that f() throws, "WRONG TYPE: ..." for another
// exception, "NO ERROR" when it throws nothing.

#include <exception>
#include <string>

#include "caps/core/error.hpp"

namespace caps_test {

template <typename F>
std::string error_of(F&& f) {
  try {
    f();
  } catch (const caps::InvalidInput& e) {
    return e.what();
  } catch (const std::exception& e) {
    return std::string("WRONG TYPE: ") + e.what();
  }
  return "NO ERROR";
}

}  // namespace caps_test
