#pragma once
/// @brief Private helper of the volume module (not installed): a 3-vector as a JSON array, as
/// model.json and the model's summaries write points, directions, sizes and spacings.

#include <Eigen/Core>
#include <nlohmann/json.hpp>

namespace caps::detail {

template <class T>
nlohmann::json vec_json(const Eigen::Matrix<T, 3, 1>& v) {
  return nlohmann::json::array({v[0], v[1], v[2]});
}

}  // namespace caps::detail
