#include "caps/fem/suture_report.hpp"

#include <algorithm>

namespace caps::fem {

double max_suture_pair_force_n(const SolveResult& result) {
  double f = 0;
  for (const auto& s : result.suture_forces) f = std::max(f, s.magnitude_n);
  return f;
}

}  // namespace caps::fem
