// Local charts (caps model chart, surface/chart.hpp): the CT measured again on a cylinder whose
// axis faces the skin at one point. Checked on the analytic face phantom, on the flank of its
// nose, where the head's own rays meet the skin obliquely: the chart's centre is the same skin
// point, its ray runs along the skin's normal, and its tissue depth there is the phantom's own
// depth along that normal; a plan at the chart's centre meshes and closes. caps plan new makes a
// chart itself where the head's image cannot hold the skin under a plan.

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "caps/app/model.hpp"
#include "caps/app/plan.hpp"
#include "caps/app/simulation.hpp"
#include "caps/app/suggest.hpp"
#include "caps/core/error.hpp"
#include "caps/core/plane_geometry.hpp"
#include "caps/plan/check.hpp"
#include "caps/plan/plan_io.hpp"
#include "caps/surface/chart.hpp"
#include "caps/surface/patient_model.hpp"
#include "caps/volume/phantom.hpp"
#include "phantom_model.hpp"

namespace fs = std::filesystem;
using namespace caps;

namespace {

constexpr double kPi = 3.14159265358979323846;

// The face phantom at 1.5 mm voxels and its whole-head model (256 x 128 grid), made once.
struct Fixture {
  fs::path dir;
  std::string ct, model;
};
const Fixture& fixture() {
  static const Fixture f = [] {
    Fixture x;
    x.dir = caps_test::program_folder("caps_test_chart");
    app::PhantomRequest ph;
    ph.output = (x.dir / "ct.nii.gz").string();
    ph.voxels = "171,171,160";
    ph.spacing = "1.5,1.5,1.5";
    ph.face = true;
    app::run_phantom(ph);
    app::FromVolumeRequest fv;
    fv.input = ph.output;
    fv.output = (x.dir / "model").string();
    fv.n_theta = 256;
    fv.n_z = 128;
    app::run_from_volume(fv);
    x.ct = ph.output;
    x.model = fv.output;
    return x;
  }();
  return f;
}

// The angle (deg) between the model's ray at (theta, z) and its skin normal there.
double ray_to_normal_deg(const PatientModel& m, double theta_deg, double z_mm) {
  const Eigen::Vector3d ray = m.axis().ray(theta_deg * kPi / 180.0);
  return std::acos(std::clamp(ray.dot(m.skin_normal(theta_deg, z_mm)), -1.0, 1.0)) * 180.0 / kPi;
}

// The phantom's soft-tissue depth from the skin point p inward along -n: the first point whose
// distance from the phantom's axis is within its analytic bone radius.
double analytic_depth(const HeadPhantom& ph, const Eigen::Vector3d& p, const Eigen::Vector3d& n) {
  for (double s = 0; s < 80; s += 0.01) {
    const Eigen::Vector3d q = p - s * n - ph.axis_point();
    const double theta = std::atan2(q.x(), -q.y());
    if (std::hypot(q.x(), q.y()) <= ph.bone_radius(theta, q.z())) return s;
  }
  return -1;
}

}  // namespace

TEST(Chart, FacesTheFlankOfTheNoseAndMeasuresTheTissueAlongItsNormal) {
  const Fixture& f = fixture();
  const PatientModel parent = PatientModel::load(f.model);
  // The nose's flank at the phantom's nose height (z -12 mm of the phantom, whose axis point is
  // at LPS z 0): the cell beside the midline where the head's ray meets the skin most obliquely.
  const double z = -12.0 - parent.axis().origin_lps.z();
  double theta = 0, worst = 0;
  for (double t = 2; t <= 30; t += 0.5)
    if (const double a = ray_to_normal_deg(parent, t, z); a > worst) {
      worst = a;
      theta = t;
    }
  ASSERT_GT(worst, 35.0) << "the nose's flank should face away from the head's axis";

  app::ChartRequest r;
  r.model = f.model;
  r.at = std::to_string(theta) + "," + std::to_string(z);
  r.output = (f.dir / "chart").string();
  const app::ModelResult res = app::run_chart(r);
  const PatientModel chart = PatientModel::load(r.output);
  const auto j = nlohmann::json::parse(res.model_json);
  ASSERT_TRUE(j.at("source").contains("chart"));
  EXPECT_EQ(j.at("source").at("chart").at("parent_content_hash"), parent.content_hash());

  // The centre is the parent's skin point, seen along the skin's normal.
  const Eigen::Vector3d p = parent.skin_point(theta, z);
  EXPECT_LT((chart.skin_point(0, 0) - p).norm(), 0.4);
  EXPECT_NEAR(chart.r_skin(0, 0), r.radius, 0.4);
  EXPECT_TRUE(flags_valid(chart.flags_at(0, 0))) << describe_flags(chart.flags_at(0, 0));
  EXPECT_LT(ray_to_normal_deg(chart, 0, 0), 8.0);
  const Eigen::Vector3d n = chart.axis().front;
  EXPECT_GT(n.dot(parent.skin_normal(theta, z)), std::cos(12.0 * kPi / 180.0));

  // The tissue under the centre along the chart's ray is the phantom's depth along the normal
  // (to a voxel's partial volume; the parent's oblique radial column there is another length).
  const HeadPhantom ph(false, false, true);
  const double depth = analytic_depth(ph, chart.skin_point(0, 0), n);
  ASSERT_GT(depth, 0);
  EXPECT_NEAR(chart.thickness(0, 0), depth, 1.0);
  EXPECT_GT(std::abs(parent.thickness(theta, z) - depth), 2.0);

  // A plan at the chart's centre meshes and closes.
  app::PlanNewRequest pn;
  pn.procedure = "ellipse";
  pn.model = r.output;
  pn.at = "0,0";
  pn.parameters = {{"length", 12.0}, {"width", 4.0}};
  pn.output = (f.dir / "ellipse.json").string();
  app::run_plan_new(pn);
  app::SimulateRequest sr;
  sr.model = r.output;
  sr.plan = pn.output;
  sr.output = (f.dir / "sim").string();
  const app::SimulateResult s = app::run_simulate(sr);
  EXPECT_EQ(s.inverted_elements, 0);
  EXPECT_GT(s.closing_force_n, 0.0);
}

TEST(Chart, RefusesAChartOfAChartAndBadOptions) {
  const Fixture& f = fixture();
  app::ChartRequest r;
  r.model = f.model;
  r.at = "10,0";
  r.output = (f.dir / "chart2").string();
  r.radius = -5;
  EXPECT_THROW(app::run_chart(r), InvalidInput);
  r.radius = 60;
  r.at = "10,900";  // beyond the model's rows
  EXPECT_THROW(app::run_chart(r), InvalidInput);
  r.at = "10,0";
  app::run_chart(r);
  app::ChartRequest again = r;
  again.model = r.output;
  again.output = (f.dir / "chart3").string();
  try {
    app::run_chart(again);
    FAIL() << "a chart of a chart was accepted";
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("itself a chart"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(again.output));
  // A parent whose model.json records an option of the wrong type (hand-edited) is bad input
  // naming the field, not an internal error.
  const fs::path edited = f.dir / "edited_model";
  fs::remove_all(edited);
  fs::copy(f.model, edited, fs::copy_options::recursive);
  {
    nlohmann::json j = nlohmann::json::parse(std::ifstream(edited / "model.json"));
    j["thickness"]["base"]["bone_cap_mm"] = "deep";
    std::ofstream(edited / "model.json") << j.dump();
  }
  app::ChartRequest bad = r;
  bad.model = edited.string();
  bad.output = (f.dir / "chart4").string();
  try {
    app::run_chart(bad);
    FAIL() << "a string bone cap was accepted";
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("/thickness/base/bone_cap_mm = \"deep\" is not a number"),
              std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(bad.output));
}

TEST(Chart, FrameGeometry) {
  // A point on the +x side, normal +x, model axis +z: the chart's axis is +z through the point
  // moved 40 mm along -x, theta 0 along +x.
  const ChartFrame c =
      chart_frame({50, 0, 10}, {2, 0, 0}, {0, 0, 1}, {0, -1, 0}, 40.0);
  EXPECT_LT((c.axis.origin_lps - Eigen::Vector3d(10, 0, 10)).norm(), 1e-12);
  EXPECT_LT((c.axis.direction - Eigen::Vector3d(0, 0, 1)).norm(), 1e-12);
  EXPECT_LT((c.axis.to_lps(0, 0, 40) - Eigen::Vector3d(50, 0, 10)).norm(), 1e-12);
  // At the vertex (normal along the model's axis) the fallback keeps the axis defined.
  const ChartFrame top = chart_frame({0, 0, 90}, {0, 0, 1}, {0, 0, 1}, {0, -1, 0}, 40.0);
  EXPECT_NEAR(top.axis.direction.dot(Eigen::Vector3d(0, 0, 1)), 0.0, 1e-12);
  EXPECT_NEAR(std::abs(top.axis.direction.y()), 1.0, 1e-12);
  EXPECT_THROW(chart_frame({0, 0, 0}, {0, 0, 0}, {0, 0, 1}, {0, -1, 0}, 40.0), InvalidInput);
  EXPECT_THROW(chart_frame({0, 0, 0}, {1, 0, 0}, {0, 0, 1}, {0, -1, 0}, 0.0), InvalidInput);
}

TEST(Chart, PlanNewMakesOneWhereTheHeadsImageCannotHoldTheSkin) {
  // The phantom head's rays graze its vertex (z ~100 mm): a plan there is refused on the head's
  // model, and caps plan new places it on a local chart facing that skin instead, made beside
  // the plan; plan check, mesh and simulate given the head's model take the chart.
  const Fixture& f = fixture();
  const fs::path dir = f.dir / "auto";
  fs::remove_all(dir);
  fs::create_directories(dir);
  app::PlanNewRequest pn;
  pn.procedure = "ellipse";
  pn.model = f.model;
  pn.at = "0,99";
  pn.parameters = {{"length", 12.0}, {"width", 4.0}};
  pn.output = (dir / "vertex.json").string();
  const fs::path chart = dir / "vertex.chart";

  // Asked not to: refused as before, with nothing written.
  pn.no_chart = true;
  EXPECT_THROW(app::run_plan_new(pn), plan::SkinNotHeld);
  EXPECT_FALSE(fs::exists(pn.output));
  EXPECT_FALSE(fs::exists(chart));

  pn.no_chart = false;
  const app::PlanResult made = app::run_plan_new(pn);
  EXPECT_EQ(made.chart, chart.string());
  ASSERT_TRUE(fs::is_regular_file(chart / "model.json"));
  for (const auto& e : fs::directory_iterator(dir))  // nothing left aside
    EXPECT_EQ(e.path().filename().string().find(".making"), std::string::npos) << e.path();
  bool said = false;
  for (const std::string& w : made.warnings) said |= w.find("local chart") != std::string::npos;
  EXPECT_TRUE(said);
  const plan::Plan p = plan::read_plan(pn.output);
  const PatientModel parent = PatientModel::load(f.model);
  const PatientModel on = PatientModel::load(chart.string());
  EXPECT_EQ(fs::path(p.model).filename(), "vertex.chart");
  EXPECT_EQ(p.model_hash, on.content_hash());
  const auto source = nlohmann::json::parse(std::ifstream(chart / "model.json")).at("source");
  EXPECT_EQ(source.at("chart").at("parent_content_hash"), parent.content_hash());
  EXPECT_TRUE(fs::path(source.at("chart").at("parent").get<std::string>()).is_absolute());
  // The plan lies at the chart's centre, the head's skin point at (0, 99) seen along its normal;
  // the chart's image holds the skin all round it.
  EXPECT_NEAR(p.frame.theta_deg, 0.0, 1e-9);
  EXPECT_NEAR(p.frame.z_mm, 0.0, 1e-9);
  EXPECT_LT((on.skin_point(0, 0) - parent.skin_point(0, 99)).norm(), 1.0);
  EXPECT_TRUE(flags_valid(on.flags_at(0, 0))) << describe_flags(on.flags_at(0, 0));

  // Again without --force: the chart is not replaced and no plan is written over.
  const auto chart_time = fs::last_write_time(chart / "model.json");
  fs::remove(pn.output);
  EXPECT_THROW(app::run_plan_new(pn), InvalidInput);
  EXPECT_FALSE(fs::exists(pn.output));
  EXPECT_EQ(fs::last_write_time(chart / "model.json"), chart_time);
  pn.force = true;
  app::run_plan_new(pn);

  // The head's model named: the plan is checked and closed on its chart, and says so.
  app::PlanCheckRequest pc;
  pc.plan = pn.output;
  pc.model = f.model;
  EXPECT_EQ(app::run_plan_check(pc).points, 4);
  app::SimulateRequest sr;
  sr.model = f.model;
  sr.plan = pn.output;
  sr.output = (dir / "sim").string();
  sr.domain.domain = "patch";  // the phantom's tissue model stops below the vertex
  sr.solver.material = "linear";
  const app::SimulateResult s = app::run_simulate(sr);
  EXPECT_EQ(s.inverted_elements, 0);
  EXPECT_GT(s.closing_force_n, 0.0);
  EXPECT_LT(s.max_suture_gap_mm, 1e-6);
  said = false;
  for (const std::string& w : s.warnings) said |= w.find("a local chart of") != std::string::npos;
  EXPECT_TRUE(said);
}

// A lesion drawn where the head's image cannot hold the skin (its clicks, LPS points on the
// skin at the vertex, as the planner sends them): caps plan suggest lays every design on a local
// chart facing the lesion, and each design's wound holds every drawn point, and every point 0.9
// of the margin beyond it, seen on that chart (issue 39: the chart's outline had no such check).
TEST(Chart, ADrawnLesionWhereTheHeadsImageCannotHoldItIsHeldOnTheChart) {
  const Fixture& f = fixture();
  const PatientModel parent = PatientModel::load(f.model);
  // A 7 x 3 mm elliptical lesion in the skin's tangent plane at (0, 99), its long axis along
  // LPS x (the skin curves away from that plane by 0.03 mm over 3.5 mm of a 90 mm head).
  const Eigen::Vector3d p = parent.skin_point(0, 99), n = parent.skin_normal(0, 99);
  const Eigen::Vector3d e1 = (Eigen::Vector3d::UnitX() - n.x() * n).normalized(), e2 = n.cross(e1);
  std::vector<Eigen::Vector3d> drawn, beyond;
  std::string text;
  const double margin = 1;
  for (int k = 0; k < 16; ++k) {
    const double a = 2 * kPi * k / 16, x = 3.5 * std::cos(a), y = 1.5 * std::sin(a);
    drawn.push_back(p + x * e1 + y * e2);
    const Eigen::Vector2d out = Eigen::Vector2d(1.5 * std::cos(a), 3.5 * std::sin(a)).normalized();
    beyond.push_back(drawn.back() + 0.9 * margin * (out.x() * e1 + out.y() * e2));
    char point[96];
    std::snprintf(point, sizeof point, "%s%.4f,%.4f,%.4f", k ? ";" : "", drawn.back().x(),
                  drawn.back().y(), drawn.back().z());
    text += point;
  }
  app::SuggestRequest r;
  r.model = f.model;
  r.outline_xyz = text;
  r.margin = margin;
  r.procedures = "ellipse";
  r.step = 45;
  r.refine = 0;
  r.solver.material = "linear";
  r.domain.domain = "patch";  // the phantom's tissue model stops below the vertex
  r.output = (f.dir / "suggest_vertex").string();
  r.force = true;
  const app::SuggestResult s = app::run_plan_suggest(r);
  const nlohmann::json j = nlohmann::json::parse(s.suggestions_json);
  const fs::path chart = fs::path(r.output) / "chart";
  ASSERT_TRUE(fs::is_regular_file(chart / "model.json")) << "the designs were not laid on a chart";
  const PatientModel on = PatientModel::load(chart.string());
  EXPECT_NEAR(j.at("lesion").at("diameter_mm").get<double>(), 7, 0.2);
  ASSERT_EQ(j.at("designs").size(), 4u);
  int held = 0;
  for (const nlohmann::json& d : j.at("designs")) {
    const plan::Plan plan = plan::read_plan(fs::path(r.output) / d.at("plan").get<std::string>());
    EXPECT_EQ(plan.model_hash, on.content_hash()) << d.at("name");
    const std::vector<Eigen::Vector2d> wound = plan::wound_border(plan).loop_theta_z;
    for (const auto* points : {&drawn, &beyond})
      for (std::size_t k = 0; k < points->size(); ++k) {
        const CylindricalPoint c = on.to_cylindrical((*points)[k]);
        EXPECT_TRUE(point_in_polygon(wound, Eigen::Vector2d(c.theta_deg, c.z_mm)))
            << d.at("name") << (points == &drawn ? " drawn point " : " point beyond ") << k;
        ++held;
      }
  }
  EXPECT_EQ(held, 4 * 32);
}
