#pragma once
// The result of a model-building verb from the directory it wrote (private to app/).

#include <string>

#include "caps/app/model.hpp"

namespace caps::app::detail {

/// model.json of `dir` (its warnings included) and the model's summary; `output` is reported.
ModelResult model_result(const std::string& dir, const std::string& output);

/// Throws why caps model chart cannot measure a local chart of the model in `model`: a model
/// built from a surface scan, itself a chart, whose bone came from a separate mask (InvalidInput),
/// or whose volume is no longer where model.json says (IoError).
void refuse_unchartable(const std::string& model);

/// A local chart (caps model chart) is a piece of its parent's skin in the parent's LPS frame:
/// the parent's folder when it is still the model the chart was cut from (model.json's content
/// hash equal to the one the chart recorded), else empty (also for a model that is no chart).
std::string chart_parent(const std::string& model_dir);

/// The model a plan is checked, meshed and solved on when the user names `given`: `given`, or
/// the local chart of `given` the plan lies on (caps plan new makes one beside the plan where
/// the head's cylindrical image cannot hold the skin), which is solved in `given`'s whole face.
/// Any other plan gets `given`, whose check then says whether the plan belongs to it.
std::string plan_model_dir(const std::string& given, const std::string& plan_model,
                           const std::string& plan_model_hash);

}  // namespace caps::app::detail
