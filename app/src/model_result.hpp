#pragma once
// The result of a model-building verb from the directory it wrote (private to app/).

#include <string>

#include "caps/app/model.hpp"

namespace caps::app::detail {

/// model.json of `dir` (its warnings included) and the model's summary; `output` is reported.
ModelResult model_result(const std::string& dir, const std::string& output);

}  // namespace caps::app::detail
