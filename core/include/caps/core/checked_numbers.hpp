#pragma once
/// @brief Converting numbers read from files without undefined behaviour: a double cast to an
/// integer type is undefined when it is NaN or out of the type's range (UBSan reports it), and a
/// file may hold any value.

#include <cmath>
#include <cstdint>
#include <limits>
#include <string>

#include "caps/core/error.hpp"

namespace caps {

/// Whether `x` is a whole number in [lo, hi] (false for NaN and infinities).
inline bool is_whole_in(double x, double lo, double hi) {
  return x >= lo && x <= hi && std::floor(x) == x;
}

/// A colour channel: `x` clamped to [0, 255] and truncated; NaN gives 0.
inline std::uint8_t channel_byte(double x) {
  return x >= 255.0 ? std::uint8_t{255} : x > 0.0 ? static_cast<std::uint8_t>(x) : std::uint8_t{0};
}

/// `x` as an int when it is a whole number within int's range; otherwise throws InvalidInput
/// "<where>: <x> is not a whole number ...". For counts and indices read from files as doubles.
inline int to_int(double x, const std::string& where) {
  if (!is_whole_in(x, std::numeric_limits<int>::min(), std::numeric_limits<int>::max()))
    throw InvalidInput(cat(where, " = ", x, " is not a whole number within [",
                           std::numeric_limits<int>::min(), ", ",
                           std::numeric_limits<int>::max(), "]"));
  return static_cast<int>(x);
}

}  // namespace caps
