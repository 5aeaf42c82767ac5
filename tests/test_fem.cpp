// caps::fem: element checks (patch, tangent, convergence, MUMPS = CHOLMOD), analytic benchmarks
// (cantilever, Lame cylinder), suture closure, mesh directory IO and the bad-input catalogue.
#include <gtest/gtest.h>
#include <tbb/global_control.h>
#include <functional>

#include "error_of.hpp"
#include "fem_test_support.hpp"

#include <Eigen/Dense>
#include <Eigen/Eigenvalues>
#include <dlfcn.h>
#include <cmath>
#include <filesystem>
#include <atomic>
#include <chrono>
#include <csignal>
#include <fstream>
#include <optional>
#include <random>
#include <thread>

#include "caps/core/error.hpp"
#include "caps/core/units.hpp"
#include "caps/fem/box.hpp"
#include "caps/fem/elements.hpp"
#include "caps/fem/material_registry.hpp"
#include "caps/fem/mesh_io.hpp"
#include "caps/fem/result_io.hpp"
#include "caps/fem/solve.hpp"
#include "../fem/src/assemble.hpp"       // the finite-strain assembly, tested directly
#include "../fem/src/constraints.hpp"
#include "../fem/src/direct_solver.hpp"  // the mixed-precision solver's fall-back, tested directly
#include "../fem/src/elements_impl.hpp"

using namespace caps;
using namespace caps::fem;
using caps::fem::test::max_displacement_error;

namespace {

const ElementType kTypes[] = {ElementType::Hex20, ElementType::Wedge15};

const std::vector<std::array<int, 2>>& mid_edges(ElementType t) {
  static const std::vector<std::array<int, 2>> hex{{0, 1}, {1, 2}, {2, 3}, {3, 0}, {4, 5}, {5, 6},
                                                   {6, 7}, {7, 4}, {0, 4}, {1, 5}, {2, 6}, {3, 7}};
  static const std::vector<std::array<int, 2>> wedge{{0, 1}, {1, 2}, {2, 0}, {3, 4}, {4, 5},
                                                     {5, 3}, {0, 3}, {1, 4}, {2, 5}};
  return t == ElementType::Hex20 ? hex : wedge;
}
int n_corners(ElementType t) { return t == ElementType::Hex20 ? 8 : 6; }

// Moves every corner node by up to `amount` × cell size and puts mid-edge nodes back at the
// middle of their (straight) edges.
void distort(Mesh& m, double amount, double h, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> d(-amount * h, amount * h);
  std::vector<char> corner(m.n_nodes(), 0);
  for (const Element& el : m.elements)
    for (int a = 0; a < n_corners(el.type); ++a) corner[el.nodes[a]] = 1;
  for (Eigen::Index i = 0; i < m.n_nodes(); ++i)
    if (corner[i])
      for (int c = 0; c < 3; ++c) m.nodes(i, c) += d(rng);
  for (const Element& el : m.elements) {
    const auto& edges = mid_edges(el.type);
    for (std::size_t k = 0; k < edges.size(); ++k)
      m.nodes.row(el.nodes[n_corners(el.type) + k]) =
          0.5 * (m.nodes.row(el.nodes[edges[k][0]]) + m.nodes.row(el.nodes[edges[k][1]]));
  }
}

std::vector<char> on_box_boundary(const Mesh& m, const Eigen::Vector3d& size) {
  std::vector<char> b(m.n_nodes(), 0);
  for (Eigen::Index i = 0; i < m.n_nodes(); ++i)
    for (int c = 0; c < 3; ++c)
      if (std::abs(m.nodes(i, c)) < 1e-9 || std::abs(m.nodes(i, c) - size[c]) < 1e-9) b[i] = 1;
  return b;
}

void prescribe_all(Mesh& m, const std::vector<char>& where,
                   const std::function<Eigen::Vector3d(const Eigen::Vector3d&)>& u) {
  for (Eigen::Index i = 0; i < m.n_nodes(); ++i)
    if (where[i]) {
      const Eigen::Vector3d v = u(m.nodes.row(i).transpose());
      for (int c = 0; c < 3; ++c) m.fixed_dofs.push_back({static_cast<int>(i), c, v[c]});
    }
}

Mesh box(ElementType t, Eigen::Vector3d size, Eigen::Vector3i cells, bool fix_bottom = false,
         LinearElastic mat = LinearElastic(0.1, 0.3)) {
  BoxOptions o;
  o.size_mm = size;
  o.cells = cells;
  o.wedges = t == ElementType::Wedge15;
  o.fix_bottom = fix_bottom;
  o.material = std::make_shared<LinearElastic>(mat);
  return make_box_mesh(o);
}

using caps_test::error_of;

}  // namespace

TEST(FemElements, ShapeFunctionsInterpolateAndDifferentiate) {
  for (ElementType t : kTypes) {
    const Eigen::MatrixX3d P = natural_nodes(t);
    const int n = static_cast<int>(P.rows());
    Eigen::VectorXd N;
    Eigen::MatrixX3d dN;
    for (int a = 0; a < n; ++a) {  // Kronecker delta at the nodes
      shape_functions(t, P.row(a).transpose(), N, dN);
      for (int b = 0; b < n; ++b) EXPECT_NEAR(N[b], a == b ? 1.0 : 0.0, 1e-14) << element_type_name(t);
    }
    const Eigen::Vector3d xi(0.21, 0.17, -0.33);
    shape_functions(t, xi, N, dN);
    EXPECT_NEAR(N.sum(), 1.0, 1e-14);
    EXPECT_LT(dN.colwise().sum().norm(), 1e-13);
    for (int c = 0; c < 3; ++c) {  // derivatives against central differences
      Eigen::VectorXd Np, Nm;
      Eigen::MatrixX3d d;
      const double h = 1e-6;
      shape_functions(t, xi + h * Eigen::Vector3d::Unit(c), Np, d);
      shape_functions(t, xi - h * Eigen::Vector3d::Unit(c), Nm, d);
      EXPECT_LT(((Np - Nm) / (2 * h) - dN.col(c)).cwiseAbs().maxCoeff(), 1e-8);
    }
    double w = 0;
    for (const auto& q : quadrature(t)) w += q.weight;
    EXPECT_NEAR(w, t == ElementType::Hex20 ? 8.0 : 1.0, 1e-12);
    EXPECT_EQ(quadrature(t).size(), t == ElementType::Hex20 ? 27u : 21u);
  }
}

TEST(FemElements, StiffnessIsSymmetricWithSixRigidModesAndMatchesResidualDerivative) {
  const LinearElastic mat(0.05, 0.35);
  for (ElementType t : kTypes) {
    Mesh m = box(t, {2, 3, 1.5}, {1, 1, 1});
    distort(m, 0.15, 1.0, 7);
    const Eigen::MatrixX3d X = element_coordinates(m, 0);
    const Eigen::MatrixXd K = element_stiffness(t, X, mat);
    EXPECT_LT((K - K.transpose()).norm(), 1e-12 * K.norm());
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(K);
    const Eigen::VectorXd ev = es.eigenvalues();
    for (int k = 0; k < 6; ++k) EXPECT_LT(std::abs(ev[k]), 1e-10 * ev.maxCoeff());
    EXPECT_GT(ev[6], 1e-6 * ev.maxCoeff()) << "spurious zero-energy mode";
    // K = d f_int / d u by central differences of the stress-based internal force.
    std::mt19937 rng(3);
    std::normal_distribution<double> nd;
    Eigen::VectorXd u(K.rows());
    for (Eigen::Index i = 0; i < u.size(); ++i) u[i] = 0.01 * nd(rng);
    Eigen::MatrixXd Kfd(K.rows(), K.cols());
    const double h = 1e-6;
    for (Eigen::Index j = 0; j < u.size(); ++j) {
      Eigen::VectorXd up = u, um = u;
      up[j] += h;
      um[j] -= h;
      Kfd.col(j) = (element_internal_force(t, X, mat, up) - element_internal_force(t, X, mat, um)) / (2 * h);
    }
    EXPECT_LT((K - Kfd).cwiseAbs().maxCoeff(), 1e-7 * K.cwiseAbs().maxCoeff()) << element_type_name(t);
    EXPECT_LT((K * u - element_internal_force(t, X, mat, u)).norm(), 1e-12 * (K * u).norm());
  }
}

namespace {

// Isotropic stiffness sum_q w_q det J B^T D B over the given natural points and weights.
Eigen::MatrixXd wedge_stiffness_with_rule(const Eigen::MatrixX3d& X, const LinearElastic& mat,
                                          const std::vector<QuadraturePoint>& rule) {
  const double lam = mat.lambda_mpa(), mu = mat.mu_mpa();
  Eigen::MatrixXd K = Eigen::MatrixXd::Zero(45, 45);
  Eigen::Matrix<double, 6, 6> D = Eigen::Matrix<double, 6, 6>::Zero();
  D.topLeftCorner<3, 3>().setConstant(lam);
  D.diagonal() << lam + 2 * mu, lam + 2 * mu, lam + 2 * mu, mu, mu, mu;
  for (const auto& q : rule) {
    Eigen::VectorXd N;
    Eigen::MatrixX3d dN;
    shape_functions(ElementType::Wedge15, q.xi, N, dN);
    const Eigen::Matrix3d J = dN.transpose() * X;
    const Eigen::MatrixX3d G = dN * J.inverse().transpose();
    Eigen::MatrixXd B = Eigen::MatrixXd::Zero(6, 45);
    for (int a = 0; a < 15; ++a) {
      for (int i = 0; i < 3; ++i) B(i, 3 * a + i) = G(a, i);
      B(3, 3 * a) = G(a, 1), B(3, 3 * a + 1) = G(a, 0);
      B(4, 3 * a + 1) = G(a, 2), B(4, 3 * a + 2) = G(a, 1);
      B(5, 3 * a) = G(a, 2), B(5, 3 * a + 2) = G(a, 0);
    }
    K += q.weight * J.determinant() * B.transpose() * D * B;
  }
  return K;
}

}  // namespace

TEST(FemElements, Wedge15IsFullyIntegratedUnlikeCalculixC3D15) {
  // Reference: 5-point Gauss in zeta times a collapsed (Duffy) 5 x 5 Gauss rule on the triangle,
  // exact for the affine wedge's integrand (degree 4 in r, s and in zeta).
  const double g[5] = {-0.9061798459386640, -0.5384693101056831, 0, 0.5384693101056831,
                       0.9061798459386640};
  const double gw[5] = {0.2369268850561891, 0.4786286704993665, 0.5688888888888889,
                        0.4786286704993665, 0.2369268850561891};
  std::vector<QuadraturePoint> ref, ccx;
  for (int k = 0; k < 5; ++k)
    for (int i = 0; i < 5; ++i)
      for (int j = 0; j < 5; ++j) {
        const double u = 0.5 * (1 + g[i]), v = 0.5 * (1 + g[j]);
        ref.push_back({Eigen::Vector3d(u, (1 - u) * v, g[k]), 0.25 * gw[i] * gw[j] * (1 - u) * gw[k]});
      }
  // CalculiX 2.20 C3D15 (e_c3d.f, gauss3d8): 3-point triangle rule (degree 2) x 3-point Gauss.
  const double z3[3] = {-std::sqrt(0.6), 0, std::sqrt(0.6)}, w3[3] = {5.0 / 9, 8.0 / 9, 5.0 / 9};
  const double tri[3][2] = {{1.0 / 6, 1.0 / 6}, {2.0 / 3, 1.0 / 6}, {1.0 / 6, 2.0 / 3}};
  for (int k = 0; k < 3; ++k)
    for (const auto& t : tri) ccx.push_back({Eigen::Vector3d(t[0], t[1], z3[k]), w3[k] / 6});
  const LinearElastic mat(0.05, 0.35);
  const Eigen::MatrixX3d P = natural_nodes(ElementType::Wedge15);
  Eigen::Matrix3d A;
  A << 3, 0.5, 0.2, 0.3, 2, -0.4, 0.1, 0.2, 1.5;
  Eigen::MatrixX3d X = P * A.transpose();  // an affine wedge
  Eigen::MatrixXd Kref = wedge_stiffness_with_rule(X, mat, ref);
  EXPECT_LT((element_stiffness(ElementType::Wedge15, X, mat) - Kref).norm(), 1e-13 * Kref.norm());
  // CalculiX's rule under-integrates the same element by ~2 % (measured 1.8 %): the whole
  // difference between ccx and caps on meshes with Wedge15 (docs/mesher.md, CalculiX export).
  EXPECT_GT((wedge_stiffness_with_rule(X, mat, ccx) - Kref).norm(), 1e-2 * Kref.norm());
  // WedgeRule::CalculiX is that rule, point for point (a mesh.inp of a mesh with it solves in
  // ccx to the same answer: FaceDomain.CalculixSolvesTheExportedWholeFaceDeck).
  const auto& nine = quadrature(ElementType::Wedge15, WedgeRule::CalculiX);
  ASSERT_EQ(nine.size(), ccx.size());
  for (std::size_t q = 0; q < ccx.size(); ++q) {
    EXPECT_LT((nine[q].xi - ccx[q].xi).norm(), 1e-15);
    EXPECT_NEAR(nine[q].weight, ccx[q].weight, 1e-15);
  }
  // Curved: the mid-edge nodes of the top triangle bulge out, as on the skin of a cylinder.
  for (int a : {6, 7, 8}) X(a, 2) -= 0.15;
  Kref = wedge_stiffness_with_rule(X, mat, ref);
  EXPECT_LT((element_stiffness(ElementType::Wedge15, X, mat) - Kref).norm(), 1e-3 * Kref.norm());
}

TEST(FemElements, CollapsedHexahedronMapsToWedge15) {
  std::array<int, 20> h{};
  for (int k = 0; k < 20; ++k) h[k] = 100 + k;
  h[3] = h[10] = h[2];
  h[19] = h[18];
  h[7] = h[14] = h[6];
  const Element w = wedge_from_collapsed_hex(h, 4);
  EXPECT_EQ(w.type, ElementType::Wedge15);
  EXPECT_EQ(w.layer, 4);
  const int expect[15] = {100, 101, 102, 104, 105, 106, 108, 109, 111, 112, 113, 115, 116, 117, 118};
  for (int k = 0; k < 15; ++k) EXPECT_EQ(w.nodes[k], expect[k]);
  h[10] = 999;
  EXPECT_NE(error_of([&] { wedge_from_collapsed_hex(h, 0); }).find("2, 10, 3"), std::string::npos);
}

TEST(FemElements, NodalStressIsFittedFromTheGaussPointsExactlyForLinearFields) {
  // gauss_to_nodes(): the Gauss-point values' least-squares corner-linear fit, at every node. A
  // linear field comes back exactly, at corners and mid-edge nodes alike; a constant keeps its
  // value (rows sum to 1).
  const std::vector<std::pair<ElementType, WedgeRule>> cases = {
      {ElementType::Hex20, WedgeRule::Full}, {ElementType::Wedge15, WedgeRule::Full},
      {ElementType::Wedge15, WedgeRule::CalculiX}, {ElementType::Tet10, WedgeRule::Full}};
  for (const auto& [type, rule] : cases) {
    SCOPED_TRACE(static_cast<int>(type) * 10 + static_cast<int>(rule));
    const Eigen::MatrixXd& M = gauss_to_nodes(type, rule);
    const auto& q = quadrature(type, rule);
    const Eigen::MatrixX3d P = natural_nodes(type);
    ASSERT_EQ(M.rows(), P.rows());
    ASSERT_EQ(M.cols(), static_cast<Eigen::Index>(q.size()));
    const auto f = [](const Eigen::Vector3d& x) { return 0.7 - 1.3 * x[0] + 2.1 * x[1] + 0.4 * x[2]; };
    Eigen::VectorXd at_gauss(M.cols());
    for (std::size_t g = 0; g < q.size(); ++g) at_gauss[static_cast<Eigen::Index>(g)] = f(q[g].xi);
    const Eigen::VectorXd at_nodes = M * at_gauss;
    for (Eigen::Index a = 0; a < P.rows(); ++a) EXPECT_NEAR(at_nodes[a], f(P.row(a).transpose()), 1e-12);
    EXPECT_LT((M.rowwise().sum().array() - 1.0).abs().maxCoeff(), 1e-12);
  }
}

TEST(FemPatch, LinearFieldIsExactOnDistortedMeshesBothSolvers) {
  Eigen::Matrix3d A;
  A << 1e-3, 2e-3, -1e-3, 0.5e-3, -2e-3, 1.5e-3, 3e-3, 1e-3, 2.5e-3;
  const Eigen::Vector3d b(0.01, -0.02, 0.03);
  auto exact = [&](const Eigen::Vector3d& x) -> Eigen::Vector3d { return A * x + b; };
  const LinearElastic mat(0.1, 0.3);
  const Eigen::Matrix3d eps = 0.5 * (A + A.transpose());
  Vector6d s_exact;
  const double lam = mat.lambda_mpa(), mu = mat.mu_mpa();
  s_exact << lam * eps.trace() + 2 * mu * eps(0, 0), lam * eps.trace() + 2 * mu * eps(1, 1),
      lam * eps.trace() + 2 * mu * eps(2, 2), 2 * mu * eps(0, 1), 2 * mu * eps(1, 2), 2 * mu * eps(0, 2);
  for (ElementType t : kTypes)
    for (SolverKind sk : {SolverKind::Mumps, SolverKind::Cholmod}) {
      const Eigen::Vector3d size(3, 3, 3);
      Mesh m = box(t, size, {3, 3, 3}, false, mat);
      const auto boundary = on_box_boundary(m, size);
      distort(m, 0.25, 1.0, 11);
      prescribe_all(m, boundary, exact);
      SolveOptions o;
      o.solver = sk;
      const SolveResult r = solve(m, o);
      const double err = max_displacement_error(m, r, exact);
      EXPECT_LT(err, 1e-12) << element_type_name(t) << " " << solver_name(sk);
      const double s_err = (r.gauss_stress_mpa.rowwise() - s_exact.transpose()).cwiseAbs().maxCoeff();
      EXPECT_LT(s_err, 1e-10 * s_exact.cwiseAbs().maxCoeff()) << element_type_name(t);
      EXPECT_LT((r.nodal_stress_mpa.rowwise() - s_exact.transpose()).cwiseAbs().maxCoeff(),
                1e-10 * s_exact.cwiseAbs().maxCoeff());
      // Strain energy = 1/2 sigma:eps V for a constant field.
      double vol = 0;
      for (std::size_t e = 0; e < m.elements.size(); ++e) {
        const auto X = element_coordinates(m, static_cast<int>(e));
        Eigen::VectorXd N;
        Eigen::MatrixX3d dN;
        for (const auto& q : quadrature(t)) {
          shape_functions(t, q.xi, N, dN);
          vol += q.weight * (dN.transpose() * X).determinant();
        }
      }
      Eigen::Matrix3d S;
      S << s_exact[0], s_exact[3], s_exact[5], s_exact[3], s_exact[1], s_exact[4], s_exact[5], s_exact[4], s_exact[2];
      EXPECT_NEAR(r.strain_energy_mj, 0.5 * (S.array() * eps.array()).sum() * vol, 1e-10 * r.strain_energy_mj);
    }
}

namespace {

// u = grad phi with phi = a e^{x/L} cos(y/L) harmonic: div u = 0 and Laplace u = 0, so it
// solves Navier's equations with no body force for any lambda, mu.
Eigen::Vector3d manufactured(const Eigen::Vector3d& x) {
  const double a = 0.01, L = 0.5;
  return a / L * std::exp(x[0] / L) * Eigen::Vector3d(std::cos(x[1] / L), -std::sin(x[1] / L), 0.0) +
         Eigen::Vector3d(0, 0, 0.002 * x[0] * x[1] * x[2]) * 0.0;
}

double manufactured_error(ElementType t, int n) {
  const Eigen::Vector3d size(1, 1, 1);
  Mesh m = box(t, size, {n, n, n}, false, LinearElastic(0.1, 0.3));
  prescribe_all(m, on_box_boundary(m, size), manufactured);
  const SolveResult r = solve(m);
  double err = 0;
  for (Eigen::Index i = 0; i < m.n_nodes(); ++i)
    err = std::max(err, (r.displacement_mm.row(i).transpose() - manufactured(m.nodes.row(i).transpose())).norm());
  return err;
}

}  // namespace

TEST(FemConvergence, ManufacturedSolutionConvergesAtQuadraticRate) {
  for (ElementType t : kTypes) {
    const double e2 = manufactured_error(t, 2), e4 = manufactured_error(t, 4), e8 = manufactured_error(t, 8);
    const double r1 = std::log2(e2 / e4), r2 = std::log2(e4 / e8);
    std::printf("%s max nodal error: h=1/2 %.3e, 1/4 %.3e, 1/8 %.3e; rates %.2f %.2f\n",
                element_type_name(t), e2, e4, e8, r1, r2);
    EXPECT_GT(r1, 2.7);
    EXPECT_GT(r2, 2.7);
    EXPECT_LT(e8, 2e-5);
  }
}

namespace {

// Consistent nodal forces of a uniform traction on the x = L face of a Hex20 box.
void add_end_traction(Mesh& m, double L, const Eigen::Vector3d& traction) {
  std::vector<Eigen::Vector3d> f(m.n_nodes(), Eigen::Vector3d::Zero());
  const double g = std::sqrt(0.6), pts[3] = {-g, 0, g}, w[3] = {5.0 / 9, 8.0 / 9, 5.0 / 9};
  for (std::size_t e = 0; e < m.elements.size(); ++e) {
    const Element& el = m.elements[e];
    if (std::abs(m.nodes(el.nodes[1], 0) - L) > 1e-9 || std::abs(m.nodes(el.nodes[2], 0) - L) > 1e-9) continue;
    const auto X = element_coordinates(m, static_cast<int>(e));
    Eigen::VectorXd N;
    Eigen::MatrixX3d dN;
    for (int j = 0; j < 3; ++j)
      for (int k = 0; k < 3; ++k) {
        shape_functions(el.type, Eigen::Vector3d(1, pts[j], pts[k]), N, dN);
        const Eigen::Matrix3d J = dN.transpose() * X;
        const double dA = J.row(1).cross(J.row(2)).norm() * w[j] * w[k];
        for (int a = 0; a < 20; ++a) f[el.nodes[a]] += N[a] * dA * traction;
      }
  }
  for (Eigen::Index i = 0; i < m.n_nodes(); ++i)
    if (f[i].norm() > 0) m.loads.push_back({static_cast<int>(i), f[i]});
}

}  // namespace

TEST(FemBenchmarks, CantileverTipDeflectionMatchesTimoshenkoBeam) {
  const double L = 100, h = 10, E = 0.1, P = 1e-3;
  Mesh m = box(ElementType::Hex20, {L, h, h}, {20, 2, 2}, false, LinearElastic(E, 0.0));
  for (Eigen::Index i = 0; i < m.n_nodes(); ++i)
    if (m.nodes(i, 0) < 1e-9) m.fixed_nodes.push_back(static_cast<int>(i));
  add_end_traction(m, L, {0, 0, -P / (h * h)});
  double total = 0;
  for (const auto& l : m.loads) total += l.force_n.z();
  EXPECT_NEAR(total, -P, 1e-15);
  const SolveResult r = solve(m);
  const double I = h * h * h * h / 12, G = E / 2, A = h * h;
  const double bending = P * L * L * L / (3 * E * I), shear = P * L / (5.0 / 6 * G * A);
  double tip = 0;
  for (Eigen::Index i = 0; i < m.n_nodes(); ++i)
    if (std::abs(m.nodes(i, 0) - L) < 1e-9 && std::abs(m.nodes(i, 1) - h / 2) < 1e-9 &&
        std::abs(m.nodes(i, 2) - h / 2) < 1e-9)
      tip = -r.displacement_mm(i, 2);
  std::printf("cantilever tip %.6f mm, Timoshenko %.6f mm (Euler-Bernoulli %.6f), ratio %.4f\n", tip,
              bending + shear, bending, tip / (bending + shear));
  EXPECT_NEAR(tip / (bending + shear), 1.0, 0.01);
  // Work of the load = 2 × strain energy (Clapeyron).
  double work = 0;
  for (const auto& l : m.loads) work += l.force_n.dot(r.displacement_mm.row(l.node).transpose());
  EXPECT_NEAR(0.5 * work, r.strain_energy_mj, 1e-9 * r.strain_energy_mj);
  // Root reactions balance the load.
  EXPECT_NEAR(r.reaction_n.col(2).sum(), P, 1e-9 * P);
}

TEST(FemBenchmarks, LameThickCylinderMatchesAnalyticSolution) {
  const double a = 10, b = 20, ua = 0.1, E = 0.1, nu = 0.3;
  const LinearElastic mat(E, nu);
  const double lam = mat.lambda_mpa(), mu = mat.mu_mpa();
  // Plane strain, u_r = A r + B / r with sigma_r(b) = 0 and u_r(a) = ua (Timoshenko & Goodier, sec. 28).
  const double Bc = (lam + mu) * b * b / mu;
  const double Ac = ua / (a + Bc / a), B = Bc * Ac;
  auto ur = [&](double r) { return Ac * r + B / r; };
  auto sig_t = [&](double r) { return 2 * (lam + mu) * Ac + 2 * mu * B / (r * r); };
  for (ElementType t : kTypes) {
    Mesh m = box(t, {b - a, kPi / 2, 2}, {6, 12, 1}, false, mat);
    for (Eigen::Index i = 0; i < m.n_nodes(); ++i) {
      const double r = a + m.nodes(i, 0), th = m.nodes(i, 1);
      m.nodes(i, 0) = r * std::cos(th);
      m.nodes(i, 1) = r * std::sin(th);
    }
    // Wedges of the (r, theta) box keep their counter-clockwise orientation under the map.
    for (Eigen::Index i = 0; i < m.n_nodes(); ++i) {
      const int n = static_cast<int>(i);
      const double x = m.nodes(i, 0), y = m.nodes(i, 1), r = std::hypot(x, y);
      m.fixed_dofs.push_back({n, 2, 0.0});
      if (std::abs(y) < 1e-9) m.fixed_dofs.push_back({n, 1, 0.0});
      if (std::abs(x) < 1e-9) m.fixed_dofs.push_back({n, 0, 0.0});
      if (std::abs(r - a) < 1e-9) {
        if (std::abs(x) >= 1e-9) m.fixed_dofs.push_back({n, 0, ua * x / r});
        if (std::abs(y) >= 1e-9) m.fixed_dofs.push_back({n, 1, ua * y / r});
      }
    }
    const SolveResult res = solve(m);
    double err_u = 0, err_s = 0;
    for (Eigen::Index i = 0; i < m.n_nodes(); ++i) {
      const double x = m.nodes(i, 0), y = m.nodes(i, 1), r = std::hypot(x, y);
      const double urn = (res.displacement_mm(i, 0) * x + res.displacement_mm(i, 1) * y) / r;
      err_u = std::max(err_u, std::abs(urn - ur(r)) / ur(b));
      const Vector6d s = res.nodal_stress_mpa.row(i).transpose();
      const double st = (s[0] * y * y + s[1] * x * x - 2 * s[3] * x * y) / (r * r);
      err_s = std::max(err_s, std::abs(st - sig_t(r)) / sig_t(a));
    }
    std::printf("Lame %s: max |u_r| error %.2e of u_r(b) = %.5f mm; max hoop stress error %.2e of %.5f MPa\n",
                element_type_name(t), err_u, ur(b), err_s, sig_t(a));
    EXPECT_LT(err_u, 1e-3);
    EXPECT_LT(err_s, 2e-2);
  }
}

// A 30 x 20 x 6 mm box with a sutured slot (the solver tests' common case).
Mesh slotted_box(ElementType t) {
  BoxOptions o;
  o.size_mm = {30, 20, 6};
  o.cells = {5, 6, 2};
  o.wedges = t == ElementType::Wedge15;
  o.slot = true;
  return make_box_mesh(o);
}

TEST(FemSolvers, MumpsAndCholmodAgree) {
  for (ElementType t : kTypes) {
    Mesh m = slotted_box(t);
    distort(m, 0.2, 3.0, 7);
    SolveOptions sm, sd, sc;  // MUMPS mixed precision (the default), MUMPS double, CHOLMOD
    sd.mixed_precision = false;
    sc.solver = SolverKind::Cholmod;
    const SolveResult rm = solve(m, sm), rd = solve(m, sd), rc = solve(m, sc);
    EXPECT_EQ(rm.precision, "mixed");
    EXPECT_FALSE(rm.fell_back_to_double);
    EXPECT_GE(rm.refinement_iterations, 1);
    EXPECT_LE(rm.refinement_iterations, 6);
    EXPECT_EQ(rd.precision, "double");
    EXPECT_EQ(rc.precision, "double");
    const double scale = rm.displacement_mm.cwiseAbs().maxCoeff();
    for (const SolveResult* r : {&rd, &rc}) {
      EXPECT_LT((rm.displacement_mm - r->displacement_mm).cwiseAbs().maxCoeff(), 1e-8 * scale);
      EXPECT_NEAR(rm.total_suture_force_n, r->total_suture_force_n, 1e-8 * rm.total_suture_force_n);
      EXPECT_LT(r->relative_residual, 1e-10);
    }
    EXPECT_LT(rm.relative_residual, 1e-11);
  }
}

// A cantilever plate 100 mm long and 2 mm thick, in 5 mm elements: the condition number is
// about 1e9 (double precision gets a relative residual of 2e-8), beyond single precision, so the
// mixed solve must notice and redo it in double precision, giving CHOLMOD's answer. (A stiffness
// contrast of 1e11 between layers is not enough to need this: the single-precision factor
// handles it.)
TEST(FemSolvers, MixedPrecisionFallsBackToDoubleWhenSinglePrecisionIsNotEnough) {
  BoxOptions o;
  o.size_mm = {100, 10, 2};
  o.cells = {20, 2, 1};
  o.fix_bottom = false;
  Mesh m = make_box_mesh(o);
  for (Eigen::Index i = 0; i < m.n_nodes(); ++i) {
    if (m.nodes(i, 0) == 0) m.fixed_nodes.push_back(static_cast<int>(i));
    if (m.nodes(i, 0) == 100) m.loads.push_back({static_cast<int>(i), Eigen::Vector3d(0, 0, -1e-9)});
  }
  SolveOptions sc;
  sc.solver = SolverKind::Cholmod;
  const SolveResult rm = solve(m), rc = solve(m, sc);
  EXPECT_TRUE(rm.fell_back_to_double);
  EXPECT_EQ(rm.precision, "double");
  const double scale = rc.displacement_mm.cwiseAbs().maxCoeff();
  EXPECT_LT((rm.displacement_mm - rc.displacement_mm).cwiseAbs().maxCoeff(), 1e-6 * scale);
}

// After a fall-back to double precision, the mixed solver factors every later tangent (Newton)
// in double precision: a singular one must be refused as the double-precision solver refuses
// it, not solved with the factor of the previous one. K = diag(1e40, 1, 1) is beyond single
// precision's range (the fall-back); then diag(1e40, 1, 0) is singular in its third equation.
TEST(FemSolvers, MixedPrecisionAfterItsFallBackRefusesASingularTangent) {
  auto diagonal = [](double a, double b, double c) {
    Eigen::SparseMatrix<double> K(3, 3);
    K.insert(0, 0) = a;
    K.insert(1, 1) = b;
    K.insert(2, 2) = c;
    K.makeCompressed();
    return K;
  };
  const Eigen::SparseMatrix<double> K0 = diagonal(1e40, 1, 1), K1 = diagonal(1e40, 1, 0);
  auto solver = fem::detail::make_direct_solver(SolverKind::Mumps, SolveOptions{}.mumps_ordering,
                                                /*mixed_precision=*/true);
  solver->analyze(K0, {0, 1, 2, 3});
  solver->factorize(K0);
  const Eigen::VectorXd x = solver->solve(Eigen::Vector3d(1e40, 2, 3));
  EXPECT_TRUE(solver->report().fell_back_to_double);
  EXPECT_NEAR(x[0], 1, 1e-12);
  EXPECT_NEAR(x[1], 2, 1e-12);
  EXPECT_NEAR(x[2], 3, 1e-12);
  EXPECT_THROW(solver->factorize(K1), SolverError);
}

// Conjugate gradients on a new tangent, preconditioned with the last factor, tell an indefinite
// tangent from one they merely could not solve in time: a direction of negative curvature proves
// the factorization would fail (the finite-strain solve then skips it; issue 35). The 1-D
// Laplacian tridiag(-1, 2, -1) of 50 equations (smallest eigenvalue 2 - 2 cos(pi / 51) = 0.0038,
// the next 0.0152) is factored; shifted by -0.01 it has one negative eigenvalue, by +0.01 none.
TEST(FemSolvers, ConjugateGradientsOnAReusedFactorProveATangentIndefinite) {
  const int n = 50;
  auto laplacian = [&](double shift) {
    Eigen::SparseMatrix<double> K(n, n);  // the upper triangle, as the solvers take it
    for (int i = 0; i < n; ++i) {
      if (i > 0) K.insert(i - 1, i) = -1;
      K.insert(i, i) = 2 + shift;
    }
    K.makeCompressed();
    return K;
  };
  std::vector<int> blocks(n + 1);
  for (int i = 0; i <= n; ++i) blocks[i] = i;
  const Eigen::SparseMatrix<double> K = laplacian(0), indefinite = laplacian(-0.01),
                                    stiffer = laplacian(0.01);
  const Eigen::VectorXd b = Eigen::VectorXd::Ones(n);
  for (const auto& [kind, mixed] : {std::pair{SolverKind::Mumps, true},
                                    {SolverKind::Mumps, false},
                                    {SolverKind::Cholmod, false}}) {
    SCOPED_TRACE(std::string(kind == SolverKind::Cholmod ? "CHOLMOD"
                             : mixed                     ? "MUMPS mixed"
                                                         : "MUMPS"));
    auto solver = fem::detail::make_direct_solver(kind, SolveOptions{}.mumps_ordering, mixed);
    solver->analyze(K, blocks);
    solver->factorize(K);
    bool negative = false;
    EXPECT_FALSE(solver->solve_reusing_factor(indefinite, b, 40, 1e-10, &negative).has_value());
    EXPECT_TRUE(negative);
    negative = false;
    const std::optional<Eigen::VectorXd> x =
        solver->solve_reusing_factor(stiffer, b, 40, 1e-10, &negative);
    ASSERT_TRUE(x.has_value());
    EXPECT_FALSE(negative);
    EXPECT_LT((stiffer.selfadjointView<Eigen::Upper>() * *x - b).norm(), 1e-8 * b.norm());
    // What the negative curvature foretold.
    EXPECT_THROW(solver->factorize(indefinite), SolverError);
  }
}

// CHOLMOD's solver leaves the process's SIGTERM handler alone while it orders and factors:
// CHOLMOD's own ordering choice would call METIS, whose GKlib swaps in a handler that longjmps to a
// thread-local buffer for as long as it runs, so that `caps serve` stopped by SIGTERM then
// crashed (the signal lands on another thread). A watcher thread reads the handler throughout
// the analysis of a 3-D grid Laplacian (large enough that CHOLMOD's default would try METIS);
// the solve of the grid's system is checked against its known answer.
extern "C" void sigterm_marker(int) {}

TEST(FemSolvers, CholmodLeavesTheSigtermHandlerAlone) {
  const int g = 36, n = g * g * g;
  auto id = [&](int i, int j, int k) { return (k * g + j) * g + i; };
  std::vector<Eigen::Triplet<double>> t;
  for (int k = 0; k < g; ++k)
    for (int j = 0; j < g; ++j)
      for (int i = 0; i < g; ++i) {
        const int a = id(i, j, k);
        t.emplace_back(a, a, 6.5);
        if (i + 1 < g) t.emplace_back(a, id(i + 1, j, k), -1);
        if (j + 1 < g) t.emplace_back(a, id(i, j + 1, k), -1);
        if (k + 1 < g) t.emplace_back(a, id(i, j, k + 1), -1);
      }
  Eigen::SparseMatrix<double> K(n, n);  // the upper triangle
  K.setFromTriplets(t.begin(), t.end());
  K.makeCompressed();
  std::vector<int> blocks(n + 1);
  for (int i = 0; i <= n; ++i) blocks[i] = i;
  struct sigaction ours {}, before {};
  ours.sa_handler = sigterm_marker;
  sigemptyset(&ours.sa_mask);
  ASSERT_EQ(sigaction(SIGTERM, &ours, &before), 0);
  std::atomic<bool> done{false}, changed{false};
  std::thread watcher([&] {
    while (!done) {
      struct sigaction now {};
      sigaction(SIGTERM, nullptr, &now);
      if (now.sa_handler != sigterm_marker) changed = true;
      std::this_thread::sleep_for(std::chrono::microseconds(50));
    }
  });
  auto solver = fem::detail::make_direct_solver(SolverKind::Cholmod, SolveOptions{}.mumps_ordering,
                                                /*mixed_precision=*/false);
  solver->analyze(K, blocks);
  solver->factorize(K);
  Eigen::VectorXd x_true(n);
  for (int i = 0; i < n; ++i) x_true[i] = std::sin(0.01 * i);
  const Eigen::VectorXd b = K.selfadjointView<Eigen::Upper>() * x_true;
  const Eigen::VectorXd x = solver->solve(b);
  done = true;
  watcher.join();
  sigaction(SIGTERM, &before, nullptr);
  EXPECT_FALSE(changed);
  EXPECT_LT((x - x_true).cwiseAbs().maxCoeff(), 1e-10);
  // The ordering reduces fill: the natural (banded) order fills the band, about n g^2 entries.
  EXPECT_LT(solver->factor_nonzeros(), static_cast<long>(n) * g * g / 4);
}

// PORD (MUMPS's ordering here) ends the process when its graph compresses to too few vertices
// (a clique: one element, every node coupled to every other); a hostile or tiny mesh must get
// an answer, not an exit. Each solver solves a single dense block and many disjoint ones.
TEST(FemSolvers, DenseAndDisjointDenseBlocksAreOrderedWithoutEndingTheProcess) {
  for (const int blocks : {1, 2, 300})
    for (const int size : {60, 3}) {
      const int n = blocks * size;
      std::vector<Eigen::Triplet<double>> t;
      for (int b = 0; b < blocks; ++b)
        for (int i = 0; i < size; ++i)
          for (int j = i; j < size; ++j)
            t.emplace_back(b * size + i, b * size + j, i == j ? size + 1.0 : -1.0);
      Eigen::SparseMatrix<double> K(n, n);
      K.setFromTriplets(t.begin(), t.end());
      K.makeCompressed();
      std::vector<int> starts;
      for (int i = 0; i <= n; i += 3) starts.push_back(i);
      Eigen::VectorXd x_true(n);
      for (int i = 0; i < n; ++i) x_true[i] = std::cos(0.1 * i);
      const Eigen::VectorXd b = K.selfadjointView<Eigen::Upper>() * x_true;
      for (const SolverKind kind : {SolverKind::Mumps, SolverKind::Cholmod})
        for (const bool mixed : {false, true}) {
          if (kind == SolverKind::Cholmod && mixed) continue;
          auto solver = fem::detail::make_direct_solver(kind, SolveOptions{}.mumps_ordering, mixed);
          solver->analyze(K, starts);
          solver->factorize(K);
          EXPECT_LT((solver->solve(b) - x_true).cwiseAbs().maxCoeff(), 1e-9)
              << blocks << " blocks of " << size << ", " << solver_name(kind)
              << (mixed ? " mixed" : "");
        }
    }
}

// fem/src/blas_gemv_forward.cpp: xGEMM with one column (MUMPS's solve phase) goes to xGEMV,
// every other call to the BLAS's own xGEMM; both give the product of the reference definition
// C = alpha op(A) op(B) + beta C, for each transposition and with leading dimensions larger
// than the matrices. And the definitions are the ones the process resolves (MUMPS calls them).
extern "C" void dgemm_(const char*, const char*, const int*, const int*, const int*, const double*,
                       const double*, const int*, const double*, const int*, const double*, double*,
                       const int*);
extern "C" void sgemm_(const char*, const char*, const int*, const int*, const int*, const float*,
                       const float*, const int*, const float*, const int*, const float*, float*,
                       const int*);

TEST(FemSolvers, GemmWithOneColumnIsTheReferenceProduct) {
  EXPECT_EQ(dlsym(RTLD_DEFAULT, "dgemm_"), reinterpret_cast<void*>(&dgemm_));
  EXPECT_EQ(dlsym(RTLD_DEFAULT, "sgemm_"), reinterpret_cast<void*>(&sgemm_));
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> d(-1, 1);
  auto random = [&](int rows, int cols) {
    return Eigen::MatrixXd(Eigen::MatrixXd::NullaryExpr(rows, cols, [&] { return d(rng); }));
  };
  const int m = 7, k = 5, pad = 3;
  for (int n : {1, 2})
    for (const char* ta : {"N", "T"})
      for (const char* tb : {"N", "t"}) {
        const bool at = *ta == 'T', bt = *tb == 't';
        // Stored with `pad` extra rows: A is m x k (or k x m), B k x n (or n x k), C m x n.
        const Eigen::MatrixXd A = random((at ? k : m) + pad, at ? m : k),
                              B = random((bt ? n : k) + pad, bt ? k : n);
        const Eigen::MatrixXd C0 = random(m + pad, n);
        const double alpha = 0.7, beta = -1.3;
        const Eigen::MatrixXd opA = at ? Eigen::MatrixXd(A.topRows(k).transpose()) : A.topRows(m);
        const Eigen::MatrixXd opB = bt ? Eigen::MatrixXd(B.topRows(n).transpose()) : B.topRows(k);
        Eigen::MatrixXd expected = C0;
        expected.topRows(m) = alpha * opA * opB + beta * C0.topRows(m);
        const int lda = static_cast<int>(A.rows()), ldb = static_cast<int>(B.rows()),
                  ldc = static_cast<int>(C0.rows());
        Eigen::MatrixXd C = C0;
        dgemm_(ta, tb, &m, &n, &k, &alpha, A.data(), &lda, B.data(), &ldb, &beta, C.data(), &ldc);
        EXPECT_LT((C - expected).cwiseAbs().maxCoeff(), 1e-14) << ta << tb << " n = " << n;
        const Eigen::MatrixXf Af = A.cast<float>(), Bf = B.cast<float>();
        Eigen::MatrixXf Cf = C0.cast<float>();
        const float alpha_f = 0.7f, beta_f = -1.3f;
        sgemm_(ta, tb, &m, &n, &k, &alpha_f, Af.data(), &lda, Bf.data(), &ldb, &beta_f, Cf.data(), &ldc);
        EXPECT_LT((Cf.cast<double>() - expected).cwiseAbs().maxCoeff(), 1e-5) << ta << tb << " n = " << n;
      }
  // k = 0: C = beta C (xGEMV's quick return would leave C as it is).
  const int m1 = 3, n1 = 1, k0 = 0, one = 1;
  const double alpha = 2, beta = 0.5, a = 0, b = 0;
  Eigen::Vector3d c(2, 4, 6);
  dgemm_("N", "N", &m1, &n1, &k0, &alpha, &a, &m1, &b, &one, &beta, c.data(), &m1);
  EXPECT_EQ(c, Eigen::Vector3d(1, 2, 3));
}

// xTRSM with one right-hand side (MUMPS's solve phase) goes to xTRSV: for each side, triangle,
// transposition and diagonal, with alpha and leading dimensions larger than the matrices, the
// solution of the reference definition op(A) X = alpha B or X op(A) = alpha B.
extern "C" void dtrsm_(const char*, const char*, const char*, const char*, const int*, const int*,
                       const double*, const double*, const int*, double*, const int*);
extern "C" void strsm_(const char*, const char*, const char*, const char*, const int*, const int*,
                       const float*, const float*, const int*, float*, const int*);

TEST(FemSolvers, TrsmWithOneRightHandSideIsTheReferenceSolve) {
  EXPECT_EQ(dlsym(RTLD_DEFAULT, "dtrsm_"), reinterpret_cast<void*>(&dtrsm_));
  EXPECT_EQ(dlsym(RTLD_DEFAULT, "strsm_"), reinterpret_cast<void*>(&strsm_));
  std::mt19937 rng(9);
  std::uniform_real_distribution<double> d(-1, 1);
  const int k = 6, pad = 2;
  for (const char* side : {"L", "R"})
    for (const char* uplo : {"U", "L"})
      for (const char* ta : {"N", "T"})
        for (const char* diag : {"N", "U"})
          for (int other : {1, 3}) {  // B's other dimension: 1 is forwarded, 3 is not
            const bool left = *side == 'L';
            Eigen::MatrixXd A = Eigen::MatrixXd::NullaryExpr(k + pad, k, [&] { return d(rng); });
            A.diagonal().array() += 4;  // well conditioned
            Eigen::MatrixXd T = Eigen::MatrixXd::Zero(k, k);
            for (int i = 0; i < k; ++i)
              for (int j = 0; j < k; ++j)
                if (*uplo == 'U' ? i <= j : i >= j) T(i, j) = i == j && *diag == 'U' ? 1.0 : A(i, j);
            const Eigen::MatrixXd opT = *ta == 'T' ? Eigen::MatrixXd(T.transpose()) : T;
            const int m = left ? k : other, n = left ? other : k;
            const Eigen::MatrixXd B0 = Eigen::MatrixXd::NullaryExpr(m + pad, n, [&] { return d(rng); });
            const double alpha = -0.8;
            const Eigen::MatrixXd X = left ? Eigen::MatrixXd(opT.lu().solve(alpha * B0.topRows(m)))
                                           : Eigen::MatrixXd((opT.transpose().lu().solve(
                                                                  (alpha * B0.topRows(m)).transpose()))
                                                                 .transpose());
            const int lda = k + pad, ldb = m + pad;
            Eigen::MatrixXd B = B0;
            dtrsm_(side, uplo, ta, diag, &m, &n, &alpha, A.data(), &lda, B.data(), &ldb);
            EXPECT_LT((B.topRows(m) - X).cwiseAbs().maxCoeff(), 1e-12) << side << uplo << ta << diag << other;
            EXPECT_EQ(B.bottomRows(pad), B0.bottomRows(pad));  // beyond m rows: untouched
            const Eigen::MatrixXf Af = A.cast<float>();
            Eigen::MatrixXf Bf = B0.cast<float>();
            const float alpha_f = -0.8f;
            strsm_(side, uplo, ta, diag, &m, &n, &alpha_f, Af.data(), &lda, Bf.data(), &ldb);
            EXPECT_LT((Bf.topRows(m).cast<double>() - X).cwiseAbs().maxCoeff(), 1e-4) << side << uplo << ta << diag;
          }
}

// Colour-by-colour assembly adds every entry in the same order whatever the thread count.
TEST(FemSolvers, ResultDoesNotDependOnTheThreadCount) {
  Mesh m = slotted_box(ElementType::Wedge15);
  distort(m, 0.2, 3.0, 11);
  SolveOptions one, all;
  one.threads = 1;
  const SolveResult r1 = solve(m, one), ra = solve(m, all);
  EXPECT_EQ(r1.refinement_iterations, ra.refinement_iterations);
  EXPECT_TRUE((r1.displacement_mm.array() == ra.displacement_mm.array()).all());
}

// Solves at once in three threads, as `caps plan suggest`'s sweep closes two designs at once:
// each one's answer is the answer alone, and none kills the process. Two threads solve with
// CHOLMOD (ordered by MUMPS's analysis), the third with MUMPS (mixed precision). Before every call
// into MUMPS held one lock (7 December 2026), the sequential library's module variables were
// shared: one run of test_app_suggest in three died of SIGFPE in mumps_init_arch_parameters, and 3
// of 6 runs of this test without the lock died (SIGSEGV, SIGFPE, a MUMPS analysis failing with
// INFOG(1) = -13); with it, 8 of 8 passed (about 4 s each).
TEST(FemSolvers, SolvesAtOnceInThreeThreadsEachGiveTheAnswerAlone) {
  Mesh m = slotted_box(ElementType::Wedge15);
  distort(m, 0.2, 3.0, 5);
  SolveOptions mumps, cholmod;
  cholmod.solver = SolverKind::Cholmod;
  for (SolveOptions* o : {&mumps, &cholmod}) o->threads = 1;
  const SolveResult alone_m = solve(m, mumps), alone_c = solve(m, cholmod);
  std::atomic<int> wrong{0};
  const auto work = [&](const SolveOptions& o, const SolveResult& alone) {
    for (int i = 0; i < 150; ++i)
      if (!(solve(m, o).displacement_mm.array() == alone.displacement_mm.array()).all()) ++wrong;
  };
  std::thread a(work, std::cref(cholmod), std::cref(alone_c));
  std::thread b(work, std::cref(cholmod), std::cref(alone_c));
  std::thread c(work, std::cref(mumps), std::cref(alone_m));
  a.join();
  b.join();
  c.join();
  EXPECT_EQ(wrong.load(), 0);
}

TEST(FemSutures, SlotClosesSymmetricallyWithEqualAndOppositeForces) {
  for (ElementType t : kTypes) {
    const Mesh m = slotted_box(t);
    ASSERT_FALSE(m.sutures.empty());
    const SolveResult r = solve(m);
    const Eigen::MatrixX3d X1 = m.nodes + r.displacement_mm;
    double gap = 0, sym = 0, balance = 0;
    for (const SuturePair& s : m.sutures) {
      gap = std::max(gap, (X1.row(s.a) - X1.row(s.b)).norm());
      const Eigen::RowVector3d ua = r.displacement_mm.row(s.a), ub = r.displacement_mm.row(s.b);
      // The wedge box splits every cell along the same diagonal, so only the Hex20 box is
      // mirror-symmetric about the slot's mid-plane.
      if (t == ElementType::Hex20)
        sym = std::max({sym, std::abs(ua.x() + ub.x()), std::abs(ua.y() - ub.y()), std::abs(ua.z() - ub.z())});
      balance = std::max(balance, (r.reaction_n.row(s.a) + r.reaction_n.row(s.b)).norm());
    }
    const double w = 30.0 / 5;  // slot width
    EXPECT_LT(gap, 1e-9) << element_type_name(t);
    EXPECT_LT(sym, 1e-9 * w);
    EXPECT_LT(balance, 1e-9 * r.total_suture_force_n);
    // Each side moves half the width at mid-length of the slot (x-displacement, mid-height).
    double max_ux = 0;
    for (const SuturePair& s : m.sutures) max_ux = std::max(max_ux, std::abs(r.displacement_mm(s.a, 0)));
    if (t == ElementType::Hex20) EXPECT_NEAR(max_ux, w / 2, 1e-9);
    // Consistent nodal forces of quadratic elements alternate in sign along an edge, so single
    // pairs may push; the resultant across the wound pulls the left face towards +x.
    Eigen::Vector3d resultant = Eigen::Vector3d::Zero();
    for (const SutureForce& f : r.suture_forces) {
      resultant += f.force_on_a_n;
      EXPECT_NEAR(f.magnitude_n, f.force_on_a_n.norm(), 1e-15);
    }
    EXPECT_GT(resultant.x(), 0.0);
    EXPECT_NEAR(r.total_suture_force_n, resultant.x(), 1e-9 * resultant.x());
    if (t == ElementType::Hex20) EXPECT_LT(std::abs(resultant.y()), 1e-9 * resultant.x());
    std::printf("slot %s: %zu sutures, total closing force %.4f N, gap %.1e mm, energy %.4f mJ\n",
                element_type_name(t), m.sutures.size(), r.total_suture_force_n, gap, r.strain_energy_mj);
  }
}

TEST(FemMeshIo, DirectoryRoundTripsBothElementTypes) {
  for (ElementType t : kTypes) {
    BoxOptions o;
    o.size_mm = {30, 20, 6};
    o.cells = {3, 4, 1};
    o.wedges = t == ElementType::Wedge15;
    o.slot = true;
    Mesh m = make_box_mesh(o);
    m.materials.emplace(1, default_subcutaneous());
    m.materials[2] = make_material("goh", parameters_of(*default_goh_skin()));  // no elements
    m.elements.back().layer = 1;
    m.fixed_dofs.push_back({static_cast<int>(m.n_nodes()) - 1, 1, 0.25});
    m.loads.push_back({3, Eigen::Vector3d(0.1, 0.2, 0.3)});
    m.model = "models/p1";
    const auto dir = std::filesystem::temp_directory_path() / ("caps_fem_io_" + std::to_string(static_cast<int>(t)));
    std::filesystem::remove_all(dir);
    std::filesystem::create_directories(dir);
    write_mesh_dir(m, dir);
    Mesh back = read_mesh_dir(dir);
    EXPECT_EQ(back.nodes, m.nodes);
    ASSERT_EQ(back.elements.size(), m.elements.size());
    for (std::size_t e = 0; e < m.elements.size(); ++e) {
      EXPECT_EQ(back.elements[e].type, m.elements[e].type);
      EXPECT_EQ(back.elements[e].layer, m.elements[e].layer);
      EXPECT_EQ(back.elements[e].nodes, m.elements[e].nodes);
    }
    EXPECT_EQ(back.fixed_nodes, m.fixed_nodes);
    EXPECT_EQ(back.sutures.size(), m.sutures.size());
    EXPECT_EQ(back.fixed_dofs.size(), 1u);
    EXPECT_DOUBLE_EQ(back.fixed_dofs[0].value_mm, 0.25);
    EXPECT_EQ(back.loads[0].force_n, m.loads[0].force_n);
    // Each layer's material and parameters come back as written.
    EXPECT_EQ(back.materials.at(1)->name(), "neo-hookean");
    EXPECT_EQ(parameters_of(*back.materials.at(1)), (MaterialParameters{{"E", 0.005}, {"nu", 0.45}}));
    EXPECT_EQ(back.materials.at(2)->name(), "goh");
    EXPECT_EQ(parameters_of(*back.materials.at(2)), parameters_of(*m.materials.at(2)));
    EXPECT_EQ(parameters_of(*back.materials.at(0)), parameters_of(*default_skin()));
    back.materials.erase(2);  // the small-strain solve has no form of goh
    EXPECT_EQ(back.model, "models/p1");
    std::ifstream v(dir / "mesh.vtu");
    std::string text((std::istreambuf_iterator<char>(v)), {});
    EXPECT_NE(text.find(t == ElementType::Hex20 ? "\n25\n" : "\n26\n"), std::string::npos);
    EXPECT_NE(text.find("Name=\"suture_partner\""), std::string::npos);
    // Results go next to it.
    const SolveResult solved = solve(back);
    write_result_dir(back, solved, dir);
    EXPECT_TRUE(std::filesystem::exists(dir / "result.vtu"));
    EXPECT_TRUE(std::filesystem::exists(dir / "result.json"));
    // The nodal fields read back exactly (the shortest text of each double), and a wrong node
    // count is refused.
    EXPECT_EQ(read_result_displacement(dir, back.n_nodes()), solved.displacement_mm);
    EXPECT_EQ(read_result_max_principal(dir, back.n_nodes()), solved.max_principal_mpa);
    EXPECT_GT(solved.max_principal_mpa.cwiseAbs().maxCoeff(), 0.0);
    EXPECT_THROW(read_result_max_principal(dir, back.n_nodes() + 1), InvalidInput);
    std::filesystem::remove_all(dir);
  }
}

// The SolverError of a solve, or nothing: the where and what of a numerical failure.
template <typename F>
std::optional<SolverError> solver_error_of(F&& f) {
  try {
    f();
  } catch (const SolverError& e) {
    return e;
  }
  return std::nullopt;
}

TEST(FemSolverError, InvertedElementNamesItsElementAndGaussPoint) {
  // Element 2 of a 2×2×2 box turned inside out (top and bottom faces swapped): det J < 0 at
  // every Gauss point, so the first one, 0, is the one reported.
  Mesh m = box(ElementType::Hex20, {2, 2, 2}, {2, 2, 2}, true);
  auto& n = m.elements[2].nodes;
  for (int k = 0; k < 4; ++k) {
    std::swap(n[k], n[4 + k]);
    std::swap(n[8 + k], n[12 + k]);
  }
  const std::optional<SolverError> e = solver_error_of([&] { solve(m); });
  ASSERT_TRUE(e.has_value());
  EXPECT_EQ(e->element, 2);
  EXPECT_EQ(e->gauss_point, 0);
  EXPECT_EQ(e->iteration, -1);
  const std::string what = e->what();
  EXPECT_NE(what.find("element 2, Gauss point 0: Jacobian determinant"), std::string::npos) << what;
  // The element kernel on its own names the element it is given.
  const std::optional<SolverError> k = solver_error_of([&] {
    element_stiffness(ElementType::Hex20, element_coordinates(m, 2), LinearElastic(0.1, 0.3), 7);
  });
  ASSERT_TRUE(k.has_value());
  EXPECT_EQ(k->element, 7);
  EXPECT_EQ(k->gauss_point, 0);
}

TEST(FemSolverError, MechanismNamesTheElementThatCanMove) {
  // A fixed 2×2×2 box (1 mm cells) and one more cell, [2,3]×[0,1]×[2,3], that shares only the
  // box's edge x = 2, z = 2 (three nodes): the support checks see one held part, but the extra
  // cell can still turn about that edge, so the stiffness is singular and only that cell moves.
  Mesh m = box(ElementType::Hex20, {2, 2, 2}, {2, 2, 2}, true);
  const Eigen::RowVector3d shift(1, 0, 1);
  int source = -1;
  for (std::size_t e = 0; e < m.elements.size() && source < 0; ++e) {
    Eigen::RowVector3d c = Eigen::RowVector3d::Zero();
    for (int a = 0; a < 8; ++a) c += m.nodes.row(m.elements[e].nodes[a]) / 8;
    if ((c - Eigen::RowVector3d(1.5, 0.5, 1.5)).norm() < 1e-9) source = static_cast<int>(e);
  }
  ASSERT_GE(source, 0);
  Element extra = m.elements[source];
  int shared = 0;
  for (int a = 0; a < extra.n_nodes(); ++a) {
    const Eigen::RowVector3d p = m.nodes.row(extra.nodes[a]) + shift;
    int id = -1;
    for (Eigen::Index i = 0; i < m.n_nodes() && id < 0; ++i)
      if ((m.nodes.row(i) - p).norm() < 1e-9) id = static_cast<int>(i);
    if (id >= 0) {
      ++shared;
    } else {
      id = static_cast<int>(m.n_nodes());
      m.nodes.conservativeResize(id + 1, 3);
      m.nodes.row(id) = p;
    }
    extra.nodes[a] = id;
  }
  ASSERT_EQ(shared, 3);
  m.elements.push_back(extra);
  const int moving = static_cast<int>(m.elements.size()) - 1;
  // A force on the extra cell's last node (unloaded, the mixed-precision solve is exact with
  // u = 0 and never meets the singularity).
  m.loads.push_back({static_cast<int>(m.n_nodes()) - 1, Eigen::Vector3d(0.01, 0.02, 0.03)});
  for (const bool mixed : {true, false}) {
    SolveOptions o;
    o.mixed_precision = mixed;
    const std::optional<SolverError> e = solver_error_of([&] { solve(m, o); });
    ASSERT_TRUE(e.has_value()) << (mixed ? "mixed" : "double");
    EXPECT_EQ(e->element, moving) << e->what();
    const std::string what = e->what();
    EXPECT_EQ(what.rfind(cat("element ", moving, ": the stiffness matrix is singular"), 0), 0u) << what;
    EXPECT_NE(what.find("under-constrained"), std::string::npos) << what;
  }
  SolveOptions o;
  o.solver = SolverKind::Cholmod;
  const std::optional<SolverError> e = solver_error_of([&] { solve(m, o); });
  ASSERT_TRUE(e.has_value());
  EXPECT_EQ(e->element, moving) << e->what();
}

TEST(FemBadInput, EachErrorIsInvalidInputNamingTheItem) {
  auto small = [] { return box(ElementType::Hex20, {2, 2, 2}, {2, 2, 2}, true); };
  // nu >= 0.5 and E out of range.
  EXPECT_NE(error_of([] { LinearElastic(0.1, 0.5, "layer 2"); }).find("layer 2: Poisson's ratio nu = 0.5"), std::string::npos);
  EXPECT_NE(error_of([] { LinearElastic(-1, 0.3); }).find("Young's modulus"), std::string::npos);
  // NaN coordinate.
  {
    Mesh m = small();
    m.nodes(5, 1) = NAN;
    EXPECT_NE(error_of([&] { solve(m); }).find("node 5 has a non-finite coordinate"), std::string::npos);
  }
  // BLAS threads: a count, 0 (as configured) or kAutoBlasThreads (by the system's size); the
  // same answer either way.
  {
    const Mesh m = small();
    SolveOptions o;
    o.blas_threads = kAutoBlasThreads - 1;
    EXPECT_NE(error_of([&] { solve(m, o); }).find("blas_threads -2 must be >= 0"), std::string::npos);
    EXPECT_EQ(SolveOptions{}.blas_threads, kAutoBlasThreads);
    o.blas_threads = 1;
    const SolveResult one = solve(m, o);
    o.blas_threads = kAutoBlasThreads;
    EXPECT_LT((solve(m, o).displacement_mm - one.displacement_mm).cwiseAbs().maxCoeff(), 1e-12);
  }
  // Self-suture.
  {
    Mesh m = small();
    m.sutures.push_back({7, 7});
    EXPECT_NE(error_of([&] { solve(m); }).find("suture 0 joins node 7 to itself"), std::string::npos);
  }
  // Node id out of range.
  {
    Mesh m = small();
    m.elements[3].nodes[4] = 100000;
    EXPECT_NE(error_of([&] { solve(m); }).find("element 3 (Hex20) local node 4 refers to node 100000"), std::string::npos);
  }
  // No support at all, and support that still allows a rotation (one fixed node).
  for (SolverKind sk : {SolverKind::Mumps, SolverKind::Cholmod}) {
    SolveOptions o;
    o.solver = sk;
    Mesh m = small();
    m.fixed_nodes.clear();
    EXPECT_NE(error_of([&] { solve(m, o); }).find("under-constrained"), std::string::npos);
    m.fixed_nodes = {0};
    const std::string e = error_of([&] { solve(m, o); });
    EXPECT_NE(e.find("can still rotate"), std::string::npos) << solver_name(sk) << ": " << e;
    EXPECT_NE(e.find("under-constrained"), std::string::npos) << e;
  }
  // Nodes fixed along one line (the x axis) hold everything but the rotation about it; the
  // classic 3-2-1 support (a point, a second point in two directions, a third in one) holds
  // exactly the six rigid motions.
  {
    Mesh m = small();
    m.fixed_nodes.clear();
    for (Eigen::Index i = 0; i < m.n_nodes(); ++i)
      if (m.nodes(i, 1) == 0 && m.nodes(i, 2) == 0) m.fixed_nodes.push_back(static_cast<int>(i));
    const std::string e = error_of([&] { solve(m); });
    EXPECT_NE(e.find("can still rotate about the axis (1, 0, 0)"), std::string::npos) << e;
    auto node_at = [&](double x, double y, double z) {
      for (Eigen::Index i = 0; i < m.n_nodes(); ++i)
        if ((m.nodes.row(i) - Eigen::RowVector3d(x, y, z)).norm() < 1e-12) return static_cast<int>(i);
      return -1;
    };
    m.fixed_nodes = {node_at(0, 0, 0)};
    m.fixed_dofs = {{node_at(2, 0, 0), 1, 0.0}, {node_at(2, 0, 0), 2, 0.0}, {node_at(0, 2, 0), 2, 0.0}};
    m.loads = {{node_at(2, 2, 2), Eigen::Vector3d(0.01, 0.02, 0.03)}};
    EXPECT_EQ(error_of([&] { solve(m); }), "NO ERROR");
  }
  // Unknown layer; conflicting constraints.
  {
    Mesh m = small();
    m.elements[0].layer = 9;
    EXPECT_NE(error_of([&] { solve(m); }).find("element 0 (Hex20) has layer 9"), std::string::npos);
  }
  {
    Mesh m = small();
    m.fixed_dofs.push_back({m.fixed_nodes[0], 2, 0.5});
    EXPECT_NE(error_of([&] { solve(m); }).find("is fixed twice"), std::string::npos);
  }
  // Missing directory / files.
  EXPECT_THROW(read_mesh_dir("/nonexistent/caps"), IoError);
}

TEST(FemFiniteAssembly, AnInvertedStateReportsTheLowestInvertedElementAsTheFullAssemblyDoes) {
  // Once an element is found inverted, the assembly only looks for a lower one (the others'
  // forces and tangents are of no use: the step is cut back). What it reports must be what the
  // kernel run on every element in id order finds, with one thread or two.
  for (const bool wedges : {false, true}) {
    BoxOptions bo;
    bo.size_mm = {24, 24, 6};
    bo.cells = {6, 6, 2};
    bo.wedges = wedges;
    const Mesh mesh = make_box_mesh(bo);
    const fem::detail::DofMap map = fem::detail::build_dof_map(mesh);
    fem::detail::FiniteMaterials materials;
    for (const auto& [layer, m] : mesh.materials) materials[layer] = m.get();
    // A smooth field and three nodes pushed through their elements (the last element's node
    // too, so that inverted elements lie at both ends of the numbering).
    Eigen::VectorXd u(3 * mesh.n_nodes());
    for (Eigen::Index i = 0; i < u.size(); ++i) u[i] = 0.05 * std::sin(0.37 * static_cast<double>(i));
    const std::vector<int> pushed = {mesh.elements[17].nodes[0], mesh.elements[40].nodes[6],
                                     mesh.elements.back().nodes[1]};
    for (const int node : pushed) u.segment<3>(3 * node) += Eigen::Vector3d(9, -7, 8);
    // The kernel on every element, in id order.
    int lowest = -1, gauss_point = -1;
    double det_F = 0;
    int n_inverted = 0;
    for (int e = 0; e < mesh.n_elements(); ++e) {
      const Element& el = mesh.elements[e];
      Eigen::MatrixX3d X(el.n_nodes(), 3);
      Eigen::VectorXd ue(3 * el.n_nodes()), fe;
      Eigen::MatrixXd Ke;
      for (int a = 0; a < el.n_nodes(); ++a) {
        X.row(a) = mesh.nodes.row(el.nodes[a]);
        ue.segment<3>(3 * a) = u.segment<3>(3 * el.nodes[a]);
      }
      const fem::detail::FiniteKernelResult r = fem::detail::finite_kernel(
          el.type, X, *materials.at(el.layer), ue, e, fe, &Ke, 1.0, mesh.wedge_rule);
      if (r.inverted_at < 0) continue;
      ++n_inverted;
      if (lowest < 0) {
        lowest = e;
        gauss_point = r.inverted_at;
        det_F = r.det_F;
      }
      // the check alone finds the same point
      const fem::detail::FiniteKernelResult c = fem::detail::first_inversion(el.type, X, ue, e, mesh.wedge_rule);
      EXPECT_EQ(c.inverted_at, r.inverted_at) << "element " << e;
      EXPECT_EQ(c.det_F, r.det_F) << "element " << e;
    }
    ASSERT_GE(n_inverted, 3) << (wedges ? "Wedge15" : "Hex20");
    ASSERT_GE(lowest, 0);
    for (const int threads : {1, 2}) {
      tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
      fem::detail::Assembly sys = fem::detail::assemble_structure(mesh, map);
      const fem::detail::FiniteAssembly a =
          fem::detail::assemble_finite(mesh, map, materials, u, 1.0, Eigen::VectorXd(), true, sys);
      EXPECT_EQ(a.inverted_element, lowest) << threads << " threads";
      EXPECT_EQ(a.inverted_gauss_point, gauss_point) << threads << " threads";
      EXPECT_EQ(a.det_F, det_F) << threads << " threads";
    }
  }
}
