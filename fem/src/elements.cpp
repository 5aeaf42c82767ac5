#include "caps/fem/elements.hpp"

#include <Eigen/Dense>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>

#include "caps/core/error.hpp"
#include "elements_impl.hpp"

namespace caps::fem {
namespace {

// Hex20 natural node coordinates in the paper's Figure 5 numbering (see mesh.hpp).
constexpr double kHexNodes[20][3] = {
    {-1, -1, -1}, {1, -1, -1}, {1, 1, -1}, {-1, 1, -1},  // top corners
    {-1, -1, 1},  {1, -1, 1},  {1, 1, 1},  {-1, 1, 1},   // bottom corners
    {0, -1, -1},  {1, 0, -1},  {0, 1, -1}, {-1, 0, -1},  // top mid
    {0, -1, 1},   {1, 0, 1},   {0, 1, 1},  {-1, 0, 1},   // bottom mid
    {-1, -1, 0},  {1, -1, 0},  {1, 1, 0},  {-1, 1, 0}};  // center (vertical edges)

// Wedge15 natural node coordinates (r, s, zeta).
constexpr double kWedgeNodes[15][3] = {
    {0, 0, -1},   {1, 0, -1},   {0, 1, -1},   {0, 0, 1},   {1, 0, 1},
    {0, 1, 1},    {0.5, 0, -1}, {0.5, 0.5, -1}, {0, 0.5, -1}, {0.5, 0, 1},
    {0.5, 0.5, 1}, {0, 0.5, 1}, {0, 0, 0},    {1, 0, 0},   {0, 1, 0}};

// Tet10 natural node coordinates (xi, eta, zeta) = (L1, L2, L3); mid-edge nodes of edges 0-1,
// 1-2, 2-0, 0-3, 1-3, 2-3 (mesh.hpp).
constexpr double kTetNodes[10][3] = {
    {0, 0, 0},     {1, 0, 0},     {0, 1, 0},   {0, 0, 1},     {0.5, 0, 0},
    {0.5, 0.5, 0}, {0, 0.5, 0},   {0, 0, 0.5}, {0.5, 0, 0.5}, {0, 0.5, 0.5}};
constexpr int kTetEdges[6][2] = {{0, 1}, {1, 2}, {2, 0}, {0, 3}, {1, 3}, {2, 3}};

// Serendipity hexahedron (Zienkiewicz, Taylor & Zhu 2005, sec. 6.5, eq. 6.32-6.33).
void hex20_shape(const Eigen::Vector3d& p, double* N, double (*dN)[3]) {
  for (int a = 0; a < 20; ++a) {
    const double xa = kHexNodes[a][0], ya = kHexNodes[a][1], za = kHexNodes[a][2];
    const double x = p[0], y = p[1], z = p[2];
    if (a < 8) {
      const double fx = 1 + x * xa, fy = 1 + y * ya, fz = 1 + z * za;
      const double g = x * xa + y * ya + z * za - 2;
      N[a] = 0.125 * fx * fy * fz * g;
      dN[a][0] = 0.125 * fy * fz * (xa * g + fx * xa);
      dN[a][1] = 0.125 * fx * fz * (ya * g + fy * ya);
      dN[a][2] = 0.125 * fx * fy * (za * g + fz * za);
    } else if (xa == 0) {
      const double fy = 1 + y * ya, fz = 1 + z * za;
      N[a] = 0.25 * (1 - x * x) * fy * fz;
      dN[a][0] = -0.5 * x * fy * fz;
      dN[a][1] = 0.25 * (1 - x * x) * ya * fz;
      dN[a][2] = 0.25 * (1 - x * x) * fy * za;
    } else if (ya == 0) {
      const double fx = 1 + x * xa, fz = 1 + z * za;
      N[a] = 0.25 * (1 - y * y) * fx * fz;
      dN[a][0] = 0.25 * (1 - y * y) * xa * fz;
      dN[a][1] = -0.5 * y * fx * fz;
      dN[a][2] = 0.25 * (1 - y * y) * fx * za;
    } else {
      const double fx = 1 + x * xa, fy = 1 + y * ya;
      N[a] = 0.25 * (1 - z * z) * fx * fy;
      dN[a][0] = 0.25 * (1 - z * z) * xa * fy;
      dN[a][1] = 0.25 * (1 - z * z) * fx * ya;
      dN[a][2] = -0.5 * z * fx * fy;
    }
  }
}

// Quadratic (15-node) wedge: quadratic triangle in area coordinates x quadratic in zeta
// (Zienkiewicz, Taylor & Zhu 2005, sec. 6.7; the same functions as CalculiX C3D15).
void wedge15_shape(const Eigen::Vector3d& p, double* N, double (*dN)[3]) {
  const double r = p[0], s = p[1], z = p[2];
  const double L[3] = {1 - r - s, r, s};
  const double dL[3][2] = {{-1, -1}, {1, 0}, {0, 1}};  // dL_i/d(r,s)
  for (int c = 0; c < 6; ++c) {  // corners
    const int i = c % 3;
    const double zc = c < 3 ? -1.0 : 1.0;
    const double fz = 1 + zc * z;
    N[c] = 0.5 * L[i] * (2 * L[i] - 1) * fz - 0.5 * L[i] * (1 - z * z);
    const double dNdL = 0.5 * (4 * L[i] - 1) * fz - 0.5 * (1 - z * z);
    dN[c][0] = dNdL * dL[i][0];
    dN[c][1] = dNdL * dL[i][1];
    dN[c][2] = 0.5 * L[i] * (2 * L[i] - 1) * zc + L[i] * z;
  }
  const int edge[3][2] = {{0, 1}, {1, 2}, {2, 0}};
  for (int e = 0; e < 6; ++e) {  // triangle edges, top then bottom
    const int i = edge[e % 3][0], j = edge[e % 3][1];
    const double zc = e < 3 ? -1.0 : 1.0;
    const double fz = 1 + zc * z;
    N[6 + e] = 2 * L[i] * L[j] * fz;
    dN[6 + e][0] = 2 * (dL[i][0] * L[j] + L[i] * dL[j][0]) * fz;
    dN[6 + e][1] = 2 * (dL[i][1] * L[j] + L[i] * dL[j][1]) * fz;
    dN[6 + e][2] = 2 * L[i] * L[j] * zc;
  }
  for (int i = 0; i < 3; ++i) {  // vertical edges
    N[12 + i] = L[i] * (1 - z * z);
    dN[12 + i][0] = dL[i][0] * (1 - z * z);
    dN[12 + i][1] = dL[i][1] * (1 - z * z);
    dN[12 + i][2] = -2 * L[i] * z;
  }
}

// Quadratic tetrahedron in volume coordinates: corners L_i (2 L_i - 1), mid-edge nodes
// 4 L_i L_j (Zienkiewicz, Taylor & Zhu 2005, sec. 6.6; CalculiX C3D10, shape10tet.f).
void tet10_shape(const Eigen::Vector3d& p, double* N, double (*dN)[3]) {
  const double L[4] = {1 - p[0] - p[1] - p[2], p[0], p[1], p[2]};
  const double dL[4][3] = {{-1, -1, -1}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};  // dL_i/d(xi,eta,zeta)
  for (int i = 0; i < 4; ++i) {
    N[i] = L[i] * (2 * L[i] - 1);
    for (int c = 0; c < 3; ++c) dN[i][c] = (4 * L[i] - 1) * dL[i][c];
  }
  for (int e = 0; e < 6; ++e) {
    const int i = kTetEdges[e][0], j = kTetEdges[e][1];
    N[4 + e] = 4 * L[i] * L[j];
    for (int c = 0; c < 3; ++c) dN[4 + e][c] = 4 * (dL[i][c] * L[j] + L[i] * dL[j][c]);
  }
}

std::vector<QuadraturePoint> make_hex_rule() {
  const double g = std::sqrt(0.6);
  const double x[3] = {-g, 0, g}, w[3] = {5.0 / 9, 8.0 / 9, 5.0 / 9};
  std::vector<QuadraturePoint> q;
  for (int k = 0; k < 3; ++k)
    for (int j = 0; j < 3; ++j)
      for (int i = 0; i < 3; ++i) q.push_back({Eigen::Vector3d(x[i], x[j], x[k]), w[i] * w[j] * w[k]});
  return q;
}

// CalculiX's C3D15 rule (2.20, e_c3d.f, gauss3d8): the 3-point degree-2 triangle rule ((1/6, 1/6),
// (2/3, 1/6), (1/6, 2/3), weight 1/6 each) x 3 Gauss points through the thickness. With it caps and ccx 2.20 solve a
// whole-face closure with 40 wedges to 5e-7 of its largest displacement (tests/test_app_face.cpp).
std::vector<QuadraturePoint> make_calculix_wedge_rule() {
  const double tri[3][2] = {{1.0 / 6, 1.0 / 6}, {2.0 / 3, 1.0 / 6}, {1.0 / 6, 2.0 / 3}};
  const double g = std::sqrt(0.6);
  const double z[3] = {-g, 0, g}, wz[3] = {5.0 / 9, 8.0 / 9, 5.0 / 9};
  std::vector<QuadraturePoint> q;
  for (int k = 0; k < 3; ++k)
    for (int t = 0; t < 3; ++t)
      q.push_back({Eigen::Vector3d(tri[t][0], tri[t][1], z[k]), wz[k] / 6.0});
  return q;
}

std::vector<QuadraturePoint> make_wedge_rule() {
  // 7-point degree-5 triangle rule (Dunavant 1985, Table "p = 5"; weights sum to 1/2 here).
  const double a1 = 0.059715871789770, b1 = 0.470142064105115;
  const double a2 = 0.797426985353087, b2 = 0.101286507323456;
  const double w0 = 0.225, w1 = 0.132394152788506, w2 = 0.125939180544827;
  const double tri[7][3] = {{1.0 / 3, 1.0 / 3, w0}, {a1, b1, w1}, {b1, a1, w1}, {b1, b1, w1},
                            {a2, b2, w2},           {b2, a2, w2}, {b2, b2, w2}};
  const double g = std::sqrt(0.6);
  const double z[3] = {-g, 0, g}, wz[3] = {5.0 / 9, 8.0 / 9, 5.0 / 9};
  std::vector<QuadraturePoint> q;
  for (int k = 0; k < 3; ++k)
    for (int t = 0; t < 7; ++t)
      q.push_back({Eigen::Vector3d(tri[t][0], tri[t][1], z[k]), 0.5 * tri[t][2] * wz[k]});
  return q;
}

// The 4-point degree-2 tetrahedron rule (Hammer, Marlowe & Stroud 1956; Zienkiewicz, Taylor &
// Zhu 2005, Table 6.4): the points at volume coordinates (b, a, a, a) and permutations,
// a = (5 - sqrt 5)/20, b = (5 + 3 sqrt 5)/20, weight 1/24 each (the volume 1/6 of the unit
// tetrahedron). CalculiX integrates C3D10 with this rule (its 4-point rule for C3D10), so caps
// and ccx solve the same discrete problem on Tet10 meshes, at finite strain too; it integrates
// the small-strain stiffness of a straight-sided Tet10 (B^T D B of degree 2) exactly.
std::vector<QuadraturePoint> make_tet_rule() {
  const double a = (5 - std::sqrt(5.0)) / 20, b = (5 + 3 * std::sqrt(5.0)) / 20;
  return {{Eigen::Vector3d(a, a, a), 1.0 / 24}, {Eigen::Vector3d(b, a, a), 1.0 / 24},
          {Eigen::Vector3d(a, b, a), 1.0 / 24}, {Eigen::Vector3d(a, a, b), 1.0 / 24}};
}

// dN/dx (#n×3) at natural point xi of the element with nodes X; throws as detail::gradients().
Eigen::MatrixX3d gradients_at(ElementType type, const Eigen::MatrixX3d& X, const Eigen::Vector3d& xi,
                              int element) {
  Eigen::VectorXd N;
  Eigen::MatrixX3d dN, G(X.rows(), 3);
  shape_functions(type, xi, N, dN);
  detail::gradients(dN, X, G, element, -1);
  return G;
}

}  // namespace

namespace detail {

// Shape functions, derivatives and weights at every Gauss point of the element's rule.
ShapeTable make_shape_table(ElementType type, int n_nodes, WedgeRule wedge = WedgeRule::Full) {
  ShapeTable t;
  t.n = n_nodes;
  for (const auto& qp : quadrature(type, wedge)) {
    Eigen::VectorXd N;
    Eigen::MatrixX3d dN;
    shape_functions(type, qp.xi, N, dN);
    t.N.push_back(N);
    t.dN.push_back(dN);
    t.w.push_back(qp.weight);
  }
  return t;
}

const ShapeTable& shape_table(ElementType type, WedgeRule rule) {
  static const ShapeTable hex = make_shape_table(ElementType::Hex20, 20);
  static const ShapeTable wedge = make_shape_table(ElementType::Wedge15, 15);
  static const ShapeTable wedge9 = make_shape_table(ElementType::Wedge15, 15, WedgeRule::CalculiX);
  static const ShapeTable tet = make_shape_table(ElementType::Tet10, 10);
  switch (type) {
    case ElementType::Hex20: return hex;
    case ElementType::Wedge15: return rule == WedgeRule::CalculiX ? wedge9 : wedge;
    case ElementType::Tet10: return tet;
  }
  throw InvalidInput("shape_table: unknown element type");
}

double gradients(const Eigen::MatrixX3d& dN_dxi, const Eigen::MatrixX3d& X, Eigen::MatrixX3d& G,
                 int element, int gauss_point) {
  // J_ij = dx_j/dxi_i; dN/dx = dN/dxi J^-T (Bathe 2014, sec. 5.3, eq. 5.25-5.27).
  const Eigen::Matrix3d J = dN_dxi.transpose() * X;
  const double det = J.determinant();
  if (!(det > 0)) {
    const double scale = J.col(0).norm() * J.col(1).norm() * J.col(2).norm() + 1e-300;
    throw SolverError(cat(gauss_point >= 0 ? "" : "at one of its nodes, ", "Jacobian determinant ",
                          det, " mm^3 (relative ", det / scale,
                          ") is not positive; the element is inverted or degenerate: check its "
                          "node order (0-1-2-3 must turn towards the bottom face; a Tet10's 0-1-2 "
                          "towards node 3: mesh.hpp) and "
                          "that no nodes coincide"),
                      element, gauss_point);
  }
  G.noalias() = dN_dxi * J.inverse().transpose();
  return det;
}

Eigen::Matrix3d strain_tensor(const Eigen::MatrixX3d& G, const Eigen::VectorXd& u_e) {
  Eigen::Matrix3d H = Eigen::Matrix3d::Zero();  // H_ij = du_i/dx_j
  for (Eigen::Index a = 0; a < G.rows(); ++a)
    H += u_e.segment<3>(3 * a) * G.row(a);
  return 0.5 * (H + H.transpose());
}

Vector6d stress_from_strain(const Eigen::Matrix3d& eps, double lambda, double mu) {
  const double tr = eps.trace();
  Vector6d s;
  s << lambda * tr + 2 * mu * eps(0, 0), lambda * tr + 2 * mu * eps(1, 1),
      lambda * tr + 2 * mu * eps(2, 2), 2 * mu * eps(0, 1), 2 * mu * eps(1, 2), 2 * mu * eps(0, 2);
  return s;
}

Eigen::Matrix3d displacement_gradient(const Eigen::MatrixX3d& G, const Eigen::VectorXd& u_e) {
  Eigen::Matrix3d H = Eigen::Matrix3d::Zero();
  for (Eigen::Index a = 0; a < G.rows(); ++a) H += u_e.segment<3>(3 * a) * G.row(a);
  return H;
}

std::string inverted_message(int element, int gauss_point, double det_F) {
  return cat("element ", element, gauss_point >= 0 ? cat(", Gauss point ", gauss_point) : ", a node",
             ": det F = ", det_F, " (the element inverts)");
}

double checked_det_F(const Eigen::Matrix3d& H, int element, int gauss_point) {
  const double J = 1 + volume_change(H);
  if (!(J > 0) || !std::isfinite(J))
    throw SolverError(inverted_message(element, gauss_point, J), element, gauss_point);
  return J;
}

Vector6d cauchy_from_pk2(const Eigen::Matrix3d& F, const Vector6d& S) {
  Eigen::Matrix3d Sm;
  Sm << S[0], S[3], S[5], S[3], S[1], S[4], S[5], S[4], S[2];
  const Eigen::Matrix3d sigma = F * Sm * F.transpose() / F.determinant();
  Vector6d s;
  s << sigma(0, 0), sigma(1, 1), sigma(2, 2), sigma(0, 1), sigma(1, 2), sigma(0, 2);
  return s;
}

Eigen::Vector3d layer_normal(const Eigen::MatrixX3d& dN_dxi, const Eigen::MatrixX3d& X) {
  const Eigen::Matrix3d J = dN_dxi.transpose() * X;
  return J.row(0).transpose().cross(J.row(1).transpose()).normalized();
}

Eigen::Matrix3d prestretch_tensor(const Eigen::Vector3d& n, double stretch) {
  const Eigen::Matrix3d nn = n * n.transpose();
  return stretch * (Eigen::Matrix3d::Identity() - nn) + nn / (stretch * stretch);
}

namespace {

double response_at(const Material& material, const Eigen::Matrix3d& H, const Eigen::Vector3d* n,
                   Vector6d& S, Matrix6d& C) {
  if (n && material.uses_layer_normal()) {
    material.stress_and_tangent_in_layer(H, *n, S, C);
    return material.strain_energy_density_in_layer(H, *n);
  }
  material.stress_and_tangent(H, S, C);
  return material.strain_energy_density(H);
}

}  // namespace

double material_response(const Material& material, const Eigen::Matrix3d& H,
                         const Eigen::Vector3d* n, double stretch, Vector6d& S, Matrix6d& C) {
  if (stretch == 1.0 || !n) return response_at(material, H, n, S, C);
  const Eigen::Matrix3d A = prestretch_tensor(*n, stretch);
  // H0 = F F_p - I = H F_p + (F_p - I): small prestretches keep their digits.
  const Eigen::Matrix3d H0 = H * A + (A - Eigen::Matrix3d::Identity());
  Vector6d S0;
  Matrix6d C0;
  const double W = response_at(material, H0, n, S0, C0);
  // Q: Voigt strain (engineering shears) of A^T E A for each unit Voigt strain E.
  static constexpr int kI[6] = {0, 1, 2, 0, 1, 0}, kJ[6] = {0, 1, 2, 1, 2, 2};
  Matrix6d Q;
  for (int k = 0; k < 6; ++k) {
    Eigen::Matrix3d E = Eigen::Matrix3d::Zero();
    const double v = k < 3 ? 1.0 : 0.5;
    E(kI[k], kJ[k]) = v;
    E(kJ[k], kI[k]) = v;
    const Eigen::Matrix3d E0 = A.transpose() * E * A;
    for (int r = 0; r < 6; ++r) Q(r, k) = r < 3 ? E0(kI[r], kJ[r]) : 2 * E0(kI[r], kJ[r]);
  }
  S.noalias() = Q.transpose() * S0;
  C.noalias() = Q.transpose() * C0 * Q;
  return W;
}

Vector6d finite_cauchy_stress(ElementType type, const Eigen::MatrixX3d& X, const Material& material,
                              const Eigen::VectorXd& u_e, const Eigen::Vector3d& xi, int element,
                              double prestretch) {
  Eigen::VectorXd N;
  Eigen::MatrixX3d dN, G(X.rows(), 3);
  shape_functions(type, xi, N, dN);
  gradients(dN, X, G, element, -1);
  const Eigen::Matrix3d H = displacement_gradient(G, u_e);
  checked_det_F(H, element, -1);
  Vector6d S;
  Matrix6d C;
  const Eigen::Vector3d n = layer_normal(dN, X);
  material_response(material, H, &n, prestretch, S, C);
  return cauchy_from_pk2(H + Eigen::Matrix3d::Identity(), S);
}

FiniteKernelResult first_inversion(ElementType type, const Eigen::MatrixX3d& X,
                                   const Eigen::VectorXd& u_e, int element, WedgeRule wedge) {
  // finite_kernel()'s own steps up to its test of det F, so that both find the same point.
  const ShapeTable& t = shape_table(type, wedge);
  Eigen::MatrixX3d G(t.n, 3);
  FiniteKernelResult out;
  for (std::size_t q = 0; q < t.w.size(); ++q) {
    const int gp = static_cast<int>(q);
    gradients(t.dN[q], X, G, element, gp);
    const Eigen::Matrix3d H = displacement_gradient(G, u_e);
    if (const double J = 1 + volume_change(H); !(J > 0) || !std::isfinite(J)) {
      out.inverted_at = gp;
      out.det_F = J;
      return out;
    }
  }
  return out;
}

FiniteKernelResult finite_kernel(ElementType type, const Eigen::MatrixX3d& X,
                                 const Material& material, const Eigen::VectorXd& u_e,
                                 int element, Eigen::VectorXd& f, Eigen::MatrixXd* K,
                                 double prestretch, WedgeRule wedge) {
  using Gradients = Eigen::Matrix<double, Eigen::Dynamic, 3, 0, 20, 3>;
  using Matrix9d = Eigen::Matrix<double, 9, 9>;
  // Voigt index of the tensor index pair (K, L): xx yy zz xy yz xz.
  static constexpr int kVoigt[3][3] = {{0, 3, 5}, {3, 1, 4}, {5, 4, 2}};
  const ShapeTable& t = shape_table(type, wedge);
  const int n = t.n, m = 3 * n;
  Eigen::MatrixX3d G(n, 3);
  Gradients FSG(n, 3);
  Vector6d S;
  Matrix6d C;
  Eigen::Matrix3d Sm;
  Matrix9d CF, A;
  double T[3][9], g[3][20];
  // The upper triangle of K by node pairs: pairs[b][3j+i][a] = K(3a+i, 3b+j), a <= b.
  double pairs[20][9][20];
  f.setZero(m);
  if (K) {
    K->resize(m, m);
    std::fill(&pairs[0][0][0], &pairs[0][0][0] + 20 * 9 * 20, 0.0);
  }
  FiniteKernelResult out;
  // The layer's plane matters to a prestretch and to fibres in it.
  const bool layered = prestretch != 1.0 || material.uses_layer_normal();
  if (layered && type == ElementType::Tet10)
    throw InvalidInput(cat("element ", element, " (Tet10): the '", material.name(), "' material",
                           prestretch != 1.0 ? " with a prestretch" : "",
                           " needs the plane of the skin's layer, which a tetrahedron does not "
                           "define; use neo-hookean without prestretch on Tet10 elements"));
  for (std::size_t q = 0; q < t.w.size(); ++q) {
    const int gp = static_cast<int>(q);
    const double w = t.w[q] * gradients(t.dN[q], X, G, element, gp);
    const Eigen::Matrix3d H = displacement_gradient(G, u_e);
    const Eigen::Matrix3d F = H + Eigen::Matrix3d::Identity();
    if (const double J = 1 + volume_change(H); !(J > 0) || !std::isfinite(J)) {
      out.inverted_at = gp;
      out.det_F = J;
      return out;
    }
    if (layered) {
      const Eigen::Vector3d nq = layer_normal(t.dN[q], X);
      out.energy_mj += w * material_response(material, H, &nq, prestretch, S, C);
    } else {
      out.energy_mj += w * material_response(material, H, nullptr, 1.0, S, C);
    }
    Sm << S[0], S[3], S[5], S[3], S[1], S[4], S[5], S[4], S[2];
    // row a: (F S G_a)^T; coefficient by coefficient (lazyProduct), cheaper at this size than
    // the blocked product Eigen picks for run-time sizes
    FSG.noalias() = G.lazyProduct(Sm * F.transpose());
    for (int a = 0; a < n; ++a) f.segment<3>(3 * a) += w * FSG.row(a).transpose();
    if (!K) continue;
    // K_ab,ij = sum_LN G_aL A_iLjN G_bN with the first elasticity tensor (without the spatial
    // derivative of the stress, which the total-Lagrangian form does not need)
    //   A_iLjN = sum_KM F_iK C_KLMN F_jM + delta_ij S_LN
    // (Bonet & Wood 2008, sec. 9.4: the material part B_a^T C B_b with dE = sym(F^T grad_X du)
    // and the geometric part (G_a . S G_b) I in one tensor). Per node pair that is 27
    // multiply-adds instead of the 60 of B_a^T (C B_b) + G_a . S G_b.
    // CF(3K+L, 3j+N) = sum_M C_KLMN F_jM
    for (int k = 0; k < 3; ++k)
      for (int l = 0; l < 3; ++l)
        for (int j = 0; j < 3; ++j)
          for (int nn = 0; nn < 3; ++nn) {
            const int I = kVoigt[k][l];
            CF(3 * k + l, 3 * j + nn) = C(I, kVoigt[0][nn]) * F(j, 0) + C(I, kVoigt[1][nn]) * F(j, 1) +
                                        C(I, kVoigt[2][nn]) * F(j, 2);
          }
    // A(3i+L, 3j+N) = w (sum_K F_iK CF(3K+L, 3j+N) + delta_ij S_LN)
    for (int i = 0; i < 3; ++i)
      A.middleRows<3>(3 * i).noalias() =
          w * (F(i, 0) * CF.middleRows<3>(0) + F(i, 1) * CF.middleRows<3>(3) + F(i, 2) * CF.middleRows<3>(6));
    for (int i = 0; i < 3; ++i) A.block<3, 3>(3 * i, 3 * i) += w * Sm;
    for (int a = 0; a < n; ++a)
      for (int c = 0; c < 3; ++c) g[c][a] = G(a, c);
    for (int b = 0; b < n; ++b) {
      // T(L, 3j+i) = sum_N A(3i+L, 3j+N) G_bN; then K_ab(i, j) = sum_L G_aL T(L, 3j+i), for
      // the nodes a <= b at once (kb[c][a], c = 3j+i).
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
          for (int l = 0; l < 3; ++l)
            T[l][3 * j + i] = A(3 * i + l, 3 * j) * g[0][b] + A(3 * i + l, 3 * j + 1) * g[1][b] +
                              A(3 * i + l, 3 * j + 2) * g[2][b];
      double(*kb)[20] = pairs[b];
      for (int c = 0; c < 9; ++c) {
        const double t0 = T[0][c], t1 = T[1][c], t2 = T[2][c];
        for (int a = 0; a <= b; ++a) kb[c][a] += g[0][a] * t0 + g[1][a] * t1 + g[2][a] * t2;
      }
    }
  }
  if (K) {
    for (int b = 0; b < n; ++b)
      for (int a = 0; a <= b; ++a)
        for (int j = 0; j < 3; ++j)
          for (int i = 0; i < 3; ++i) {
            (*K)(3 * a + i, 3 * b + j) = pairs[b][3 * j + i][a];
            (*K)(3 * b + j, 3 * a + i) = pairs[b][3 * j + i][a];
          }
  }
  return out;
}

}  // namespace detail

FiniteElementResponse element_finite_response(ElementType type, const Eigen::MatrixX3d& X,
                                              const Material& material, const Eigen::VectorXd& u_e,
                                              int element, bool with_tangent) {
  FiniteElementResponse r;
  const detail::FiniteKernelResult k =
      detail::finite_kernel(type, X, material, u_e, element, r.f, with_tangent ? &r.K : nullptr);
  if (k.inverted_at >= 0)
    throw SolverError(detail::inverted_message(element, k.inverted_at, k.det_F), element,
                      k.inverted_at);
  r.energy_mj = k.energy_mj;
  return r;
}

Vector6d element_cauchy_stress(ElementType type, const Eigen::MatrixX3d& X,
                               const Material& material, const Eigen::VectorXd& u_e,
                               const Eigen::Vector3d& xi, int element) {
  return detail::finite_cauchy_stress(type, X, material, u_e, xi, element, 1.0);
}

int n_element_nodes(ElementType type) {
  switch (type) {
    case ElementType::Hex20: return 20;
    case ElementType::Wedge15: return 15;
    case ElementType::Tet10: return 10;
  }
  return 0;
}

const char* wedge_rule_name(WedgeRule rule) { return rule == WedgeRule::Full ? "full" : "calculix"; }

WedgeRule parse_wedge_rule(const std::string& name) {
  if (name == "full") return WedgeRule::Full;
  if (name == "calculix") return WedgeRule::CalculiX;
  throw InvalidInput(cat("wedge rule '", name, "' is unknown; use full or calculix"));
}

const char* element_type_name(ElementType type) {
  switch (type) {
    case ElementType::Hex20: return "Hex20";
    case ElementType::Wedge15: return "Wedge15";
    case ElementType::Tet10: return "Tet10";
  }
  return "unknown";
}

const std::vector<QuadraturePoint>& quadrature(ElementType type, WedgeRule rule) {
  static const std::vector<QuadraturePoint> hex = make_hex_rule();
  static const std::vector<QuadraturePoint> wedge = make_wedge_rule();
  static const std::vector<QuadraturePoint> wedge9 = make_calculix_wedge_rule();
  static const std::vector<QuadraturePoint> tet = make_tet_rule();
  switch (type) {
    case ElementType::Hex20: return hex;
    case ElementType::Wedge15: return rule == WedgeRule::CalculiX ? wedge9 : wedge;
    case ElementType::Tet10: return tet;
  }
  throw InvalidInput("quadrature: unknown element type");
}

Eigen::MatrixX3d natural_nodes(ElementType type) {
  const int n = n_element_nodes(type);
  const double(*table)[3] = type == ElementType::Hex20     ? kHexNodes
                            : type == ElementType::Wedge15 ? kWedgeNodes
                                                           : kTetNodes;
  Eigen::MatrixX3d P(n, 3);
  for (int a = 0; a < n; ++a)
    for (int c = 0; c < 3; ++c) P(a, c) = table[a][c];
  return P;
}

namespace {

// The corner-linear shape function of corner c (natural coordinates pc) at natural point p.
double corner_linear(ElementType type, const Eigen::Vector3d& pc, const Eigen::Vector3d& p) {
  switch (type) {
    case ElementType::Hex20:
      return 0.125 * (1 + p[0] * pc[0]) * (1 + p[1] * pc[1]) * (1 + p[2] * pc[2]);
    case ElementType::Wedge15: {
      const double tri = pc[0] > 0.5 ? p[0] : pc[1] > 0.5 ? p[1] : 1 - p[0] - p[1];
      return tri * 0.5 * (1 + p[2] * pc[2]);
    }
    case ElementType::Tet10:
      for (int i = 0; i < 3; ++i)
        if (pc[i] > 0.5) return p[i];
      return 1 - p[0] - p[1] - p[2];
  }
  return 0;
}

Eigen::MatrixXd make_gauss_to_nodes(ElementType type, WedgeRule wedge) {
  const int n_corners = type == ElementType::Hex20 ? 8 : type == ElementType::Wedge15 ? 6 : 4;
  const Eigen::MatrixX3d P = natural_nodes(type);
  const auto& rule = quadrature(type, wedge);
  Eigen::MatrixXd A(static_cast<Eigen::Index>(rule.size()), n_corners), L(P.rows(), n_corners);
  for (int c = 0; c < n_corners; ++c) {
    const Eigen::Vector3d pc = P.row(c).transpose();
    for (std::size_t g = 0; g < rule.size(); ++g)
      A(static_cast<Eigen::Index>(g), c) = corner_linear(type, pc, rule[g].xi);
    for (Eigen::Index a = 0; a < P.rows(); ++a) L(a, c) = corner_linear(type, pc, P.row(a).transpose());
  }
  // corner values = (A^T A)^-1 A^T gauss; nodal = L corner values
  return L * (A.transpose() * A).ldlt().solve(A.transpose());
}

}  // namespace

const Eigen::MatrixXd& gauss_to_nodes(ElementType type, WedgeRule wedge) {
  static const Eigen::MatrixXd hex = make_gauss_to_nodes(ElementType::Hex20, WedgeRule::Full);
  static const Eigen::MatrixXd wedge21 = make_gauss_to_nodes(ElementType::Wedge15, WedgeRule::Full);
  static const Eigen::MatrixXd wedge9 = make_gauss_to_nodes(ElementType::Wedge15, WedgeRule::CalculiX);
  static const Eigen::MatrixXd tet = make_gauss_to_nodes(ElementType::Tet10, WedgeRule::Full);
  switch (type) {
    case ElementType::Hex20: return hex;
    case ElementType::Wedge15: return wedge == WedgeRule::CalculiX ? wedge9 : wedge21;
    case ElementType::Tet10: return tet;
  }
  return hex;
}

void shape_functions(ElementType type, const Eigen::Vector3d& xi, Eigen::VectorXd& N,
                     Eigen::MatrixX3d& dN_dxi) {
  double n[20], d[20][3];
  const int m = n_element_nodes(type);
  switch (type) {
    case ElementType::Hex20: hex20_shape(xi, n, d); break;
    case ElementType::Wedge15: wedge15_shape(xi, n, d); break;
    case ElementType::Tet10: tet10_shape(xi, n, d); break;
  }
  N.resize(m);
  dN_dxi.resize(m, 3);
  for (int a = 0; a < m; ++a) {
    N[a] = n[a];
    for (int c = 0; c < 3; ++c) dN_dxi(a, c) = d[a][c];
  }
}

Eigen::MatrixX3d element_coordinates(const Mesh& mesh, int element) {
  const Element& el = mesh.elements[element];
  const int n = el.n_nodes();
  Eigen::MatrixX3d X(n, 3);
  for (int a = 0; a < n; ++a) X.row(a) = mesh.nodes.row(el.nodes[a]);
  return X;
}

Eigen::MatrixXd element_stiffness(ElementType type, const Eigen::MatrixX3d& X,
                                  const IsotropicElastic& material, int element) {
  Eigen::MatrixXd K;
  detail::stiffness_kernel(type, X, material.lambda_mpa(), material.mu_mpa(), element, K);
  return K;
}

Eigen::VectorXd element_internal_force(ElementType type, const Eigen::MatrixX3d& X,
                                       const IsotropicElastic& material, const Eigen::VectorXd& u_e,
                                       int element) {
  const auto& t = detail::shape_table(type);
  Eigen::MatrixX3d G(t.n, 3), F = Eigen::MatrixX3d::Zero(t.n, 3);
  for (std::size_t q = 0; q < t.w.size(); ++q) {
    const double det = detail::gradients(t.dN[q], X, G, element, static_cast<int>(q));
    const Vector6d s = detail::stress_from_strain(detail::strain_tensor(G, u_e),
                                                  material.lambda_mpa(), material.mu_mpa());
    Eigen::Matrix3d S;
    S << s[0], s[3], s[5], s[3], s[1], s[4], s[5], s[4], s[2];
    F += (t.w[q] * det) * G * S;  // f_a,i = int sigma_ij dN_a/dx_j dV
  }
  Eigen::VectorXd f(3 * t.n);
  for (int a = 0; a < t.n; ++a) f.segment<3>(3 * a) = F.row(a).transpose();
  return f;
}

Vector6d element_stress(ElementType type, const Eigen::MatrixX3d& X,
                        const IsotropicElastic& material, const Eigen::VectorXd& u_e,
                        const Eigen::Vector3d& xi, int element) {
  const Eigen::MatrixX3d G = gradients_at(type, X, xi, element);
  return detail::stress_from_strain(detail::strain_tensor(G, u_e), material.lambda_mpa(),
                                    material.mu_mpa());
}

double von_mises(const Vector6d& s) {
  const double d = (s[0] - s[1]) * (s[0] - s[1]) + (s[1] - s[2]) * (s[1] - s[2]) +
                   (s[2] - s[0]) * (s[2] - s[0]);
  return std::sqrt(0.5 * d + 3 * (s[3] * s[3] + s[4] * s[4] + s[5] * s[5]));
}

double max_principal(const Vector6d& s) {
  Eigen::Matrix3d S;
  S << s[0], s[3], s[5], s[3], s[1], s[4], s[5], s[4], s[2];
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(S, Eigen::EigenvaluesOnly);
  return es.eigenvalues()[2];
}

}  // namespace caps::fem
