#pragma once
// Internal: suture pairs in JSON, shared by plan files and procedure files:
// [[a,b],[c,d]] (the paper's edge pairs) or [[a,...,b],[c,...,d]] (runs).

#include <nlohmann/json.hpp>
#include <string>

#include "caps/core/checked_numbers.hpp"
#include "caps/core/error.hpp"
#include "caps/plan/plan.hpp"

namespace caps::plan::detail {

/// A JSON array of indices, each a whole number within int's range (a cast of 1e300 to int is
/// undefined): InvalidInput naming `where` and the entry otherwise.
inline std::vector<int> index_list(const nlohmann::json& a, const std::string& where) {
  if (!a.is_array()) throw InvalidInput(cat(where, " must be an array of indices, got ", a.dump()));
  std::vector<int> out;
  for (std::size_t i = 0; i < a.size(); ++i) {
    if (!a[i].is_number())
      throw InvalidInput(cat(where, "[", i, "] must be an index, got ", a[i].dump()));
    out.push_back(to_int(a[i].get<double>(), cat(where, "[", i, "]")));
  }
  return out;
}

/// A JSON array of index arrays (paths, flaps).
inline std::vector<std::vector<int>> index_lists(const nlohmann::json& a, const std::string& where) {
  if (!a.is_array()) throw InvalidInput(cat(where, " must be an array of index arrays, got ", a.dump()));
  std::vector<std::vector<int>> out;
  for (std::size_t i = 0; i < a.size(); ++i) out.push_back(index_list(a[i], cat(where, "[", i, "]")));
  return out;
}

inline SuturePair suture_from_json(const nlohmann::json& s, const std::string& source) {
  auto run = [&](const nlohmann::json& r) {
    if (!r.is_array() || r.size() < 2)
      throw InvalidInput(cat(source, ": sutures: each entry is [[a,b],[c,d]] (two border edges) "
                                     "or [[a,...,b],[c,...,d]] (two runs of border nodes), got ",
                             s.dump()));
    return index_list(r, cat(source, ": sutures: a run"));
  };
  if (!s.is_array() || s.size() != 2) run(nlohmann::json());  // throws with the message
  return {run(s[0]), run(s[1])};
}

inline nlohmann::json suture_to_json(const SuturePair& s) { return {s.first, s.second}; }

}  // namespace caps::plan::detail
