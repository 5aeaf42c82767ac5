#include "caps/core/json_limits.hpp"

#include "caps/core/error.hpp"

namespace caps {

void check_json_depth(std::string_view text, const std::string& source, int max_depth) {
  int depth = 0;
  bool in_string = false;
  for (std::size_t i = 0; i < text.size(); ++i) {
    const char c = text[i];
    if (in_string) {
      if (c == '\\') ++i;  // skip the escaped character
      else if (c == '"') in_string = false;
      continue;
    }
    if (c == '"') {
      in_string = true;
    } else if (c == '[' || c == '{') {
      if (++depth > max_depth)
        throw InvalidInput(cat(source, ": JSON nested more than ", max_depth,
                               " levels deep (at byte ", i,
                               "); the file is damaged or was not written by caps"));
    } else if (c == ']' || c == '}') {
      --depth;
    }
  }
}

}  // namespace caps
