#pragma once
// Numbers as users type and read them, for app/src only.

#include <array>
#include <cmath>
#include <sstream>
#include <string>
#include <vector>

#include "caps/core/error.hpp"

namespace caps::app {

/// x rounded to `digits` decimals (for messages and summaries: 0.95, not 0.949219).
inline double round_to(double x, int digits) {
  const double f = std::pow(10.0, digits);
  return std::round(x * f) / f;
}

/// x rounded to `significant` significant digits.
inline double round_sig(double x, int significant) {
  if (x == 0 || !std::isfinite(x)) return x;
  const int digits = significant - 1 - static_cast<int>(std::floor(std::log10(std::abs(x))));
  return round_to(x, digits);
}

/// Parses "a,b,c" (N numbers separated by commas); throws InvalidInput naming `option` and
/// saying what the numbers are (`meaning`).
template <std::size_t N>
std::array<double, N> parse_numbers(const std::string& text, const std::string& option,
                                    const std::string& meaning) {
  std::array<double, N> v{};
  std::istringstream in(text);
  for (std::size_t i = 0; i < N; ++i) {
    char comma = ',';
    if ((i > 0 && !(in >> comma)) || comma != ',' || !(in >> v[i]) || !std::isfinite(v[i]))
      throw InvalidInput(cat(option, " '", text, "': expected ", N, " numbers separated by "
                             "commas (", meaning, ")"));
  }
  if (!(in >> std::ws).eof())
    throw InvalidInput(cat(option, " '", text, "': expected ", N, " numbers separated by commas (",
                           meaning, ")"));
  return v;
}

/// "a,b;c,d;..." as points of N numbers each (`option`, `meaning` for the message).
template <std::size_t N>
std::vector<std::array<double, N>> parse_point_list(const std::string& text,
                                                    const std::string& option,
                                                    const std::string& meaning) {
  std::vector<std::array<double, N>> out;
  std::istringstream in(text);
  for (std::string item; std::getline(in, item, ';');)
    if (item.find_first_not_of(" \t") != std::string::npos)
      out.push_back(parse_numbers<N>(item, option, meaning));
  return out;
}

}  // namespace caps::app
