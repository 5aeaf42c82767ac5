#pragma once
/// @brief Element kernels: shape functions, Gauss rules, stiffness, internal force and stress
/// for Hex20Q27 (20-node serendipity hexahedron, 3x3x3 Gauss), Wedge15Q21 (15-node quadratic
/// wedge, 7-point degree-5 triangle rule x 3-point Gauss line) and Tet10Q4 (10-node quadratic
/// tetrahedron, the 4-point degree-2 rule CalculiX uses for C3D10). Numbering: mesh.hpp.
/// A Tet10 has no layer plane: materials that need one (goh) and the skin's prestretch are
/// refused on it (InvalidInput).
///
/// Voigt order for stresses and strains: xx, yy, zz, xy, yz, xz (VTK's tensor order); shear
/// strains are tensor components (not engineering gamma). Stresses in MPa.

#include <Eigen/Core>
#include <vector>

#include "caps/fem/material.hpp"
#include "caps/fem/mesh.hpp"

namespace caps::fem {

/// A quadrature point in natural coordinates with its weight.
struct QuadraturePoint {
  Eigen::Vector3d xi;
  double weight;
};

/// Gauss rule used for the element type: 27 points for Hex20, 21 (WedgeRule::Full) or 9 for
/// Wedge15, 4 for Tet10 (weights sum to the natural volume: 8, 1, 1/6).
const std::vector<QuadraturePoint>& quadrature(ElementType type, WedgeRule wedge = WedgeRule::Full);

/// Natural coordinates of the element's nodes (#n×3).
Eigen::MatrixX3d natural_nodes(ElementType type);

/// Stress recovery at the nodes (#n × #points of quadrature(type, wedge)): the least-squares fit
/// of the Gauss-point values by the element's corner-linear field (trilinear, linear wedge,
/// linear tet), evaluated at every node; as Abaqus and CalculiX extrapolate integration-point
/// values to the nodes. Exact for linear fields; a quadratic element's own stress at its nodes
/// is where it is least accurate (Zienkiewicz, Taylor & Zhu 2005, sec. 6.12; docs/fem.md).
const Eigen::MatrixXd& gauss_to_nodes(ElementType type, WedgeRule wedge = WedgeRule::Full);

/// Shape functions N (#n) and derivatives dN/dxi (#n×3) at natural point xi.
void shape_functions(ElementType type, const Eigen::Vector3d& xi, Eigen::VectorXd& N,
                     Eigen::MatrixX3d& dN_dxi);

/// Element coordinates X (#n×3, mm) gathered from the mesh.
Eigen::MatrixX3d element_coordinates(const Mesh& mesh, int element);

/// Small strain: the isotropic constants of `material` (LinearElastic, or the linearization of
/// NeoHookean: Material::small_strain()).
/// Element stiffness K_e (3n×3n, N/mm), dofs ordered node-major (u0x,u0y,u0z,u1x,...).
/// Throws SolverError naming element `element` and the Gauss point if det J <= 0.
Eigen::MatrixXd element_stiffness(ElementType type, const Eigen::MatrixX3d& X,
                                  const IsotropicElastic& material, int element = -1);

/// Internal force f_e = int B^T sigma(u_e) dV (3n, N), computed from stresses, not from K_e.
Eigen::VectorXd element_internal_force(ElementType type, const Eigen::MatrixX3d& X,
                                       const IsotropicElastic& material, const Eigen::VectorXd& u_e,
                                       int element = -1);

/// Total-Lagrangian response of one element at displacement u_e (finite strain).
struct FiniteElementResponse {
  Eigen::VectorXd f;      ///< 3n internal force (N): f_a = int F S dN_a/dX dV0
  Eigen::MatrixXd K;      ///< 3n×3n consistent tangent (N/mm): material + geometric stiffness
  double energy_mj = 0;   ///< int W dV0 (mJ)
};

/// Internal force, consistent tangent (unless `with_tangent` is false: K stays empty) and strain
/// energy of an element in the total-Lagrangian form, with the element's Gauss rule:
///   f_a = sum_q w_q det J_q F S G_a,  K_ab = sum_q w_q det J_q (B_a^T C B_b + (G_a . S G_b) I)
/// (Bonet & Wood 2008, sec. 9.4; Wriggers 2008, sec. 4.2), G = dN/dX in the reference frame.
/// @param X    reference coordinates #n×3 (mm)
/// @param u_e  3n displacements (mm), node-major
/// Throws SolverError(element, Gauss point) if det F <= 0 at a Gauss point (the element
/// inverts), InvalidInput if the reference element is inverted.
FiniteElementResponse element_finite_response(ElementType type, const Eigen::MatrixX3d& X,
                                              const Material& material, const Eigen::VectorXd& u_e,
                                              int element = -1, bool with_tangent = true);

/// Cauchy stress sigma = F S F^T / det F (Voigt, MPa) at natural point xi of a deformed element
/// (reference coordinates X, displacements u_e in mm). Throws as element_finite_response().
Vector6d element_cauchy_stress(ElementType type, const Eigen::MatrixX3d& X,
                               const Material& material, const Eigen::VectorXd& u_e,
                               const Eigen::Vector3d& xi, int element = -1);

/// Stress (Voigt, MPa) at natural point xi for element displacements u_e (3n, mm).
Vector6d element_stress(ElementType type, const Eigen::MatrixX3d& X,
                        const IsotropicElastic& material, const Eigen::VectorXd& u_e,
                        const Eigen::Vector3d& xi, int element = -1);

/// Von Mises equivalent stress (MPa) of a Voigt stress.
double von_mises(const Vector6d& s);
/// Largest principal stress (MPa) of a Voigt stress (skin tension when positive).
double max_principal(const Vector6d& s);

}  // namespace caps::fem
