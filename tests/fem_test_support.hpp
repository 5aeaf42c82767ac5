#pragma once
// Shared helpers of the FE core's tests (test_fem_nonlinear, test_fem_tet10, test_fem_tie): the
// default skin's constants, a free neo-Hookean box, finite-strain options, and the closed-form
// neo-Hookean uniaxial stretch the patch tests compare with.

#include <Eigen/Core>
#include <cmath>
#include <memory>

#include "caps/fem/box.hpp"
#include "caps/fem/material.hpp"
#include "caps/fem/solve.hpp"

namespace caps::fem::test {

inline constexpr double kE = 0.1, kNu = 0.45;  // MPa: the default skin

/// A box of Hex20 (or Wedge15) cells of the default skin, neo-Hookean, nothing fixed.
inline Mesh neo_hookean_box(const Eigen::Vector3d& size, const Eigen::Vector3i& cells, bool wedges = false) {
  BoxOptions o;
  o.size_mm = size;
  o.cells = cells;
  o.wedges = wedges;
  o.fix_bottom = false;
  o.material = std::make_shared<NeoHookean>(kE, kNu);
  return make_box_mesh(o);
}

/// Finite-strain solve options closing in n_steps load steps at first, with the tight
/// solve's tolerances (1e-8 of the load and of the step's increment at lambda = 1, 1e-5 before):
/// the closed forms and the Newton solver's mechanics are checked at these. The defaults
/// (NewtonOptions, looser: what the answer needs) are checked against this tight solve in
/// test_fem_nonlinear, "TheDefaultTolerancesGiveTheTightSolvesAnswer".
inline SolveOptions finite_strain(int n_steps) {
  SolveOptions o;
  o.kinematics = Kinematics::Finite;
  o.newton.n_steps = n_steps;
  o.newton.residual_tolerance = 1e-8;
  o.newton.displacement_tolerance = 1e-8;
  o.newton.intermediate_tolerance = 1e-5;
  return o;
}

/// Principal Cauchy stresses of the decoupled neo-Hookean solid for F = diag(l1, l2, l2):
/// sigma = mu J^(-5/3) (b - I1/3 I) + K (J - 1) I (Holzapfel 2000, eq. 6.144 pushed forward).
inline Eigen::Vector2d principal_cauchy(double l1, double l2, double mu, double K) {
  const double J = l1 * l2 * l2, I1 = l1 * l1 + 2 * l2 * l2;
  const double a = mu * std::pow(J, -5.0 / 3.0);
  return {a * (l1 * l1 - I1 / 3) + K * (J - 1), a * (l2 * l2 - I1 / 3) + K * (J - 1)};
}

/// Lateral stretch of a bar stretched by l1 with free lateral faces: sigma_22 = 0, by bisection.
inline double lateral_stretch(double l1, double mu, double K) {
  double lo = 0.3, hi = 1.0 + 1e-12;
  for (int i = 0; i < 200; ++i) {
    const double mid = 0.5 * (lo + hi);
    (principal_cauchy(l1, mid, mu, K)[1] > 0 ? hi : lo) = mid;
  }
  return 0.5 * (lo + hi);
}

/// The largest distance between a solve's nodal displacements and an exact field u(X).
template <class Exact>
double max_displacement_error(const Mesh& m, const SolveResult& r, const Exact& exact) {
  double err = 0;
  for (Eigen::Index i = 0; i < m.n_nodes(); ++i)
    err = std::max(err, (r.displacement_mm.row(i).transpose() - exact(m.nodes.row(i).transpose())).norm());
  return err;
}

}  // namespace caps::fem::test
