// One plan on a patient's CT, scan-built and fused models (`caps compare-models`), and the map
// of where a constant thickness misleads (`caps model sensitivity`), on the phantom's CT model:
// - a plan carried to a rigidly moved copy of the model lands on the same skin points and gives
//   the same closure (the difference maps are zero);
// - a face cut from the CT's own skin, moved by a known pose, registered back and fused gives a
//   fused model whose closure equals the CT's (exactly with the scan's colour, within the
//   smoothed skin's offset with its skin), and the plan lands at the same anatomical point on
//   the scan-built model;
// - a scan-built model with twice (half) the CT's thickness needs a larger (smaller) closing force;
// - the sensitivity map is zero where the constant equals the measured thickness, and a map
//   run in two threads equals the one run in one.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <unistd.h>

#include "caps/app/compare_models.hpp"
#include "caps/app/model.hpp"
#include "caps/app/register.hpp"
#include "caps/app/simulation.hpp"
#include "caps/core/error.hpp"
#include "caps/core/units.hpp"
#include "caps/study/compare_models.hpp"
#include "caps/study/thickness_sensitivity.hpp"
#include "caps/image/image_io.hpp"
#include "caps/plan/plan_io.hpp"
#include "caps/plan/procedures.hpp"
#include "caps/render/model_comparison_report.hpp"
#include "caps/render/overlay.hpp"
#include "caps/render/simulation_report.hpp"
#include "caps/surface/patient_model.hpp"
#include "caps/surface/register.hpp"
#include "caps/volume/mesh_io.hpp"
#include "cli_run.hpp"
#include "phantom_model.hpp"

namespace fs = std::filesystem;
using namespace caps;
using nlohmann::json;

namespace {

const fs::path& folder() { return caps_test::program_folder("caps_compare_models"); }

const std::string& model_dir() { return caps_test::program_phantom_model("caps_compare_models"); }

Eigen::Matrix4d pose(double angle_deg, const Eigen::Vector3d& axis, const Eigen::Vector3d& t) {
  Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
  T.topLeftCorner<3, 3>() = Eigen::AngleAxisd(deg_to_rad(angle_deg), axis.normalized()).toRotationMatrix();
  T.topRightCorner<3, 1>() = t;
  return T;
}

// The same model moved by T: its axis moved, its maps unchanged.
PatientModel moved_model(const PatientModel& m, const Eigen::Matrix4d& T) {
  CylindricalMaps maps = m.maps();
  const Eigen::Matrix3d R = T.topLeftCorner<3, 3>();
  maps.axis.origin_lps = R * maps.axis.origin_lps + T.topRightCorner<3, 1>();
  maps.axis.direction = R * maps.axis.direction;
  maps.axis.front = R * maps.axis.front;
  return PatientModel(maps, m.color(), m.source_kind());
}

// A small ellipse on the phantom's forehead, where the face scans below cover the skin.
plan::Plan forehead_ellipse(const PatientModel& model, double theta_deg = 10.0) {
  const CylindricalPoint nose = model.to_cylindrical(model.skin_point(0.0, -20.0));
  return plan::place_procedure(plan::layout_procedure("ellipse", {{"length", 16.0}, {"width", 6.0}}),
                               model, theta_deg, nose.z_mm + 35.0, 70.0);
}

closure::SimulateOptions small_mesh() {
  closure::SimulateOptions o;
  o.surface.size_mm = 2.0;
  o.surface.extent_mm = 16.0;
  return o;
}

// The options `caps compare-models` uses by default (the neo-Hookean closure), on that mesh.
closure::SimulateOptions small_mesh_app_defaults() {
  app::MeshingFields meshing;
  meshing.mesh_size = 2.0;
  meshing.extent = 16.0;
  return app::simulate_options(meshing, app::SolverFields{});
}

// The face of the model's skin.ply (within 60 degrees of the front and 70 mm of the nose's
// height), grey, moved by `model_to_scan`, written as PLY with vertex colours.
void write_face_scan(const fs::path& path, const PatientModel& model, const Eigen::Matrix4d& model_to_scan) {
  const TriMesh skin = read_ply(fs::path(model_dir()) / "skin.ply");
  const CylindricalPoint nose = model.to_cylindrical(model.skin_point(0.0, -20.0));
  std::vector<char> keep(skin.n_vertices());
  for (Eigen::Index v = 0; v < skin.n_vertices(); ++v) {
    const CylindricalPoint c = model.to_cylindrical(skin.V.row(v).transpose());
    keep[v] = std::abs(c.theta_deg) <= 60 && std::abs(c.z_mm - nose.z_mm) <= 70 && c.r_mm > 30;
  }
  TriMesh scan = crop_mesh(skin, keep);
  Eigen::Matrix<std::uint8_t, Eigen::Dynamic, 3> colours(scan.n_vertices(), 3);
  colours.setConstant(150);
  scan.V = transform_points(model_to_scan, scan.V);
  write_ply(scan, path, &colours);
}

}  // namespace

TEST(CompareModels, PlanCarriedToAMovedCopyLandsOnTheSameSkinAndClosesAlike) {
  const PatientModel a = PatientModel::load(model_dir());
  const Eigen::Matrix4d T = pose(14.0, {-1, 0.5, 2}, {-30, 20, 35});
  const PatientModel b = moved_model(a, T);
  const plan::Plan plan = forehead_ellipse(a);
  const study::TransferredPlan moved = study::transfer_plan(plan, a, b, T);
  EXPECT_NEAR(moved.plan.frame.theta_deg, plan.frame.theta_deg, 1e-6);
  EXPECT_NEAR(moved.plan.frame.z_mm, plan.frame.z_mm, 1e-6);
  EXPECT_NEAR(moved.plan.frame.orientation_deg, plan.frame.orientation_deg, 1e-6);
  EXPECT_LT(moved.centre_gap_mm, 1e-6);
  ASSERT_EQ(moved.plan.points.size(), plan.points.size());
  for (std::size_t i = 0; i < plan.points.size(); ++i)
    EXPECT_LT((moved.plan.points[i].lps - transform_points(T, plan.points[i].lps.transpose()).row(0).transpose()).norm(),
              1e-6);

  const closure::SimulateOptions o = small_mesh();
  const study::ModelComparison c =
      study::compare_models({"a", "a", &a, Eigen::Matrix4d::Identity()}, plan, {{"b", "b moved", &b, T}}, o);
  ASSERT_EQ(c.sides.size(), 2u);
  const auto& sa = c.sides[0].summary;
  const auto& sb = c.sides[1].summary;
  EXPECT_GT(sa.closing_force_n, 0.0);
  EXPECT_NEAR(sb.closing_force_n, sa.closing_force_n, 1e-6 * sa.closing_force_n);
  EXPECT_NEAR(sb.max_displacement_mm, sa.max_displacement_mm, 1e-6 * sa.max_displacement_mm);
  EXPECT_NEAR(sb.max_skin_tension_kpa, sa.max_skin_tension_kpa, 1e-6 * sa.max_skin_tension_kpa);
  // The difference maps: zero, every vertex matched.
  const render::SkinSurfaces ka = render::simulated_skin(a, c.sides[0].simulation);
  const render::SkinSurfaces kb = render::simulated_skin(b, c.sides[1].simulation);
  const auto& ma = c.sides[0].simulation;
  const auto& mb = c.sides[1].simulation;
  const render::SkinDifference d = render::skin_difference(
      ka, render::tension_map(ka, ma.wound.continuum.mesh, ma.result.max_principal_mpa).value, kb,
      render::tension_map(kb, mb.wound.continuum.mesh, mb.result.max_principal_mpa).value, T);
  EXPECT_EQ(std::count(d.matched.begin(), d.matched.end(), 1), static_cast<long>(d.matched.size()));
  EXPECT_LT(d.max_displacement_mm, 1e-6);
  EXPECT_LT(d.tension_kpa.cwiseAbs().maxCoeff(), 1e-6 * sa.max_skin_tension_kpa);
  // A known displacement difference: the same skin with its displacement doubled differs by |u|.
  render::SkinSurfaces doubled = ka;
  doubled.post.V = ka.pre.V + 2 * (ka.post.V - ka.pre.V);
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(ka.pre.V.rows());
  const render::SkinDifference d2 = render::skin_difference(ka, zero, doubled, zero, Eigen::Matrix4d::Identity());
  EXPECT_NEAR(d2.max_displacement_mm, (ka.post.V - ka.pre.V).rowwise().norm().maxCoeff(), 1e-9);
}

TEST(CompareModels, ScanCtAndFusedModelsOfOnePhantom) {
  const PatientModel ct = PatientModel::load(model_dir());
  const Eigen::Matrix4d model_to_scan = pose(12.0, {1, -0.4, 1.5}, {25, -40, 15});
  const fs::path scan = folder() / "face.ply";
  write_face_scan(scan, ct, model_to_scan);
  app::RegisterRequest reg;
  reg.input = scan.string();
  reg.to = model_dir();
  reg.scan_scale = 1.0;
  reg.output = (folder() / "reg").string();
  app::run_register(reg);
  app::FuseRequest fu;
  fu.input = scan.string();
  fu.to = model_dir();
  fu.registration = reg.output + "/registration.json";
  fu.output = (folder() / "fused_colour").string();
  app::run_fuse(fu);  // the scan's colour only: the CT's maps
  const std::string fused_colour = fu.output;
  fu.scan_skin = true;
  fu.output = (folder() / "fused").string();
  app::run_fuse(fu);  // the scan's skin over the CT's depths
  const plan::Plan plan = forehead_ellipse(ct);
  const fs::path plan_path = folder() / "ellipse.json";
  plan::write_plan(plan_path, plan);

  // Measured thickness under the wound on the CT model, then scan-built models with twice and
  // half of it.
  const closure::Simulation measured = closure::simulate(ct, plan, small_mesh_app_defaults());
  const double t_ct = study::summarize(measured, ct, "ct").thickness_mean_mm;
  ASSERT_GT(t_ct, 2.0);
  std::map<double, app::CompareModelsResult> results;
  for (double factor : {2.0, 0.5}) {
    app::FromScanRequest fs_req;
    fs_req.input = scan.string();
    fs_req.up = "+z";
    fs_req.front = "-y";
    fs_req.scale = 1.0;
    fs_req.thickness = factor * t_ct;
    fs_req.output = (folder() / ("scan_model_" + std::to_string(factor))).string();
    app::run_from_scan(fs_req);
    app::CompareModelsRequest r;
    r.model = model_dir();
    r.plan = plan_path.string();
    r.scan_model = fs_req.output;
    r.registration = reg.output + "/registration.json";
    r.fused_model = factor == 2.0 ? fu.output : fused_colour;
    r.meshing.mesh_size = 2.0;
    r.meshing.extent = 16.0;
    r.output = (folder() / ("models_" + std::to_string(factor))).string();
    results[factor] = app::run_compare_models(r);
    // The scan model's plan centre lies on the CT's centre once carried back.
    const PatientModel scan_model = PatientModel::load(fs_req.output);
    const auto& side = results[factor].sides.at(1);
    ASSERT_EQ(side.key, "scan");
    EXPECT_LT(side.centre_gap_mm, 0.5);
    const json j = json::parse(results[factor].comparison_json);
    Eigen::Matrix4d M;
    for (int i = 0; i < 4; ++i)
      for (int k = 0; k < 4; ++k) M(i, k) = j.at("sides").at(1).at("placement").at("reference_to_model").at(i).at(k).get<double>();
    const Eigen::Vector3d back = transform_points(M.inverse(), scan_model.skin_point(side.theta_deg, side.z_mm).transpose()).row(0);
    EXPECT_LT((back - ct.skin_point(plan.frame.theta_deg, plan.frame.z_mm)).norm(), 0.7);
    // The direction: carried back, within 2 degrees of the plan's.
    const plan::Plan scan_plan = plan::place_procedure(plan::layout_procedure("ellipse", {{"length", 16.0}, {"width", 6.0}}), scan_model,
                                                       side.theta_deg, side.z_mm, side.orientation_deg);
    const Eigen::Vector3d d_back = (M.topLeftCorner<3, 3>().inverse() * study::plan_direction(scan_plan, scan_model)).normalized();
    EXPECT_GT(d_back.dot(study::plan_direction(plan, ct)), std::cos(deg_to_rad(2.0)));
    for (const char* f : {"report.html", "model_comparison.json", "difference_scan_displacement.png",
                          "difference_scan_tension.png", "difference_fused_displacement.png",
                          "difference_fused_tension.png", "ct/post_plan.png", "scan/post_plan.png",
                          "fused/result.json"})
      EXPECT_TRUE(fs::exists(fs::path(r.output) / f)) << f;
  }
  const auto& twice = results[2.0].sides;
  const auto& half = results[0.5].sides;
  // The CT side is the same run in both. The fused model with the scan's colour only has the
  // CT's maps and closes exactly like it. With the scan's skin it has the skin of the CT
  // model's skin.ply, the smoothed isosurface, which lies a median 0.39 mm inside the CT's range
  // map: the thickness under the wound is 7 % less, the closing force a few % less, the
  // displacement within 2 % and the largest tension, a peak, within 3 % (2.2 % since the
  // wound's floor slides on the base; 2 % before).
  EXPECT_NEAR(twice[0].closing_force_n, half[0].closing_force_n, 1e-9 * twice[0].closing_force_n);
  EXPECT_NEAR(twice[0].closing_force_n, study::summarize(measured, ct, "ct").closing_force_n, 1e-6 * twice[0].closing_force_n);
  ASSERT_EQ(half[2].key, "fused");
  EXPECT_NEAR(half[2].theta_deg, plan.frame.theta_deg, 1e-9);
  EXPECT_NEAR(half[2].closing_force_n, half[0].closing_force_n, 1e-9 * half[0].closing_force_n);
  EXPECT_NEAR(half[2].max_displacement_mm, half[0].max_displacement_mm, 1e-9 * half[0].max_displacement_mm);
  EXPECT_NEAR(twice[2].max_displacement_mm, twice[0].max_displacement_mm, 0.02 * twice[0].max_displacement_mm);
  EXPECT_NEAR(twice[2].max_skin_tension_kpa, twice[0].max_skin_tension_kpa, 0.03 * twice[0].max_skin_tension_kpa);
  EXPECT_LT(twice[2].thickness_mean_mm, twice[0].thickness_mean_mm);
  EXPECT_LT(twice[2].closing_force_n, twice[0].closing_force_n);
  EXPECT_GT(twice[2].closing_force_n, 0.9 * twice[0].closing_force_n);
  // Thicker tissue is stiffer to close: twice the thickness needs more force, half needs less.
  EXPECT_GT(twice[1].closing_force_n, 1.1 * twice[0].closing_force_n);
  EXPECT_LT(half[1].closing_force_n, 0.9 * half[0].closing_force_n);
  EXPECT_NEAR(twice[1].thickness_mean_mm, 2.0 * t_ct, 0.05 * t_ct);

  // The command line: the same verb, and a scan model without its registration refused.
  const auto ok = caps_test::caps("compare-models --model " + model_dir() + " --plan " + plan_path.string() +
                                  " --fused-model " + fused_colour + " --mesh-size 2 --extent 16 -o " +
                                  (folder() / "cli").string() + " --json -q");
  ASSERT_EQ(ok.code, 0) << ok.out;
  const json cli = json::parse(ok.out);
  EXPECT_NEAR(cli.at("sides").at(1).at("closing_force_n").get<double>(), half[2].closing_force_n,
              1e-6 * half[2].closing_force_n);
  const auto refused = caps_test::caps("compare-models --model " + model_dir() + " --plan " + plan_path.string() +
                                       " --scan-model " + (folder() / "scan_model_2.000000").string() + " -o " +
                                       (folder() / "cli2").string());
  EXPECT_EQ(refused.code, 2);
  EXPECT_NE(refused.out.find("--registration"), std::string::npos) << refused.out;
}

TEST(ThicknessSensitivity, ZeroWhereTheConstantIsTheMeasuredAndTheSameInTwoThreads) {
  const PatientModel ct = PatientModel::load(model_dir());
  const CylindricalPoint nose = ct.to_cylindrical(ct.skin_point(0.0, -20.0));
  study::SensitivityOptions o;
  o.parameters = {{"length", 16.0}, {"width", 6.0}};
  o.simulate = small_mesh();
  o.theta_min_deg = -20;
  o.theta_max_deg = 20;
  o.theta_step_deg = 20;
  // Three rows: one on the forehead, two far above the head (they cannot be planned).
  o.z_min_mm = nose.z_mm + 35;
  o.z_step_mm = 250;
  o.z_max_mm = o.z_min_mm + 2 * o.z_step_mm;
  o.threads = 1;
  o.simulate.solve.solver = fem::SolverKind::Cholmod;
  const study::SensitivityMap one = study::thickness_sensitivity(ct, o);
  ASSERT_EQ(one.points.size(), 9u);
  EXPECT_EQ(one.planned, 3);
  for (std::size_t i = 0; i < 3; ++i) EXPECT_TRUE(one.points[i].planned) << one.points[i].reason;
  for (std::size_t i = 3; i < 9; ++i) {
    EXPECT_FALSE(one.points[i].planned);
    EXPECT_FALSE(one.points[i].reason.empty());
  }
  o.threads = 2;
  const study::SensitivityMap two = study::thickness_sensitivity(ct, o);
  for (std::size_t i = 0; i < 9; ++i) {
    EXPECT_EQ(two.points[i].planned, one.points[i].planned);
    EXPECT_DOUBLE_EQ(two.points[i].closing_force_constant_n, one.points[i].closing_force_constant_n);
  }
  // With the constant set to the mean measured thickness under the wound the change is small
  // (the phantom's thickness still varies over the 16 mm around the wound that the mesh covers,
  // which moves the largest displacement most); a constant twice as thick raises the force.
  const study::SensitivityPoint& p = one.points[1];
  o.theta_min_deg = o.theta_max_deg = p.theta_deg;
  o.z_min_mm = o.z_max_mm = p.z_mm;
  o.constant_thickness_mm = p.thickness_mean_mm;
  const study::SensitivityMap same = study::thickness_sensitivity(ct, o);
  ASSERT_EQ(same.planned, 1);
  EXPECT_LT(std::abs(same.points[0].force_change), 0.05);
  EXPECT_LT(std::abs(same.points[0].displacement_change), 0.1);
  o.constant_thickness_mm = 2 * p.thickness_mean_mm;
  const study::SensitivityMap thick = study::thickness_sensitivity(ct, o);
  EXPECT_GT(thick.points[0].force_change, 0.1);
}
