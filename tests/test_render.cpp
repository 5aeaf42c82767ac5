// caps::render: the displacement-mapped skin (paper section 4) on synthetic cylinders: it lies on
// the range surface where nothing moves, moves exactly with a manufactured displacement, is a
// closed consistently oriented surface (no cracks at the seam), and its images are deterministic
// (zero displacement: pre and post pixel-identical) with the expected silhouette.
#include <gtest/gtest.h>

#include "synthetic_model.hpp"

#include <cmath>
#include <array>
#include <map>
#include <set>

#include "caps/core/units.hpp"
#include "caps/mesher/continuum_mesher.hpp"
#include "caps/closure/simulate.hpp"
#include "caps/plan/procedures.hpp"
#include "caps/render/render.hpp"
#include "caps/render/simulation_report.hpp"
#include "caps/render/skin_surface.hpp"
#include "caps/surface/patient_model.hpp"

using namespace caps;
using namespace caps::render;

namespace {

constexpr double kR = 70.0;

// A cylinder about the LPS z axis, z in [-100, 100], skin radius r(theta, z), 5 mm of tissue.
template <typename Radius>
PatientModel cylinder(Radius&& r) {
  return PatientModel(caps_test::synthetic_maps(caps_test::grid(360, 201, -100, 1), r,
                                                [](double, double) { return 5.0; }));
}

// A bumpy cylinder, so that the element faces and the range surface differ (d != 0).
const PatientModel& bumpy() {
  static const PatientModel m = cylinder([](double theta, double z) {
    return kR + 2.0 * std::sin(deg_to_rad(3 * theta)) * std::cos(z / 15.0);
  });
  return m;
}

const PatientModel& round_cylinder() {
  static const PatientModel m = cylinder([](double, double) { return kR; });
  return m;
}

// A 20 x `width_mm` ellipse at theta `theta_deg`, z `z_mm`, its long axis along z.
plan::Plan ellipse_plan(const PatientModel& model, double width_mm = 6.0, double theta_deg = 10.0,
                        double z_mm = 5.0) {
  return plan::place_procedure(
      plan::layout_procedure("ellipse", {{"length", 20.0}, {"width", width_mm}}), model, theta_deg,
      z_mm, 90.0);
}

closure::Simulation ellipse_on(const PatientModel& model) {
  closure::SimulateOptions o;
  o.surface.size_mm = 3.0;
  return closure::simulate(model, ellipse_plan(model), o);
}

// The directed edges of the surface without exactly one opposite edge: 0 for a closed, manifold,
// consistently oriented surface.
int open_or_misoriented_edges(const SkinSurfaces& s) {
  std::map<std::pair<int, int>, int> directed;
  for (Eigen::Index f = 0; f < s.pre.F.rows(); ++f)
    for (int k = 0; k < 3; ++k) ++directed[{s.pre.F(f, k), s.pre.F(f, (k + 1) % 3)}];
  int bad = 0;
  for (const auto& [e, count] : directed)
    if (count != 1 || !directed.count({e.second, e.first})) ++bad;
  return bad;
}

const closure::Simulation& bumpy_sim() {
  static const closure::Simulation s = ellipse_on(bumpy());
  return s;
}

double off_skin_mm(const PatientModel& m, const Eigen::Vector3d& p) {
  const CylindricalPoint c = m.to_cylindrical(p);
  return std::abs(c.r_mm - m.r_skin(c.theta_deg, c.z_mm));
}

}  // namespace

TEST(SkinSurface, ZeroDisplacementLiesOnTheRangeSurface) {
  const closure::Simulation& sim = bumpy_sim();
  const SkinSurfaces s = displaced_skin(bumpy(), sim.wound.continuum.mesh,
                                        static_cast<const fem::SolveResult*>(nullptr), 4);
  ASSERT_GT(s.n_micropolygon_vertices, 100);
  EXPECT_EQ(s.pre.V, s.post.V);
  EXPECT_EQ(s.pre.F, s.post.F);
  double worst = 0, max_offset = 0;
  for (int v = 0; v < s.n_micropolygon_vertices; ++v) {
    worst = std::max(worst, off_skin_mm(bumpy(), s.pre.V.row(v)));
    max_offset = std::max(max_offset, s.range_offset_mm.row(v).norm());
  }
  EXPECT_LT(worst, 1e-6);
  EXPECT_GT(max_offset, 1e-3) << "the faces should differ from the bumpy skin";
  // the top layer of elements, and only it, is on the skin
  int top = 0;
  for (Eigen::Index e = 0; e < static_cast<Eigen::Index>(sim.wound.continuum.mesh.n_elements()); ++e) {
    const int n0 = sim.wound.continuum.mesh.elements[e].nodes[0];
    if (sim.wound.continuum.node_level[n0] == 0) ++top;
  }
  EXPECT_EQ(static_cast<int>(s.skin_elements.size()), top);
}

TEST(SkinSurface, ConstantTranslationMovesMicropolygonsExactly) {
  const fem::Mesh& mesh = bumpy_sim().wound.continuum.mesh;
  const Eigen::RowVector3d t(0.7, -1.3, 2.1);
  const Eigen::MatrixX3d u = t.replicate(mesh.n_nodes(), 1);
  const SkinSurfaces s = displaced_skin(bumpy(), mesh, &u, 3);
  for (Eigen::Index v = 0; v < s.pre.V.rows(); ++v) {
    const Eigen::RowVector3d expect = v < s.n_micropolygon_vertices ? t : Eigen::RowVector3d::Zero();
    ASSERT_LT((s.post.V.row(v) - s.pre.V.row(v) - expect).norm(), 1e-9) << "vertex " << v;
  }
}

TEST(SkinSurface, ClosedOrientedSurfaceWithoutCracks) {
  const closure::Simulation& sim = bumpy_sim();
  const SkinSurfaces s = displaced_skin(bumpy(), sim.wound.continuum.mesh, &sim.result, 5);
  // every directed edge has exactly one opposite: closed, manifold, consistently oriented
  const int bad = open_or_misoriented_edges(s);
  EXPECT_EQ(bad, 0);
  // micropolygons face outwards
  int inward = 0, n_micro = 0;
  for (Eigen::Index f = 0; f < s.pre.F.rows(); ++f) {
    if (s.face_part[f] != SkinPart::Micropolygon) continue;
    ++n_micro;
    const Eigen::Vector3d a = s.pre.V.row(s.pre.F(f, 0)), b = s.pre.V.row(s.pre.F(f, 1)),
                          c = s.pre.V.row(s.pre.F(f, 2));
    Eigen::Vector3d radial = (a + b + c) / 3;
    radial.z() = 0;
    if ((b - a).cross(c - a).dot(radial) <= 0) ++inward;
  }
  EXPECT_GT(n_micro, 0);
  EXPECT_EQ(inward, 0);
}

// The patch alone (SkinExtent::Patch, what the planner page draws over the model's range mesh)
// is the whole head's skin without its range cells: the same micropolygons, wound fill and seam
// triangles at the same positions before and after, and the range cells it leaves out
// (replaced_cells) are exactly those the whole head's range mesh does not draw, so the page's
// range mesh without them and the patch together are the whole head's skin.
TEST(SkinSurface, ThePatchIsTheWholeHeadWithoutItsRangeCells) {
  const closure::Simulation& sim = bumpy_sim();
  const fem::Mesh& mesh = sim.wound.continuum.mesh;
  const SkinSurfaces whole = displaced_skin(bumpy(), mesh, &sim.result, 3);
  const SkinSurfaces patch =
      displaced_skin(bumpy(), mesh, &sim.result, 3, nullptr, SkinExtent::Patch);
  using Tri = std::array<double, 18>;
  auto triangles = [](const SkinSurfaces& s, bool range) {
    std::multiset<Tri> out;
    for (Eigen::Index f = 0; f < s.pre.F.rows(); ++f) {
      if ((s.face_part[static_cast<std::size_t>(f)] == SkinPart::Range) != range) continue;
      Tri t{};
      for (int c = 0; c < 3; ++c)
        for (int d = 0; d < 3; ++d) {
          t[static_cast<std::size_t>(3 * c + d)] = s.pre.V(s.pre.F(f, c), d);
          t[static_cast<std::size_t>(9 + 3 * c + d)] = s.post.V(s.pre.F(f, c), d);
        }
      out.insert(t);
    }
    return out;
  };
  EXPECT_TRUE(triangles(patch, true).empty());
  EXPECT_EQ(triangles(patch, false), triangles(whole, false));
  EXPECT_EQ(patch.n_micropolygon_vertices, whole.n_micropolygon_vertices);
  EXPECT_LT(patch.pre.n_vertices(), whole.pre.n_vertices() / 10);
  // The whole head's range cells: cell q = k n_theta + j is drawn as two triangles whose lowest
  // vertex sits on row k (the end caps' fans are not cells).
  const CylinderGrid& g = bumpy().grid();
  std::vector<char> drawn(static_cast<std::size_t>(g.n_theta) * (g.n_z - 1), 0);
  for (Eigen::Index f = 0; f < whole.pre.F.rows(); ++f) {
    if (whole.face_part[static_cast<std::size_t>(f)] != SkinPart::Range) continue;
    long j_min = g.n_theta, k_min = g.n_z, k_max = -1;
    std::set<long> js;
    for (int c = 0; c < 3; ++c) {
      const Eigen::Index v = whole.pre.F(f, c);
      const long j = std::lround((whole.theta_z(v, 0) - g.theta0_deg) / g.dtheta_deg());
      const long k = std::lround((whole.theta_z(v, 1) - g.z0_mm) / g.dz_mm);
      js.insert(((j % g.n_theta) + g.n_theta) % g.n_theta);
      k_min = std::min(k_min, k);
      k_max = std::max(k_max, k);
    }
    if (k_max != k_min + 1) continue;
    j_min = *js.begin();
    const long j = js.size() == 2 && *js.rbegin() - j_min > 1 ? *js.rbegin() : j_min;
    drawn[static_cast<std::size_t>(k_min * g.n_theta + j)] = 1;
  }
  std::vector<int> missing;
  for (std::size_t q = 0; q < drawn.size(); ++q)
    if (!drawn[q]) missing.push_back(static_cast<int>(q));
  EXPECT_EQ(patch.replaced_cells, missing);
  EXPECT_EQ(whole.replaced_cells, missing);
  EXPECT_FALSE(missing.empty());
}

TEST(SkinSurface, FixedNodesStayOnTheSkinAndTheWoundCloses) {
  const closure::Simulation& sim = bumpy_sim();
  const fem::Mesh& mesh = sim.wound.continuum.mesh;
  const Eigen::MatrixX3d& u = sim.result.displacement_mm;
  const SkinSurfaces s = displaced_skin(bumpy(), mesh, &sim.result, 4);
  int checked = 0;
  for (Eigen::Index n = 0; n < mesh.n_nodes(); ++n) {
    if (u.row(n).norm() != 0.0) continue;
    for (int v = 0; v < s.n_micropolygon_vertices; ++v)
      if ((s.pre.V.row(v) - mesh.nodes.row(n)).norm() < 1e-9) {
        EXPECT_LT(off_skin_mm(bumpy(), s.post.V.row(v)), 1e-6);
        ++checked;
      }
  }
  EXPECT_GT(checked, 10);
  EXPECT_GT((s.post.V - s.pre.V).rowwise().norm().maxCoeff(), 0.5);
}

// The seam's stitch does not depend on where exactly the mesh's rim falls between the range
// image's samples: moving the ellipse's nodes by hundredths of a mm (its width 6.00 +- 0.02 mm,
// its centre by 0.02 deg or 0.02 mm) moves the rim of the 3 mm mesh around it, and the skin
// stays closed and oriented for each. With 6.00 mm on the 20 x 6 ellipse the constrained
// triangulation once made a sliver of three collinear range samples outside the footprint's
// staircase, whose centroid fell on the staircase and was taken as inside it: 3 open edges.
TEST(SkinSurface, ClosedWhereverTheRimFallsBetweenSamples) {
  struct Placement {
    double width_mm, theta_deg, z_mm;
  };
  for (const Placement& at : {Placement{5.98, 10.0, 5.0}, Placement{6.00, 10.0, 5.0},
                              Placement{6.02, 10.0, 5.0}, Placement{6.00, 10.02, 5.0},
                              Placement{6.00, 10.0, 5.02}}) {
    mesher::SurfaceMeshOptions surface;
    surface.size_mm = 3.0;
    const mesher::WoundMesh wound = mesher::mesh_wound(
        plan::wound_border(ellipse_plan(bumpy(), at.width_mm, at.theta_deg, at.z_mm)), bumpy(),
        surface);
    const SkinSurfaces s = displaced_skin(bumpy(), wound.continuum.mesh,
                                          static_cast<const Eigen::MatrixX3d*>(nullptr), 5);
    int n_seam = 0;
    for (SkinPart part : s.face_part) n_seam += part == SkinPart::Seam;
    EXPECT_GT(n_seam, 0) << "width " << at.width_mm << " mm at " << at.theta_deg << ", " << at.z_mm;
    EXPECT_EQ(open_or_misoriented_edges(s), 0)
        << "width " << at.width_mm << " mm at " << at.theta_deg << ", " << at.z_mm;
  }
}

TEST(RenderImage, ZeroDisplacementGivesIdenticalPreAndPostImages) {
  const closure::Simulation& sim = bumpy_sim();
  const Eigen::MatrixX3d zero = Eigen::MatrixX3d::Zero(sim.wound.continuum.mesh.n_nodes(), 3);
  const SkinSurfaces s = displaced_skin(bumpy(), sim.wound.continuum.mesh, &zero, 4);
  RenderOptions o;
  o.width = o.height = 160;
  for (View v : {View::Front, View::Plan}) {
    const Camera cam = standard_camera(v, bumpy(), s, o.width, o.height);
    const RgbImage pre = render_image(s.pre, s.color, cam, o);
    const RgbImage post = render_image(s.post, s.color, cam, o);
    EXPECT_EQ(pre.rgb, post.rgb) << view_name(v);
  }
  // with the solved closure the plan view changes
  const SkinSurfaces moved = displaced_skin(bumpy(), sim.wound.continuum.mesh, &sim.result, 4);
  const Camera cam = standard_camera(View::Plan, bumpy(), moved, o.width, o.height);
  EXPECT_NE(render_image(moved.pre, moved.color, cam, o).rgb,
            render_image(moved.post, moved.color, cam, o).rgb);
}

TEST(RenderImage, CylinderSilhouetteWidth) {
  const closure::Simulation sim = ellipse_on(round_cylinder());
  const SkinSurfaces s = displaced_skin(round_cylinder(), sim.wound.continuum.mesh,
                                        static_cast<const Eigen::MatrixX3d*>(nullptr), 2);
  RenderOptions o;
  o.width = 400;
  o.height = 100;
  o.samples_per_side = 1;
  Camera cam;
  cam.width_px = o.width;
  cam.height_px = o.height;
  cam.target = Eigen::Vector3d(0, 0, 40);  // below the top cap, away from the wound (z = 5)
  cam.forward = Eigen::Vector3d(0, 1, 0);  // looking at the face (front = -y)
  cam.up = Eigen::Vector3d(0, 0, 1);
  cam.width_mm = 200;
  const RgbImage img = render_image(s.pre, s.color, cam, o);
  const auto bg = [&](int x, int y) {
    const std::size_t i = (static_cast<std::size_t>(y) * img.width + x) * 3;
    return std::abs(img.rgb[i] - std::lround(o.background.x() * 255)) <= 0 &&
           std::abs(img.rgb[i + 1] - std::lround(o.background.y() * 255)) <= 0 &&
           std::abs(img.rgb[i + 2] - std::lround(o.background.z() * 255)) <= 0;
  };
  for (int y : {10, 50, 90}) {
    int covered = 0;
    for (int x = 0; x < img.width; ++x) covered += !bg(x, y);
    // 2R = 140 mm at 0.5 mm per pixel; the 360-sided polygon is at most 0.0027 px narrower
    EXPECT_NEAR(covered, 2 * kR / 0.5, 1.0) << "row " << y;
  }
}
TEST(SkinSurface, WoundFillCollapsesWhenTheWoundCloses) {
  const closure::Simulation& sim = bumpy_sim();
  const SkinSurfaces s = displaced_skin(bumpy(), sim.wound.continuum.mesh, &sim.result, 4);
  double pre = 0, post = 0;
  for (Eigen::Index f = 0; f < s.pre.F.rows(); ++f) {
    if (s.face_part[f] != SkinPart::WoundFill) continue;
    for (const TriMesh* m : {&s.pre, &s.post}) {
      const Eigen::Vector3d a = m->V.row(m->F(f, 0)), b = m->V.row(m->F(f, 1)),
                            c = m->V.row(m->F(f, 2));
      (m == &s.pre ? pre : post) += 0.5 * (b - a).cross(c - a).norm();
    }
  }
  // the ellipse is 20 x 6 mm: about 80 mm2 of skin to excise, nothing left after the closure
  EXPECT_GT(pre, 50.0);
  EXPECT_LT(post, 1e-3 * pre);
}

// A bilobed flap closes its defect round the first lobe, not along a line: no triangulation of
// its border collapses after the closure, and a fill that followed the border would lie across
// the lobes as a fan of flat triangles cutting through the skin (seen on Cranium's nasal
// sidewall). The closed wound's fill has vertices of its own, gathered at one point afterwards.
TEST(SkinSurface, AClosedTranspositionFlapsFillVanishesInsteadOfFanningAcrossTheLobes) {
  closure::SimulateOptions o;
  o.surface.size_mm = 3.0;
  o.surface.extent_mm = 12.0;
  o.solve.kinematics = fem::Kinematics::Finite;
  o.solve.newton.n_steps = 5;
  const plan::Plan p = plan::place_procedure(plan::layout_procedure("bilobed", {}),
                                             round_cylinder(), 10.0, 5.0, 90.0);
  const closure::Simulation sim = closure::simulate(round_cylinder(), p, o);
  ASSERT_LT(sim.max_suture_gap_mm, 1e-6);
  const SkinSurfaces s = displaced_skin(round_cylinder(), sim.wound.continuum.mesh, &sim.result, 2);
  const auto [pre, post] = wound_fill_area_mm2(s);
  EXPECT_GT(pre, 0.8 * kPi * 6 * 6);  // the defect, radius 6 mm, and the lobes' slits
  EXPECT_LT(post, 1e-9 * pre);
  // Its vertices are its own: no micropolygon uses them, and before the closure they lie where
  // the border's do (the pre-operative skin is whole).
  std::set<int> micro, fill;
  for (Eigen::Index f = 0; f < s.pre.F.rows(); ++f)
    for (int k = 0; k < 3; ++k)
      (s.face_part[f] == SkinPart::WoundFill ? fill : micro).insert(s.pre.F(f, k));
  ASSERT_FALSE(fill.empty());
  for (int v : fill) {
    EXPECT_FALSE(micro.count(v));
    double nearest = 1e9;
    for (int w : micro) nearest = std::min(nearest, (s.pre.V.row(v) - s.pre.V.row(w)).norm());
    EXPECT_LT(nearest, 1e-9);
  }
}

// A V-Y flap is an incision without excision: no hole opens, so there is nothing to fill (a fill
// of its zero-area loop could only be a fan across the flap, visible after the closure).
TEST(SkinSurface, AnIncisionWithoutExcisionGetsNoFill) {
  const plan::Plan p = plan::place_procedure(
      plan::layout_procedure("v-y-advancement", {{"length", 15.0}, {"advance", 5.0}}),
      round_cylinder(), 10.0, 5.0, 0.0);
  closure::SimulateOptions o;
  o.surface.size_mm = 3.0;
  const closure::Simulation sim = closure::simulate(round_cylinder(), p, o);
  const SkinSurfaces s = displaced_skin(round_cylinder(), sim.wound.continuum.mesh, &sim.result, 2);
  int fills = 0;
  for (Eigen::Index f = 0; f < s.pre.F.rows(); ++f) fills += s.face_part[f] == SkinPart::WoundFill;
  EXPECT_EQ(fills, 0);
  EXPECT_GT(s.pre.F.rows(), 1000);
}

TEST(SkinSurface, FullResolutionSubdivisionsMatchTheSampleSpacing) {
  const fem::Mesh& mesh = bumpy_sim().wound.continuum.mesh;
  const int n = full_resolution_subdivisions(bumpy(), mesh);
  const SkinSurfaces s = displaced_skin(bumpy(), mesh, static_cast<const Eigen::MatrixX3d*>(nullptr), n);
  // 1 degree at r = 72 mm is 1.26 mm; dz = 1 mm: micropolygon edges of a quadratic face stay
  // close to the finest spacing
  double longest = 0;
  for (Eigen::Index f = 0; f < s.pre.F.rows(); ++f)
    if (s.face_part[f] == SkinPart::Micropolygon)
      for (int k = 0; k < 3; ++k)
        longest = std::max(longest, (s.pre.V.row(s.pre.F(f, k)) - s.pre.V.row(s.pre.F(f, (k + 1) % 3))).norm());
  EXPECT_GE(n, 2);
  EXPECT_LT(longest, 2.0);
}
