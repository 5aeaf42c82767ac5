#pragma once
// Refusing an output that is, or contains, one of the request's inputs (private to app/).
// `solve mesh -o mesh` or `model from-scan model/skin.ply -o model` would replace the input with
// the result, even with --force: every request's path fields are compared with its output.

#include <string>
#include <string_view>
#include <type_traits>
#include <utility>
#include <vector>

#include "caps/app/fields.hpp"

namespace caps::app::detail {

/// Throws InvalidInput naming both fields when `output` (as a path) is the same file or folder as
/// one of `inputs`, or a folder that holds one. Inputs that do not exist are ignored (they are
/// not paths, or their own reader reports them).
void refuse_output_over_inputs(const std::string& output,
                               const std::vector<std::pair<std::string, std::string>>& inputs);

// Collects a request's "output" field and its other text fields.
struct PathFields {
  const std::string* output = nullptr;
  std::vector<std::pair<std::string, std::string>> inputs;
  template <class T>
  void operator()(const T& value, const Field& f) {
    if constexpr (std::is_same_v<T, std::string>) {
      if (f.key == "output") output = &value;
      else if (!value.empty()) inputs.emplace_back(option_name(f), value);
    }
  }
};

/// The same for a request: its "output" field against every other text field.
template <class Request>
void refuse_output_over_inputs(const Request& request) {
  PathFields p;
  Request::fields(request, p);
  if (p.output && !p.output->empty()) refuse_output_over_inputs(*p.output, p.inputs);
}

}  // namespace caps::app::detail
