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
///
/// Results are declared the same way: a static `fields(result, visitor)` lists the keys of the
/// result's JSON, from which `to_json(result)` is derived (and `result_from_json` reads it back).
/// Besides `v(value, {"key"})` (the types above, std::vector<std::string>, Eigen 3-vectors) a
/// result's fields may use
///   v.group({"lengthening"}, [&] { ... })   a nested object of fields;
///   v.when(flag, [&] { ... })               fields written only when `flag` holds (a bool member
///                                           is set on reading to whether they were there);
///   v.computed({"mm"}, [&] { return x; })   a value computed from others: written, not read;
///   v.pair(a, b, {"thickness_mm"})           [a, b] under one key;
///   v.json_value(text, {"features"})         a JSON value (array or object) kept as its text;
///   v.document(text, {"model_json"})         a JSON document written elsewhere (model.json) whose
///                                           keys sit beside the declared ones (declare it first:
///                                           the declared keys win).

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
  std::string_view help = {};       ///< one line, with the unit
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

/// A result's JSON from its declared fields (what each result's to_json() returns).
template <class Result>
std::string result_to_json(const Result& result);

/// Reads a result back from its JSON (to_json()'s): every key must be a declared field (or go to
/// its document); errors name `source`. Defined for every result type in app/.
template <class Result>
Result result_from_json(const std::string& json_text, const std::string& source = "result");

}  // namespace caps::app
