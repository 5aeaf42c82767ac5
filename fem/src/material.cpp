#include "caps/fem/material.hpp"

#include <cmath>

#include "caps/core/error.hpp"

namespace caps::fem {

LinearElastic::LinearElastic(double E_mpa, double nu, const std::string& where)
    : E_mpa_(E_mpa), nu_(nu) {
  if (!std::isfinite(E_mpa) || E_mpa <= 0 || E_mpa > kMaxE_mpa)
    throw InvalidInput(cat(where, ": Young's modulus E = ", E_mpa, " MPa (", E_mpa * 1e3,
                           " kPa) is out of range; it must be in (0, ", kMaxE_mpa,
                           "] MPa; soft tissue is about 0.001-1 MPa (1-1000 kPa)"));
  if (!std::isfinite(nu) || nu < 0 || nu >= 0.5)
    throw InvalidInput(cat(where, ": Poisson's ratio nu = ", nu,
                           " is out of range [0, 0.5); nu = 0.5 (incompressible) locks "
                           "displacement elements: use nu <= ", kMaxNu,
                           " (0.45-0.49 for nearly incompressible tissue)"));
  if (nu > kMaxNu)
    throw InvalidInput(cat(where, ": Poisson's ratio nu = ", nu, " is above ", kMaxNu,
                           "; the displacement formulation locks volumetrically this close to "
                           "0.5: use nu <= ", kMaxNu));
}

// Indicative values; sources and ranges in docs/fem.md.
LinearElastic default_skin() { return LinearElastic(0.1, 0.45, "default skin"); }
LinearElastic default_subcutaneous() { return LinearElastic(0.005, 0.45, "default subcutaneous"); }

}  // namespace caps::fem
