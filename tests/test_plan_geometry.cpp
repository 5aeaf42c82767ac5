// caps::plan: every template of the library lays the geometry asked for, measured on the skin in
// 3-D (tests/plan_measure.hpp, independent of the laying code): lengths within 2 %, angles and
// the orientation within 1 deg, on analytic phantoms (a cylinder, a sphere, the caps head
// phantom's analytic skin) at flat and strongly curved sites, and on Cranium's forehead and
// temple when the Debian data package is installed.
#include <gtest/gtest.h>

#include "plan_measure.hpp"
#include "synthetic_model.hpp"

#include <cstdio>
#include <filesystem>
#include <map>

#include "caps/core/error.hpp"
#include "caps/core/units.hpp"
#include "caps/plan/plan.hpp"
#include "caps/plan/procedures.hpp"
#include "caps/volume/model.hpp"
#include "caps/volume/phantom.hpp"
#include "caps/volume/read_volume.hpp"

using namespace caps;
using namespace caps::plan;
using caps_test::Measured;

namespace {

constexpr double kLengthTol = 0.02, kAngleTolDeg = 1.0;

// A cylinder of radius 80 mm: developable, so every quantity is exact.
const PatientModel& cylinder() {
  static const PatientModel m(caps_test::synthetic_maps(
      caps_test::grid(1440, 801, -100, 0.25), [](double, double) { return 80.0; },
      [](double, double) { return 6.0; }));
  return m;
}

// A sphere of radius 90 mm centred on the axis at z = 0.
const PatientModel& sphere() {
  static const PatientModel m(caps_test::synthetic_maps(
      caps_test::grid(1440, 641, -80, 0.25),
      [](double, double z) { return std::sqrt(90.0 * 90.0 - z * z); },
      [](double, double) { return 6.0; }));
  return m;
}

// The caps head phantom's analytic skin (volume/phantom.hpp: an ellipsoid 150 x 190 mm across,
// 105 mm above z = 0, with the nose and the marker bump), sampled on a fine grid.
const PatientModel& head() {
  static const PatientModel m = [] {
    const HeadPhantom ph;
    return PatientModel(caps_test::synthetic_maps(
        caps_test::grid(2880, 801, -100, 0.25),
        [&](double t, double z) { return ph.skin_radius(deg_to_rad(t), z); },
        [](double, double) { return 6.0; }));
  }();
  return m;
}

const std::filesystem::path kCranium = "/usr/share/doc/invesalius-examples/examples/Cranium.inv3";

const PatientModel* cranium() {
  static const std::unique_ptr<PatientModel> m = []() -> std::unique_ptr<PatientModel> {
    if (!std::filesystem::exists(kCranium)) return nullptr;
    VolumeModel v = build_volume_model(read_volume(kCranium));
    return std::make_unique<PatientModel>(std::move(v.maps));
  }();
  return m.get();
}

struct Site {
  const char* name;
  const PatientModel* (*model)();
  double theta, z, orientation;
};

const PatientModel* cyl() { return &cylinder(); }
const PatientModel* sph() { return &sphere(); }
const PatientModel* hd() { return &head(); }

// Sites: the cylinder and the sphere (exact shapes), the head phantom's forehead, its steep
// upper forehead (z 75: the radius falls 0.9 mm per mm), its side, the flank of its nose
// (strongly curved) and an oblique one; Cranium's forehead and temple.
const std::vector<Site>& sites() {
  static const std::vector<Site> s = {
      {"cylinder 0,60 h", cyl, 0, 60, 90},
      {"cylinder 20,60 o35", cyl, 20, 60, 35},
      {"sphere 0,0 h", sph, 0, 0, 90},
      {"sphere 45,40 h", sph, 45, 40, 90},
      {"sphere -120,-30 o20", sph, -120, -30, 20},
      {"head 0,40 h", hd, 0, 40, 90},
      {"head 0,75 h", hd, 0, 75, 90},
      {"head 0,75 v", hd, 0, 75, 0},
      {"head 90,20 h", hd, 90, 20, 90},
      {"head 45,60 o30", hd, 45, 60, 30},
      {"head -25,-15 v (nose)", hd, -25, -15, 0},
      {"Cranium 30,110 h (forehead)", cranium, 30, 110, 90},
      {"Cranium 75,100 h (temple)", cranium, 75, 100, 90},
  };
  return s;
}

// The templates with the parameters of the issue (15 mm Z limbs, the 30 x 10 mm ellipse) and
// the library's defaults for the others.
const std::vector<std::pair<std::string, std::map<std::string, double>>>& cases() {
  static const std::vector<std::pair<std::string, std::map<std::string, double>>> c = {
      {"ellipse", {{"length", 30}, {"width", 10}}},
      {"z-plasty", {{"length", 15}, {"angle", 30}}},
      {"z-plasty", {{"length", 15}, {"angle", 60}}},
      {"z-plasty", {{"length", 15}, {"angle", 90}}},
      {"multiple-z-plasty", {}},
      {"w-plasty", {}},
      {"rhomboid", {}},
      {"rotation-flap", {}},
      {"rotation-flap", {{"back_cut", 5}, {"arc_side", -1}}},
      {"v-y-advancement", {}},
      {"bilobed", {}},
      {"bilobed", {{"radius", 5}, {"lobe_angle", 50}, {"second_lobe", 0.6}, {"lobe_side", -1}}},
  };
  return c;
}

std::string label(const std::pair<std::string, std::map<std::string, double>>& c) {
  std::string s = c.first;
  for (const auto& [k, v] : c.second) s += cat(" ", k, "=", v);
  return s;
}

}  // namespace

// The known answers of the measurement itself, on shapes where they are hand-worked: a
// horizontal segment on the cylinder is an arc of the circle (80 mm x the angle); on the
// sphere a meridian is an arc of the great circle, and the angle between a meridian and a
// parallel is 90 deg; the parallel leaves horizontally (90 deg) and the meridian upwards (0).
TEST(PlanMeasure, KnownAnswersOnACylinderAndASphere) {
  using caps_test::skin_angle;
  using caps_test::skin_heading;
  using caps_test::skin_length;
  const Eigen::Vector2d a(0, 10), b(20, 10), c(0, 40);
  EXPECT_NEAR(skin_length(cylinder(), a, b), 80.0 * deg_to_rad(20.0), 1e-3);
  EXPECT_NEAR(skin_length(cylinder(), a, c), 30.0, 1e-6);
  EXPECT_NEAR(skin_length(sphere(), {10, 0}, {10, 45}), 90.0 * std::asin(0.5), 2e-3);
  EXPECT_NEAR(skin_angle(sphere(), {10, 20}, {30, 20}, {10, 40}), 90.0, 1e-3);
  EXPECT_NEAR(skin_heading(sphere(), {10, 20}, {30, 20}, {10, 20}), 90.0, 1e-3);
  EXPECT_NEAR(skin_heading(sphere(), {10, 20}, {10, 40}, {10, 20}), 0.0, 1e-3);
  EXPECT_NEAR(skin_heading(cylinder(), {10, 20}, {10, 0}, {10, 20}), 180.0, 1e-3);
  // Across the seam at theta = +-180.
  EXPECT_NEAR(skin_length(cylinder(), {175, 0}, {-175, 0}), 80.0 * deg_to_rad(10.0), 1e-3);
}

// Every template at every site: lengths within 2 %, angles within 1 deg, the orientation within
// 1 deg, for every quantity a parameter sets. Quantities that close a figure (the rhombus's
// corners, the W-plasty's moved sides: Measured::closure) are asserted where the (theta, z)
// chart's straight lines are the skin's geodesics (the cylinder, the sphere's equator) and
// reported elsewhere. The table (worst errors per template and site) is printed for
// docs/plan.md.
TEST(PlanGeometry, EveryTemplateLaysWhatWasAskedOnTheSkin) {
  std::printf(
      "| site | template | length | angle | orientation | closure length | closure angle "
      "| derived length | derived angle |\n");
  for (const Site& site : sites()) {
    const PatientModel* m = site.model();
    if (!m) {
      std::printf("| %s | (Cranium.inv3 not installed) | | | | | | | |\n", site.name);
      continue;
    }
    const bool chart_flat = site.model == cyl || std::string(site.name) == "sphere 0,0 h";
    for (const auto& c : cases()) {
      SCOPED_TRACE(::testing::Message() << site.name << ": " << label(c));
      const LocalProcedure proc = layout_procedure(c.first, c.second);
      const Plan plan = place_procedure(proc, *m, site.theta, site.z, site.orientation);
      const std::vector<Measured> v = caps_test::measure_plan(proc, plan, *m);
      using caps_test::Kind;
      const caps_test::WorstError w = caps_test::worst(v, Kind::kByConstruction),
                                  k = caps_test::worst(v, Kind::kClosure),
                                  d = caps_test::worst(v, Kind::kDerived);
      auto pct = [](double x, const std::string& what) {
        return cat(std::round(x * 1e4) / 100, " % (", what, ")");
      };
      auto deg = [](double x, const std::string& what) {
        return cat(std::round(x * 100) / 100, " deg (", what, ")");
      };
      std::printf("| %s | %s | %s | %s | %.2f deg | %s | %s | %s | %s |\n", site.name,
                  label(c).c_str(), pct(w.length_rel, w.length_what).c_str(),
                  deg(w.angle_deg, w.angle_what).c_str(),
                  std::max(w.orientation_deg, k.orientation_deg),
                  pct(k.length_rel, k.length_what).c_str(), deg(k.angle_deg, k.angle_what).c_str(),
                  pct(d.length_rel, d.length_what).c_str(), deg(d.angle_deg, d.angle_what).c_str());
      for (const Measured& x : v) {
        if (!x.requested || (x.closure && !chart_flat)) continue;
        if (x.kind == 'L')
          EXPECT_LE(x.error(), kLengthTol)
              << x.what << ": asked " << x.asked << " mm, measured " << x.measured << " mm";
        else if (x.kind == 'A')
          EXPECT_LE(std::abs(x.error()), kAngleTolDeg)
              << x.what << ": asked " << x.asked << " deg, measured " << x.measured << " deg";
      }
      EXPECT_LE(w.orientation_deg, kAngleTolDeg);
      if (chart_flat) EXPECT_LE(k.orientation_deg, kAngleTolDeg);
    }
  }
}

// The issue's numbers, as asked: the 30 x 10 mm ellipse is 30 mm long and 10 mm wide on the
// skin with an apex of 2 atan(10/30) = 36.87 deg (at 3, the apex laid; the other within 1 deg
// here, at the phantom's forehead) and a level axis; 15 mm Z limbs are 15 mm.
TEST(PlanGeometry, TheIssuesEllipseAndZPlastyOnTheHeadPhantom) {
  const PatientModel& m = head();
  const LocalProcedure e = layout_procedure("ellipse", {{"length", 30}, {"width", 10}});
  const Plan pe = place_procedure(e, m, 0, 40, 90);
  const auto tz = wound_border(pe).loop_theta_z;
  EXPECT_NEAR(caps_test::skin_length(m, tz[1], tz[5]), 10.0, 0.2);
  EXPECT_NEAR(caps_test::skin_length(m, tz[0], tz[3]), 30.0, 0.6);
  EXPECT_NEAR(caps_test::skin_angle(m, tz[0], tz[1], tz[5]), 36.87, 1.0);
  EXPECT_NEAR(caps_test::skin_angle(m, tz[3], tz[2], tz[4]), 36.87, 1.0);
  EXPECT_NEAR(caps_test::skin_heading(m, tz[0], tz[3], {0, 40}), 90.0, 1.0);
  const LocalProcedure z = layout_procedure("z-plasty", {{"length", 15}, {"angle", 60}});
  const Plan pz = place_procedure(z, m, 0, 75, 90);
  for (int i = 0; i < 3; ++i) {
    const Eigen::Vector2d a(pz.points[i].theta_deg, pz.points[i].z_mm);
    const Eigen::Vector2d b(pz.points[i + 1].theta_deg, pz.points[i + 1].z_mm);
    EXPECT_NEAR(caps_test::skin_length(m, a, b), 15.0, 0.3) << "limb " << i;
  }
}

// laid_from travels with a procedure file, and a bad one is refused when the plan is laid.
TEST(PlanGeometry, LaidFromInProcedureFiles) {
  const LocalProcedure rot = layout_procedure("rotation-flap", {});
  ASSERT_EQ(rot.laid_from.size(), rot.points_mm.size());
  const LocalProcedure back = parse_procedure_json(procedure_to_json(rot), "rot.json");
  EXPECT_EQ(back.laid_from, rot.laid_from);
  // Laid from the file, the flap is the library's: the same points on the sphere.
  const Plan a = place_procedure(rot, sphere(), 45, 40, 90),
             b = place_procedure(back, sphere(), 45, 40, 90);
  for (std::size_t i = 0; i < a.points.size(); ++i) {
    EXPECT_NEAR(a.points[i].theta_deg, b.points[i].theta_deg, 1e-9);
    EXPECT_NEAR(a.points[i].z_mm, b.points[i].z_mm, 1e-9);
  }
  LocalProcedure cyc = rot;
  cyc.laid_from[0] = 1;
  cyc.laid_from[1] = 0;
  EXPECT_THROW(place_procedure(cyc, sphere(), 45, 40, 90), InvalidInput);
  LocalProcedure wrong = rot;
  wrong.laid_from.pop_back();
  EXPECT_THROW(place_procedure(wrong, sphere(), 45, 40, 90), InvalidInput);
  std::string text = procedure_to_json(rot);
  text.replace(text.find("\"laid_from\""), 11, "\"laid_from\": [0], \"x\"");
  EXPECT_THROW(parse_procedure_json(text, "bad.json"), InvalidInput);
}

// The plan simulated on Cranium's nasal sidewall (docs/fem.md: `caps plan new bilobed --at 4,57
// --orientation 270 --radius 5`), where the skin is steep to the model's rays: what it asks is
// laid within 2 % / 1 deg there too. (Not every template is: the Z-plasty's angles come out
// 1.9 deg wide at this site, docs/plan.md.)
TEST(PlanGeometry, BilobedOnCraniumsNasalSidewall) {
  const PatientModel* m = cranium();
  if (!m) GTEST_SKIP() << kCranium << " not installed";
  const LocalProcedure proc = layout_procedure("bilobed", {{"radius", 5}});
  const Plan plan = place_procedure(proc, *m, 4, 57, 270);
  const std::vector<Measured> v = caps_test::measure_plan(proc, plan, *m);
  int n = 0;
  for (const Measured& x : v) {
    if (!x.requested || x.closure) continue;
    ++n;
    if (x.kind == 'L') EXPECT_LE(x.error(), kLengthTol) << x.what << ": " << x.measured << " mm";
    if (x.kind == 'A') EXPECT_LE(x.error(), kAngleTolDeg) << x.what << ": " << x.measured << " deg";
  }
  EXPECT_GT(n, 20);
  const caps_test::WorstError w = caps_test::worst(v, caps_test::Kind::kByConstruction),
                              d = caps_test::worst(v, caps_test::Kind::kDerived);
  std::printf("bilobed radius 5 at Cranium 4,57 o270: %d quantities asked, worst %.2f %% (%s), "
              "%.2f deg (%s); derived worst %.2f %% (%s), %.2f deg (%s)\n",
              n, 100 * w.length_rel, w.length_what.c_str(), w.angle_deg, w.angle_what.c_str(),
              100 * d.length_rel, d.length_what.c_str(), d.angle_deg, d.angle_what.c_str());
}
