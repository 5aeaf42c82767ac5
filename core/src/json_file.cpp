#include "caps/core/json_file.hpp"

#include <fstream>
#include <sstream>
#include <system_error>

#include "caps/core/file_access.hpp"

namespace caps {

std::string read_json_text(const std::filesystem::path& path, const std::string& what_to_do,
                           std::size_t max_bytes) {
  require_readable(path, false, what_to_do);
  std::error_code ec;
  const auto size = std::filesystem::file_size(path, ec);
  if (!ec && size > max_bytes)
    throw InvalidInput(cat(path.string(), ": ", size, " bytes, more than the ", max_bytes,
                           " a JSON file caps reads may hold; ", what_to_do));
  std::ifstream in(path, std::ios::binary);
  std::ostringstream text;
  if (!in || !(text << in.rdbuf()) || in.bad())
    throw IoError(cat(path.string(), ": cannot be read; ", what_to_do));
  std::string s = std::move(text).str();
  if (s.size() > max_bytes)  // a file that grew, or a pipe whose size was not known
    throw InvalidInput(cat(path.string(), ": more than the ", max_bytes,
                           " bytes a JSON file caps reads may hold; ", what_to_do));
  check_json_depth(s, path.string());
  return s;
}

std::string json_syntax_message(std::string_view text, std::size_t byte, const std::string& source,
                                std::string_view parser_message) {
  // nlohmann: "[json.exception.parse_error.101] parse error at line 1, column 9: syntax error
  // ..."; keep what follows the position, the place is said once, in the user's terms.
  std::string_view what = parser_message;
  if (what.starts_with("[json.exception.")) {
    const auto end = what.find("] ");
    if (end != std::string_view::npos) what.remove_prefix(end + 2);
  }
  if (what.starts_with("parse error")) {
    const auto colon = what.find(": ");
    if (colon != std::string_view::npos) what.remove_prefix(colon + 2);
  }
  if (byte == 0) return cat(source, ": not valid JSON (", what, ")");
  std::size_t line = 1, column = 1;
  const std::size_t end = std::min(byte - 1, text.size());
  for (std::size_t i = 0; i < end; ++i) {
    if (text[i] == '\n') {
      ++line;
      column = 1;
    } else {
      ++column;
    }
  }
  return cat(source, ": not valid JSON at line ", line, ", column ", column, " (", what, ")");
}

}  // namespace caps
