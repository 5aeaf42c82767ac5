#pragma once
// Where the model's ray (theta, z) crosses one of the analytic phantom's surfaces: the expected
// values of the volume model tests, computed from the phantom's closed form.

#include <cmath>

#include "caps/volume/cylindrical_map.hpp"
#include "caps/volume/phantom.hpp"

namespace caps_test {

/// The radius along the model's ray (theta [rad], z [mm]) where the phantom's surface
/// r = R(theta', z') (in the phantom's own cylindrical frame) is crossed, the outermost crossing
/// inward from r_from; NaN if never.
template <typename Radius>
double analytic_crossing(const caps::HeadPhantom& ph, const caps::CylinderAxis& axis, double theta,
                         double z, Radius&& R, double r_from = 160.0) {
  const Eigen::Vector3d a = ph.axis_point();
  auto g = [&](double r) {
    const Eigen::Vector3d p = axis.to_lps(theta, z, r) - a;
    const double th = std::atan2(p[0], -p[1]);
    return R(th, p[2]) - std::hypot(p[0], p[1]);  // > 0 inside
  };
  double prev = r_from;
  if (g(prev) > 0) return std::nan("");
  for (double r = r_from - 0.05; r >= 0; r -= 0.05) {
    if (g(r) > 0) {
      double lo = r, hi = prev;
      for (int i = 0; i < 40; ++i) {
        const double m = 0.5 * (lo + hi);
        (g(m) > 0 ? lo : hi) = m;
      }
      return 0.5 * (lo + hi);
    }
    prev = r;
  }
  return std::nan("");
}

}  // namespace caps_test
