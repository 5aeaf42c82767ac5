#pragma once
/// @brief Limits on JSON text caps reads (plan, model.json, mesh.json, procedure files, requests).
///
/// A JSON parser that builds a tree recurses, and so does the code that walks and frees the tree:
/// a file nested 200,000 deep overflows the stack or takes gigabytes. Every reader of JSON from a
/// file or a request calls check_json_depth() on the text before parsing it.

#include <cstddef>
#include <string>
#include <string_view>

namespace caps {

/// Deepest nesting of arrays and objects accepted in any JSON caps reads (caps' own files nest
/// at most 6 deep).
constexpr int kMaxJsonDepth = 100;

/// Throws InvalidInput naming `source` when `text` nests arrays/objects deeper than `max_depth`.
/// Brackets inside strings (escapes included) do not count; the text is not otherwise validated
/// (the parser does that). Linear time, no allocation.
void check_json_depth(std::string_view text, const std::string& source,
                      int max_depth = kMaxJsonDepth);

}  // namespace caps

namespace caps {

/// The offset of the first byte of `text` that is not part of valid UTF-8 (overlong forms,
/// surrogates and code points above U+10FFFF included), or npos when it is all valid.
std::size_t first_invalid_utf8(std::string_view text);

/// Throws InvalidInput when `text` (a file or folder name that caps will record in a JSON file,
/// which must be UTF-8) is not valid UTF-8: the message names `what`, shows the text with the
/// invalid bytes as \xNN, and says to rename it. A name recorded with its bytes replaced could
/// not be found again (a plan's model folder), and JSON writers throw on such bytes.
void require_utf8(std::string_view text, const std::string& what);

}  // namespace caps
