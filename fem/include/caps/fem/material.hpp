#pragma once
/// @brief Materials (mm-N-MPa): the declared-parameter interface, isotropic linear elasticity
/// (the small-strain model of the 1992 paper) and the compressible neo-Hookean solid for the
/// finite-strain path, and the default soft-tissue layers.
///
/// Every material declares its parameters once, with unit and valid range (FEBio's
/// ADD_PARAMETER with a range), and validates them once, when it is built: an out-of-range value
/// is InvalidInput naming the material, the parameter, its value and the range.
///
/// Stresses and tangents use Voigt order xx, yy, zz, xy, yz, xz. A tangent maps the Green-Lagrange
/// strain with engineering shears (E_xx, E_yy, E_zz, 2E_xy, 2E_yz, 2E_xz) to the second
/// Piola-Kirchhoff stress: dS = C dE, C_IJ = C_ijkl (Holzapfel 2000, sec. 6.6).

#include <Eigen/Core>
#include <string>
#include <vector>

namespace caps::fem {

using Vector6d = Eigen::Matrix<double, 6, 1>;
using Matrix6d = Eigen::Matrix<double, 6, 6>;

/// One declared material parameter and its valid range (bounds open or closed).
struct ParameterSpec {
  std::string name;         ///< as in messages and files: "E", "nu"
  std::string unit;         ///< "MPa", "1" (dimensionless)
  double min = 0, max = 0;  ///< valid range
  bool min_open = false;    ///< min itself is invalid
  bool max_open = false;    ///< max itself is invalid
  std::string hint;         ///< what to do about a bad value
};

/// A hyperelastic (or, for LinearElastic, small-strain) material: stress and tangent from the
/// deformation gradient F = dx/dX = I + H (3×3, dimensionless). F is passed as its displacement
/// gradient H = du/dX so that small strains keep their digits (1 + 1e-6 keeps only ten of them,
/// and the Newton residual of a small load would stall at that round-off).
class Material {
 public:
  virtual ~Material() = default;
  /// "linear", "neo-hookean".
  virtual std::string name() const = 0;
  /// The declared parameters, in the order of values().
  virtual std::vector<ParameterSpec> parameters() const = 0;
  /// Current parameter values, in the units of parameters().
  virtual std::vector<double> values() const = 0;
  /// Second Piola-Kirchhoff stress S (Voigt, MPa) and material tangent C (6×6 Voigt, MPa) at
  /// F = I + H. det F must be > 0 (the caller checks; an inverted point has no stress).
  virtual void stress_and_tangent(const Eigen::Matrix3d& H, Vector6d& S, Matrix6d& C) const = 0;
  /// Strain energy per reference volume W(I + H), MPa = mJ/mm^3.
  virtual double strain_energy_density(const Eigen::Matrix3d& H) const = 0;

 protected:
  /// Checks values() against parameters(); throws InvalidInput naming `where` and the parameter.
  void validate_parameters(const std::string& where) const;
};

/// Base of the isotropic materials defined by the small-strain Young's modulus and Poisson's
/// ratio. Declared parameters:
///   E   Young's modulus, MPa (= N/mm^2), 0 < E <= 1e3 (soft tissue is 1e-4..1 MPa)
///   nu  Poisson's ratio, dimensionless, 0 <= nu <= 0.499 (keeps the displacement elements free
///       of volumetric locking; use 0.45-0.49 for nearly incompressible tissue, never 0.5)
class IsotropicElastic : public Material {
 public:
  static constexpr double kMaxE_mpa = 1e3;
  static constexpr double kMaxNu = 0.499;

  double E_mpa() const { return E_mpa_; }
  double nu() const { return nu_; }
  /// Lame's first parameter lambda (MPa).
  double lambda_mpa() const { return E_mpa_ * nu_ / ((1 + nu_) * (1 - 2 * nu_)); }
  /// Shear modulus mu = G (MPa).
  double mu_mpa() const { return E_mpa_ / (2 * (1 + nu_)); }
  /// Bulk modulus K (MPa).
  double bulk_mpa() const { return E_mpa_ / (3 * (1 - 2 * nu_)); }

  std::vector<ParameterSpec> parameters() const override;
  std::vector<double> values() const override { return {E_mpa_, nu_}; }

 protected:
  IsotropicElastic(double E_mpa, double nu) : E_mpa_(E_mpa), nu_(nu) {}

 private:
  double E_mpa_;
  double nu_;
};

/// Isotropic linear elastic material: the small-strain model (sigma = D : eps). Throws
/// InvalidInput on construction if E or nu is out of range (IsotropicElastic).
/// As a Material it gives the linearized response: S = D : eps with eps = sym(H) and
/// C = D (valid only for small strains; the linear solve uses it in its own small-strain path).
class LinearElastic final : public IsotropicElastic {
 public:
  /// @param E_mpa  Young's modulus (MPa)
  /// @param nu     Poisson's ratio
  /// @param where  names the material in error messages ("layer 1", "--E")
  LinearElastic(double E_mpa, double nu, const std::string& where = "material");

  std::string name() const override { return "linear"; }
  void stress_and_tangent(const Eigen::Matrix3d& H, Vector6d& S, Matrix6d& C) const override;
  double strain_energy_density(const Eigen::Matrix3d& H) const override;
};

/// Compressible neo-Hookean solid in the decoupled form of Abaqus and CalculiX (*HYPERELASTIC,
/// NEO HOOKE), so that a CalculiX NLGEOM run solves the same problem:
///   W = mu/2 (J^(-2/3) I1 - 3) + K/2 (J - 1)^2,   C10 = mu/2, D1 = 2/K
/// (Holzapfel 2000, sec. 6.4-6.6, eq. 6.144 with U(J) = K/2 (J-1)^2). mu and K come from the
/// small-strain E and nu (mu = E / (2(1+nu)), K = E / (3(1-2nu))), so small loads give the
/// linear answer. Parameters as IsotropicElastic; throws InvalidInput naming `where` and the
/// parameter if one is out of range.
class NeoHookean final : public IsotropicElastic {
 public:
  /// @param E_mpa  small-strain Young's modulus (MPa)
  /// @param nu     small-strain Poisson's ratio
  /// @param where  names the material in error messages
  NeoHookean(double E_mpa, double nu, const std::string& where = "material");
  /// The neo-Hookean solid with the small-strain constants of `linear`.
  explicit NeoHookean(const LinearElastic& linear, const std::string& where = "material");

  /// CalculiX / Abaqus C10 = mu/2 (MPa).
  double c10_mpa() const { return 0.5 * mu_mpa(); }
  /// CalculiX / Abaqus D1 = 2/K (1/MPa).
  double d1_per_mpa() const { return 2 / bulk_mpa(); }

  std::string name() const override { return "neo-hookean"; }
  void stress_and_tangent(const Eigen::Matrix3d& H, Vector6d& S, Matrix6d& C) const override;
  double strain_energy_density(const Eigen::Matrix3d& H) const override;
};

/// det(I + H) - 1 without the cancellation of det(F) - 1 at small strain:
/// tr H + ((tr H)^2 - tr(H^2)) / 2 + det H.
double volume_change(const Eigen::Matrix3d& H);

/// Indicative skin (dermis + epidermis) in vivo: E = 100 kPa, nu = 0.45. Sources in docs/fem.md.
LinearElastic default_skin();
/// Indicative subcutaneous fat: E = 5 kPa, nu = 0.45. Sources in docs/fem.md.
LinearElastic default_subcutaneous();

}  // namespace caps::fem

namespace caps::fem {

/// The tissue layers the continuum mesher follows with TissueLayers::Measured (docs/fem.md,
/// "Measured layers", has the sources). Small-strain constants; the finite-strain solve uses the
/// neo-Hookean solid with the same E and nu.
/// Dermis (skin layer down to the subcutaneous fat): E = 100 kPa, nu = 0.45 (as default_skin()).
LinearElastic default_dermis();
/// Subcutaneous fat: E = 3 kPa, nu = 0.45.
LinearElastic default_fat();
/// Deep soft tissue between the fat and the bone (muscle, fascia, galea, SMAS): E = 20 kPa,
/// nu = 0.45.
LinearElastic default_deep();

}  // namespace caps::fem
