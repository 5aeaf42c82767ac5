#pragma once
// Internal text helpers of the HTML reports (simulation_report.cpp, model_comparison_report.cpp).

#include <cstdio>
#include <string>

namespace caps::render::detail {

/// x with `digits` decimals ("%.*f").
inline std::string fmt(double x, int digits = 2) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*f", digits, x);
  return buf;
}

/// text with <, >, & and " escaped for HTML.
inline std::string html_escape(const std::string& text) {
  std::string out;
  for (const char ch : text) {
    if (ch == '<') out += "&lt;";
    else if (ch == '>') out += "&gt;";
    else if (ch == '&') out += "&amp;";
    else if (ch == '"') out += "&quot;";
    else out += ch;
  }
  return out;
}

}  // namespace caps::render::detail
