// caps::fem ties on non-matching interfaces and sliding on an implicit (level-set) surface:
// patch tests across a tied interface of Hex20 blocks of different divisions (small and finite
// strain), CalculiX's exact *EQUATIONs on the same deck, the tie search (inside, nearest within
// a tolerance, refused beyond it), sliding on a cylinder of a forehead's curvature, validation
// and mesh.json.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <filesystem>
#include <iostream>
#include <memory>
#include <random>
#include <string>

#include "caps/core/error.hpp"
#include "caps/fem/box.hpp"
#include "caps/fem/elements.hpp"
#include "caps/fem/inp_io.hpp"
#include "caps/fem/mesh_io.hpp"
#include "caps/fem/solve.hpp"
#include "caps/fem/tie.hpp"
#include "ccx_run.hpp"
#include "fem_test_support.hpp"

using namespace caps;
using namespace caps::fem;

namespace {

using namespace caps::fem::test;

Mesh box(const Eigen::Vector3d& size, const Eigen::Vector3i& cells) { return neo_hookean_box(size, cells); }

SolveOptions finite(int n_steps = 4) { return finite_strain(n_steps); }

// Two 4 x 4 x 2 mm blocks stacked in z: the bottom one (z 0..2) of 2 x 2 cells, the top one
// (z 2..4) of 3 x 3 cells on the shared face, so no node of the top block's bottom face but
// the four corners lies on a node of the bottom block. The top block's face nodes (the slaves)
// are tied to the bottom block's elements by tie_nodes().
struct TiedBlocks {
  Mesh mesh;
  int n_bottom_nodes = 0;
  std::vector<int> slaves;
};

TiedBlocks tied_blocks(TieMethod method = TieMethod::Mortar) {
  TiedBlocks t;
  Mesh bottom = box({4, 4, 2}, {2, 2, 1});
  const Mesh top = box({4, 4, 2}, {3, 3, 1});
  t.n_bottom_nodes = static_cast<int>(bottom.n_nodes());
  Mesh& m = t.mesh;
  m = bottom;
  m.nodes.conservativeResize(bottom.n_nodes() + top.n_nodes(), 3);
  for (Eigen::Index i = 0; i < top.n_nodes(); ++i)
    m.nodes.row(bottom.n_nodes() + i) = top.nodes.row(i) + Eigen::RowVector3d(0, 0, 2);
  for (Element el : top.elements) {
    for (int a = 0; a < el.n_nodes(); ++a) el.nodes[a] += t.n_bottom_nodes;
    m.elements.push_back(el);
  }
  std::vector<int> masters;
  for (std::size_t e = 0; e < bottom.elements.size(); ++e) masters.push_back(static_cast<int>(e));
  for (int i = t.n_bottom_nodes; i < m.n_nodes(); ++i)
    if (std::abs(m.nodes(i, 2) - 2) < 1e-12) t.slaves.push_back(i);
  const TieSearchResult found = tie_nodes(m, t.slaves, masters, 1e-6, method);
  EXPECT_TRUE(found.unmatched.empty());
  EXPECT_EQ(found.n_mortar, method == TieMethod::Mortar ? static_cast<int>(t.slaves.size()) : 0);
  EXPECT_EQ(found.ties.size(), t.slaves.size());
  m.ties = found.ties;
  return t;
}

// Uniaxial tension in z: the base z = 0 held in z (its centre pinned, one more node in y), the
// top z = 4 moved by `delta` in z.
void uniaxial_supports(Mesh& m, double delta) {
  for (int i = 0; i < m.n_nodes(); ++i) {
    const Eigen::Vector3d x = m.nodes.row(i).transpose();
    if (std::abs(x.z()) < 1e-12) {
      if ((x - Eigen::Vector3d(2, 2, 0)).norm() < 1e-12) {
        m.fixed_nodes.push_back(i);
        continue;
      }
      if ((x - Eigen::Vector3d(4, 2, 0)).norm() < 1e-12) m.fixed_dofs.push_back({i, 1, 0.0});
      m.fixed_dofs.push_back({i, 2, 0.0});
    }
    if (std::abs(x.z() - 4) < 1e-12) m.fixed_dofs.push_back({i, 2, delta});
  }
}

// The lateral stretch of the neo-Hookean solid in uniaxial stress at axial stretch lz (S_xx = 0,
// by bisection on the material's own stress), and its Cauchy stress sigma_zz (MPa).
std::pair<double, double> neo_hookean_uniaxial(double lz) {
  const NeoHookean mat(kE, kNu);
  auto stress = [&](double lt) {
    Eigen::Matrix3d H = Eigen::Vector3d(lt - 1, lt - 1, lz - 1).asDiagonal();
    Vector6d S;
    Matrix6d C;
    mat.stress_and_tangent(H, S, C);
    return S;
  };
  double lo = 0.5, hi = 1.0;  // S_xx > 0 at lt = 1 (stretched in z), < 0 at 0.5
  for (int it = 0; it < 200; ++it) {
    const double mid = 0.5 * (lo + hi);
    (stress(mid)[0] > 0 ? hi : lo) = mid;
  }
  const double lt = 0.5 * (lo + hi);
  const double J = lt * lt * lz;
  return {lt, lz * lz * stress(lt)[2] / J};
}

// A cylinder of radius R about the x axis: phi = sqrt(y^2 + z^2) - R (a signed distance).
class Cylinder final : public ImplicitSurface {
 public:
  explicit Cylinder(double R) : R_(R) {}
  double distance(const Eigen::Vector3d& x) const override { return std::hypot(x.y(), x.z()) - R_; }
  Eigen::Vector3d gradient(const Eigen::Vector3d& x) const override {
    return Eigen::Vector3d(0, x.y(), x.z()) / std::hypot(x.y(), x.z());
  }

 private:
  double R_;
};

}  // namespace

TEST(Tie, TheSearchInvertsACurvedElementAndProjectsOntoTheNearestWithinTheTolerance) {
  // One Hex20 with its mid-side nodes moved up to 0.15 mm (curved faces) and one Wedge15: points
  // inside are found by inverting the map (the weights reproduce the point to round-off), a
  // point 0.05 mm above the hexahedron's top face is projected onto it within a 0.1 mm
  // tolerance and refused at 0.01 mm, with its distance.
  Mesh m = box({2, 2, 2}, {1, 1, 1});
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> jitter(-0.15, 0.15);
  const Element hex = m.elements[0];
  for (int a = 8; a < 20; ++a)
    if (std::abs(m.nodes(hex.nodes[a], 2) - 2) > 1e-12)  // keep the face z = 2 flat
      for (int c = 0; c < 3; ++c) m.nodes(hex.nodes[a], c) += jitter(rng);
  // A Wedge15 beside it (x 3..5), nodes appended.
  const Mesh wedge_box = [] {
    BoxOptions o;
    o.size_mm = {2, 2, 2};
    o.cells = {1, 1, 1};
    o.wedges = true;
    o.fix_bottom = false;
    return make_box_mesh(o);
  }();
  const int offset = static_cast<int>(m.n_nodes());
  m.nodes.conservativeResize(offset + wedge_box.n_nodes(), 3);
  for (Eigen::Index i = 0; i < wedge_box.n_nodes(); ++i)
    m.nodes.row(offset + i) = wedge_box.nodes.row(i) + Eigen::RowVector3d(3, 0, 0);
  Element w = wedge_box.elements[0];
  for (int a = 0; a < w.n_nodes(); ++a) w.nodes[a] += offset;
  m.elements.push_back(w);

  const std::vector<Eigen::Vector3d> inside{{0.7, 1.1, 0.9}, {1.6, 0.5, 1.3}, {3.8, 0.3, 1.5}};
  const Eigen::Vector3d above(1.2, 0.8, 2.05);
  std::vector<int> slaves;
  for (const auto& p : inside) {
    m.nodes.conservativeResize(m.n_nodes() + 1, 3);
    m.nodes.row(m.n_nodes() - 1) = p.transpose();
    slaves.push_back(static_cast<int>(m.n_nodes() - 1));
  }
  m.nodes.conservativeResize(m.n_nodes() + 1, 3);
  m.nodes.row(m.n_nodes() - 1) = above.transpose();
  slaves.push_back(static_cast<int>(m.n_nodes() - 1));

  const TieSearchResult r = tie_nodes(m, slaves, {0, 1}, 0.1);
  ASSERT_TRUE(r.unmatched.empty());
  ASSERT_EQ(r.ties.size(), 4u);
  EXPECT_EQ(r.master_element[0], 0);
  EXPECT_EQ(r.master_element[2], 1);  // the wedge
  for (std::size_t i = 0; i < r.ties.size(); ++i) {
    Eigen::Vector3d x = Eigen::Vector3d::Zero();
    double sum = 0;
    for (std::size_t k = 0; k < r.ties[i].masters.size(); ++k) {
      x += r.ties[i].weights[k] * m.nodes.row(r.ties[i].masters[k]).transpose();
      sum += r.ties[i].weights[k];
    }
    EXPECT_NEAR(sum, 1, 1e-12);
    const Eigen::Vector3d p = m.nodes.row(r.ties[i].node).transpose();
    if (i < 3) {
      EXPECT_LT((x - p).norm(), 1e-10) << "slave " << i;
      EXPECT_LT(r.distance_mm[i], 1e-10);
    } else {
      EXPECT_LT((x - (p - Eigen::Vector3d(0, 0, 0.05))).norm(), 1e-10);  // its foot on the face
      EXPECT_NEAR(r.distance_mm[i], 0.05, 1e-10);
      EXPECT_NEAR(r.natural[i].z(), 1.0, 1e-12);  // on face zeta = +1 (z = 2)
      EXPECT_EQ(r.ties[i].masters.size(), 8u);    // that face's nodes only
    }
  }
  const TieSearchResult tight = tie_nodes(m, slaves, {0, 1}, 0.01);
  ASSERT_EQ(tight.unmatched.size(), 1u);
  EXPECT_EQ(tight.unmatched[0], slaves[3]);
  EXPECT_NEAR(tight.unmatched_distance_mm[0], 0.05, 1e-10);
  EXPECT_EQ(tight.ties.size(), 3u);
  // A point beside the hexahedron's edge (x = -0.3, z = 2.4): its nearest point is on the edge.
  m.nodes.conservativeResize(m.n_nodes() + 1, 3);
  m.nodes.row(m.n_nodes() - 1) = Eigen::RowVector3d(-0.3, 1.0, 2.4);
  const TieSearchResult edge = tie_nodes(m, {static_cast<int>(m.n_nodes() - 1)}, {0, 1}, 1.0);
  ASSERT_EQ(edge.ties.size(), 1u);
  EXPECT_NEAR(edge.distance_mm[0], 0.5, 1e-9);
  EXPECT_THROW(tie_nodes(m, {slaves[0], slaves[0]}, {0}, 0.1), InvalidInput);
  EXPECT_THROW(tie_nodes(m, {slaves[0]}, {5}, 0.1), InvalidInput);
  EXPECT_THROW(tie_nodes(m, {slaves[0]}, {0}, -1), InvalidInput);
}

TEST(Tie, AStraightTet10IsSearchedInClosedFormAsTheIterationWouldFindIt) {
  // A straight-sided Tet10 (mid-edge nodes at the midpoints: the tissue model's) is searched in
  // closed form; a copy with one mid-edge node moved 1e-7 mm takes the iterative search. For
  // points inside and beyond every face, edge and vertex both find the same nearest point.
  Mesh m;
  const Eigen::Matrix<double, 4, 3> corners{{0.2, 0.1, 0}, {3, 0.4, 0.3}, {0.5, 2.6, -0.2}, {0.9, 0.8, 2.4}};
  constexpr int kEdges[6][2] = {{0, 1}, {1, 2}, {2, 0}, {0, 3}, {1, 3}, {2, 3}};
  m.nodes.resize(20, 3);
  for (int copy = 0; copy < 2; ++copy) {
    Element el;
    el.type = ElementType::Tet10;
    for (int a = 0; a < 10; ++a) el.nodes[a] = 10 * copy + a;
    for (int a = 0; a < 4; ++a) m.nodes.row(10 * copy + a) = corners.row(a);
    for (int k = 0; k < 6; ++k)
      m.nodes.row(10 * copy + 4 + k) = 0.5 * (corners.row(kEdges[k][0]) + corners.row(kEdges[k][1]));
    m.elements.push_back(el);
  }
  m.nodes(14, 2) += 1e-7;  // the copy is curved, just
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-1.5, 4.0);
  std::vector<int> slaves;
  for (int i = 0; i < 400; ++i) {
    m.nodes.conservativeResize(m.n_nodes() + 1, 3);
    m.nodes.row(m.n_nodes() - 1) = Eigen::RowVector3d(u(rng), u(rng), u(rng));
    slaves.push_back(static_cast<int>(m.n_nodes() - 1));
  }
  const TieSearchResult closed = tie_nodes(m, slaves, {0}, 10, TieMethod::NodeToSurface);
  const TieSearchResult iterated = tie_nodes(m, slaves, {1}, 10, TieMethod::NodeToSurface);
  ASSERT_EQ(closed.ties.size(), slaves.size());
  ASSERT_EQ(iterated.ties.size(), slaves.size());
  int inside = 0;
  for (std::size_t i = 0; i < slaves.size(); ++i) {
    EXPECT_NEAR(closed.distance_mm[i], iterated.distance_mm[i], 1e-6) << "point " << i;
    EXPECT_LT((closed.natural[i] - iterated.natural[i]).norm(), 1e-5) << "point " << i;
    inside += closed.distance_mm[i] < 1e-12;
  }
  EXPECT_GT(inside, 5);  // some points fall inside, the rest beyond faces, edges and vertices
}

TEST(Tie, UniaxialTensionAcrossANonMatchingInterfaceIsUniform) {
  // Patch test: 2 x 2 cells tied to 3 x 3 on the shared face, pulled 0.2 mm (5 %) in z across
  // it. Quadratic elements hold the uniform state exactly and the mortar rows pass it across
  // the interface, so the answer is the analytic one to the penalty's give: small strain u =
  // eps (-nu (x - 2), -nu (y - 2), z), sigma_zz = E eps everywhere; finite strain (neo-Hookean)
  // the homogeneous stretch. Node-to-surface ties (CalculiX's *TIE) do not pass it: the top
  // block's consistent nodal forces, sent to the masters at the slaves' positions, are not the
  // bottom block's, and the stress near the interface is off by a quarter.
  const double delta = 0.2, L = 4;
  for (const bool finite_strain : {false, true}) {
    SCOPED_TRACE(finite_strain ? "finite strain" : "small strain");
    double lt = 1 - kNu * delta / L, sigma = kE * delta / L;
    if (finite_strain) std::tie(lt, sigma) = neo_hookean_uniaxial(1 + delta / L);
    for (const TieMethod method : {TieMethod::Mortar, TieMethod::NodeToSurface}) {
      const bool mortar = method == TieMethod::Mortar;
      TiedBlocks t = tied_blocks(method);
      uniaxial_supports(t.mesh, delta);
      const SolveResult r = solve(t.mesh, finite_strain ? finite() : SolveOptions{});
      double max_err = 0;
      for (int i = 0; i < t.mesh.n_nodes(); ++i) {
        const Eigen::Vector3d x = t.mesh.nodes.row(i).transpose();
        const Eigen::Vector3d u((lt - 1) * (x.x() - 2), (lt - 1) * (x.y() - 2), delta / L * x.z());
        max_err = std::max(max_err, (r.displacement_mm.row(i).transpose() - u).norm());
      }
      double stress_err = 0;
      for (Eigen::Index g = 0; g < r.gauss_stress_mpa.rows(); ++g) {
        Vector6d expected = Vector6d::Zero();
        expected[2] = sigma;
        stress_err = std::max(stress_err, (r.gauss_stress_mpa.row(g).transpose() - expected).norm());
      }
      std::cout << (finite_strain ? "finite" : "small") << " strain, "
                << (mortar ? "mortar" : "node-to-surface") << ": max |u - exact| " << max_err
                << " mm of " << delta << ", stress " << stress_err << " MPa of " << sigma
                << ", tie force " << r.tie_force_n.transpose() << " N, largest gap "
                << r.tie_gap_max_mm << " mm, precision " << r.precision
                << (r.fell_back_to_double ? " (fell back)" : "") << "\n";
      // Factored in double precision from the start, not after a failed single-precision try.
      EXPECT_EQ(r.precision, "double");
      EXPECT_FALSE(r.fell_back_to_double);
      if (!mortar) {
        EXPECT_GT(stress_err, 0.1 * sigma);
        continue;
      }
      EXPECT_LT(max_err, 1e-6 * delta);
      EXPECT_LT(stress_err, 1e-5 * sigma);
      // The tie carries the whole load: the force on the top block's face is -sigma a (a: the
      // deformed area).
      const double force = sigma * 16 * (finite_strain ? lt * lt : 1.0);
      EXPECT_NEAR(r.tie_force_n.z(), -force, 1e-5 * force);
      EXPECT_NEAR(r.tie_force_n.head<2>().norm(), 0, 1e-7 * force);
      EXPECT_LT(r.tie_gap_max_mm, 1e-6 * delta);  // the penalty gives way by < 1e-6
    }
  }
}

TEST(Tie, TheRowsHoldEveryLinearField) {
  // Kinematics of the rows: for u = A x (stretch, shear, rotation) every tie's gap u_s - sum w
  // u_m is zero (both faces reproduce linear fields and the weights sum to 1), mortar and
  // node-to-surface.
  Eigen::Matrix3d A;
  A << 0.02, 0.015, -0.01, 0.005, -0.01, 0.02, 0.01, -0.015, 0.03;
  for (const TieMethod method : {TieMethod::Mortar, TieMethod::NodeToSurface}) {
    const TiedBlocks t = tied_blocks(method);
    double worst = 0;
    for (const TiedNode& tie : t.mesh.ties) {
      Eigen::Vector3d gap = A * t.mesh.nodes.row(tie.node).transpose();
      for (std::size_t k = 0; k < tie.masters.size(); ++k)
        gap -= tie.weights[k] * A * t.mesh.nodes.row(tie.masters[k]).transpose();
      worst = std::max(worst, gap.norm());
    }
    EXPECT_LT(worst, 1e-13);
  }
}

TEST(Tie, CalculixWithExactEquationsAgreesOnATiedBlockBentSideways) {
  // The tied blocks clamped at the base, their top moved 0.3 mm sideways and 0.1 mm up: shear
  // and bending, not a state the elements hold exactly, so the tie's give shows. CalculiX
  // (Debian calculix-ccx) solves the same deck with the ties as exact *EQUATIONs, linear and
  // NLGEOM.
  ASSERT_TRUE(test::has_ccx()) << "ccx (Debian calculix-ccx) is not installed: scripts/setup.sh installs it; the CalculiX cross-checks need it";
  TiedBlocks t = tied_blocks();
  for (int i = 0; i < t.mesh.n_nodes(); ++i) {
    if (std::abs(t.mesh.nodes(i, 2)) < 1e-12) t.mesh.fixed_nodes.push_back(i);
    if (std::abs(t.mesh.nodes(i, 2) - 4) < 1e-12) {
      t.mesh.fixed_dofs.push_back({i, 0, 0.3});
      t.mesh.fixed_dofs.push_back({i, 1, 0.0});
      t.mesh.fixed_dofs.push_back({i, 2, 0.1});
    }
  }
  const std::string deck = inp_text(t.mesh);
  EXPECT_NE(deck.find("** ties (" + std::to_string(t.slaves.size()) + " slave nodes)"), std::string::npos);
  for (const bool finite_strain : {false, true}) {
    SCOPED_TRACE(finite_strain ? "NLGEOM" : "linear");
    InpOptions io;
    io.finite_strain = finite_strain;
    const SolveResult r = solve(t.mesh, finite_strain ? finite() : SolveOptions{});
    const Eigen::MatrixX3d u = test::ccx_displacements(t.mesh, finite_strain ? "tie_nlgeom" : "tie_linear", io);
    ASSERT_TRUE(u.allFinite()) << "ccx did not print every node's displacement";
    const double scale = r.displacement_mm.rowwise().norm().maxCoeff();
    const double diff = (u - r.displacement_mm).rowwise().norm().maxCoeff();
    std::cout << (finite_strain ? "NLGEOM" : "linear") << ": ccx vs caps max |du| " << diff
              << " mm of " << scale << " mm; the tie's largest gap " << r.tie_gap_max_mm
              << " mm; tie force " << r.tie_force_n.transpose() << " N\n";
    EXPECT_LT(diff, 1e-4 * scale);
    EXPECT_LT(r.tie_gap_max_mm, 1e-6 * scale);  // the penalty gives way by < 1e-6
    EXPECT_GT(r.tie_gap_max_mm, 0.0);
    // SolverKind::Auto: CHOLMOD factors a tied mesh's Newton tangents, MUMPS its linear solve;
    // either solver, asked for, gives the same answer to the round-off the ties' penalties
    // leave (measured 1.8e-8 of the largest displacement, linear).
    EXPECT_EQ(r.solver, finite_strain ? "cholmod" : "mumps");
    SolveOptions other = finite_strain ? finite() : SolveOptions{};
    other.solver = finite_strain ? SolverKind::Mumps : SolverKind::Cholmod;
    const SolveResult o = solve(t.mesh, other);
    EXPECT_EQ(o.solver, finite_strain ? "mumps" : "cholmod");
    EXPECT_LT((o.displacement_mm - r.displacement_mm).cwiseAbs().maxCoeff(), 1e-7 * scale);
  }
}

TEST(Tie, TiedPartsAreOnePartForTheSupportCheck) {
  // The top block has no support of its own: held through the tie it solves; without the tie
  // it is refused as a part that can move freely.
  TiedBlocks t = tied_blocks();
  for (int i = 0; i < t.n_bottom_nodes; ++i)
    if (std::abs(t.mesh.nodes(i, 2)) < 1e-12) t.mesh.fixed_nodes.push_back(i);
  t.mesh.loads.push_back({t.n_bottom_nodes + 1, Eigen::Vector3d(0, 0, 0.01)});
  EXPECT_NO_THROW(solve(t.mesh));
  Mesh untied = t.mesh;
  untied.ties.clear();
  EXPECT_THROW(solve(untied), InvalidInput);
}

TEST(Tie, BadTiesAreRefusedAndTiesSurviveMeshJson) {
  TiedBlocks t = tied_blocks();
  for (int i = 0; i < t.n_bottom_nodes; ++i)
    if (std::abs(t.mesh.nodes(i, 2)) < 1e-12) t.mesh.fixed_nodes.push_back(i);
  const auto refused = [&](auto&& change, const std::string& words) {
    Mesh m = t.mesh;
    change(m);
    try {
      solve(m);
      ADD_FAILURE() << "accepted; expected: " << words;
    } catch (const InvalidInput& e) {
      EXPECT_NE(std::string(e.what()).find(words), std::string::npos) << e.what();
    }
  };
  refused([](Mesh& m) { m.ties[0].weights[0] += 1e-3; }, "summing to");
  refused([](Mesh& m) { m.ties[0].weights[0] = NAN; }, "non-finite weight");
  refused([](Mesh& m) { m.ties[0].masters[0] = 100000; }, "refers to node 100000");
  refused([](Mesh& m) { m.ties[0].weights.pop_back(); }, "one weight per master");
  refused([](Mesh& m) { m.ties[1].node = m.ties[0].node; }, "already ties");
  refused([](Mesh& m) { m.ties[0].masters[0] = m.ties[0].node; }, "tied to itself");
  refused([](Mesh& m) { m.fixed_dofs.push_back({m.ties[0].node, 2, 0.0}); }, "is also prescribed");
  refused([](Mesh& m) { m.sliding.push_back({m.ties[0].node, Eigen::Vector3d::UnitZ(), 1e3}); },
          "also slides");

  const auto dir = std::filesystem::temp_directory_path() / "caps_test_tie_mesh";
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  write_mesh_dir(t.mesh, dir);
  const Mesh back = read_mesh_dir(dir);
  ASSERT_EQ(back.ties.size(), t.mesh.ties.size());
  for (std::size_t i = 0; i < back.ties.size(); ++i) {
    EXPECT_EQ(back.ties[i].node, t.mesh.ties[i].node);
    EXPECT_EQ(back.ties[i].masters, t.mesh.ties[i].masters);
    ASSERT_EQ(back.ties[i].weights.size(), t.mesh.ties[i].weights.size());
    for (std::size_t k = 0; k < back.ties[i].weights.size(); ++k)
      EXPECT_EQ(back.ties[i].weights[k], t.mesh.ties[i].weights[k]);  // written with 17 digits
  }
  std::filesystem::remove_all(dir);
}

namespace {

// A strip of tissue 4 mm wide (x), 20 mm long and 3 mm thick lying on a cylinder of radius R
// about the x axis (the curvature of a forehead): the box [0,4] x [0,20] x [0,3] bent so that
// s = y runs along the arc from the top of the cylinder (y = 0, z = R) and t = z outwards. Its
// bottom nodes slide on the cylinder; its far end (s = 20) is held, the near end (s = 0) moved
// `d` along -y (the tangent there).
struct Strip {
  Mesh mesh;
  std::vector<int> bottom_near_end;  // bottom nodes at s = 0
};

Strip sliding_strip(double R, double d, bool on_surface) {
  Strip s;
  Mesh& m = s.mesh;
  m = box({4, 20, 3}, {2, 10, 2});
  const auto cylinder = std::make_shared<Cylinder>(R);
  for (Eigen::Index i = 0; i < m.n_nodes(); ++i) {
    const double x = m.nodes(i, 0), arc = m.nodes(i, 1), t = m.nodes(i, 2);
    m.nodes.row(i) << x, (R + t) * std::sin(arc / R), (R + t) * std::cos(arc / R);
  }
  m.sliding_surface = cylinder;
  m.sliding_surface_name = "cylinder";
  for (int i = 0; i < m.n_nodes(); ++i) {
    const Eigen::Vector3d X = m.nodes.row(i).transpose();
    const double arc = R * std::atan2(X.y(), X.z());
    if (std::abs(arc - 20) < 1e-9) {
      m.fixed_nodes.push_back(i);
      continue;
    }
    if (std::abs(arc) < 1e-9) m.fixed_dofs.push_back({i, 1, -d});
    if (std::abs(cylinder->distance(X)) < 1e-9) {
      m.sliding.push_back({i, cylinder->gradient(X).normalized(), 1e5 * kE * 3, on_surface});
      if (std::abs(arc) < 1e-9) s.bottom_near_end.push_back(i);
    }
  }
  return s;
}

}  // namespace

TEST(SlidingSurface, AStripPulledOverACylinderStaysOnItUnderFiniteStrain) {
  // R = 30 mm, the near end pulled d = 3 mm: on the level set every sliding node ends on the
  // cylinder (|phi| < 1e-3 mm) and the near end's bottom nodes at z = sqrt(R^2 - d^2); held
  // along their start normals (today's sliding) they stay on the tangent plane z = R, off the
  // cylinder by sqrt(R^2 + d^2) - R = 0.150 mm, R - sqrt(R^2 - d^2) = 0.150 mm above where the
  // surface puts them.
  const double R = 30, d = 3;
  const Strip curved = sliding_strip(R, d, true), plane = sliding_strip(R, d, false);
  const SolveResult rc = solve(curved.mesh, finite(4)), rp = solve(plane.mesh, finite(4));
  const Cylinder cyl(R);
  double worst_curved = 0, worst_plane = 0;
  for (const SlidingNode& s : curved.mesh.sliding) {
    const Eigen::Vector3d X = curved.mesh.nodes.row(s.node).transpose();
    worst_curved = std::max(worst_curved, std::abs(cyl.distance(X + rc.displacement_mm.row(s.node).transpose())));
    worst_plane = std::max(worst_plane, std::abs(cyl.distance(X + rp.displacement_mm.row(s.node).transpose())));
  }
  EXPECT_LT(worst_curved, 1e-3);
  ASSERT_EQ(curved.bottom_near_end.size(), 5u);
  for (int i : curved.bottom_near_end) {
    const Eigen::Vector3d xc = curved.mesh.nodes.row(i) + rc.displacement_mm.row(i);
    const Eigen::Vector3d xp = plane.mesh.nodes.row(i) + rp.displacement_mm.row(i);
    EXPECT_NEAR(xc.y(), -d, 1e-12);
    EXPECT_NEAR(xc.z(), std::sqrt(R * R - d * d), 1e-3);
    EXPECT_NEAR(xp.z(), R, 1e-5);
    EXPECT_NEAR(cyl.distance(xp), std::sqrt(R * R + d * d) - R, 1e-5);
    EXPECT_NEAR(xp.z() - xc.z(), R - std::sqrt(R * R - d * d), 1e-3);
  }
  // Put back on the surface after each correction, Newton converges about as fast as along
  // the fixed normals (12 solves against 8; 39 without the projection).
  EXPECT_LE(rc.newton_iterations, 2 * rp.newton_iterations);
  std::cout << "strip on a cylinder of " << R << " mm pulled " << d << " mm: |phi| at most "
            << worst_curved << " mm on the surface, " << worst_plane
            << " mm along the start normals; Newton iterations " << rc.newton_iterations << " / "
            << rp.newton_iterations << "\n";
}

TEST(SlidingSurface, TheSmallStrainSolveAndTheDeckHoldTheStartNormal) {
  // Small strain: sliding on the surface is its linearisation, today's sliding along the start
  // normal, to round-off. mesh.json keeps the start normals and the surface's name without the
  // surface: the mesh read back slides along the start normals (and says so), so its
  // finite-strain answer is the fixed-normal one. The deck says what it writes.
  const double R = 30, d = 1;
  const Strip curved = sliding_strip(R, d, true), plane = sliding_strip(R, d, false);
  const SolveResult lc = solve(curved.mesh), lp = solve(plane.mesh);
  EXPECT_LT((lc.displacement_mm - lp.displacement_mm).cwiseAbs().maxCoeff(),
            1e-10 * lp.displacement_mm.cwiseAbs().maxCoeff());
  const std::string deck = inp_text(curved.mesh);
  EXPECT_NE(deck.find("nodes slide on the 'cylinder' surface: written as its linearisation"), std::string::npos);
  EXPECT_EQ(inp_text(plane.mesh).find("linearisation"), std::string::npos);

  const auto dir = std::filesystem::temp_directory_path() / "caps_test_sliding_surface_mesh";
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  write_mesh_dir(curved.mesh, dir);
  const Mesh back = read_mesh_dir(dir);
  std::filesystem::remove_all(dir);
  ASSERT_EQ(back.sliding.size(), curved.mesh.sliding.size());
  EXPECT_EQ(back.sliding_surface_name, "cylinder");
  EXPECT_FALSE(back.sliding_surface);
  ASSERT_EQ(back.warnings.size(), 1u);
  EXPECT_NE(back.warnings[0].find("slide along their start normals"), std::string::npos);
  for (std::size_t i = 0; i < back.sliding.size(); ++i) {
    EXPECT_TRUE(back.sliding[i].on_surface);
    EXPECT_LT((back.sliding[i].normal - curved.mesh.sliding[i].normal).norm(), 1e-14);
  }
  const SolveResult fb = solve(back, finite(2)), fp = solve(plane.mesh, finite(2));
  EXPECT_LT((fb.displacement_mm - fp.displacement_mm).cwiseAbs().maxCoeff(), 1e-9);
}

TEST(SlidingSupport, TheReactionOfASlidingNodeIsItsSpringsForce) {
  // A 4 x 4 x 2 mm block whose base slides on z = 0 (the centre pinned), pressed down 0.05 mm
  // at the top: the base's sliding nodes carry the load, sum R_z = E A delta / h, and each one's
  // reaction is its spring's force along the normal (until 5 December a sliding node that was
  // not also fixed reported no reaction).
  Mesh m = box({4, 4, 2}, {2, 2, 1});
  const double delta = 0.05, h = 2, k = 1e5 * kE * h;
  for (int i = 0; i < m.n_nodes(); ++i) {
    const Eigen::Vector3d x = m.nodes.row(i).transpose();
    if (std::abs(x.z()) < 1e-12) {
      if ((x - Eigen::Vector3d(2, 2, 0)).norm() < 1e-12) {
        m.fixed_nodes.push_back(i);
        continue;
      }
      if ((x - Eigen::Vector3d(4, 2, 0)).norm() < 1e-12) m.fixed_dofs.push_back({i, 1, 0.0});
      m.sliding.push_back({i, Eigen::Vector3d::UnitZ(), k});
    }
    if (std::abs(x.z() - h) < 1e-12) m.fixed_dofs.push_back({i, 2, -delta});
  }
  const SolveResult r = solve(m);
  double base = 0;
  for (const SlidingNode& s : m.sliding) {
    base += r.reaction_n(s.node, 2);
    EXPECT_NEAR(r.reaction_n(s.node, 2), -k * r.displacement_mm(s.node, 2), 1e-6 * kE * 16 * delta / h);
  }
  for (int node : m.fixed_nodes) base += r.reaction_n(node, 2);
  EXPECT_NEAR(base, kE * 16 * delta / h, 1e-4 * kE * 16 * delta / h);
}
