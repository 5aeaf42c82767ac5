#pragma once
// A synthetic patient model for the mesher, closure and study tests: a cylinder of skin with a
// thickness known exactly.

#include <cstdint>
#include <utility>

#include "caps/surface/patient_model.hpp"
#include "synthetic_model.hpp"

namespace caps_test {

inline constexpr double kR = 70.0;

// A cylinder of radius 70 mm about the LPS z axis, z in [-200, 200], with thickness T(theta, z).
template <typename Thickness>
caps::PatientModel cylinder(Thickness&& T, std::uint8_t flag_band = 0) {
  caps::CylindricalMaps m = caps_test::synthetic_maps(caps_test::grid(360, 401, -200, 1),
                                                [](double, double) { return kR; }, T);
  // an invalid band at z in [60, 70] (e.g. no bone)
  for (int k = 0; k < m.grid.n_z; ++k)
    for (int j = 0; j < m.grid.n_theta; ++j)
      if (flag_band && m.grid.z_mm(k) >= 60 && m.grid.z_mm(k) <= 70) m.flags[m.grid.index(j, k)] = flag_band;
  return caps::PatientModel(std::move(m));
}

inline caps::PatientModel constant_cylinder() { return cylinder([](double, double) { return 5.0; }); }

}  // namespace caps_test
