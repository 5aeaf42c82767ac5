#include "caps/app/fields.hpp"

#include <algorithm>

namespace caps::app {

std::string dashed(std::string_view key) {
  std::string s(key);
  std::replace(s.begin(), s.end(), '_', '-');
  return s;
}

std::string option_name(const Field& f) {
  if (f.cli.empty()) return "--" + dashed(f.key);
  const std::string_view cli = f.cli;
  const auto comma = cli.rfind(',');  // "-o,--output" -> "--output"
  return std::string(comma == std::string_view::npos ? cli : cli.substr(comma + 1));
}

}  // namespace caps::app
