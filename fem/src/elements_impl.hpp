#pragma once
// Internal element helpers shared by elements.cpp, assemble.cpp and solve.cpp.

#include <Eigen/Core>
#include <string>
#include <vector>

#include "caps/fem/elements.hpp"

namespace caps::fem::detail {

/// Shape functions and derivatives tabulated at the Gauss points of one element type.
struct ShapeTable {
  int n = 0;
  std::vector<Eigen::VectorXd> N;
  std::vector<Eigen::MatrixX3d> dN;
  std::vector<double> w;
};
const ShapeTable& shape_table(ElementType type, WedgeRule wedge = WedgeRule::Full);

/// G = dN/dx (#n×3); returns det J. Throws SolverError naming `element` and `gauss_point`
/// (-1: evaluated at a node) if det J <= 0.
double gradients(const Eigen::MatrixX3d& dN_dxi, const Eigen::MatrixX3d& X, Eigen::MatrixX3d& G,
                 int element, int gauss_point);
Eigen::Matrix3d strain_tensor(const Eigen::MatrixX3d& G, const Eigen::VectorXd& u_e);
Vector6d stress_from_strain(const Eigen::Matrix3d& eps, double lambda, double mu);

/// Displacement gradient H = sum_a u_a (x) G_a (G = dN/dX, #n×3; u_e 3n node-major); F = I + H.
Eigen::Matrix3d displacement_gradient(const Eigen::MatrixX3d& G, const Eigen::VectorXd& u_e);

/// det F of F = I + H; throws SolverError naming the element and Gauss point if det F <= 0
/// (or not finite).
double checked_det_F(const Eigen::Matrix3d& H, int element, int gauss_point);

/// Cauchy stress F S F^T / J (Voigt) from S (Voigt).
Vector6d cauchy_from_pk2(const Eigen::Matrix3d& F, const Vector6d& S);

/// The unit normal of the element's layer at a point: the layer's plane is the natural xi-eta
/// plane (the mesher stacks elements along zeta), its normal dX/dxi x dX/deta, from the rows of
/// the reference Jacobian dN^T X (dN_dxi #n×3, X #n×3).
Eigen::Vector3d layer_normal(const Eigen::MatrixX3d& dN_dxi, const Eigen::MatrixX3d& X);

/// The pre-deformation F_p of a prestretched layer with unit normal n (FEBio's prestrain: the
/// stress-free tissue is mapped onto the reference by F_p, F_total = F F_p): `stretch` in the
/// layer's plane and 1/stretch^2 along n (isochoric, J_p = 1).
Eigen::Matrix3d prestretch_tensor(const Eigen::Vector3d& n, double stretch);

/// Second Piola-Kirchhoff stress S and tangent C (Voigt, MPa) and the strain energy density
/// (MPa) of `material` at F = I + H of a point with layer normal n (needed when the material
/// uses_layer_normal() or stretch != 1; may be null otherwise) whose tissue is prestretched by
/// F_p = prestretch_tensor(n, stretch):
///   W(F) = W0(F F_p),  E0 = F_p^T E F_p + E(F_p) = Q E + E(F_p),  S = Q^T S0,  C = Q^T C0 Q
/// (Q the Voigt form of E -> F_p^T E F_p; energy conjugacy gives S and C).
double material_response(const Material& material, const Eigen::Matrix3d& H,
                         const Eigen::Vector3d* n, double stretch, Vector6d& S, Matrix6d& C);

/// What finite_kernel() found: the strain energy (mJ), or the first Gauss point where the
/// element inverts (det F <= 0; f and K are then incomplete).
struct FiniteKernelResult {
  double energy_mj = 0;
  int inverted_at = -1;  ///< Gauss point, -1 if none
  double det_F = 1;      ///< det F there
};

/// The total-Lagrangian kernel of element_finite_response() into caller buffers (hot loop):
/// f (3n) and, when K is not null, K (3n×3n) are overwritten. An inverted Gauss point is
/// reported in the result, not thrown (the Newton solver cuts the step back).
/// `prestretch`: the in-plane stretch of prestretch_tensor() (1: none).
FiniteKernelResult finite_kernel(ElementType type, const Eigen::MatrixX3d& X,
                                 const Material& material, const Eigen::VectorXd& u_e,
                                 int element, Eigen::VectorXd& f, Eigen::MatrixXd* K,
                                 double prestretch = 1.0, WedgeRule wedge = WedgeRule::Full);

/// The first Gauss point (in finite_kernel()'s order) where the element inverts at u_e, and
/// det F there, as finite_kernel() reports it; no energy, force or tangent (what an assembly
/// that has already met an inverted element still needs of the elements before it).
FiniteKernelResult first_inversion(ElementType type, const Eigen::MatrixX3d& X,
                                   const Eigen::VectorXd& u_e, int element,
                                   WedgeRule wedge = WedgeRule::Full);

/// Cauchy stress (Voigt, MPa) at natural point xi of an element whose tissue is prestretched
/// (`prestretch` as finite_kernel()); throws SolverError if det F <= 0 there.
Vector6d finite_cauchy_stress(ElementType type, const Eigen::MatrixX3d& X, const Material& material,
                              const Eigen::VectorXd& u_e, const Eigen::Vector3d& xi, int element,
                              double prestretch);

/// The message of an inverted element: "element 3, Gauss point 9: det F = -0.01 (...)".
std::string inverted_message(int element, int gauss_point, double det_F);

/// Isotropic stiffness without forming B: with g = vec(G) (node-major) and weights w,
///   A = sum w g g^T,  K_(a i)(b j) = lambda A_(a i)(b j) + mu A_(a j)(b i) + mu delta_ij tr A_ab
/// (the three terms of int B^T D B dV for isotropic D; Hughes 2000, sec. 2.7; the trace of the
/// 3×3 block A_ab is sum w grad N_a . grad N_b).
inline void stiffness_kernel(ElementType type, const Eigen::MatrixX3d& X, double lambda,
                             double mu, int element, Eigen::MatrixXd& K,
                             WedgeRule wedge = WedgeRule::Full) {
  const ShapeTable& t = shape_table(type, wedge);
  const int n = t.n, m = 3 * n;
  Eigen::MatrixXd A = Eigen::MatrixXd::Zero(m, m);
  Eigen::MatrixX3d G(n, 3);
  Eigen::VectorXd g(m);
  for (std::size_t q = 0; q < t.w.size(); ++q) {
    const double det = gradients(t.dN[q], X, G, element, static_cast<int>(q));
    const double w = t.w[q] * det;
    for (int a = 0; a < n; ++a) g.segment<3>(3 * a) = G.row(a).transpose();
    A.selfadjointView<Eigen::Upper>().rankUpdate(g, w);
  }
  A.triangularView<Eigen::StrictlyLower>() = A.transpose();
  K.resize(m, m);
  for (int b = 0; b < n; ++b)
    for (int a = 0; a <= b; ++a) {
      const Eigen::Matrix3d Aab = A.block<3, 3>(3 * a, 3 * b);
      const Eigen::Matrix3d Kab = lambda * Aab + mu * Aab.transpose() +
                                  (mu * Aab.trace()) * Eigen::Matrix3d::Identity();
      K.block<3, 3>(3 * a, 3 * b) = Kab;
      K.block<3, 3>(3 * b, 3 * a) = Kab.transpose();
    }
}

}  // namespace caps::fem::detail
