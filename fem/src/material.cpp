#include "caps/fem/material.hpp"

#include <Eigen/Dense>
#include <cmath>

#include "caps/core/error.hpp"
#include "caps/fem/material_registry.hpp"

namespace caps::fem {
namespace {

// Voigt index I -> tensor indices (i, j), order xx yy zz xy yz xz.
constexpr int kVoigt[6][2] = {{0, 0}, {1, 1}, {2, 2}, {0, 1}, {1, 2}, {0, 2}};

Vector6d to_voigt(const Eigen::Matrix3d& A) {
  Vector6d v;
  for (int I = 0; I < 6; ++I) v[I] = A(kVoigt[I][0], kVoigt[I][1]);
  return v;
}

// (A ⊙ A)_ijkl = 1/2 (A_ik A_jl + A_il A_jk) for symmetric A, in Voigt form.
Matrix6d odot(const Eigen::Matrix3d& A) {
  Matrix6d M;
  for (int I = 0; I < 6; ++I)
    for (int J = 0; J < 6; ++J) {
      const int i = kVoigt[I][0], j = kVoigt[I][1], k = kVoigt[J][0], l = kVoigt[J][1];
      M(I, J) = 0.5 * (A(i, k) * A(j, l) + A(i, l) * A(j, k));
    }
  return M;
}

// The isotropic D: lambda I ⊗ I + 2 mu I ⊙ I.
Matrix6d isotropic_tangent(double lambda, double mu) {
  Matrix6d C = mu * odot(Eigen::Matrix3d::Identity()) * 2;
  C.topLeftCorner<3, 3>().array() += lambda;
  return C;
}

std::string range_text(const ParameterSpec& p) {
  return cat(p.min_open ? "(" : "[", p.min, ", ", p.max, p.max_open ? ")" : "]");
}

std::vector<ParameterSpec> elastic_constants() {
  return {{"E", "MPa", 0.0, IsotropicElastic::kMaxE_mpa, true, false,
           "soft tissue is about 0.001-1 MPa (1-1000 kPa)"},
          {"nu", "1", 0.0, IsotropicElastic::kMaxNu, false, false,
           "nu = 0.5 (incompressible) locks displacement elements; use 0.45-0.49 for nearly "
           "incompressible tissue"}};
}

}  // namespace

void Material::validate_parameters(const std::string& where) const {
  const std::vector<ParameterSpec> spec = parameters();
  const std::vector<double> v = values();
  for (std::size_t i = 0; i < spec.size(); ++i) {
    const ParameterSpec& p = spec[i];
    const bool ok = std::isfinite(v[i]) && (p.min_open ? v[i] > p.min : v[i] >= p.min) &&
                    (p.max_open ? v[i] < p.max : v[i] <= p.max);
    if (!ok)
      throw InvalidInput(cat(where, ": ", name(), " parameter ", p.name, " = ", v[i], " ", p.unit,
                             " is out of its valid range ", range_text(p), " ", p.unit, "; ",
                             p.hint));
  }
}

LinearElastic::LinearElastic(double E_mpa, double nu, const std::string& where)
    : IsotropicElastic(E_mpa, nu) {
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
  validate_parameters(where);  // the declared ranges (the messages above say it in more words)
}

std::vector<ParameterSpec> IsotropicElastic::parameters() const { return elastic_constants(); }

void LinearElastic::stress_and_tangent(const Eigen::Matrix3d& H, Vector6d& S, Matrix6d& C) const {
  C = isotropic_tangent(lambda_mpa(), mu_mpa());
  Vector6d eps = to_voigt(0.5 * (H + H.transpose()));
  eps.tail<3>() *= 2;  // engineering shears
  S = C * eps;
}

double LinearElastic::strain_energy_density(const Eigen::Matrix3d& H) const {
  const Eigen::Matrix3d eps = 0.5 * (H + H.transpose());
  return 0.5 * lambda_mpa() * eps.trace() * eps.trace() + mu_mpa() * eps.squaredNorm();
}

NeoHookean::NeoHookean(double E_mpa, double nu, const std::string& where)
    : IsotropicElastic(E_mpa, nu) {
  validate_parameters(where);
}

NeoHookean::NeoHookean(const LinearElastic& linear, const std::string& where)
    : NeoHookean(linear.E_mpa(), linear.nu(), where) {}

void NeoHookean::stress_and_tangent(const Eigen::Matrix3d& H, Vector6d& S, Matrix6d& C) const {
  // Holzapfel 2000: S = S_iso + S_vol (eq. 6.89-6.90, 6.101), C = C_iso + C_vol (eq. 6.165-6.168)
  // for W_iso = mu/2 (I1bar - 3), U = K/2 (J-1)^2, p = U'(J), p~ = p + J U''(J). The stress is
  // written with the Green strain E and J - 1, never with their cancelling forms:
  // I - I1/3 C^-1 = C^-1 (C - I1/3 I) = 2 C^-1 dev E.
  const double mu = mu_mpa(), K = bulk_mpa();
  const Eigen::Matrix3d E = 0.5 * (H + H.transpose() + H.transpose() * H);
  const Eigen::Matrix3d Ci = (Eigen::Matrix3d::Identity() + 2 * E).inverse();
  const double Jm1 = volume_change(H), J = 1 + Jm1, Jm23 = std::pow(J, -2.0 / 3.0);
  const double I1 = 3 + 2 * E.trace();
  const Eigen::Matrix3d devE = E - E.trace() / 3 * Eigen::Matrix3d::Identity();
  const Eigen::Matrix3d CidevE = Ci * devE;
  const double p = K * Jm1, pt = K * (2 * J - 1);
  const Vector6d ci = to_voigt(Ci), id = to_voigt(Eigen::Matrix3d::Identity());
  S = mu * Jm23 * to_voigt(CidevE + CidevE.transpose()) + J * p * ci;
  const Matrix6d cc = odot(Ci);
  C = (2.0 / 3.0) * mu * Jm23 *
          (-id * ci.transpose() - ci * id.transpose() + I1 / 3 * ci * ci.transpose() + I1 * cc) +
      J * pt * ci * ci.transpose() - 2 * J * p * cc;
}

double NeoHookean::strain_energy_density(const Eigen::Matrix3d& H) const {
  // J^(-2/3) I1 - 3 = J^(-2/3) (I1 - 3) + 3 (J^(-2/3) - 1), both terms free of cancellation.
  const double Jm1 = volume_change(H);
  const double I1m3 = 2 * H.trace() + H.squaredNorm();
  const double Jm23m1 = std::expm1(-2.0 / 3.0 * std::log1p(Jm1));
  return 0.5 * mu_mpa() * ((1 + Jm23m1) * I1m3 + 3 * Jm23m1) + 0.5 * bulk_mpa() * Jm1 * Jm1;
}

namespace {

// E and nu of the neo-Hookean with shear modulus mu and bulk modulus K (MPa).
double young_of(double mu, double K) { return 9 * K * mu / (3 * K + mu); }
double poisson_of(double mu, double K) { return (3 * K - 2 * mu) / (2 * (3 * K + mu)); }

}  // namespace

GasserOgdenHolzapfel::GasserOgdenHolzapfel(double mu_mpa, double K_mpa, double k1_mpa, double k2,
                                           double kappa, double gamma_deg,
                                           const Eigen::Vector3d& langer, const std::string& where)
    : mu_(mu_mpa), K_(K_mpa), k1_(k1_mpa), k2_(k2), kappa_(kappa), gamma_deg_(gamma_deg),
      langer_(langer),
      matrix_([&] {
        validate_parameters(where);
        if (!(K_mpa > 2 * mu_mpa / 3))
          throw InvalidInput(cat(where, ": goh bulk modulus K = ", K_mpa, " MPa must exceed 2/3 of mu = ",
                                 mu_mpa, " MPa (a negative Poisson's ratio otherwise)"));
        if (!(langer.allFinite() && langer.norm() > 0))
          throw InvalidInput(cat(where, ": goh fibre direction must be a non-zero vector"));
        if (poisson_of(mu_mpa, K_mpa) > IsotropicElastic::kMaxNu)
          throw InvalidInput(cat(where, ": goh bulk modulus K = ", K_mpa, " MPa is more than 500 times mu = ",
                                 mu_mpa, " MPa (Poisson's ratio above ", IsotropicElastic::kMaxNu,
                                 "): the displacement elements lock; lower K"));
        return NeoHookean(young_of(mu_mpa, K_mpa), poisson_of(mu_mpa, K_mpa), where);
      }()) {
  langer_.normalize();
}

std::vector<ParameterSpec> GasserOgdenHolzapfel::parameters() const {
  return {{"mu", "MPa", 0.0, 1e3, true, false, "skin's ground matrix is about 0.01-0.1 MPa"},
          {"K", "MPa", 0.0, 1e4, true, false, "a few times mu or more (nearly incompressible)"},
          {"k1", "MPa", 0.0, 1e3, false, false, "fibre stiffness; skin fits give 1-100 MPa"},
          {"k2", "1", 0.0, 1e3, true, false, "exponential stiffening; skin fits give 0.1-10"},
          {"kappa", "1", 0.0, 1.0 / 3.0, false, false, "0 = aligned fibres, 1/3 = isotropic"},
          {"gamma", "deg", 0.0, 90.0, false, false, "fibre angle from the reference direction"},
          {"fibre_x", "1", -1.0, 1.0, false, false, "reference fibre direction, LPS x (normalised)"},
          {"fibre_y", "1", -1.0, 1.0, false, false, "reference fibre direction, LPS y (normalised)"},
          {"fibre_z", "1", -1.0, 1.0, false, false, "reference fibre direction, LPS z (normalised)"}};
}

std::vector<Eigen::Vector3d> GasserOgdenHolzapfel::fibres(const Eigen::Vector3d& n) const {
  Eigen::Vector3d a = langer_ - langer_.dot(n) * n;
  if (a.norm() < 1e-6) {  // the reference direction is normal to the layer: any in-plane one
    a = n.unitOrthogonal();
  }
  a.normalize();
  if (gamma_deg_ == 0) return {a};
  const double g = gamma_deg_ * 3.14159265358979323846 / 180;
  const Eigen::Vector3d b = n.cross(a).normalized();
  return {std::cos(g) * a + std::sin(g) * b, std::cos(g) * a - std::sin(g) * b};
}

void GasserOgdenHolzapfel::stress_and_tangent_in_layer(const Eigen::Matrix3d& H,
                                                       const Eigen::Vector3d& n, Vector6d& S,
                                                       Matrix6d& C) const {
  matrix_.stress_and_tangent(H, S, C);
  const Eigen::Matrix3d Cg = Eigen::Matrix3d::Identity() + H + H.transpose() + H.transpose() * H;
  const Eigen::Matrix3d Ci = Cg.inverse();
  const double J = 1 + volume_change(H), Jm23 = std::pow(J, -2.0 / 3.0);
  const Vector6d ci = to_voigt(Ci);
  const Matrix6d cc = odot(Ci);
  for (const Eigen::Vector3d& a : fibres(n)) {
    const Eigen::Matrix3d Hs = kappa_ * Eigen::Matrix3d::Identity() + (1 - 3 * kappa_) * a * a.transpose();
    const double Ih = (Hs.array() * Cg.array()).sum();  // Hs : C
    const double Eb = Jm23 * Ih - 1;
    if (!(Eb > 0)) continue;  // the fibres are slack
    const double ex = std::exp(k2_ * Eb * Eb);
    const double d1 = k1_ * Eb * ex, d2 = k1_ * (1 + 2 * k2_ * Eb * Eb) * ex;  // psi', psi''
    // dIbar/dC = J^(-2/3) A, A = Hs - Ih/3 C^-1; S = 2 psi' dIbar/dC;
    // C = 4 psi'' (dIbar/dC) (x) (dIbar/dC) + 4 psi' d2Ibar/dC2,
    // d2Ibar/dC2 = J^(-2/3) [-(Hs (x) C^-1 + C^-1 (x) Hs)/3 + Ih/9 C^-1 (x) C^-1 + Ih/3 C^-1 (.) C^-1].
    const Vector6d hs = to_voigt(Hs), A = hs - Ih / 3 * ci;
    S += 2 * d1 * Jm23 * A;
    C += 4 * d2 * Jm23 * Jm23 * A * A.transpose() +
         4 * d1 * Jm23 *
             (-(hs * ci.transpose() + ci * hs.transpose()) / 3 + Ih / 9 * ci * ci.transpose() + Ih / 3 * cc);
  }
}

double GasserOgdenHolzapfel::strain_energy_density_in_layer(const Eigen::Matrix3d& H,
                                                            const Eigen::Vector3d& n) const {
  double W = matrix_.strain_energy_density(H);
  const Eigen::Matrix3d Cg = Eigen::Matrix3d::Identity() + H + H.transpose() + H.transpose() * H;
  const double Jm23 = std::pow(1 + volume_change(H), -2.0 / 3.0);
  for (const Eigen::Vector3d& a : fibres(n)) {
    const Eigen::Matrix3d Hs = kappa_ * Eigen::Matrix3d::Identity() + (1 - 3 * kappa_) * a * a.transpose();
    const double Eb = Jm23 * (Hs.array() * Cg.array()).sum() - 1;
    if (Eb > 0) W += k1_ / (2 * k2_) * std::expm1(k2_ * Eb * Eb);
  }
  return W;
}

void GasserOgdenHolzapfel::stress_and_tangent(const Eigen::Matrix3d& H, Vector6d& S, Matrix6d& C) const {
  stress_and_tangent_in_layer(H, Eigen::Vector3d::UnitZ(), S, C);
}

double GasserOgdenHolzapfel::strain_energy_density(const Eigen::Matrix3d& H) const {
  return strain_energy_density_in_layer(H, Eigen::Vector3d::UnitZ());
}

std::shared_ptr<const Material> default_goh_skin() { return preset_material("goh-porcine-skin"); }

double volume_change(const Eigen::Matrix3d& H) {
  const double tr = H.trace();
  return tr + 0.5 * (tr * tr - (H * H).trace()) + H.determinant();
}

// Indicative values; the files give their sources (docs/fem.md, "Materials").
std::shared_ptr<const Material> default_skin() { return preset_material("skin"); }
std::shared_ptr<const Material> default_subcutaneous() { return preset_material("subcutaneous"); }

}  // namespace caps::fem

namespace caps::fem {

// The measured tissue layers; sources in the files (docs/fem.md, "Measured layers").
std::shared_ptr<const Material> default_dermis() { return preset_material("dermis"); }
std::shared_ptr<const Material> default_fat() { return preset_material("fat"); }
std::shared_ptr<const Material> default_deep() { return preset_material("deep"); }

}  // namespace caps::fem
