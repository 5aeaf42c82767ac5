#include "caps/image/colormap.hpp"

#include <algorithm>

namespace caps {

Eigen::Vector3d viridis(double t) {
  static const double kStops[11][3] = {
      {68, 1, 84},    {72, 36, 117},  {65, 68, 135},  {53, 95, 141},  {42, 120, 142},
      {33, 145, 140}, {34, 168, 132}, {68, 191, 112}, {122, 209, 81}, {189, 223, 38},
      {253, 231, 37}};
  t = std::clamp(t, 0.0, 1.0) * 10.0;
  const int i = std::min(9, static_cast<int>(t));
  const double f = t - i;
  Eigen::Vector3d c;
  for (int a = 0; a < 3; ++a) c[a] = (kStops[i][a] * (1 - f) + kStops[i + 1][a] * f) / 255.0;
  return c;
}

}  // namespace caps
