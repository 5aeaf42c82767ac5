#pragma once
/// @brief Materials (mm-N-MPa): the declared-parameter interface, isotropic linear elasticity
/// (the small-strain model of the 1992 paper), the compressible neo-Hookean solid, the
/// Gasser-Ogden-Holzapfel skin, and the default soft-tissue layers (presets read from
/// data/materials; material_registry.hpp makes any of them by name).
///
/// Kinematics are the solve's (SolveOptions::kinematics), not the material's: the small-strain
/// solve uses a material's linearization at F = I (small_strain(): Hooke's law with the same E
/// and nu for linear and neo-hookean; goh has none and is refused there), the finite-strain
/// solve its hyperelastic response (hyperelastic(): linear is refused there, as it is not
/// objective; St Venant-Kirchhoff is not offered).
///
/// Every material declares its parameters once, with unit and valid range (FEBio's
/// ADD_PARAMETER with a range), and validates them once, when it is built: an out-of-range value
/// is InvalidInput naming the material, the parameter, its value and the range.
///
/// Stresses and tangents use Voigt order xx, yy, zz, xy, yz, xz. A tangent maps the Green-Lagrange
/// strain with engineering shears (E_xx, E_yy, E_zz, 2E_xy, 2E_yz, 2E_xz) to the second
/// Piola-Kirchhoff stress: dS = C dE, C_IJ = C_ijkl (Holzapfel 2000, sec. 6.6).

#include <Eigen/Core>
#include <memory>
#include <string>
#include <vector>

namespace caps::fem {

class IsotropicElastic;

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
  /// The registered name (material_registry.hpp): "linear", "neo-hookean", "goh".
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

  /// Whether the response depends on the plane of the element's layer (fibres in the skin's
  /// plane): the elements then call the *_in_layer forms with the layer's unit normal n (LPS) at
  /// the point. The isotropic materials ignore n.
  virtual bool uses_layer_normal() const { return false; }
  virtual void stress_and_tangent_in_layer(const Eigen::Matrix3d& H, const Eigen::Vector3d& n,
                                           Vector6d& S, Matrix6d& C) const {
    (void)n;
    stress_and_tangent(H, S, C);
  }
  virtual double strain_energy_density_in_layer(const Eigen::Matrix3d& H,
                                                 const Eigen::Vector3d& n) const {
    (void)n;
    return strain_energy_density(H);
  }

  /// The isotropic elastic constants of the material's response at F = I, which the
  /// small-strain solve uses; null for a material without them (goh: its fibres switch on at
  /// F = I), which the small-strain solve refuses.
  virtual const IsotropicElastic* small_strain() const { return nullptr; }
  /// Whether the finite-strain solve may use the material (false for linear elasticity, which a
  /// rotation stresses).
  virtual bool hyperelastic() const { return true; }
  /// A Young's modulus for scaling (MPa; penalty springs): the small-strain E, or the ground
  /// matrix's for a fibre-reinforced solid.
  virtual double stiffness_scale_mpa() const = 0;

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
  const IsotropicElastic* small_strain() const override { return this; }
  double stiffness_scale_mpa() const override { return E_mpa_; }

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
  bool hyperelastic() const override { return false; }
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

/// Skin as a fibre-reinforced solid: the Gasser-Ogden-Holzapfel model (Gasser, Ogden & Holzapfel
/// 2006, J R Soc Interface 3:15), in the decoupled form of FEBio and Abaqus, with the volumetric
/// term of NeoHookean:
///   W = mu/2 (I1bar - 3) + K/2 (J - 1)^2 + sum_i k1/(2 k2) (exp(k2 <Ebar_i>^2) - 1),
///   Ebar_i = kappa (I1bar - 3) + (1 - 3 kappa) (I4bar_i - 1),  I4bar_i = J^(-2/3) a_i . C a_i
/// (<x> = max(x, 0): collagen fibres carry no compression). The fibres lie in the skin's plane
/// (the layer's, Material::uses_layer_normal): the reference direction `langer` (LPS, e.g. along
/// Langer's lines; projected onto the plane at each point) turned by +-gamma in the plane gives
/// two families; gamma = 0 gives one. Declared parameters (throws InvalidInput naming `where`):
///   mu     ground-matrix shear modulus, MPa, (0, 1e3]
///   K      bulk modulus, MPa, (0, 1e4], K > 2 mu / 3 (Poisson's ratio >= 0)
///   k1     fibre stiffness, MPa, [0, 1e3]
///   k2     fibre exponential stiffening, dimensionless, (0, 1e3]
///   kappa  fibre dispersion, dimensionless, [0, 1/3] (1/3: isotropic)
///   gamma  fibre angle from `langer`, deg, [0, 90]
///   fibre_x, fibre_y, fibre_z  `langer` (LPS, dimensionless, each in [-1, 1]; normalised)
/// The stress and tangent follow Holzapfel 2000, sec. 6.7, written for any Ibar_h = J^(-2/3) Hs:C
/// with Hs = kappa I + (1 - 3 kappa) a (x) a (tr Hs = 1, so Ebar = Ibar_h - 1).
class GasserOgdenHolzapfel final : public Material {
 public:
  GasserOgdenHolzapfel(double mu_mpa, double K_mpa, double k1_mpa, double k2, double kappa,
                       double gamma_deg, const Eigen::Vector3d& langer,
                       const std::string& where = "material");

  std::string name() const override { return "goh"; }
  std::vector<ParameterSpec> parameters() const override;
  std::vector<double> values() const override {
    return {mu_, K_, k1_, k2_, kappa_, gamma_deg_, langer_.x(), langer_.y(), langer_.z()};
  }
  bool uses_layer_normal() const override { return true; }
  double stiffness_scale_mpa() const override { return matrix_.E_mpa(); }
  /// The frame-free forms take the layer's normal as +z.
  void stress_and_tangent(const Eigen::Matrix3d& H, Vector6d& S, Matrix6d& C) const override;
  double strain_energy_density(const Eigen::Matrix3d& H) const override;
  void stress_and_tangent_in_layer(const Eigen::Matrix3d& H, const Eigen::Vector3d& n, Vector6d& S,
                                   Matrix6d& C) const override;
  double strain_energy_density_in_layer(const Eigen::Matrix3d& H,
                                        const Eigen::Vector3d& n) const override;
  /// The unit fibre directions at a point whose layer normal is n (one or two).
  std::vector<Eigen::Vector3d> fibres(const Eigen::Vector3d& n) const;
  /// The ground matrix: the neo-Hookean solid of mu and K.
  const NeoHookean& matrix() const { return matrix_; }

 private:
  double mu_, K_, k1_, k2_, kappa_, gamma_deg_;
  Eigen::Vector3d langer_;
  NeoHookean matrix_;
};

/// Porcine skin, the preset data/materials/goh-porcine-skin.json (Tepole group's Bayesian
/// calibration, ../shared/docs/references.md): mu = 0.05 MPa, K = 0.24 MPa, k1 = 4.97 MPa,
/// k2 = 2.88, kappa = 0.0498, one fibre family along the patient's left-right (LPS x).
std::shared_ptr<const Material> default_goh_skin();

/// det(I + H) - 1 without the cancellation of det(F) - 1 at small strain:
/// tr H + ((tr H)^2 - tr(H^2)) / 2 + det H.
double volume_change(const Eigen::Matrix3d& H);

/// The presets of data/materials (their sources are in the files; InvalidInput if a file is
/// missing or bad). E and nu are small-strain constants; the presets are neo-Hookean solids,
/// whose small-strain response (small_strain()) is the linear material of the same E and nu.
/// Indicative skin (dermis + epidermis) in vivo, skin.json: E = 100 kPa, nu = 0.45.
std::shared_ptr<const Material> default_skin();
/// Indicative subcutaneous fat, subcutaneous.json: E = 5 kPa, nu = 0.45.
std::shared_ptr<const Material> default_subcutaneous();

}  // namespace caps::fem

namespace caps::fem {

/// The tissue layers the continuum mesher follows with TissueLayers::Measured (docs/fem.md,
/// "Measured layers"), presets as above.
/// Dermis (skin layer down to the subcutaneous fat), dermis.json: E = 100 kPa, nu = 0.45.
std::shared_ptr<const Material> default_dermis();
/// Subcutaneous fat, fat.json: E = 3 kPa, nu = 0.45.
std::shared_ptr<const Material> default_fat();
/// Deep soft tissue between the fat and the bone (muscle, fascia, galea, SMAS), deep.json:
/// E = 20 kPa, nu = 0.45.
std::shared_ptr<const Material> default_deep();

}  // namespace caps::fem
