// The skin tension map (tension_<view>.png): nodal maximum principal stress carried to the
// displacement-mapped skin by the elements' own shape functions, in kPa, on a synthetic round
// cylinder with a solved ellipse closure. Known answers: a linear nodal field gives exactly the
// field at each micropolygon vertex's face point, a constant field the constant, the range mesh 0;
// the top of the scale is viridis' last colour and zero stress is its first colour everywhere.
#include <gtest/gtest.h>

#include <algorithm>

#include "synthetic_model.hpp"

#include <cmath>
#include <filesystem>
#include <string>

#include <unistd.h>

#include "caps/core/error.hpp"
#include "caps/closure/simulate.hpp"
#include "caps/plan/procedures.hpp"
#include "caps/render/overlay.hpp"
#include "caps/render/render.hpp"
#include "caps/render/skin_surface.hpp"
#include "caps/surface/patient_model.hpp"
#include "caps/image/colormap.hpp"
#include "caps/image/image_io.hpp"

using namespace caps;
using namespace caps::render;

namespace {

const PatientModel& round_cylinder() {
  static const PatientModel m(caps_test::synthetic_maps(
      caps_test::grid(360, 201, -100, 1), [](double, double) { return 70.0; },
      [](double, double) { return 5.0; }));
  return m;
}

const closure::Simulation& ellipse_sim() {
  static const closure::Simulation s = [] {
    const plan::Plan p = plan::place_procedure(
        plan::layout_procedure("ellipse", {{"length", 20.0}, {"width", 6.0}}), round_cylinder(),
        10.0, 5.0, 90.0);
    closure::SimulateOptions o;
    o.surface.size_mm = 3.0;
    return closure::simulate(round_cylinder(), p, o);
  }();
  return s;
}

const fem::Mesh& mesh() { return ellipse_sim().wound.continuum.mesh; }

const SkinSurfaces& skin() {
  static const SkinSurfaces s = displaced_skin(round_cylinder(), mesh(), &ellipse_sim().result, 4);
  return s;
}

// The closest pixel colour to a multiple of `c` (shading scales the albedo): the largest
// channel error after fitting the scale.
double hue_error(const std::uint8_t* px, const Eigen::Vector3d& c) {
  const Eigen::Vector3d p(px[0], px[1], px[2]);
  const double k = p.dot(c) / c.squaredNorm();
  return (p - k * c).cwiseAbs().maxCoeff();
}

}  // namespace

TEST(TensionMap, LinearNodalFieldIsReproducedExactlyOnTheFaces) {
  // A linear field f = a + b . x (MPa): the shape functions reproduce it, so a micropolygon vertex
  // must carry f(x_face) with x_face = sum_a N_a X_a = pre - d, the point that placed it.
  const Eigen::Vector3d grad(2e-4, -1e-4, 3e-4);
  const double a = 0.004;
  const Eigen::VectorXd f = (a + (mesh().nodes * grad).array()).matrix();
  const ScalarMap t = tension_map(skin(), mesh(), f);
  ASSERT_EQ(t.value.size(), skin().pre.V.rows());
  EXPECT_EQ(t.name, "tension");
  EXPECT_EQ(t.unit, "kPa");
  int n_on_mesh = 0;
  double worst = 0;
  for (Eigen::Index v = 0; v < t.value.size(); ++v) {
    if (skin().vertex_element[v] < 0) {
      ASSERT_EQ(t.value[v], 0.0) << "range vertex " << v;
      continue;
    }
    ++n_on_mesh;
    const Eigen::Vector3d x_face = (skin().pre.V.row(v) - skin().range_offset_mm.row(v)).transpose();
    worst = std::max(worst, std::abs(t.value[v] - 1e3 * (a + grad.dot(x_face))));
  }
  EXPECT_LT(worst, 1e-9);  // kPa
  EXPECT_EQ(n_on_mesh, skin().n_micropolygon_vertices);
  // The field varies over the mesh by more than the tolerance, so the check has teeth.
  const Eigen::VectorXd on = t.value.head(skin().n_micropolygon_vertices);
  EXPECT_GT(on.maxCoeff() - on.minCoeff(), 1.0);
  // The default top of the scale is the 99th percentile over the skin faces (the peaks at
  // sutured corners are singular), and the note under the bar gives the peak.
  std::vector<double> sorted(on.data(), on.data() + on.size());
  std::sort(sorted.begin(), sorted.end());
  EXPECT_DOUBLE_EQ(t.max_value, sorted[static_cast<std::size_t>(0.99 * (sorted.size() - 1))]);
  EXPECT_LT(t.max_value, on.maxCoeff());
  EXPECT_NE(t.note.find(cat("peak ", std::lround(on.maxCoeff()), " kPa")), std::string::npos) << t.note;
}

TEST(TensionMap, ElementCornersCarryTheirNodalValue) {
  // The solved closure's own max principal stress: a micropolygon vertex at a face corner node
  // carries exactly that node's value (kPa), whichever element it was welded from.
  const Eigen::VectorXd& sigma1 = ellipse_sim().result.max_principal_mpa;
  const ScalarMap t = tension_map(skin(), mesh(), sigma1);
  int checked = 0;
  for (Eigen::Index v = 0; v < skin().n_micropolygon_vertices; ++v) {
    const fem::Element& el = mesh().elements[skin().vertex_element[v]];
    const Eigen::Vector2d xi = skin().vertex_natural.row(v);
    const bool hex = el.type == fem::ElementType::Hex20;
    const std::vector<Eigen::Vector2d> corners =
        hex ? std::vector<Eigen::Vector2d>{{-1, -1}, {1, -1}, {1, 1}, {-1, 1}}
            : std::vector<Eigen::Vector2d>{{0, 0}, {1, 0}, {0, 1}};
    for (std::size_t c = 0; c < corners.size(); ++c)
      if ((xi - corners[c]).norm() < 1e-12) {
        EXPECT_NEAR(t.value[v], 1e3 * sigma1[el.nodes[c]], 1e-9) << "vertex " << v;
        ++checked;
      }
  }
  EXPECT_GT(checked, 20);
  // The closure stretches the skin: some tension, some of it above 1 kPa.
  EXPECT_GT(t.value.maxCoeff(), 1.0);
}

TEST(TensionMap, ConstantStressIsTheTopColourAndTheRangeTheBottom) {
  const Eigen::VectorXd f = Eigen::VectorXd::Constant(mesh().n_nodes(), 0.0123);  // MPa
  const ScalarMap t = tension_map(skin(), mesh(), f);
  EXPECT_NEAR(t.max_value, 12.3, 1e-9);
  const Eigen::MatrixX3d c = scalar_colors(t.value, t.max_value);
  for (Eigen::Index v = 0; v < t.value.size(); ++v) {
    const bool on = skin().vertex_element[v] >= 0;
    ASSERT_NEAR(t.value[v], on ? 12.3 : 0.0, 1e-9) << "vertex " << v;
    const Eigen::Vector3d expect = on ? viridis(1.0) : viridis(0.0);
    ASSERT_LT((c.row(v).transpose() - expect).norm(), 1e-12) << "vertex " << v;
  }
  // A user-given top of the scale: 12.3 kPa at a 24.6 kPa top is the middle colour.
  const ScalarMap half = tension_map(skin(), mesh(), f, 24.6);
  EXPECT_DOUBLE_EQ(half.max_value, 24.6);
  const Eigen::MatrixX3d ch = scalar_colors(half.value, half.max_value);
  EXPECT_LT((ch.row(0).transpose() - viridis(0.5)).norm(), 1e-12);
}

TEST(TensionMap, CompressionAndZeroStressAreTheBottomColour) {
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(mesh().n_nodes());
  const ScalarMap t = tension_map(skin(), mesh(), zero);
  EXPECT_EQ(t.value.cwiseAbs().maxCoeff(), 0.0);
  EXPECT_DOUBLE_EQ(t.max_value, 1.0);  // a readable 0 .. 1 kPa scale, not a degenerate one
  const Eigen::MatrixX3d c = scalar_colors(t.value, t.max_value);
  for (Eigen::Index v = 0; v < c.rows(); ++v)
    ASSERT_LT((c.row(v).transpose() - viridis(0.0)).norm(), 1e-12) << "vertex " << v;
  // Compression (negative max principal stress) and values beyond the top are clamped.
  const Eigen::VectorXd mixed = (Eigen::VectorXd(3) << -5.0, 0.0, 7.0).finished();
  const Eigen::MatrixX3d m = scalar_colors(mixed, 3.5);
  EXPECT_LT((m.row(0).transpose() - viridis(0.0)).norm(), 1e-12);
  EXPECT_LT((m.row(1).transpose() - viridis(0.0)).norm(), 1e-12);
  EXPECT_LT((m.row(2).transpose() - viridis(1.0)).norm(), 1e-12);
  EXPECT_DOUBLE_EQ(scale_top(-mixed.cwiseAbs(), 0), 1.0);
  EXPECT_DOUBLE_EQ(scale_top(mixed, 0), 7.0);
  EXPECT_DOUBLE_EQ(scale_top(mixed, 2.0), 2.0);
}

TEST(TensionMap, ImagesShowTheFieldWhereItIs) {
  // Plan view. With zero stress every skin pixel (not at the silhouette) is a shade of the bottom
  // colour: the colour bar's panel lies in a margin right of the view, over no skin. With a constant stress on the mesh the inner half of
  // the mesh's footprint is a shade of the top colour and the skin outside it (range mesh) a
  // shade of the bottom colour.
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("caps_test_tension_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  RenderOptions o;
  o.width = o.height = 400;
  Overlays zero, constant;
  zero.scalar_maps.push_back(tension_map(skin(), mesh(), Eigen::VectorXd::Zero(mesh().n_nodes())));
  constant.scalar_maps.push_back(
      tension_map(skin(), mesh(), Eigen::VectorXd::Constant(mesh().n_nodes(), 0.01)));
  const auto files = render_views_with_overlays(round_cylinder(), skin(), {View::Plan}, o, zero, dir);
  ASSERT_EQ(files.size(), 3u);
  EXPECT_EQ(files[2].filename(), "tension_plan.png");
  const RgbImage post = read_png(files[1]), z = read_png(files[2]);
  const RgbImage c =
      read_png(render_views_with_overlays(round_cylinder(), skin(), {View::Plan}, o, constant, dir)[2]);
  // The view as large as pre_ and post_, the panel in a margin to its right.
  EXPECT_EQ(post.width, o.width);
  EXPECT_EQ(z.height, o.height);
  EXPECT_EQ(z.width, o.width + 120);
  EXPECT_EQ(c.width, z.width);
  // In the image: r_mesh, the largest distance of a projected micropolygon vertex from the
  // projected mesh centre, and r_seam, that of any vertex of a seam triangle (the strip that
  // blends the rim's values into the range mesh's 0).
  const Camera cam = standard_camera(View::Plan, round_cylinder(), skin(), o.width, o.height);
  const Eigen::Vector2d centre = cam.project(skin().mesh_centre_lps);
  auto r_of = [&](Eigen::Index v) {
    return (cam.project(skin().post.V.row(v).transpose()) - centre).norm();
  };
  double r_px = 0, r_seam = 0;
  for (int v = 0; v < skin().n_micropolygon_vertices; ++v) r_px = std::max(r_px, r_of(v));
  for (Eigen::Index f = 0; f < skin().post.F.rows(); ++f)
    if (skin().face_part[f] == SkinPart::Seam)
      for (int k = 0; k < 3; ++k) r_seam = std::max(r_seam, r_of(skin().post.F(f, k)));
  ASSERT_GT(r_px, 20);
  ASSERT_LT(r_seam, r_px + 15);
  auto skin_px = [&](int x, int y) {  // skin here and all around: not a silhouette blend
    for (int dy = -1; dy <= 1; ++dy)
      for (int dx = -1; dx <= 1; ++dx)
        if (post.rgb[(std::size_t(y + dy) * post.width + x + dx) * 3] < 60) return false;
    return true;
  };
  const Eigen::Vector3d bottom = 255 * viridis(0.0), top = 255 * viridis(1.0);
  double worst_zero = 0, worst_top = 0, worst_bottom = 0;
  int n_zero = 0, n_top = 0, n_bottom = 0;
  for (int y = 1; y + 1 < o.height; ++y)
    for (int x = 1; x + 1 < o.width; ++x) {
      if (!skin_px(x, y)) continue;
      const std::size_t i = (std::size_t(y) * z.width + x) * 3;
      worst_zero = std::max(worst_zero, hue_error(&z.rgb[i], bottom));
      ++n_zero;
      const double r = (Eigen::Vector2d(x, y) - centre).norm();
      if (r < 0.5 * r_px) {
        worst_top = std::max(worst_top, hue_error(&c.rgb[i], top));
        ++n_top;
      } else if (r > r_seam + 2) {
        worst_bottom = std::max(worst_bottom, hue_error(&c.rgb[i], bottom));
        ++n_bottom;
      }
    }
  EXPECT_GT(n_zero, 40000);
  EXPECT_GT(n_top, 1000);
  EXPECT_GT(n_bottom, 1000);
  EXPECT_LE(worst_zero, 1.5);
  EXPECT_LE(worst_top, 2.0);
  EXPECT_LE(worst_bottom, 1.5);
  if (!::testing::Test::HasFailure()) std::filesystem::remove_all(dir);
}

TEST(TensionMap, BadInputIsRefused) {
  EXPECT_THROW(tension_map(skin(), mesh(), Eigen::VectorXd::Zero(mesh().n_nodes() - 1)), InvalidInput);
  Eigen::VectorXd nan = Eigen::VectorXd::Zero(mesh().n_nodes());
  nan[3] = std::nan("");
  EXPECT_THROW(tension_map(skin(), mesh(), nan), InvalidInput);
  EXPECT_THROW(tension_map(skin(), mesh(), Eigen::VectorXd::Zero(mesh().n_nodes()), -1.0), InvalidInput);
  EXPECT_THROW(scalar_colors(Eigen::VectorXd::Zero(2), 0.0), InvalidInput);
  Overlays wrong;
  ScalarMap m;
  m.name = "tension";
  m.value = Eigen::VectorXd::Zero(5);
  wrong.scalar_maps.push_back(m);
  RenderOptions o;
  o.width = o.height = 32;
  EXPECT_THROW(render_views_with_overlays(round_cylinder(), skin(), {View::Plan}, o, wrong,
                                          std::filesystem::temp_directory_path()),
               InvalidInput);
}
