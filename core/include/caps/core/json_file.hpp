#pragma once
/// @brief Reading a JSON file (or JSON text) the one way every caps reader does: the file's
/// access checked with a reason the user can act on, its size and its nesting bounded, and a
/// syntax error reported with the file, the line and the column.
///
/// The parser is the caller's (nlohmann::json in every module that reads JSON); this header
/// names no JSON library, only the parse function's shape:
///
///     const nlohmann::json j = read_json_file<nlohmann::json>(path, "is this a caps mesh?");
///     const nlohmann::json k = parse_json<nlohmann::json>(text, "the request");

#include <cstddef>
#include <filesystem>
#include <string>
#include <string_view>

#include "caps/core/error.hpp"
#include "caps/core/json_limits.hpp"

namespace caps {

/// Largest JSON file caps reads: 256 MiB (caps' own largest, a simulation's mesh.json, holds
/// about 0.1 MB on the demo patient).
constexpr std::size_t kMaxJsonBytes = std::size_t(256) << 20;

/// The text of the JSON file `path`. Throws IoError "<path>: <why>; <what_to_do>" when it cannot
/// be read (no such file, permission denied, a folder: unreadable_reason()) and InvalidInput
/// naming it when it holds more than `max_bytes` or nests deeper than kMaxJsonDepth.
std::string read_json_text(const std::filesystem::path& path, const std::string& what_to_do,
                           std::size_t max_bytes = kMaxJsonBytes);

/// "<source>: not valid JSON at line L, column C (<what the parser says>)", the line and column
/// of byte `byte` (1-based, the parser's count; 0: no position) of `text`.
std::string json_syntax_message(std::string_view text, std::size_t byte, const std::string& source,
                                std::string_view parser_message);

/// Parses `text` as JSON with `Json::parse` after check_json_depth(); throws InvalidInput naming
/// `source` (a file's path, "the request") and the place of a syntax error.
template <class Json>
Json parse_json(const std::string& text, const std::string& source) {
  check_json_depth(text, source);
  try {
    return Json::parse(text);
  } catch (const typename Json::parse_error& e) {
    throw InvalidInput(json_syntax_message(text, e.byte, source, e.what()));
  } catch (const typename Json::exception& e) {
    throw InvalidInput(json_syntax_message(text, 0, source, e.what()));
  }
}

/// read_json_text() and parse_json(): the JSON of the file `path`, errors naming it.
template <class Json>
Json read_json_file(const std::filesystem::path& path, const std::string& what_to_do,
                    std::size_t max_bytes = kMaxJsonBytes) {
  return parse_json<Json>(read_json_text(path, what_to_do, max_bytes), path.string());
}

}  // namespace caps
