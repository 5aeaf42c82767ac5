#pragma once
// Synthetic patient-model maps for tests: a grid where every cell is measured and valid, with a
// skin radius r(theta_deg, z_mm) and a soft-tissue thickness t(theta_deg, z_mm) known exactly.

#include "caps/volume/cylindrical_map.hpp"

namespace caps_test {

template <typename Radius, typename Thickness>
caps::CylindricalMaps synthetic_maps(const caps::CylinderGrid& grid, Radius&& r, Thickness&& t) {
  caps::CylindricalMaps m;
  m.grid = grid;
  m.allocate();
  for (int k = 0; k < grid.n_z; ++k)
    for (int j = 0; j < grid.n_theta; ++j) {
      const auto c = grid.index(j, k);
      const double theta = grid.theta_deg(j), z = grid.z_mm(k);
      m.r_skin[c] = static_cast<float>(r(theta, z));
      m.thickness[c] = m.thickness_normal[c] = static_cast<float>(t(theta, z));
      m.r_bone[c] = m.r_skin[c] - m.thickness[c];
      m.measured_skin[c] = m.measured_bone[c] = 1;
    }
  return m;
}

/// A grid over theta in [-180, 180) with n_theta samples and z from z0_mm in n_z steps of dz_mm.
inline caps::CylinderGrid grid(int n_theta, int n_z, double z0_mm, double dz_mm) {
  caps::CylinderGrid g;
  g.n_theta = n_theta;
  g.n_z = n_z;
  g.z0_mm = z0_mm;
  g.dz_mm = dz_mm;
  return g;
}

}  // namespace caps_test
