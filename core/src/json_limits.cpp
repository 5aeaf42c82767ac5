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

namespace caps {

std::size_t first_invalid_utf8(std::string_view text) {
  const auto* s = reinterpret_cast<const unsigned char*>(text.data());
  const std::size_t n = text.size();
  std::size_t i = 0;
  while (i < n) {
    const unsigned c = s[i];
    if (c < 0x80) {
      ++i;
      continue;
    }
    std::size_t len = 0;
    unsigned lo = 0x80, hi = 0xbf;  // the allowed range of the second byte (RFC 3629, section 4)
    if (c >= 0xc2 && c <= 0xdf) len = 2;
    else if (c == 0xe0) len = 3, lo = 0xa0;
    else if (c == 0xed) len = 3, hi = 0x9f;  // no UTF-16 surrogates
    else if (c >= 0xe1 && c <= 0xef) len = 3;
    else if (c == 0xf0) len = 4, lo = 0x90;
    else if (c == 0xf4) len = 4, hi = 0x8f;  // nothing above U+10FFFF
    else if (c >= 0xf1 && c <= 0xf3) len = 4;
    else return i;
    if (i + len > n || s[i + 1] < lo || s[i + 1] > hi) return i;
    for (std::size_t k = 2; k < len; ++k)
      if (s[i + k] < 0x80 || s[i + k] > 0xbf) return i;
    i += len;
  }
  return std::string_view::npos;
}

void require_utf8(std::string_view text, const std::string& what) {
  const std::size_t bad = first_invalid_utf8(text);
  if (bad == std::string_view::npos) return;
  // The valid runs as they are, each invalid byte as \xNN.
  std::string shown;
  static const char* hex = "0123456789abcdef";
  for (std::size_t i = 0; i < text.size();) {
    const std::size_t run = first_invalid_utf8(text.substr(i));
    if (run == std::string_view::npos) {
      shown += text.substr(i);
      break;
    }
    shown += text.substr(i, run);
    const auto c = static_cast<unsigned char>(text[i + run]);
    shown += "\\x";
    shown += hex[c >> 4];
    shown += hex[c & 15];
    i += run + 1;
  }
  throw InvalidInput(cat(what, " \"", shown, "\" is not valid UTF-8 (byte ", bad,
                         "): caps records it in its JSON files, which must be UTF-8; rename it "
                         "with UTF-8 characters (e.g. `convmv -f latin1 -t utf8 -r --notest`)"));
}

}  // namespace caps
