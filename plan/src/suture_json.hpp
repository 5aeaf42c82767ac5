#pragma once
// Internal: suture pairs in JSON, shared by plan files and procedure files:
// [[a,b],[c,d]] (the paper's edge pairs) or [[a,...,b],[c,...,d]] (runs).

#include <nlohmann/json.hpp>
#include <string>

#include "caps/core/error.hpp"
#include "caps/plan/plan.hpp"

namespace caps::plan::detail {

inline SuturePair suture_from_json(const nlohmann::json& s, const std::string& source) {
  auto run = [&](const nlohmann::json& r) {
    if (!r.is_array() || r.size() < 2)
      throw InvalidInput(cat(source, ": sutures: each entry is [[a,b],[c,d]] (two border edges) "
                                     "or [[a,...,b],[c,...,d]] (two runs of border nodes), got ",
                             s.dump()));
    return r.get<BorderRun>();
  };
  if (!s.is_array() || s.size() != 2) run(nlohmann::json());  // throws with the message
  return {run(s[0]), run(s[1])};
}

inline nlohmann::json suture_to_json(const SuturePair& s) { return {s.first, s.second}; }

}  // namespace caps::plan::detail
