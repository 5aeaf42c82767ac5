// caps::fem Tet10 (the quadratic tetrahedron of the whole-face model): shape functions and the
// 4-point rule, linear tets made quadratic (shared mid-edge nodes, bad tets refused), the patch
// test (small strain, both solvers), a manufactured solution's convergence and the homogeneous
// finite-strain stretch on irregular tet meshes, the tangent against finite differences, Tet10
// against Hex20 in bending as the meshes are refined, CalculiX C3D10 on the same decks (linear
// and NLGEOM), and the mesh files.
#include <gtest/gtest.h>

#include "ccx_run.hpp"
#include "fem_test_support.hpp"

#include <Eigen/Dense>
#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <memory>
#include <random>
#include <sstream>
#include <string>

#include "caps/core/error.hpp"
#include "caps/fem/box.hpp"
#include "caps/fem/elements.hpp"
#include "caps/fem/inp_io.hpp"
#include "caps/fem/mesh_io.hpp"
#include "caps/fem/result_io.hpp"
#include "caps/fem/solve.hpp"
#include "caps/fem/tet_mesh.hpp"

using namespace caps;
using namespace caps::fem;

namespace {

using namespace caps::fem::test;

// Linear tetrahedra filling the box [0,size]: each of cells.x × cells.y × cells.z cubes cut into
// the six tets of its 000-111 diagonal (Kuhn's triangulation, conforming across cubes), every
// tet oriented (mesh.hpp). Interior corners are moved by up to `jitter` × the cell size in each
// direction (seeded), so the tets are irregular; boundary corners stay on their faces.
struct TetGrid {
  Eigen::MatrixX3d V;
  Eigen::MatrixX4i T;
};

TetGrid tet_grid(const Eigen::Vector3d& size, const Eigen::Vector3i& cells, double jitter = 0,
                 unsigned seed = 1) {
  const int nx = cells.x(), ny = cells.y(), nz = cells.z();
  const Eigen::Vector3d h = size.cwiseQuotient(cells.cast<double>());
  auto id = [&](int i, int j, int k) { return i + (nx + 1) * (j + (ny + 1) * k); };
  TetGrid g;
  g.V.resize((nx + 1) * (ny + 1) * (nz + 1), 3);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> d(-jitter, jitter);
  for (int k = 0; k <= nz; ++k)
    for (int j = 0; j <= ny; ++j)
      for (int i = 0; i <= nx; ++i) {
        Eigen::Vector3d x(i * h.x(), j * h.y(), k * h.z());
        if (i > 0 && i < nx && j > 0 && j < ny && k > 0 && k < nz)
          for (int c = 0; c < 3; ++c) x[c] += d(rng) * h[c];
        g.V.row(id(i, j, k)) = x.transpose();
      }
  const std::array<std::array<int, 3>, 6> perms{{{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}}};
  g.T.resize(6 * nx * ny * nz, 4);
  int t = 0;
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i)
        for (const auto& p : perms) {
          Eigen::Vector3i c(i, j, k);
          g.T(t, 0) = id(c.x(), c.y(), c.z());
          for (int s = 0; s < 3; ++s) {
            ++c[p[s]];
            g.T(t, s + 1) = id(c.x(), c.y(), c.z());
          }
          const Eigen::Vector3d x0 = g.V.row(g.T(t, 0)), x1 = g.V.row(g.T(t, 1)),
                                x2 = g.V.row(g.T(t, 2)), x3 = g.V.row(g.T(t, 3));
          if ((x1 - x0).cross(x2 - x0).dot(x3 - x0) < 0) std::swap(g.T(t, 1), g.T(t, 2));
          ++t;
        }
  return g;
}

Mesh tet_mesh(const Eigen::Vector3d& size, const Eigen::Vector3i& cells,
              std::shared_ptr<const Material> material, double jitter = 0, unsigned seed = 1) {
  const TetGrid g = tet_grid(size, cells, jitter, seed);
  QuadraticTetMesh q = quadratic_tetrahedra(g.V, g.T);
  Mesh m;
  m.nodes = std::move(q.nodes);
  m.elements = std::move(q.elements);
  m.materials[0] = std::move(material);
  return m;
}

Mesh hex_mesh(const Eigen::Vector3d& size, const Eigen::Vector3i& cells,
              std::shared_ptr<const Material> material) {
  BoxOptions o;
  o.size_mm = size;
  o.cells = cells;
  o.fix_bottom = false;
  o.material = std::move(material);
  return make_box_mesh(o);
}

bool near(double a, double b) { return std::abs(a - b) < 1e-9; }

std::vector<char> on_box_boundary(const Mesh& m, const Eigen::Vector3d& size) {
  std::vector<char> b(m.n_nodes(), 0);
  for (Eigen::Index i = 0; i < m.n_nodes(); ++i)
    for (int c = 0; c < 3; ++c)
      if (near(m.nodes(i, c), 0) || near(m.nodes(i, c), size[c])) b[i] = 1;
  return b;
}

Vector6d voigt(const Eigen::Matrix3d& s) {
  Vector6d v;
  v << s(0, 0), s(1, 1), s(2, 2), s(0, 1), s(1, 2), s(0, 2);
  return v;
}

}  // namespace

TEST(Tet10Shape, PartitionOfUnityKroneckerDeltaAndDerivatives) {
  const ElementType t = ElementType::Tet10;
  EXPECT_EQ(n_element_nodes(t), 10);
  EXPECT_STREQ(element_type_name(t), "Tet10");
  const Eigen::MatrixX3d P = natural_nodes(t);
  ASSERT_EQ(P.rows(), 10);
  // Mid-edge nodes halfway along edges 0-1, 1-2, 2-0, 0-3, 1-3, 2-3 (VTK 24, CalculiX C3D10).
  const int edges[6][2] = {{0, 1}, {1, 2}, {2, 0}, {0, 3}, {1, 3}, {2, 3}};
  for (int e = 0; e < 6; ++e)
    EXPECT_LT((P.row(4 + e) - 0.5 * (P.row(edges[e][0]) + P.row(edges[e][1]))).norm(), 1e-15);
  EXPECT_EQ(P.row(3), Eigen::RowVector3d(0, 0, 1));
  Eigen::VectorXd N;
  Eigen::MatrixX3d dN;
  for (int b = 0; b < 10; ++b) {
    shape_functions(t, P.row(b).transpose(), N, dN);
    for (int a = 0; a < 10; ++a) EXPECT_NEAR(N[a], a == b ? 1.0 : 0.0, 1e-14) << a << " at node " << b;
  }
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> d(0, 1);
  // An affine map of the unit tet: the isoparametric element reproduces x = A xi + c exactly.
  Eigen::Matrix3d A;
  A << 2, 0.3, -0.1, 0.2, 1.5, 0.4, -0.3, 0.1, 1.8;
  const Eigen::Vector3d c(1, -2, 0.5);
  Eigen::MatrixX3d X(10, 3);
  for (int a = 0; a < 10; ++a) X.row(a) = (A * P.row(a).transpose() + c).transpose();
  for (int trial = 0; trial < 20; ++trial) {
    Eigen::Vector3d xi(d(rng), d(rng), d(rng));
    if (xi.sum() > 1) xi *= 0.99 / xi.sum();
    shape_functions(t, xi, N, dN);
    EXPECT_NEAR(N.sum(), 1.0, 1e-14);
    EXPECT_LT(dN.colwise().sum().norm(), 1e-13);
    EXPECT_LT((X.transpose() * N - (A * xi + c)).norm(), 1e-13);
    EXPECT_LT((dN.transpose() * X - A.transpose()).norm(), 1e-13);  // J_ij = dx_j/dxi_i
    const double h = 1e-6;
    for (int k = 0; k < 3; ++k) {
      Eigen::VectorXd Np, Nm;
      Eigen::MatrixX3d unused;
      shape_functions(t, xi + h * Eigen::Vector3d::Unit(k), Np, unused);
      shape_functions(t, xi - h * Eigen::Vector3d::Unit(k), Nm, unused);
      EXPECT_LT(((Np - Nm) / (2 * h) - dN.col(k)).cwiseAbs().maxCoeff(), 1e-9) << "d/dxi_" << k;
    }
  }
}

TEST(Tet10Shape, TheFourPointRuleIntegratesQuadraticsExactly) {
  const auto& q = quadrature(ElementType::Tet10);
  ASSERT_EQ(q.size(), 4u);
  // int over the unit tet of xi^a eta^b zeta^c = a! b! c! / (a+b+c+3)!
  auto integrate = [&](const std::function<double(const Eigen::Vector3d&)>& f) {
    double s = 0;
    for (const auto& p : q) s += p.weight * f(p.xi);
    return s;
  };
  EXPECT_NEAR(integrate([](const Eigen::Vector3d&) { return 1.0; }), 1.0 / 6, 1e-15);
  for (int k = 0; k < 3; ++k) {
    EXPECT_NEAR(integrate([&](const Eigen::Vector3d& x) { return x[k]; }), 1.0 / 24, 1e-15);
    EXPECT_NEAR(integrate([&](const Eigen::Vector3d& x) { return x[k] * x[k]; }), 1.0 / 60, 1e-15);
    EXPECT_NEAR(integrate([&](const Eigen::Vector3d& x) { return x[k] * x[(k + 1) % 3]; }), 1.0 / 120,
                1e-15);
  }
  // Degree 3 is beyond it (so the rule is the 4-point one, not a richer rule).
  EXPECT_GT(std::abs(integrate([](const Eigen::Vector3d& x) { return x[0] * x[0] * x[0]; }) - 1.0 / 120),
            1e-4);
  for (const auto& p : q) EXPECT_GT(1 - p.xi.sum(), 0);  // inside
}

TEST(Tet10Mesh, QuadraticTetrahedraShareOneMidNodePerEdge) {
  // Two tets on the face 0-1-2: 5 corners, 6 + 6 - 3 = 9 edges.
  Eigen::MatrixX3d V(5, 3);
  V << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0.3, 0.3, -1;
  Eigen::MatrixX4i T(2, 4);
  T << 0, 1, 2, 3, 0, 2, 1, 4;
  Eigen::VectorXi layers(2);
  layers << 0, 2;
  const QuadraticTetMesh q = quadratic_tetrahedra(V, T, layers);
  ASSERT_EQ(q.nodes.rows(), 5 + 9);
  ASSERT_EQ(q.edges.rows(), 9);
  ASSERT_EQ(q.elements.size(), 2u);
  EXPECT_EQ(q.nodes.topRows(5), V);
  EXPECT_EQ(q.elements[1].layer, 2);
  const Eigen::MatrixX3d P = natural_nodes(ElementType::Tet10);
  for (const Element& el : q.elements) {
    EXPECT_EQ(el.type, ElementType::Tet10);
    // Each mid node is its edge's midpoint, and the mesh maps the natural nodes there.
    Eigen::MatrixX3d X(10, 3);
    for (int a = 0; a < 10; ++a) X.row(a) = q.nodes.row(el.nodes[a]);
    for (int a = 4; a < 10; ++a) {
      Eigen::VectorXd N;
      Eigen::MatrixX3d dN;
      shape_functions(ElementType::Tet10, P.row(a).transpose(), N, dN);
      Eigen::RowVector3d affine = Eigen::RowVector3d::Zero();
      const double L[4] = {1 - P.row(a).sum(), P(a, 0), P(a, 1), P(a, 2)};
      for (int c = 0; c < 4; ++c) affine += L[c] * X.row(c);
      EXPECT_LT((X.row(a) - affine).norm(), 1e-15);
    }
  }
  // The shared face's three edges have one node each: edge 0-1 of tet 0 is edge 2-0 of tet 1.
  EXPECT_EQ(q.elements[0].nodes[4], q.elements[1].nodes[6]);
  EXPECT_EQ(q.elements[0].nodes[5], q.elements[1].nodes[5]);
  EXPECT_EQ(q.elements[0].nodes[6], q.elements[1].nodes[4]);
  for (Eigen::Index k = 0; k < q.edges.rows(); ++k) {
    EXPECT_LT(q.edges(k, 0), q.edges(k, 1));
    EXPECT_LT((q.nodes.row(5 + k) - 0.5 * (V.row(q.edges(k, 0)) + V.row(q.edges(k, 1)))).norm(), 1e-15);
  }
  // A grid of n^3 cubes, six tets each: grid edges + face diagonals + cube diagonals.
  const int n = 3;
  const TetGrid g = tet_grid({3, 3, 3}, {n, n, n}, 0.15, 5);
  const QuadraticTetMesh a = quadratic_tetrahedra(g.V, g.T), b = quadratic_tetrahedra(g.V, g.T);
  EXPECT_EQ(a.edges.rows(), 3 * n * (n + 1) * (n + 1) + 3 * n * n * (n + 1) + n * n * n);
  EXPECT_EQ(a.edges, b.edges);  // deterministic
  EXPECT_EQ(a.nodes, b.nodes);
  Mesh m;
  m.nodes = a.nodes;
  m.elements = a.elements;
  m.materials[0] = std::make_shared<LinearElastic>(kE, 0.3);
  EXPECT_NO_THROW(validate(m));
}

TEST(Tet10Mesh, InvertedDegenerateAndBadTetsAreRefusedByName) {
  Eigen::MatrixX3d V(5, 3);
  V << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0.5, 0.5, 0;
  auto message = [&](const Eigen::MatrixX4i& T, Eigen::VectorXi layers = {}) -> std::string {
    try {
      if (layers.size())
        quadratic_tetrahedra(V, T, layers);
      else
        quadratic_tetrahedra(V, T);
    } catch (const InvalidInput& e) {
      return e.what();
    }
    return "accepted";
  };
  Eigen::MatrixX4i T(2, 4);
  T << 0, 1, 2, 3, 0, 2, 1, 3;  // the second is the first turned inside out
  std::string what = message(T);
  EXPECT_NE(what.find("tetrahedron 1"), std::string::npos) << what;
  EXPECT_NE(what.find("inverted"), std::string::npos) << what;
  T << 0, 1, 2, 3, 0, 1, 4, 2;  // corners 0, 1, 4, 2 lie in z = 0
  what = message(T);
  EXPECT_NE(what.find("tetrahedron 1"), std::string::npos) << what;
  EXPECT_NE(what.find("degenerate"), std::string::npos) << what;
  T << 0, 1, 2, 3, 0, 1, 2, 7;
  what = message(T);
  EXPECT_NE(what.find("refers to node 7"), std::string::npos) << what;
  T << 0, 1, 2, 3, 0, 1, 1, 3;
  what = message(T);
  EXPECT_NE(what.find("twice"), std::string::npos) << what;
  T << 0, 1, 2, 3, 0, 1, 4, 3;
  EXPECT_EQ(message(T), "accepted");
  EXPECT_NE(message(T, Eigen::VectorXi::Zero(3)).find("layer ids"), std::string::npos);
}

TEST(Tet10Patch, LinearFieldIsExactOnIrregularTetsBothSolvers) {
  Eigen::Matrix3d A;
  A << 1e-3, 2e-3, -1e-3, 0.5e-3, -2e-3, 1.5e-3, 3e-3, 1e-3, 2.5e-3;
  const Eigen::Vector3d b(0.01, -0.02, 0.03);
  auto exact = [&](const Eigen::Vector3d& x) -> Eigen::Vector3d { return A * x + b; };
  const auto mat = std::make_shared<LinearElastic>(kE, 0.3);
  const Eigen::Matrix3d eps = 0.5 * (A + A.transpose());
  const Vector6d s_exact =
      voigt(mat->lambda_mpa() * eps.trace() * Eigen::Matrix3d::Identity() + 2 * mat->mu_mpa() * eps);
  const Eigen::Vector3d size(3, 2, 2.5);
  Mesh m = tet_mesh(size, {3, 2, 3}, mat, 0.2, 7);  // 108 tets
  const auto boundary = on_box_boundary(m, size);
  int n_free = 0;
  for (Eigen::Index i = 0; i < m.n_nodes(); ++i) {
    if (!boundary[i]) {
      ++n_free;
      continue;
    }
    const Eigen::Vector3d v = exact(m.nodes.row(i).transpose());
    for (int c = 0; c < 3; ++c) m.fixed_dofs.push_back({static_cast<int>(i), c, v[c]});
  }
  ASSERT_GT(n_free, 20);
  for (SolverKind sk : {SolverKind::Mumps, SolverKind::Cholmod}) {
    SolveOptions o;
    o.solver = sk;
    const SolveResult r = solve(m, o);
    const double err = max_displacement_error(m, r, exact);
    EXPECT_LT(err, 1e-12) << solver_name(sk);
    EXPECT_EQ(r.gauss_stress_mpa.rows(), 4 * static_cast<Eigen::Index>(m.n_elements()));
    const double scale = s_exact.cwiseAbs().maxCoeff();
    EXPECT_LT((r.gauss_stress_mpa.rowwise() - s_exact.transpose()).cwiseAbs().maxCoeff(), 1e-10 * scale);
    EXPECT_LT((r.nodal_stress_mpa.rowwise() - s_exact.transpose()).cwiseAbs().maxCoeff(), 1e-10 * scale);
    // Strain energy = 1/2 sigma:eps × the box's volume (the tets fill it exactly).
    Eigen::Matrix3d S;
    S << s_exact[0], s_exact[3], s_exact[5], s_exact[3], s_exact[1], s_exact[4], s_exact[5],
        s_exact[4], s_exact[2];
    const double energy = 0.5 * (S.array() * eps.array()).sum() * size.prod();
    EXPECT_NEAR(r.strain_energy_mj, energy, 1e-10 * energy);
  }
}

namespace {

// u = grad phi with phi = a e^{x/L} cos(y/L) harmonic: div u = 0 and Laplace u = 0, so it solves
// Navier's equations without body force for any lambda, mu (as tests/test_fem.cpp).
Eigen::Vector3d manufactured(const Eigen::Vector3d& x) {
  const double a = 0.01, L = 0.5;
  return a / L * std::exp(x[0] / L) * Eigen::Vector3d(std::cos(x[1] / L), -std::sin(x[1] / L), 0.0);
}

}  // namespace

TEST(Tet10Convergence, ManufacturedSolutionConvergesAtThirdOrder) {
  // Unit cube, n^3 cubes of six tets, the exact field on the boundary: the largest nodal error
  // falls as h^3 (quadratic elements), like Hex20's and Wedge15's in tests/test_fem.cpp.
  const Eigen::Vector3d size(1, 1, 1);
  std::vector<double> err;
  for (int n : {2, 4, 8}) {
    Mesh m = tet_mesh(size, {n, n, n}, std::make_shared<LinearElastic>(kE, 0.3));
    const auto boundary = on_box_boundary(m, size);
    for (Eigen::Index i = 0; i < m.n_nodes(); ++i)
      if (boundary[i]) {
        const Eigen::Vector3d v = manufactured(m.nodes.row(i).transpose());
        for (int c = 0; c < 3; ++c) m.fixed_dofs.push_back({static_cast<int>(i), c, v[c]});
      }
    const SolveResult r = solve(m);
    double e = 0;
    for (Eigen::Index i = 0; i < m.n_nodes(); ++i)
      e = std::max(e, (r.displacement_mm.row(i).transpose() - manufactured(m.nodes.row(i).transpose())).norm());
    err.push_back(e);
  }
  const double rate1 = std::log2(err[0] / err[1]), rate2 = std::log2(err[1] / err[2]);
  std::cout << "Tet10 manufactured solution: max nodal error " << err[0] << " / " << err[1] << " / "
            << err[2] << " mm for h = 1/2, 1/4, 1/8 (rates " << rate1 << ", " << rate2 << ")\n";
  EXPECT_GT(rate2, 3.0);
  EXPECT_GT(rate1, 2.5);
}

TEST(Tet10Element, StiffnessIsSymmetricWithSixRigidModesAndMatchesTheInternalForce) {
  const TetGrid g = tet_grid({1, 1, 1}, {1, 1, 1});
  QuadraticTetMesh q = quadratic_tetrahedra(g.V, g.T);
  Mesh m;
  m.nodes = q.nodes;
  m.elements = q.elements;
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> d(-0.05, 0.05);
  Eigen::MatrixX3d X = element_coordinates(m, 0);
  for (int a = 0; a < 4; ++a)
    for (int c = 0; c < 3; ++c) X(a, c) += d(rng);
  const LinearElastic mat(kE, 0.3);
  const Eigen::MatrixXd K = element_stiffness(ElementType::Tet10, X, mat);
  ASSERT_EQ(K.rows(), 30);
  EXPECT_LT((K - K.transpose()).cwiseAbs().maxCoeff(), 1e-14 * K.cwiseAbs().maxCoeff());
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(K);
  for (int k = 0; k < 6; ++k) EXPECT_LT(std::abs(es.eigenvalues()[k]), 1e-12 * es.eigenvalues()[29]);
  EXPECT_GT(es.eigenvalues()[6], 1e-4 * es.eigenvalues()[29]);  // no spurious zero-energy mode
  Eigen::VectorXd u(30);
  for (int i = 0; i < 30; ++i) u[i] = d(rng);
  EXPECT_LT((element_internal_force(ElementType::Tet10, X, mat, u) - K * u).norm(), 1e-12 * (K * u).norm());
}

TEST(Tet10Finite, TangentMatchesFiniteDifferencesOfTheForce) {
  const TetGrid g = tet_grid({2, 2, 2}, {1, 1, 1});
  const QuadraticTetMesh q = quadratic_tetrahedra(g.V, g.T);
  std::mt19937 rng(13);
  std::uniform_real_distribution<double> d(-1, 1);
  Eigen::MatrixX3d X(10, 3);
  for (int a = 0; a < 10; ++a) X.row(a) = q.nodes.row(q.elements[2].nodes[a]);
  X += 0.03 * Eigen::MatrixX3d::NullaryExpr(10, 3, [&] { return d(rng); });  // curved edges too
  const Eigen::VectorXd u = 0.15 * Eigen::VectorXd::NullaryExpr(30, [&] { return d(rng); });
  const NeoHookean mat(kE, kNu);
  const FiniteElementResponse r = element_finite_response(ElementType::Tet10, X, mat, u);
  const double h = 1e-6;
  Eigen::MatrixXd K_fd(30, 30);
  for (int j = 0; j < 30; ++j) {
    Eigen::VectorXd up = u, um = u;
    up[j] += h;
    um[j] -= h;
    K_fd.col(j) = (element_finite_response(ElementType::Tet10, X, mat, up, 0, false).f -
                   element_finite_response(ElementType::Tet10, X, mat, um, 0, false).f) / (2 * h);
  }
  EXPECT_LT((K_fd - r.K).cwiseAbs().maxCoeff() / r.K.cwiseAbs().maxCoeff(), 1e-7);
  EXPECT_LT((r.K - r.K.transpose()).cwiseAbs().maxCoeff(), 1e-12 * r.K.cwiseAbs().maxCoeff());
  const Eigen::VectorXd v = Eigen::VectorXd::NullaryExpr(30, [&] { return d(rng); });
  const double dPi = (element_finite_response(ElementType::Tet10, X, mat, u + h * v, 0, false).energy_mj -
                      element_finite_response(ElementType::Tet10, X, mat, u - h * v, 0, false).energy_mj) / (2 * h);
  EXPECT_NEAR(dPi, r.f.dot(v), 1e-7 * r.f.norm() * v.norm());
}

TEST(Tet10Finite, UniaxialStretchOfANeoHookeanBlockMatchesTheClosedForm) {
  // Symmetry planes x = 0, y = 0, z = 0; the face x = L pulled to l1 L; the other faces free.
  // The homogeneous state is in the Tet10 space, so every Gauss point carries the closed form.
  const double L = 10, l1 = 1.5;
  const auto nh = std::make_shared<NeoHookean>(kE, kNu);
  Mesh m = tet_mesh({L, L, L}, {2, 2, 2}, nh, 0.2, 3);
  for (int i = 0; i < m.n_nodes(); ++i) {
    for (int c = 0; c < 3; ++c)
      if (near(m.nodes(i, c), 0)) m.fixed_dofs.push_back({i, c, 0.0});
    if (near(m.nodes(i, 0), L)) m.fixed_dofs.push_back({i, 0, (l1 - 1) * L});
  }
  SolveOptions o;
  o.kinematics = Kinematics::Finite;
  o.newton.n_steps = 10;
  const SolveResult r = solve(m, o);
  const double l2 = lateral_stretch(l1, nh->mu_mpa(), nh->bulk_mpa());
  const double s11 = principal_cauchy(l1, l2, nh->mu_mpa(), nh->bulk_mpa())[0];
  std::cout << "Tet10 uniaxial stretch 1.5: lateral stretch " << l2 << ", sigma_11 " << s11 << " MPa\n";
  for (int i = 0; i < m.n_nodes(); ++i) {
    EXPECT_NEAR(r.displacement_mm(i, 0), (l1 - 1) * m.nodes(i, 0), 1e-6 * L);
    for (int c = 1; c < 3; ++c) EXPECT_NEAR(r.displacement_mm(i, c), (l2 - 1) * m.nodes(i, c), 1e-6 * L);
  }
  for (Eigen::Index g = 0; g < r.gauss_stress_mpa.rows(); ++g) {
    EXPECT_NEAR(r.gauss_stress_mpa(g, 0), s11, 1e-6 * s11);
    for (int c = 1; c < 6; ++c) EXPECT_NEAR(r.gauss_stress_mpa(g, c), 0.0, 1e-6 * s11);
  }
  EXPECT_LT((r.nodal_stress_mpa.col(0).array() - s11).abs().maxCoeff(), 1e-6 * s11);
  double fx = 0;  // the pulled face's reaction = sigma_11 × its deformed area (l2 L)^2
  for (int i = 0; i < m.n_nodes(); ++i)
    if (near(m.nodes(i, 0), L)) fx += r.reaction_n(i, 0);
  EXPECT_NEAR(fx, s11 * l2 * l2 * L * L, 1e-6 * s11 * L * L);
}

TEST(Tet10Finite, MaterialsThatNeedALayerPlaneAreRefused) {
  Mesh m = tet_mesh({2, 2, 2}, {1, 1, 1},
                    std::make_shared<GasserOgdenHolzapfel>(0.05, 0.24, 4.97, 2.88, 0.0498, 30.0,
                                                           Eigen::Vector3d(1, 0, 0)));
  for (int i = 0; i < m.n_nodes(); ++i)
    if (near(m.nodes(i, 2), 0)) m.fixed_nodes.push_back(i);
  for (int i = 0; i < m.n_nodes(); ++i)
    if (near(m.nodes(i, 2), 2)) m.fixed_dofs.push_back({i, 0, 0.2});
  SolveOptions o;
  o.kinematics = Kinematics::Finite;
  try {
    solve(m, o);
    ADD_FAILURE() << "goh on a Tet10 was accepted";
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("Tet10"), std::string::npos) << e.what();
  }
  EXPECT_THROW(element_finite_response(ElementType::Tet10, element_coordinates(m, 0),
                                       *m.materials[0], Eigen::VectorXd::Zero(30)),
               InvalidInput);
  m.materials[0] = std::make_shared<NeoHookean>(kE, kNu);
  o.prestretch = 1.1;
  EXPECT_THROW(solve(m, o), InvalidInput);
  o.prestretch = 1.0;
  EXPECT_NO_THROW(solve(m, o));
}

namespace {

// A block L × W × H clamped at x = 0 whose end x = L is moved by delta along z (held in x and y:
// a guided cantilever, bent in double curvature). Returns the end's total z reaction (N) and the
// displacement (mm) at the node (L/4, W/2, H/2).
struct Bending {
  double force_n = 0;
  Eigen::Vector3d u_quarter = Eigen::Vector3d::Zero();
};

Bending guided_cantilever(Mesh m, const Eigen::Vector3d& size, double delta) {
  int quarter = -1;
  for (int i = 0; i < m.n_nodes(); ++i) {
    if (near(m.nodes(i, 0), 0)) m.fixed_nodes.push_back(i);
    if (near(m.nodes(i, 0), size.x()))
      for (int c = 0; c < 3; ++c) m.fixed_dofs.push_back({i, c, c == 2 ? delta : 0.0});
    if ((m.nodes.row(i).transpose() - Eigen::Vector3d(size.x() / 4, size.y() / 2, size.z() / 2)).norm() < 1e-9)
      quarter = i;
  }
  EXPECT_GE(quarter, 0);
  const SolveResult r = solve(m);
  Bending b;
  for (int i = 0; i < m.n_nodes(); ++i)
    if (near(m.nodes(i, 0), size.x())) b.force_n += r.reaction_n(i, 2);
  b.u_quarter = r.displacement_mm.row(quarter).transpose();
  return b;
}

}  // namespace

TEST(Tet10VsHex20, BendingAgreesAsTheMeshIsRefined) {
  // A 16 × 4 × 4 mm block (linear, E = 0.1 MPa, nu = 0.3), its end moved 1 mm sideways. The
  // reference is Hex20 at 32 × 8 × 8 cells; Tet10 on 6 tets per cube at h = 2, 1, 0.5 mm
  // (regular cubes: interior jitter would make the sequence of meshes non-nested).
  const Eigen::Vector3d size(16, 4, 4);
  const auto mat = std::make_shared<LinearElastic>(kE, 0.3);
  const double delta = 1.0;
  const Bending ref = guided_cantilever(hex_mesh(size, {32, 8, 8}, mat), size, delta);
  const Bending hex_coarse = guided_cantilever(hex_mesh(size, {8, 2, 2}, mat), size, delta);
  std::cout << "Hex20 32x8x8: end force " << ref.force_n << " N, u(L/4) " << ref.u_quarter.transpose()
            << " mm; Hex20 8x2x2: " << hex_coarse.force_n << " N\n";
  std::vector<double> force_err, u_err;
  for (int k : {1, 2, 4}) {
    const Bending t = guided_cantilever(tet_mesh(size, {8 * k, 2 * k, 2 * k}, mat), size, delta);
    force_err.push_back(std::abs(t.force_n - ref.force_n) / std::abs(ref.force_n));
    u_err.push_back((t.u_quarter - ref.u_quarter).norm() / ref.u_quarter.norm());
    std::cout << "Tet10 " << 8 * k << "x" << 2 * k << "x" << 2 * k << " cubes (" << 6 * 32 * k * k * k
              << " tets): end force " << t.force_n << " N (" << 100 * force_err.back()
              << " % off Hex20), u(L/4) " << t.u_quarter.transpose() << " mm (" << 100 * u_err.back()
              << " %)\n";
  }
  // Stiffer when coarse (a displacement method), converging to Hex20's answer.
  for (std::size_t k = 1; k < force_err.size(); ++k) {
    EXPECT_LT(force_err[k], 0.5 * force_err[k - 1]);
    EXPECT_LT(u_err[k], 0.6 * u_err[k - 1] + 1e-4);
  }
  EXPECT_LT(force_err.back(), 0.01);
  EXPECT_LT(u_err.back(), 0.01);
}

namespace {

// A 12 × 3 × 3 mm neo-Hookean cantilever of irregular Tet10 (144 tets) clamped at x = 0, its end
// x = L loaded node by node with forces growing across the face (bending about y and z and a
// twist about x): not a state either code can hit by symmetry.
Mesh calculix_cantilever(double load_n) {
  const Eigen::Vector3d size(12, 3, 3);
  Mesh m = tet_mesh(size, {6, 2, 2}, std::make_shared<NeoHookean>(kE, kNu), 0.2, 17);
  for (int i = 0; i < m.n_nodes(); ++i) {
    const Eigen::Vector3d x = m.nodes.row(i).transpose();
    if (near(x.x(), 0)) m.fixed_nodes.push_back(i);
    if (near(x.x(), size.x())) {
      const double y = x.y() / size.y(), z = x.z() / size.z();
      m.loads.push_back({i, load_n * Eigen::Vector3d(0.1 * y, 0.3 * (z - 0.5), -(1 + y + 0.5 * y * z))});
    }
  }
  return m;
}

}  // namespace

TEST(Tet10Calculix, LinearC3D10SolvesTheSameProblem) {
  const Mesh m = calculix_cantilever(2e-5);
  const std::string deck = inp_text(m);
  EXPECT_NE(deck.find("*ELEMENT, TYPE=C3D10, ELSET=LAYER0"), std::string::npos);
  ASSERT_TRUE(test::has_ccx()) << "ccx (Debian calculix-ccx) is not installed: scripts/setup.sh installs it; the CalculiX cross-checks need it";
  const Eigen::MatrixX3d u = test::ccx_displacements(m, "tet10_linear");
  ASSERT_TRUE(u.allFinite()) << "ccx did not print every node's displacement";
  const SolveResult r = solve(m);
  const double scale = r.displacement_mm.cwiseAbs().maxCoeff();
  const double diff = (u - r.displacement_mm).cwiseAbs().maxCoeff();
  std::cout << "ccx C3D10 linear vs caps Tet10: max |du| " << diff << " mm of " << scale << " mm\n";
  EXPECT_GT(scale, 0.05);
  EXPECT_LT(diff, 1e-5 * scale);  // the .dat file prints about 6 digits
  SolveOptions cholmod;
  cholmod.solver = SolverKind::Cholmod;
  EXPECT_LT((solve(m, cholmod).displacement_mm - r.displacement_mm).cwiseAbs().maxCoeff(), 1e-8 * scale)
      << "CHOLMOD and MUMPS differ";
}

TEST(Tet10Calculix, NlgeomNeoHookeanC3D10SolvesTheSameProblem) {
  const Mesh m = calculix_cantilever(2e-4);
  InpOptions io;
  io.finite_strain = true;
  io.increments = 10;
  const std::string deck = inp_text(m, io);
  EXPECT_NE(deck.find("*HYPERELASTIC, NEO HOOKE"), std::string::npos);
  ASSERT_TRUE(test::has_ccx()) << "ccx (Debian calculix-ccx) is not installed: scripts/setup.sh installs it; the CalculiX cross-checks need it";
  const Eigen::MatrixX3d u = test::ccx_displacements(m, "tet10_nlgeom", io);
  ASSERT_TRUE(u.allFinite()) << "ccx did not print every node's displacement";
  SolveOptions o;
  o.kinematics = Kinematics::Finite;
  o.newton.n_steps = 10;
  const SolveResult r = solve(m, o);
  const double scale = r.displacement_mm.cwiseAbs().maxCoeff();
  const double diff = (u - r.displacement_mm).cwiseAbs().maxCoeff();
  const double diff_linear = (u - solve(m).displacement_mm).cwiseAbs().maxCoeff();
  std::cout << "ccx C3D10 NLGEOM vs caps Tet10 finite: max |du| " << diff << " mm of " << scale
            << " mm; vs caps linear " << diff_linear << " mm\n";
  EXPECT_LT(diff, 1e-4 * scale);
  EXPECT_GT(diff_linear, 0.05 * scale);  // large enough to be nonlinear
}

TEST(Tet10Files, MeshAndResultDirectoriesRoundTrip) {
  Mesh m = tet_mesh({3, 2, 2}, {3, 2, 2}, std::make_shared<NeoHookean>(kE, kNu), 0.2, 9);
  for (int i = 0; i < m.n_nodes(); ++i)
    if (near(m.nodes(i, 2), 0)) m.fixed_nodes.push_back(i);
  for (int i = 0; i < m.n_nodes(); ++i)
    if (near(m.nodes(i, 2), 2)) m.loads.push_back({i, Eigen::Vector3d(1e-4, 0, 0)});
  const auto dir = std::filesystem::temp_directory_path() / "caps_test_tet10_files";
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  write_mesh_dir(m, dir);
  const Mesh back = read_mesh_dir(dir);
  ASSERT_EQ(back.n_elements(), m.n_elements());
  EXPECT_LT((back.nodes - m.nodes).cwiseAbs().maxCoeff(), 1e-14);
  for (std::size_t e = 0; e < m.n_elements(); ++e) {
    EXPECT_EQ(back.elements[e].type, ElementType::Tet10);
    EXPECT_EQ(back.elements[e].layer, m.elements[e].layer);
    for (int a = 0; a < 10; ++a) EXPECT_EQ(back.elements[e].nodes[a], m.elements[e].nodes[a]);
  }
  std::ifstream js(dir / "mesh.json");
  const std::string json((std::istreambuf_iterator<char>(js)), std::istreambuf_iterator<char>());
  EXPECT_NE(json.find("\"tet10\": " + std::to_string(m.n_elements())), std::string::npos) << json.substr(0, 400);
  EXPECT_NE(json.find("\"hex20\": 0"), std::string::npos);
  EXPECT_NE(json.find("\"wedge15\": 0"), std::string::npos);
  // result.vtu: VTK type 24 for every cell, connectivity in caps order (VTK's is the same).
  const SolveResult r = solve(back);
  write_result_dir(back, r, dir);
  std::ifstream vs(dir / "result.vtu");
  const std::string vtu((std::istreambuf_iterator<char>(vs)), std::istreambuf_iterator<char>());
  const auto types = vtu.find("Name=\"types\"");
  ASSERT_NE(types, std::string::npos);
  std::istringstream ts(vtu.substr(vtu.find('>', types) + 1));
  for (std::size_t e = 0; e < m.n_elements(); ++e) {
    int t = 0;
    ts >> t;
    EXPECT_EQ(t, 24) << "cell " << e;
  }
  const auto conn = vtu.find("Name=\"connectivity\"");
  std::istringstream cs(vtu.substr(vtu.find('>', conn) + 1));
  for (int a = 0; a < 10; ++a) {
    int id = -1;
    cs >> id;
    EXPECT_EQ(id, m.elements[0].nodes[a]);
  }
  EXPECT_LT((read_result_displacement(dir, m.n_nodes()) - r.displacement_mm).cwiseAbs().maxCoeff(),
            1e-12 * r.displacement_mm.cwiseAbs().maxCoeff());
  // The deck: one C3D10 line per element, its nodes + 1 in caps order.
  const std::string deck = inp_text(m);
  std::istringstream ds(deck.substr(deck.find("*ELEMENT, TYPE=C3D10")));
  std::string line;
  std::getline(ds, line);
  for (std::size_t e = 0; e < m.n_elements(); ++e) {
    ASSERT_TRUE(std::getline(ds, line));
    std::istringstream ls(line);
    std::vector<int> ids;
    std::string field;
    while (std::getline(ls, field, ',')) ids.push_back(std::stoi(field));
    ASSERT_EQ(ids.size(), 11u) << line;
    EXPECT_EQ(ids[0], static_cast<int>(e) + 1);
    for (int a = 0; a < 10; ++a) EXPECT_EQ(ids[1 + a], m.elements[e].nodes[a] + 1);
  }
  std::filesystem::remove_all(dir);
}
