#pragma once
/// @brief Isotropic linear elastic material (mm-N-MPa) and the default soft-tissue layers.
///
/// Parameters and ranges (validated once, in the constructor):
///   E_mpa  Young's modulus, MPa (= N/mm^2), 0 < E_mpa <= 1e3 (soft tissue is 1e-4..1 MPa)
///   nu     Poisson's ratio, dimensionless, 0 <= nu < 0.5 (nu <= 0.499 keeps the displacement
///          elements free of volumetric locking; use nu ~ 0.45-0.49 for nearly incompressible
///          tissue, never 0.5, which needs a mixed u-p formulation)

#include <string>

namespace caps::fem {

/// Isotropic linear elastic material. Throws InvalidInput on construction if out of range.
class LinearElastic {
 public:
  static constexpr double kMaxE_mpa = 1e3;
  static constexpr double kMaxNu = 0.499;

  /// @param E_mpa  Young's modulus (MPa)
  /// @param nu     Poisson's ratio
  /// @param where  names the material in error messages ("layer 1", "--E")
  LinearElastic(double E_mpa, double nu, const std::string& where = "material");

  double E_mpa() const { return E_mpa_; }
  double nu() const { return nu_; }
  /// Lame's first parameter lambda (MPa).
  double lambda_mpa() const { return E_mpa_ * nu_ / ((1 + nu_) * (1 - 2 * nu_)); }
  /// Shear modulus mu = G (MPa).
  double mu_mpa() const { return E_mpa_ / (2 * (1 + nu_)); }

 private:
  double E_mpa_;
  double nu_;
};

/// Indicative skin (dermis + epidermis) in vivo: E = 100 kPa, nu = 0.45. Sources in docs/fem.md.
LinearElastic default_skin();
/// Indicative subcutaneous fat: E = 5 kPa, nu = 0.45. Sources in docs/fem.md.
LinearElastic default_subcutaneous();

}  // namespace caps::fem
