#pragma once
/// @brief Requests declared once: each request struct lists its fields (name, help, kind) in a
/// member template `fields(visitor)`, so that the command line, the JSON reader and writer, the
/// planner's server and the Python bindings all take the same names, help texts and defaults.
///
/// A field's JSON key is snake_case (`mesh_size`); its command-line option is the key with
/// dashes (`--mesh-size`) unless the field says otherwise (`-o,--output`, a positional
/// `MODEL_DIR`). Defaults are the request struct's member initialisers, which take them from the
/// library's options structs. Field types: std::string, double, int, bool, std::optional<double>,
/// std::map<std::string, double> (named parameters such as a template's).

#include <string>
#include <string_view>

namespace caps::app {

enum class FieldKind {
  Option,      ///< --name VALUE, optional
  Required,    ///< --name VALUE, required
  Positional,  ///< a positional argument (required)
  Flag,        ///< --name (a bool)
  Parameters,  ///< a map of named numbers; on the command line one option per known name
};

/// One field of a request.
struct Field {
  std::string_view key;             ///< JSON key, snake_case
  std::string_view help;            ///< one line, with the unit
  FieldKind kind = FieldKind::Option;
  std::string_view cli = {};        ///< command-line spelling when not "--" + dashed key
  std::string_view old_cli = {};    ///< a former spelling, still accepted with a note
};

/// "mesh_size" -> "mesh-size".
std::string dashed(std::string_view key);

/// The option as a user types it: "--mesh-size" (or the positional's name).
std::string option_name(const Field& field);

/// Reads a request from JSON text: every key must be a field of the request, of the field's type
/// (errors name the key and `source`); fields not given keep their defaults. Required and
/// positional fields must be present. Defined for every request type in app/.
template <class Request>
Request read_request(const std::string& json_text, const std::string& source = "request");

/// Writes every field of a request as JSON text.
template <class Request>
std::string write_request(const Request& request);

}  // namespace caps::app
