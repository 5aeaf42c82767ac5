#pragma once
/// @brief Element kernels: shape functions, Gauss rules, stiffness, internal force and stress
/// for Hex20Q27 (20-node serendipity hexahedron, 3x3x3 Gauss) and Wedge15Q21 (15-node quadratic
/// wedge, 7-point degree-5 triangle rule x 3-point Gauss line). Numbering: mesh.hpp.
///
/// Voigt order for stresses and strains: xx, yy, zz, xy, yz, xz (VTK's tensor order); shear
/// strains are tensor components (not engineering gamma). Stresses in MPa.

#include <Eigen/Core>
#include <vector>

#include "caps/fem/material.hpp"
#include "caps/fem/mesh.hpp"

namespace caps::fem {

using Vector6d = Eigen::Matrix<double, 6, 1>;

/// A quadrature point in natural coordinates with its weight.
struct QuadraturePoint {
  Eigen::Vector3d xi;
  double weight;
};

/// Gauss rule used for the element type: 27 points for Hex20, 21 for Wedge15.
const std::vector<QuadraturePoint>& quadrature(ElementType type);

/// Natural coordinates of the element's nodes (#n×3).
Eigen::MatrixX3d natural_nodes(ElementType type);

/// Shape functions N (#n) and derivatives dN/dxi (#n×3) at natural point xi.
void shape_functions(ElementType type, const Eigen::Vector3d& xi, Eigen::VectorXd& N,
                     Eigen::MatrixX3d& dN_dxi);

/// Element coordinates X (#n×3, mm) gathered from the mesh.
Eigen::MatrixX3d element_coordinates(const Mesh& mesh, int element);

/// Element stiffness K_e (3n×3n, N/mm), dofs ordered node-major (u0x,u0y,u0z,u1x,...).
/// Throws SolverError naming element `element` and the Gauss point if det J <= 0.
Eigen::MatrixXd element_stiffness(ElementType type, const Eigen::MatrixX3d& X,
                                  const LinearElastic& material, int element = -1);

/// Internal force f_e = int B^T sigma(u_e) dV (3n, N), computed from stresses, not from K_e.
Eigen::VectorXd element_internal_force(ElementType type, const Eigen::MatrixX3d& X,
                                       const LinearElastic& material, const Eigen::VectorXd& u_e,
                                       int element = -1);

/// Stress (Voigt, MPa) at natural point xi for element displacements u_e (3n, mm).
Vector6d element_stress(ElementType type, const Eigen::MatrixX3d& X,
                        const LinearElastic& material, const Eigen::VectorXd& u_e,
                        const Eigen::Vector3d& xi, int element = -1);

/// Von Mises equivalent stress (MPa) of a Voigt stress.
double von_mises(const Vector6d& s);
/// Largest principal stress (MPa) of a Voigt stress (skin tension when positive).
double max_principal(const Vector6d& s);

}  // namespace caps::fem
