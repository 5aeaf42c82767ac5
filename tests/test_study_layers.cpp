// The continuum mesher's measured tissue layers (TissueLayers::Measured): interface nodes on the
// layer maps' depths (synthetic maps known exactly, and the layered analytic phantom against its
// closed-form interfaces), one material per layer, the fallback where no fat was seen, the uniform
// fallback without layer maps, the CalculiX deck's sections and the compare's third column.
#include <gtest/gtest.h>

#include "ccx_run.hpp"
#include "layered_phantom_model.hpp"
#include "phantom_crossing.hpp"
#include "synthetic_model.hpp"

#include <cmath>
#include <map>
#include <regex>
#include <string>

#include "caps/core/error.hpp"
#include "caps/core/units.hpp"
#include "caps/study/compare.hpp"
#include "caps/mesher/continuum_mesher.hpp"
#include "caps/fem/inp_io.hpp"
#include "caps/fem/material_registry.hpp"
#include "caps/closure/simulate.hpp"
#include "caps/fem/solve.hpp"
#include "caps/plan/procedures.hpp"
#include "caps/surface/patient_model.hpp"

using namespace caps;
using namespace caps::fem;
using namespace caps::mesher;
using namespace caps::closure;
using namespace caps::study;

namespace {

constexpr double kR = 70.0;

// A cylinder of radius 70 mm about the LPS z axis, z in [-100, 100], with layer depths
// skin/fat/deep(theta deg, z mm) and layer flags flag(theta, z); thickness = their sum.
template <typename Skin, typename Fat, typename Deep, typename Flag>
PatientModel layered_cylinder(Skin&& skin, Fat&& fat, Deep&& deep, Flag&& flag) {
  CylindricalMaps m = caps_test::synthetic_maps(
      caps_test::grid(360, 201, -100, 1), [](double, double) { return kR; },
      [&](double t, double z) { return skin(t, z) + fat(t, z) + deep(t, z); });
  m.allocate_layers();
  for (int k = 0; k < m.grid.n_z; ++k)
    for (int j = 0; j < m.grid.n_theta; ++j) {
      const std::size_t c = m.grid.index(j, k);
      const double t = m.grid.theta_deg(j), z = m.grid.z_mm(k);
      m.thickness_skin[c] = m.thickness_skin_normal[c] = static_cast<float>(skin(t, z));
      m.thickness_fat[c] = m.thickness_fat_normal[c] = static_cast<float>(fat(t, z));
      m.thickness_deep[c] = m.thickness_deep_normal[c] = static_cast<float>(deep(t, z));
      m.layer_flags[c] = m.layer_flags_normal[c] = flag(t, z);
    }
  return PatientModel(std::move(m));
}

std::uint8_t measured(double, double) { return 0; }

// (x mm of arc, z mm) on the cylinder to (theta deg, z mm).
Eigen::Vector2d tz(double x, double z) { return {x / kR * 180.0 / kPi, z}; }

// An elliptical excision (paper Figure 1) centred at arc x0: tips 0 and 3, lips 1 2 and 5 4.
WoundBorder lens(double x0 = 0, double half_length = 12, double half_width = 3) {
  const double a = half_length, w = half_width;
  WoundBorder b;
  b.loop_theta_z = {tz(x0 - a, 0),     tz(x0 - a / 3, w),  tz(x0 + a / 3, w),
                    tz(x0 + a, 0),     tz(x0 + a / 3, -w), tz(x0 - a / 3, -w)};
  b.sutures = {{0, 1, 0, 5}, {1, 2, 5, 4}, {2, 3, 4, 3}};
  return b;
}

SurfaceMeshOptions small_surface() {
  SurfaceMeshOptions s;
  s.size_mm = 2.0;
  s.extent_mm = 16.0;
  return s;
}

// A node's depth under the skin along its column (mm).
double depth_of(const PatientModel& model, const ContinuumMesh& c, Eigen::Index i) {
  const CylindricalPoint p = model.to_cylindrical(c.mesh.nodes.row(i).transpose());
  return model.r_skin(c.node_theta_z(i, 0), c.node_theta_z(i, 1)) - p.r_mm;
}

// The depth the mesher must give a node of level `level` (0 skin .. 3 bone, halves at the
// centres) for interface depths D[0..3].
double expected_depth(double level, const std::array<double, 4>& D) {
  const int k = static_cast<int>(std::floor(level));
  return level == k ? D[k] : 0.5 * (D[k] + D[k + 1]);
}

}  // namespace

TEST(MeasuredLayers, InterfaceNodesLieOnTheLayerMapsDepths) {
  // skin 2 + z/100, fat 3 + z/50, deep 4 mm: linear in z, so the maps' bilinear samples are exact.
  const PatientModel model = layered_cylinder([](double, double z) { return 2.0 + 0.01 * z; },
                                              [](double, double z) { return 3.0 + 0.02 * z; },
                                              [](double, double) { return 4.0; }, measured);
  ContinuumMeshOptions o;
  o.tissue = TissueLayers::Measured;
  const WoundMesh w = mesh_wound(lens(), model, small_surface(), o);
  const ContinuumMesh& c = w.continuum;
  ASSERT_EQ(c.tissue, TissueLayers::Measured);
  EXPECT_EQ(c.n_layers, 3);  // n_layers 2 -> one element layer per tissue layer
  EXPECT_EQ(c.fat_top_level, 1);
  EXPECT_EQ(c.fat_bottom_level, 2);
  EXPECT_EQ(c.widened_fat_columns, 0);
  double worst = 0;
  for (Eigen::Index i = 0; i < c.mesh.n_nodes(); ++i) {
    const double z = c.node_theta_z(i, 1);
    const double s = 2.0 + 0.01 * z, f = 3.0 + 0.02 * z;
    const std::array<double, 4> D{0, s, s + f, s + f + 4.0};
    worst = std::max(worst, std::abs(depth_of(model, c, i) - expected_depth(c.node_level[i], D)));
  }
  EXPECT_LT(worst, 1e-4);  // the maps are stored as float
  // One material per tissue layer, element layer k is tissue layer k.
  const std::size_t n_poly = w.surface.polygons.size();
  ASSERT_EQ(c.mesh.n_elements(), 3 * n_poly);
  for (std::size_t e = 0; e < c.mesh.n_elements(); ++e) EXPECT_EQ(c.mesh.elements[e].layer, static_cast<int>(e % 3));
  ASSERT_EQ(c.mesh.materials.size(), 3u);
  // The presets (data/materials/dermis.json, fat.json, deep.json): neo-Hookean solids.
  EXPECT_EQ(parameters_of(*c.mesh.materials.at(kDermisLayer)), (MaterialParameters{{"E", 0.1}, {"nu", 0.45}}));
  EXPECT_EQ(parameters_of(*c.mesh.materials.at(kFatLayer)), (MaterialParameters{{"E", 0.003}, {"nu", 0.45}}));
  EXPECT_EQ(parameters_of(*c.mesh.materials.at(kDeepLayer)), (MaterialParameters{{"E", 0.02}, {"nu", 0.45}}));
  for (int id : {kDermisLayer, kFatLayer, kDeepLayer})
    EXPECT_EQ(c.mesh.materials.at(id)->name(), "neo-hookean");
  // Six element layers: two per tissue layer, each halving its tissue layer.
  o.n_layers = 6;
  const WoundMesh w6 = mesh_wound(lens(), model, small_surface(), o);
  EXPECT_EQ(w6.continuum.n_layers, 6);
  EXPECT_EQ(w6.continuum.fat_top_level, 2);
  EXPECT_EQ(w6.continuum.fat_bottom_level, 4);
  for (std::size_t e = 0; e < w6.continuum.mesh.n_elements(); ++e)
    EXPECT_EQ(w6.continuum.mesh.elements[e].layer, static_cast<int>(e % 6) / 2);
  for (Eigen::Index i = 0; i < w6.continuum.mesh.n_nodes(); ++i)
    if (w6.continuum.node_level[i] == 1) {
      const double z = w6.continuum.node_theta_z(i, 1);
      EXPECT_NEAR(depth_of(model, w6.continuum, i), 0.5 * (2.0 + 0.01 * z), 1e-4);
    }
}

TEST(MeasuredLayers, WhereNoFatWasSeenTheFatLayerIsTheThinnestAndDeepTissue) {
  // theta < 0: no fat seen (fat 0, kLayerNoFat), skin 2, deep 4; theta >= 0: fat 3 mm.
  const PatientModel model = layered_cylinder(
      [](double, double) { return 2.0; }, [](double t, double) { return t < 0 ? 0.0 : 3.0; },
      [](double, double) { return 4.0; },
      [](double t, double) -> std::uint8_t { return t < 0 ? kLayerNoFat : 0; });
  ContinuumMeshOptions o;
  o.tissue = TissueLayers::Measured;
  const WoundMesh w = mesh_wound(lens(), model, small_surface(), o);
  const ContinuumMesh& c = w.continuum;
  EXPECT_GT(c.widened_fat_columns, 0);
  // No fat: the fat is widened to 0.5 mm (min_tissue_layer_mm) out of the thickest layer (the
  // deep tissue, 4 -> 3.5 mm): interfaces 0, 2, 2.5, 6 mm. Fat: 0, 2, 5, 9 mm. Columns within
  // a grid cell (1 deg) of theta 0 blend the two and are not checked.
  int n_no_fat = 0, n_fat = 0;
  for (Eigen::Index i = 0; i < c.mesh.n_nodes(); ++i) {
    const double t = c.node_theta_z(i, 0);
    if (std::abs(t) < 1.0) continue;
    const std::array<double, 4> D = t < 0 ? std::array<double, 4>{0, 2, 2.5, 6} : std::array<double, 4>{0, 2, 5, 9};
    EXPECT_NEAR(depth_of(model, c, i), expected_depth(c.node_level[i], D), 1e-4) << "theta " << t;
    (t < 0 ? n_no_fat : n_fat) += 1;
  }
  EXPECT_GT(n_no_fat, 50);
  EXPECT_GT(n_fat, 50);
  // The fat layer's elements: deep tissue where all corners had no fat, fat where all had it.
  int deep_in_fat_layer = 0, fat = 0;
  for (std::size_t e = 0; e < c.mesh.n_elements(); ++e) {
    if (e % 3 != 1) {
      EXPECT_EQ(c.mesh.elements[e].layer, static_cast<int>(e % 3) == 0 ? kDermisLayer : kDeepLayer);
      continue;
    }
    const auto& poly = w.surface.polygons[c.element_polygon[e]];
    double tmin = 1e9, tmax = -1e9;
    for (int v : poly) {
      tmin = std::min(tmin, w.surface.theta_z(v, 0));
      tmax = std::max(tmax, w.surface.theta_z(v, 0));
    }
    if (tmax < 0) {
      EXPECT_EQ(c.mesh.elements[e].layer, kDeepLayer);
      ++deep_in_fat_layer;
    } else if (tmin >= 0) {
      EXPECT_EQ(c.mesh.elements[e].layer, kFatLayer);
      ++fat;
    }
  }
  EXPECT_GT(deep_in_fat_layer, 10);
  EXPECT_GT(fat, 10);
  // A thin column: 1.2 mm with no fat; the thinnest layer is a quarter of it (0.3 mm).
  const PatientModel thin = layered_cylinder(
      [](double, double) { return 0.9; }, [](double, double) { return 0.0; },
      [](double, double) { return 0.3; }, [](double, double) -> std::uint8_t { return kLayerNoFat; });
  const ContinuumMesh ct = mesh_wound(lens(), thin, small_surface(), o).continuum;
  for (Eigen::Index i = 0; i < ct.mesh.n_nodes(); ++i)
    EXPECT_NEAR(depth_of(thin, ct, i), expected_depth(ct.node_level[i], {0, 0.6, 0.9, 1.2}), 1e-4);
}

TEST(MeasuredLayers, WithoutLayerMapsAutoIsUniformAndMeasuredIsRefused) {
  CylindricalMaps maps = caps_test::synthetic_maps(caps_test::grid(360, 201, -100, 1),
                                                   [](double, double) { return kR; },
                                                   [](double, double) { return 5.0; });
  const PatientModel model(std::move(maps));
  ASSERT_FALSE(model.has_layers());
  ContinuumMeshOptions uniform;
  uniform.tissue = TissueLayers::Uniform;
  const ContinuumMesh u = mesh_wound(lens(), model, small_surface(), uniform).continuum;
  ContinuumMeshOptions automatic;  // the default is uniform: auto is asked for
  automatic.tissue = TissueLayers::Auto;
  const ContinuumMesh a = mesh_wound(lens(), model, small_surface(), automatic).continuum;
  EXPECT_EQ(a.tissue, TissueLayers::Uniform);
  EXPECT_EQ(a.fat_top_level, -1);
  ASSERT_EQ(a.mesh.n_nodes(), u.mesh.n_nodes());
  EXPECT_EQ((a.mesh.nodes - u.mesh.nodes).cwiseAbs().maxCoeff(), 0.0);
  EXPECT_EQ(a.mesh.materials.size(), 2u);  // one entry per element layer, all default_skin
  ContinuumMeshOptions m;
  m.tissue = TissueLayers::Measured;
  EXPECT_THROW(mesh_wound(lens(), model, small_surface(), m), InvalidInput);
  // With layer maps but none measured (every cell flagged), Auto is uniform too.
  const PatientModel none = layered_cylinder(
      [](double, double) { return 2.0; }, [](double, double) { return 0.0; },
      [](double, double) { return 3.0; }, [](double, double) -> std::uint8_t { return kLayerNoFat; });
  EXPECT_EQ(mesh_wound(lens(), none, small_surface(), automatic).continuum.tissue, TissueLayers::Uniform);
  // Auto needs a quarter of the surface vertices on measured cells: the lens's mesh spans theta
  // about -23..+23 deg; measured beyond +20 deg is too few, beyond -5 deg enough.
  auto measured_beyond = [&](double theta0) {
    return layered_cylinder(
        [](double, double) { return 2.0; }, [](double, double) { return 1.0; },
        [](double, double) { return 3.0; },
        [=](double t, double) -> std::uint8_t { return t > theta0 ? 0 : kLayerSeveralBands; });
  };
  EXPECT_EQ(mesh_wound(lens(), measured_beyond(20), small_surface(), automatic).continuum.tissue, TissueLayers::Uniform);
  EXPECT_EQ(mesh_wound(lens(), measured_beyond(-5), small_surface(), automatic).continuum.tissue, TissueLayers::Measured);
  EXPECT_EQ(mesh_wound(lens(), measured_beyond(-5), small_surface(), {}).continuum.tissue, TissueLayers::Uniform);
  EXPECT_EQ(parse_tissue_layers("measured"), TissueLayers::Measured);
  EXPECT_STREQ(tissue_layers_name(TissueLayers::Auto), "auto");
  EXPECT_THROW(parse_tissue_layers("layered"), InvalidInput);
}

TEST(MeasuredLayers, EqualThirdsInOneMaterialAreTheUniformMesh) {
  // Layers of a third of the 6 mm each, all three materials the skin's: the measured mesh is
  // the uniform 3-layer mesh node for node, and the closure the same; a soft fat and deep
  // tissue close with less force.
  auto third = [](double, double) { return 2.0; };
  const PatientModel model = layered_cylinder(third, third, third, measured);
  ContinuumMeshOptions uniform;
  uniform.tissue = TissueLayers::Uniform;
  uniform.n_layers = 3;
  ContinuumMeshOptions same = uniform;
  same.tissue = TissueLayers::Measured;
  same.dermis = same.fat = same.deep = default_skin();
  const ContinuumMesh u = mesh_wound(lens(), model, small_surface(), uniform).continuum;
  const ContinuumMesh m = mesh_wound(lens(), model, small_surface(), same).continuum;
  ASSERT_EQ(u.mesh.n_nodes(), m.mesh.n_nodes());
  EXPECT_LT((u.mesh.nodes - m.mesh.nodes).cwiseAbs().maxCoeff(), 1e-4);
  const SolveResult ru = solve(u.mesh), rm = solve(m.mesh);
  EXPECT_NEAR(rm.total_suture_force_n, ru.total_suture_force_n, 1e-4 * ru.total_suture_force_n);
  ContinuumMeshOptions soft = same;
  soft.fat = default_fat();
  soft.deep = default_deep();
  const SolveResult rs = solve(mesh_wound(lens(), model, small_surface(), soft).continuum.mesh);
  EXPECT_LT(rs.total_suture_force_n, 0.9 * ru.total_suture_force_n);
  EXPECT_GT(rs.total_suture_force_n, 0.0);
}

TEST(MeasuredLayers, CalculixDeckHasOneSectionPerLayer) {
  const PatientModel model = layered_cylinder([](double, double) { return 2.0; },
                                              [](double, double) { return 3.0; },
                                              [](double, double) { return 4.0; }, measured);
  ContinuumMeshOptions o;
  o.tissue = TissueLayers::Measured;
  const ContinuumMesh c = mesh_wound(lens(), model, small_surface(), o).continuum;
  auto count = [](const std::string& text, const std::string& what) {
    int n = 0;
    for (std::size_t p = text.find(what); p != std::string::npos; p = text.find(what, p + 1)) ++n;
    return n;
  };
  const std::string lin = inp_text(c.mesh);
  EXPECT_EQ(count(lin, "*MATERIAL,"), 3);
  EXPECT_EQ(count(lin, "*SOLID SECTION"), 3);
  for (int id : {0, 1, 2})
    EXPECT_NE(lin.find(cat("*SOLID SECTION, ELSET=LAYER", id, ", MATERIAL=MAT", id)), std::string::npos);
  // E and nu of each layer, in the order of the ids: dermis, fat, deep.
  std::smatch mt;
  std::vector<double> E;
  const std::regex elastic("\\*ELASTIC\n([0-9.e+-]+), ([0-9.e+-]+)\n");
  for (auto it = std::sregex_iterator(lin.begin(), lin.end(), elastic); it != std::sregex_iterator(); ++it)
    E.push_back(std::stod((*it)[1]));
  EXPECT_EQ(E, (std::vector<double>{0.1, 0.003, 0.02}));
  InpOptions fin;
  fin.finite_strain = true;
  const std::string nl = inp_text(c.mesh, fin);
  EXPECT_EQ(count(nl, "*HYPERELASTIC, NEO HOOKE"), 3);
  // C10 = mu / 2 = E / (4 (1 + nu)).
  for (double e : {0.1, 0.003, 0.02}) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "%.12g, ", e / (4 * 1.45));
    EXPECT_NE(nl.find(buf), std::string::npos) << buf;
  }
  // CalculiX solves the same layered problem (when installed).
  ASSERT_TRUE(test::has_ccx()) << "ccx (Debian calculix-ccx) is not installed: scripts/setup.sh installs it; the CalculiX cross-checks need it";
  const SolveResult r = solve(c.mesh);
  const Eigen::MatrixX3d u = test::ccx_displacements(c.mesh, "layers");
  const double umax = r.displacement_mm.rowwise().norm().maxCoeff();
  EXPECT_LT((u - r.displacement_mm).rowwise().norm().maxCoeff(), 0.05 * umax);
}

TEST(MeasuredLayers, OnTheLayeredPhantomInterfacesFollowTheAnalyticLayers) {
  const auto& lm = caps_test::layered_model();
  const PatientModel model(lm.model.maps);
  ASSERT_TRUE(model.has_layers());
  const HeadPhantom& ph = lm.ph;
  const auto& g = model.grid();
  // An ellipse 16 x 5 mm on the right side of the head, half-way up the model's z range.
  const double z0 = g.z_mm(g.n_z / 2);
  const plan::Plan p = plan::place_procedure(
      plan::layout_procedure("ellipse", {{"length", 16.0}, {"width", 5.0}}), model, -90.0, z0, 0.0);
  ContinuumMeshOptions o;
  o.tissue = TissueLayers::Measured;
  SurfaceMeshOptions s;
  s.size_mm = 2.0;
  s.extent_mm = 15.0;
  const WoundMesh w = mesh_wound(plan::wound_border(p), model, s, o);
  const ContinuumMesh& c = w.continuum;
  ASSERT_EQ(c.tissue, TissueLayers::Measured);
  // Interface nodes: the depth of the fat's top and bottom under the mesh's skin against the
  // phantom's closed-form interfaces crossed along the same ray, at every vertex column whose
  // layers were measured (the map's accuracy: 0.15 mm RMS, docs/volume.md).
  double se_top = 0, se_bottom = 0, worst = 0;
  int n = 0;
  for (Eigen::Index i = 0; i < c.mesh.n_nodes(); ++i) {
    const double L = c.node_level[i];
    if (L != c.fat_top_level && L != c.fat_bottom_level) continue;
    const double theta = c.node_theta_z(i, 0), z = c.node_theta_z(i, 1);
    if (model.layer_flags_at(theta, z) != 0) continue;
    auto at = [&](auto R, double from) {
      return caps_test::analytic_crossing(ph, model.axis(), deg_to_rad(theta), z, R, from);
    };
    const double rs = at([&](double t, double zz) { return ph.skin_radius(t, zz); }, 160.0);
    const double R = L == c.fat_top_level
                         ? at([&](double t, double zz) { return ph.fat_top_radius(t, zz); }, rs)
                         : at([&](double t, double zz) { return ph.fat_bottom_radius(t, zz); }, rs);
    ASSERT_TRUE(std::isfinite(R));
    const double err = depth_of(model, c, i) - (rs - R);
    (L == c.fat_top_level ? se_top : se_bottom) += err * err;
    worst = std::max(worst, std::abs(err));
    ++n;
  }
  ASSERT_GT(n, 100);
  const double rms_top = std::sqrt(se_top / (n / 2.0)), rms_bottom = std::sqrt(se_bottom / (n / 2.0));
  std::printf("layered phantom mesh: fat top RMS %.3f, bottom RMS %.3f, worst %.3f mm over %d nodes\n",
              rms_top, rms_bottom, worst, n);
  EXPECT_LT(rms_top, 0.3);
  EXPECT_LT(rms_bottom, 0.3);
  EXPECT_LT(worst, 0.6);
  // Each element's material is the phantom's tissue at the element's centre (the mean of its
  // centre-level nodes), wherever that centre lies farther from an analytic interface than the
  // map's worst error above (0.3 mm): closer, the measured interface may be on either side;
  // and where the map measured the layers at all the element's corners.
  int agree = 0, total = 0;
  for (std::size_t e = 0; e < c.mesh.n_elements(); ++e) {
    const Element& el = c.mesh.elements[e];
    // Only where the map measured the layers at every corner (elsewhere it has no fat to follow).
    bool all_measured = true;
    for (int v : w.surface.polygons[c.element_polygon[e]])
      all_measured = all_measured && model.layer_flags_at(w.surface.theta_z(v, 0), w.surface.theta_z(v, 1)) == 0;
    if (!all_measured) continue;
    const int centre = el.type == ElementType::Hex20 ? 16 : 12;
    Eigen::Vector3d x = Eigen::Vector3d::Zero();
    const int n_corners = el.type == ElementType::Hex20 ? 4 : 3;
    for (int k = 0; k < n_corners; ++k) x += c.mesh.nodes.row(el.nodes[centre + k]).transpose() / n_corners;
    const Eigen::Vector3d q = x - ph.axis_point();
    const double th = std::atan2(q[0], -q[1]), r = std::hypot(q[0], q[1]);
    const double top = ph.fat_top_radius(th, q[2]), bottom = ph.fat_bottom_radius(th, q[2]);
    if (std::min(std::abs(r - top), std::abs(r - bottom)) < 0.3) continue;
    const int tissue = r > top ? kDermisLayer : r > bottom ? kFatLayer : kDeepLayer;
    EXPECT_EQ(el.layer, tissue) << "element " << e << " at " << r - top << " mm from the fat's top";
    agree += el.layer == tissue;
    ++total;
  }
  std::printf("layered phantom mesh: %d of %d elements in their analytic layer\n", agree, total);
  EXPECT_GT(total, static_cast<int>(c.mesh.n_elements() * 3 / 4));
}

TEST(MeasuredLayers, CompareHasAThirdColumnWithTheMeasuredLayers) {
  const PatientModel model = layered_cylinder([](double, double) { return 2.0; },
                                              [](double, double) { return 3.0; },
                                              [](double, double) { return 4.0; }, measured);
  SimulateOptions o;
  o.surface.size_mm = 2.0;
  o.surface.extent_mm = 16.0;
  const plan::Plan p = plan::place_procedure(
      plan::layout_procedure("ellipse", {{"length", 20.0}, {"width", 6.0}}), model, 0, 0, 90);
  const Comparison c = compare_thickness(model, p, 0, o);
  EXPECT_EQ(c.measured_summary.tissue, "uniform");
  EXPECT_EQ(c.constant_summary.tissue, "uniform");
  EXPECT_EQ(c.layered_summary.tissue, "measured");
  // The same 9 mm everywhere: measured and constant are one problem; the layered one is softer
  // (fat 3 kPa and deep tissue 20 kPa under the 100 kPa dermis).
  EXPECT_NEAR(c.measured_summary.closing_force_n, c.constant_summary.closing_force_n, 1e-9);
  EXPECT_LT(c.layered_summary.closing_force_n, c.measured_summary.closing_force_n);
  EXPECT_GT(c.layered_summary.closing_force_n, 0.0);
  EXPECT_EQ(c.layered.wound.surface.extent_mm, c.measured.wound.surface.extent_mm);
  const std::string j = comparison_json(c, "p");
  EXPECT_NE(j.find("\"layers\""), std::string::npos);
  EXPECT_NE(j.find("\"tissue\": \"measured\""), std::string::npos);
}

TEST(MeasuredLayers, CompareStopsShortOfABonyRimInsteadOfMeshingAcrossIt) {
  // Over z > 20 the bone lies 30 mm deeper than below it (rays that pass under a bony rim into
  // the orbit read 20-30 mm of "skin", fat and deep tissue on Cranium): a cliff that an element
  // cannot span. The demo's compare failed there with an inverted dermis element. The automatic
  // extent now stops short of the cliff in all three columns, and a given extent that reaches
  // it is refused naming the drop; a wound on the rim itself is meshed across it, with a warning.
  const auto above = [](double z) { return z > 20.0; };
  const PatientModel model = layered_cylinder(
      [&](double, double z) { return above(z) ? 22.0 : 2.0; },
      [&](double, double z) { return above(z) ? 8.0 : 3.0; },
      [&](double, double z) { return above(z) ? 4.0 : 4.0; }, measured);
  SimulateOptions o;
  o.surface.size_mm = 2.0;
  const plan::Plan p = plan::place_procedure(
      plan::layout_procedure("ellipse", {{"length", 20.0}, {"width", 6.0}}), model, 0, 0, 90);
  const Comparison c = compare_thickness(model, p, 0, o);
  EXPECT_EQ(c.layered_summary.tissue, "measured");
  for (const Simulation* s : {&c.measured, &c.constant, &c.layered}) {
    const ContinuumMesh& m = s->wound.continuum;
    EXPECT_GT(m.min_jacobian, 0.0);
    EXPECT_LE(m.node_theta_z.col(1).maxCoeff(), 20.0);  // every column below the cliff
    EXPECT_LT(s->max_suture_gap_mm, 1e-6);
  }
  EXPECT_NEAR(c.measured_summary.thickness_max_mm, 9.0, 1e-6);
  EXPECT_LT(c.measured.wound.surface.extent_mm, 3.0 * c.measured.wound.surface.wound_size_mm);
  EXPECT_GT(c.layered_summary.closing_force_n, 0.0);
  // A given extent across the cliff is refused, naming where and how far the bone drops.
  o.surface.extent_mm = 30.0;
  try {
    simulate(model, p, o);
    FAIL() << "expected OffModelError";
  } catch (const OffModelError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("drops from 9 to"), std::string::npos) << what;
    EXPECT_TRUE(what.find("z 19") != std::string::npos || what.find("z 20") != std::string::npos)
        << what;
  }
  // A wound that lies on the rim itself leaves no extent short of it (the cheek over the
  // maxilla, where the bone's depth steps wherever the mesh reaches): the automatic extent then
  // meshes across the rim at the largest extent that is otherwise valid, and says so.
  const PatientModel step = layered_cylinder(
      [](double, double) { return 2.0; }, [](double, double) { return 3.0; },
      [](double, double z) { return z > 4.0 ? 14.0 : 4.0; }, measured);
  const plan::Plan on_step = plan::place_procedure(
      plan::layout_procedure("ellipse", {{"length", 20.0}, {"width", 6.0}}), step, 0, 0, 90);
  o.surface.extent_mm = 0;
  const Simulation across = simulate(step, on_step, o);
  EXPECT_GT(across.wound.continuum.min_jacobian, 0.0);
  EXPECT_GT(across.wound.continuum.node_theta_z.col(1).maxCoeff(), 10.0);  // beyond the wound
  EXPECT_LT(across.max_suture_gap_mm, 1e-6);
  const auto& warnings = across.wound.continuum.mesh.warnings;
  EXPECT_TRUE(std::any_of(warnings.begin(), warnings.end(), [](const std::string& w) {
    return w.find("drops from 9 to") != std::string::npos && w.find("meshed across") != std::string::npos;
  })) << (warnings.empty() ? std::string("no warning") : warnings.front());
  // A slope the bone really has (9 to 39 mm over 30 mm of skin) is meshed.
  const PatientModel ramp = layered_cylinder(
      [](double, double z) { return 2.0 + std::clamp(z - 10.0, 0.0, 30.0) * 20.0 / 30.0; },
      [](double, double z) { return 3.0 + std::clamp(z - 10.0, 0.0, 30.0) * 5.0 / 30.0; },
      [](double, double) { return 4.0; }, measured);
  o.surface.extent_mm = 30.0;
  const plan::Plan on_ramp = plan::place_procedure(
      plan::layout_procedure("ellipse", {{"length", 20.0}, {"width", 6.0}}), ramp, 0, 0, 90);
  const Simulation s = simulate(ramp, on_ramp, o);
  EXPECT_GT(s.wound.continuum.node_theta_z.col(1).maxCoeff(), 20.0);
  EXPECT_GT(s.wound.continuum.min_jacobian, 0.0);
}

TEST(MeasuredLayers, OneMaterialOverThickFatIsSaid) {
  // The cheek below the eye on Cranium: 8.4 of its 14.5 mm of soft tissue are fat, which one
  // material (--tissue uniform, the default) makes as stiff as the dermis: the closing force was
  // 4 x that of the measured layers. The closure says so where the fat under the wound is at
  // least kThickFatMm and 40 % of the soft tissue; not over thin fat, nor with the layers.
  const auto warned = [](const Simulation& s) {
    const auto& w = s.wound.continuum.mesh.warnings;
    return std::any_of(w.begin(), w.end(), [](const std::string& m) {
      return m.find("mm of fat") != std::string::npos && m.find("--tissue auto") != std::string::npos;
    });
  };
  const auto cheek = layered_cylinder([](double, double) { return 3.5; },
                                      [](double, double) { return 8.5; },
                                      [](double, double) { return 2.5; }, measured);
  const auto forehead = layered_cylinder([](double, double) { return 2.0; },
                                         [](double, double) { return 1.0; },
                                         [](double, double) { return 1.5; }, measured);
  SimulateOptions o;
  o.surface.size_mm = 2.0;
  const auto ellipse = [](const PatientModel& m) {
    return plan::place_procedure(
        plan::layout_procedure("ellipse", {{"length", 20.0}, {"width", 6.0}}), m, 0, 0, 90);
  };
  const Simulation thick = simulate(cheek, ellipse(cheek), o);
  EXPECT_TRUE(warned(thick));
  EXPECT_FALSE(warned(simulate(forehead, ellipse(forehead), o)));
  o.continuum.tissue = TissueLayers::Measured;
  const Simulation layered = simulate(cheek, ellipse(cheek), o);
  EXPECT_FALSE(warned(layered));
  // What the warning is about: one material closes the same wound with several times the force.
  EXPECT_GT(thick.result.total_suture_force_n, 2.0 * layered.result.total_suture_force_n);
}

TEST(AutomaticExtent, ShrinksPastOuterSurfaceLayersThatFold) {
  // A C-shaped incision (300 deg of a 10 mm circle, no sutures): the surface mesh's layers grow
  // into the C from both of its arms and collide some 8 mm in, so the full extent (3 x the
  // wound's 20 mm) cannot be meshed, while the wound itself and a smaller extent can.
  const PatientModel model = layered_cylinder([](double, double) { return 2.0; },
                                              [](double, double) { return 3.0; },
                                              [](double, double) { return 4.0; }, measured);
  WoundBorder b;
  const int n = 21;
  std::vector<Eigen::Vector2d> path;
  for (int i = 0; i < n; ++i) {
    const double a = (30.0 + 300.0 * i / (n - 1)) * kPi / 180.0;
    path.push_back(tz(10.0 * std::cos(a), 10.0 * std::sin(a)));
  }
  for (int i = 0; i < n; ++i) b.loop_theta_z.push_back(path[i]);
  for (int i = n - 2; i >= 1; --i) b.loop_theta_z.push_back(path[i]);
  SurfaceMeshOptions s;
  s.size_mm = 2.0;
  ContinuumMeshOptions o;
  o.tissue = TissueLayers::Uniform;
  const WoundMesh w = mesh_wound(b, model, s, o);
  const double full = 3.0 * w.surface.wound_size_mm;
  EXPECT_LT(w.surface.extent_mm, 0.75 * full + 1e-9);
  ASSERT_FALSE(w.continuum.mesh.warnings.empty());
  EXPECT_NE(w.continuum.mesh.warnings[0].find("outer layers from folding"), std::string::npos)
      << w.continuum.mesh.warnings[0];
  // The full extent, given, is refused: the layers do fold there.
  s.extent_mm = full;
  EXPECT_THROW(mesh_wound(b, model, s, o), InvalidParameter);
}
