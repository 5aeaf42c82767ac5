// caps::plan: the paper's rules (Figure 2 incision to loop, Figure 1 excision, suture pairs), the
// procedure library against hand-worked loops and suture lists, plan files, and a catalogue of
// plans that cannot be operated. The model is an analytic cylinder built in memory.
#include <gtest/gtest.h>

#include "synthetic_model.hpp"

#include <unistd.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <numeric>

#include "caps/core/data_dir.hpp"
#include "caps/core/error.hpp"
#include "caps/core/json_limits.hpp"
#include "caps/core/units.hpp"
#include "caps/plan/check.hpp"
#include "caps/plan/plan.hpp"
#include "caps/plan/plan_io.hpp"
#include "caps/plan/procedures.hpp"
#include "caps/plan/skin_lines.hpp"

using namespace caps;
using namespace caps::plan;

namespace {

constexpr double kR = 80.0;  // skin radius of the test cylinder, mm

// A cylinder of radius 80 mm, z from -50 to 150 mm, 6 mm of soft tissue, with a patch of cells
// without bone at theta 30..40 deg, z 20..30 mm.
const PatientModel& cylinder() {
  static const PatientModel model = [] {
    CylindricalMaps m = caps_test::synthetic_maps(caps_test::grid(720, 401, -50, 0.5),
                                                  [](double, double) { return kR; },
                                                  [](double, double) { return 6.0; });
    for (int k = 0; k < m.grid.n_z; ++k)
      for (int j = 0; j < m.grid.n_theta; ++j)
        if (m.grid.theta_deg(j) >= 30 && m.grid.theta_deg(j) <= 40 && m.grid.z_mm(k) >= 20 &&
            m.grid.z_mm(k) <= 30)
          m.flags[m.grid.index(j, k)] = kNoBone;
    return PatientModel(std::move(m));
  }();
  return model;
}

Plan placed(const std::string& name, const std::map<std::string, double>& p = {},
            double theta = 0, double z = 60, double orientation = 90) {
  return place_procedure(layout_procedure(name, p), cylinder(), theta, z, orientation);
}

std::vector<SuturePair> pairs(std::initializer_list<std::array<int, 4>> q) {
  std::vector<SuturePair> v;
  for (const auto& x : q) v.push_back({{x[0], x[1]}, {x[2], x[3]}});
  return v;
}

// Every border edge sewn exactly once, and the nodes brought together form consistent groups.
void expect_closed(const Plan& plan) {
  const BorderLoop loop = border_loop(plan);
  std::vector<int> uses(loop.size(), 0);
  for (const auto& s : plan.sutures)
    for (const auto& side : suture_edges(oriented_suture(s, loop.size()), loop.size()))
      for (int e : side) ++uses[e];
  for (int i = 0; i < loop.size(); ++i) EXPECT_EQ(uses[i], 1) << "border edge " << i;
}

}  // namespace

TEST(PlanRules, IncisionToLoopIsFigure2) {
  EXPECT_EQ(incision_to_loop(4), (std::vector<int>{0, 1, 2, 3, 2, 1}));
  EXPECT_EQ(incision_to_loop(2), (std::vector<int>{0, 1}));
  EXPECT_EQ(incision_to_loop(5), (std::vector<int>{0, 1, 2, 3, 4, 3, 2, 1}));
  EXPECT_THROW(incision_to_loop(1), InvalidInput);
  // The walk around a single path is the same rule, whatever the path's shape.
  std::vector<Eigen::Vector2d> xy = {{0, 0}, {5, 3}, {9, -2}, {14, 1}, {20, 0}};
  EXPECT_EQ(walk_around_cut(xy, {{0, 1, 2, 3, 4}}), incision_to_loop(5));
}

TEST(PlanRules, SutureOrientationFollowsTheLoop) {
  // The paper's ellipse and Z-plasty pairs: a meets c, b meets d after orientation.
  EXPECT_EQ(oriented_suture({{0, 1}, {0, 5}}, 6), (std::array<int, 4>{0, 1, 0, 5}));
  EXPECT_EQ(oriented_suture({{1, 2}, {5, 4}}, 6), (std::array<int, 4>{1, 2, 5, 4}));
  EXPECT_EQ(oriented_suture({{2, 3}, {4, 3}}, 6), (std::array<int, 4>{2, 3, 4, 3}));
  EXPECT_EQ(oriented_suture({{5, 0}, {5, 4}}, 6), (std::array<int, 4>{5, 0, 5, 4}));
  EXPECT_EQ(oriented_suture({{2, 1}, {2, 3}}, 6), (std::array<int, 4>{1, 2, 3, 2}));
  EXPECT_EQ(oriented_suture({{0, 1}, {3, 4}}, 6), (std::array<int, 4>{0, 1, 4, 3}));
  EXPECT_THROW(oriented_suture({{0, 2}, {3, 4}}, 6), InvalidInput);
}

TEST(PlanLibrary, ZPlastyIsThePapersFigure2) {
  const Plan plan = placed("z-plasty", {{"length", 20}, {"angle", 60}});
  const BorderLoop loop = border_loop(plan);
  EXPECT_EQ(loop.point, (std::vector<int>{0, 1, 2, 3, 2, 1}));
  EXPECT_LT((loop.local_mm[4] - loop.local_mm[2]).norm(), 1e-9);
  EXPECT_LT((loop.local_mm[5] - loop.local_mm[1]).norm(), 1e-9);
  EXPECT_EQ(plan.sutures, pairs({{5, 0, 5, 4}, {2, 1, 2, 3}, {0, 1, 3, 4}}));
  const WoundBorder w = wound_border(plan);
  EXPECT_EQ(w.sutures, (std::vector<std::array<int, 4>>{{5, 0, 5, 4}, {1, 2, 3, 2}, {0, 1, 4, 3}}));
  ASSERT_EQ(w.loop_theta_z.size(), 6u);
  // Limbs of 20 mm at 60 degrees to the central limb, measured on the skin.
  const PlanReport r = check_plan(plan, cylinder());
  EXPECT_TRUE(r.warnings.empty()) << r.warnings.front();
  EXPECT_NEAR(r.cut_length_mm, 60.0, 0.6);
  const Eigen::Vector2d u = loop.local_mm[0] - loop.local_mm[1], v = loop.local_mm[2] - loop.local_mm[1];
  EXPECT_NEAR(rad_to_deg(std::acos(u.normalized().dot(v.normalized()))), 60.0, 1e-6);
  // The flap tips (nodes 1 and 4) are the acute corners on their tissue side: the tissue lies
  // left of the loop, so the turn there is to the left.
  auto turn = [&](int i) {
    const Eigen::Vector2d a = loop.local_mm[(i + 5) % 6], b = loop.local_mm[i], c = loop.local_mm[(i + 1) % 6];
    const Eigen::Vector2d d1 = b - a, d2 = c - b;
    return d1.x() * d2.y() - d1.y() * d2.x();
  };
  EXPECT_GT(turn(1), 0);
  expect_closed(plan);
}

TEST(PlanLibrary, EllipseIsThePapersFigure1) {
  const Plan plan = placed("ellipse", {{"length", 30}, {"width", 10}});
  const BorderLoop loop = border_loop(plan);
  EXPECT_EQ(loop.point, (std::vector<int>{0, 1, 2, 3, 2, 1}));
  EXPECT_EQ(plan.sutures, pairs({{0, 1, 0, 5}, {1, 2, 5, 4}, {2, 3, 4, 3}}));
  // 4 and 5 started on 2 and 1 and were moved across the axis; 1 and 2 to the other side.
  EXPECT_NEAR(loop.local_mm[1].y(), -loop.local_mm[5].y(), 1e-9);
  EXPECT_NEAR(loop.local_mm[2].y(), -loop.local_mm[4].y(), 1e-9);
  EXPECT_GT(loop.local_mm[1].y(), 3.0);
  EXPECT_NEAR(loop.local_mm[3].x() - loop.local_mm[0].x(), 30.0, 1e-9);
  EXPECT_NEAR(plan.parameters.at("apex_angle"), rad_to_deg(2 * std::atan(10.0 / 30.0)), 1e-9);
  const PlanReport r = check_plan(plan, cylinder());
  EXPECT_TRUE(r.warnings.empty());
  for (const auto& s : r.suture_lengths) EXPECT_NEAR(s.ratio(), 1.0, 0.02);
  expect_closed(plan);
  // The apex angle sets the width.
  const Plan narrow = placed("ellipse", {{"length", 40}, {"apex_angle", 30}});
  EXPECT_NEAR(narrow.parameters.at("width"), 40 * std::tan(deg_to_rad(15)), 1e-9);
}

TEST(PlanLibrary, MultipleZPlastyWalksAroundTheBranchingCut) {
  const Plan plan = placed("multiple-z-plasty", {{"segments", 2}, {"length", 30}});
  const BorderLoop loop = border_loop(plan);
  // Points: centre line 0,1,2; limb ends p0 = 3, p1 = 4, q1 = 5, q2 = 6 (worked by hand in
  // docs/plan.md).
  EXPECT_EQ(loop.point, (std::vector<int>{3, 0, 1, 4, 1, 2, 6, 2, 1, 5, 1, 0}));
  EXPECT_EQ(plan.sutures, pairs({{11, 0, 10, 11}, {1, 2, 8, 9}, {0, 1, 9, 10},
                                 {2, 3, 7, 8}, {4, 5, 5, 6}, {3, 4, 6, 7}}));
  expect_closed(plan);
  EXPECT_TRUE(check_plan(plan, cylinder()).warnings.empty());
  const Plan four = placed("multiple-z-plasty", {{"segments", 4}, {"length", 48}});
  EXPECT_EQ(border_loop(four).size(), 24);
  expect_closed(four);
  EXPECT_NO_THROW(check_plan(four, cylinder()));
}

TEST(PlanLibrary, WPlastySewsEachToothToItsTwin) {
  const Plan plan = placed("w-plasty", {{"length", 30}, {"limb", 6}, {"angle", 60}, {"width", 3}});
  const int m = static_cast<int>(plan.parameters.at("teeth"));
  EXPECT_EQ(m, 9);  // pitch 6 sin 30 = 3 mm over 30 mm: 10 intervals, 9 inner points
  const BorderLoop loop = border_loop(plan);
  EXPECT_EQ(loop.point, incision_to_loop(m + 2));
  ASSERT_EQ(plan.sutures.size(), static_cast<std::size_t>(m + 1));
  EXPECT_EQ(plan.sutures.front(), (SuturePair{{0, 1}, {0, 2 * m + 1}}));
  EXPECT_EQ(plan.sutures.back(), (SuturePair{{m, m + 1}, {m + 2, m + 1}}));
  // The two sides are translates: twins are 3 mm apart across the axis.
  for (int k = 1; k <= m; ++k)
    EXPECT_NEAR((loop.local_mm[k] - loop.local_mm[2 * (m + 1) - k]).norm(), 3.0, 1e-9);
  expect_closed(plan);
  EXPECT_NO_THROW(check_plan(plan, cylinder()));
}

TEST(PlanLibrary, RhomboidFlapClosesWithEqualEdges) {
  const Plan plan = placed("rhomboid", {{"side", 12}});
  const BorderLoop loop = border_loop(plan);
  EXPECT_EQ(loop.point, (std::vector<int>{0, 1, 2, 3, 4, 3, 2, 1}));
  EXPECT_EQ(plan.sutures, pairs({{1, 2, 5, 4}, {3, 2, 3, 4}, {0, 1, 6, 5}, {7, 0, 7, 6}}));
  expect_closed(plan);
  const PlanReport r = check_plan(plan, cylinder());
  EXPECT_TRUE(r.warnings.empty());
  for (const auto& s : r.suture_lengths) {
    EXPECT_NEAR(s.first_mm, 12.0, 0.15);
    EXPECT_NEAR(s.ratio(), 1.0, 0.01);
  }
  // The rhombus: node 5 (C's twin) moved to the corner A, opposite C along the orientation.
  EXPECT_NEAR((loop.local_mm[5] - loop.local_mm[3]).norm(), 12 * std::sqrt(3.0), 1e-9);
}

TEST(PlanFrame, LengthsAndOrientationMeanWhatTheySay) {
  // Orientation 0 points superior: an ellipse along z, 30 mm in z.
  const Plan up = placed("ellipse", {{"length", 30}}, 10, 40, 0);
  EXPECT_NEAR(up.points[3].z_mm - up.points[0].z_mm, 30, 1e-6);
  EXPECT_NEAR(up.points[3].theta_deg - up.points[0].theta_deg, 0, 1e-6);
  // Orientation 90 points towards +theta: 30 mm of arc on a radius of 80 mm.
  const Plan across = placed("ellipse", {{"length", 30}}, 10, 40, 90);
  // The tangent comes from the bilinear (polygonal) skin, so the arc agrees to 0.01 mm.
  EXPECT_NEAR(deg_to_rad(across.points[3].theta_deg - across.points[0].theta_deg) * kR, 30, 0.01);
  EXPECT_NEAR((across.points[3].lps - across.points[0].lps).norm(), 2 * kR * std::sin(15.0 / kR), 0.02);
}

TEST(PlanFrame, PlansStraddleTheSeam) {
  const Plan a = placed("z-plasty", {}, 179.0, 40, 90);
  bool wrapped = false;
  for (const auto& p : a.points) wrapped |= p.theta_deg < 0;
  EXPECT_TRUE(wrapped);
  const PlanReport r = check_plan(a, cylinder());
  EXPECT_NEAR(r.cut_length_mm, 60.0, 0.6);
  const BorderLoop la = border_loop(a), lb = border_loop(placed("z-plasty", {}, 0.0, 40, 90));
  for (int i = 0; i < la.size(); ++i) EXPECT_LT((la.local_mm[i] - lb.local_mm[i]).norm(), 1e-6);
}

TEST(PlanFiles, RoundTripAndUserProcedures) {
  const Plan plan = placed("rhomboid");
  const Plan back = parse_plan_json(plan_to_json(plan), "test");
  EXPECT_EQ(back.sutures, plan.sutures);
  EXPECT_EQ(back.paths, plan.paths);
  EXPECT_EQ(back.procedure, "rhomboid");
  const WoundBorder w1 = wound_border(plan), w2 = wound_border(back);
  EXPECT_EQ(w1.sutures, w2.sutures);
  for (std::size_t i = 0; i < w1.loop_theta_z.size(); ++i)
    EXPECT_LT((w1.loop_theta_z[i] - w2.loop_theta_z[i]).norm(), 1e-9);
  // A plan saved as a procedure and placed elsewhere keeps its topology and shape.
  const LocalProcedure user = parse_procedure_json(procedure_to_json(procedure_from_plan(plan)), "user");
  const Plan again = place_procedure(user, cylinder(), -60, 80, 90);
  EXPECT_EQ(again.sutures, plan.sutures);
  EXPECT_NO_THROW(check_plan(again, cylinder()));
  EXPECT_THROW(parse_plan_json("{\"format\":\"caps-plan\",\"format_version\":2}", "v2"), InvalidInput);
}

TEST(PlanCheck, WarnsOnSuturedEdgesOfDifferentLengths) {
  Plan plan = placed("z-plasty");
  // Stretch the first limb to twice its length: sutures 0 and 2 now sew 40 mm to 20 mm.
  const Eigen::Vector2d p0 = plan.frame.to_local(plan.points[0].theta_deg, plan.points[0].z_mm);
  const Eigen::Vector2d p1 = plan.frame.to_local(plan.points[1].theta_deg, plan.points[1].z_mm);
  const Eigen::Vector2d tz = plan.frame.to_theta_z(p1 + 2 * (p0 - p1));
  plan.points[0].theta_deg = tz[0];
  plan.points[0].z_mm = tz[1];
  const PlanReport r = check_plan(plan, cylinder());
  ASSERT_FALSE(r.warnings.empty());
  EXPECT_NE(r.warnings.front().find("ratio 2.0"), std::string::npos) << r.warnings.front();
}

// The catalogue of plans that cannot be operated: each is refused with InvalidInput and a message
// naming the offending item.
namespace {

Plan custom(std::vector<Eigen::Vector2d> xy, std::vector<std::vector<int>> paths,
            std::vector<SuturePair> sutures = {}, std::vector<ExcisionOffset> ex = {},
            double theta = 0, double z = 60) {
  LocalProcedure p;
  p.points_mm = std::move(xy);
  p.paths = std::move(paths);
  p.sutures = std::move(sutures);
  p.excisions = std::move(ex);
  return place_procedure(p, cylinder(), theta, z, 90);
}

void expect_refused(const std::function<void()>& f, const std::vector<std::string>& words) {
  try {
    f();
    ADD_FAILURE() << "not refused; expected: " << words.front();
  } catch (const InvalidInput& e) {
    for (const auto& w : words)
      EXPECT_NE(std::string(e.what()).find(w), std::string::npos) << e.what() << "\n  lacks: " << w;
  }
}

// arc_side / lobe_side -1 lays the mirror image: the path reversed (so the flap stays on its
// left), the loop the same loop run backwards, every node mirrored across the axis.
void expect_mirror_image(const BorderLoop& a, const BorderLoop& b, int n_path, double tol) {
  ASSERT_EQ(a.size(), b.size());
  const int n = a.size();
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector2d p = a.local_mm[i], q = b.local_mm[(n + n_path - 1 - i) % n];
    EXPECT_LT((p - Eigen::Vector2d(q.x(), -q.y())).norm(), tol) << i;
  }
}

const std::vector<Eigen::Vector2d> kLine = {{0, 0}, {10, 0}, {20, 0}, {30, 0}};

}  // namespace

TEST(PlanCatalogue, BadPlansAreRefusedByName) {
  const auto& M = cylinder();
  auto check = [&](const Plan& p) { return [p, &M] { check_plan(p, M); }; };
  Plan empty = custom(kLine, {{0, 1, 2, 3}});
  empty.points.clear();
  expect_refused(check(empty), {"no points"});                                            // 1
  expect_refused(check(custom(kLine, {})), {"no cutting path"});                          // 2
  expect_refused(check(custom(kLine, {{0}, {0, 1, 2, 3}})), {"path 0", "at least 2"});     // 3
  expect_refused(check(custom(kLine, {{0, 1, 2, 7}})), {"names point 7"});                // 4
  expect_refused(check(custom(kLine, {{0, 1, 1, 2, 3}})), {"repeats point 1"});           // 5
  expect_refused(check(custom(kLine, {{0, 1, 2, 3}, {2, 1}})), {"(2,1)", "cut twice"});   // 6
  expect_refused(check(custom({{0, 0}, {10, 0}, {10, 10}, {0, 10}}, {{0, 1}, {1, 2}, {2, 3}, {3, 1}})),
                 {"close a loop"});                                                        // 7
  expect_refused(check(custom(kLine, {{0, 1, 2}})), {"point 3 is on no cutting path"});   // 8
  expect_refused(check(custom(kLine, {{0, 1}, {2, 3}})), {"point 2", "not connected"});   // 9
  expect_refused(check(custom(kLine, {{1, 0}, {1, 2, 3}})), {"point 1 joins 2"});         // 10
  expect_refused(check(custom({{0, 0}, {10, 10}, {10, 0}, {0, 10}}, {{0, 1, 2, 3}})),
                 {"crosses itself", "(0,1)", "(2,3)"});                                    // 11
  expect_refused(check(custom({{0, 0}, {10, 0}, {5, 0}}, {{0, 1, 2}})),
                 {"overlaps itself", "point 1"});                                          // 12
  expect_refused(check(custom({{0, 0}, {10, 0}, {10.01, 0}}, {{0, 1, 2}})),
                 {"segment (1,2)", "mm long"});                                            // 13
  expect_refused(check(custom(kLine, {{0, 1, 2, 3}}, {}, {{9, {0, 1}}})),
                 {"excision 0", "loop node 9"});                                           // 14
  expect_refused(check(custom(kLine, {{0, 1, 2, 3}}, {}, {{4, {0, 1}}, {4, {0, 2}}})),
                 {"loop node 4", "moved twice"});                                          // 15
  expect_refused(check(custom(kLine, {{0, 1, 2, 3}}, {}, {{1, {0, 3}}, {2, {0, -3}}})),
                 {"border crosses itself", "(1,2)", "(4,5)"});                             // 16
  expect_refused(check(custom(kLine, {{0, 1, 2, 3}}, {}, {{1, {0, -3}}, {5, {0, 3}}})),
                 {"inside out", "loop node 1"});                                           // 16b
  expect_refused(check(custom(kLine, {{0, 1, 2, 3}}, pairs({{0, 2, 3, 4}}))),
                 {"suture 0", "(0,2) is not on the border"});                              // 17
  expect_refused(check(custom(kLine, {{0, 1, 2, 3}}, pairs({{0, 1, 0, 5}, {5, 0, 3, 4}}))),
                 {"border edge (5,0)", "sutures 0 and 1"});                                // 18
  expect_refused(check(custom(kLine, {{0, 1, 2, 3}}, pairs({{0, 1, 1, 0}}))),
                 {"suture 0", "sewn to itself"});                                          // 19
  expect_refused(check(custom(kLine, {{0, 1, 2, 3}}, pairs({{0, 1, 7, 8}}))),
                 {"(7,8) is not on the border"});                                          // 20
  expect_refused(check(custom(kLine, {{0, 1, 2, 3}}, {}, {}, 0, 155)),
                 {"loop node", "outside the model"});                                      // 21
  expect_refused(check(custom(kLine, {{0, 1, 2, 3}}, {}, {}, 35, 25)),
                 {"loop node 0 (point 0)", "no_bone"});                                    // 22
  // The ends are valid, the edge between them crosses the no-bone patch.
  expect_refused(check(custom({{0, 0}, {40, 0}}, {{0, 1}}, {}, {}, 22, 25)),
                 {"loop edge (0,1)", "no_bone"});                                          // 23
  expect_refused([] { layout_procedure("z-plasty", {{"angle", 20}}); },
                 {"z-plasty", "angle = 20", "clinical range [30, 90]"});                   // 24
  expect_refused([] { layout_procedure("x-plasty", {}); }, {"unknown procedure 'x-plasty'"});  // 25
  expect_refused([] { layout_procedure("ellipse", {{"radius", 3}}); }, {"no parameter 'radius'"});  // 26
  expect_refused([] { layout_procedure("ellipse", {{"length", 20}, {"width", 40}}); },
                 {"apex angle"});                                                          // 27
  Plan edited = placed("z-plasty");
  edited.parameters["angle"] = 100;
  expect_refused(check(edited), {"angle = 100", "clinical range"});                        // 28
  Plan nan_point = placed("z-plasty");
  nan_point.points[2].z_mm = NAN;
  expect_refused(check(nan_point), {"point 2", "finite"});                                 // 29
  expect_refused([] { parse_plan_json("{\"format\":\"caps-plan\",\"format_version\":1}", "p.json"); },
                 {"p.json", "frame"});                                                     // 30
  expect_refused([] { layout_procedure("multiple-z-plasty", {{"segments", 12}}); },
                 {"segments = 12"});                                                       // 31
}

TEST(PlanFiles, ErrorsNameThePlanFileAndTheEntry) {
  namespace fs = std::filesystem;
  const fs::path dir = fs::temp_directory_path() / ("caps_test_plan_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  // A path naming a point the plan does not have: the check's message starts with the file and
  // points at the entry.
  Plan plan = placed("z-plasty");
  const std::size_t last = plan.paths[0].size() - 1;
  plan.paths[0][last] = 99;
  const fs::path bad = dir / "bad_path.json";
  write_plan(bad, plan);
  const Plan back = read_plan(bad);
  EXPECT_EQ(back.source, bad.string());
  const std::string pointer = "/paths/0/" + std::to_string(last);
  expect_refused([&] { check_plan_structure(back); }, {bad.string() + ": ", pointer, "names point 99"});
  expect_refused([&] { check_plan(back, cylinder()); }, {bad.string() + ": ", pointer});
  expect_refused([&] { wound_border(back); }, {bad.string() + ": ", pointer});
  // A suture side that is not a border edge, through wound_border() (what the mesher reads).
  Plan sewn = placed("z-plasty");
  sewn.sutures[0].first = {0, 2};
  const fs::path bad_suture = dir / "bad_suture.json";
  write_plan(bad_suture, sewn);
  expect_refused([&] { wound_border(read_plan(bad_suture)); },
                 {bad_suture.string() + ": /sutures/0: ", "(0,2) is not a border edge"});
  // A plan made in memory has no file to name: the message is as before.
  try {
    check_plan_structure(plan);
    ADD_FAILURE() << "not refused";
  } catch (const InvalidInput& e) {
    EXPECT_EQ(std::string(e.what()).rfind("path 0 ", 0), 0u) << e.what();
  }
  // A model folder whose name is not UTF-8 cannot be recorded: refused, nothing written.
  Plan latin = placed("z-plasty");
  latin.model = "/data/mod\xe8le";
  const fs::path out = dir / "latin.json";
  expect_refused([&] { write_plan(out, latin); }, {"mod\\xe8le", "not valid UTF-8"});
  EXPECT_FALSE(fs::exists(out));
  fs::remove_all(dir);
}

TEST(PlanFiles, Utf8IsValidatedByTheStandardsRules) {
  constexpr auto npos = std::string_view::npos;
  EXPECT_EQ(first_invalid_utf8("plan"), npos);
  EXPECT_EQ(first_invalid_utf8("caf\xc3\xa9 \xe2\x82\xac \xf0\x9f\x98\x80"), npos);  // e-acute, euro, emoji
  EXPECT_EQ(first_invalid_utf8("caf\xe9"), 3u);                    // Latin-1 e-acute
  EXPECT_EQ(first_invalid_utf8("a\xc0\xaf"), 1u);                  // overlong '/'
  EXPECT_EQ(first_invalid_utf8("\xed\xa0\x80"), 0u);               // a UTF-16 surrogate
  EXPECT_EQ(first_invalid_utf8("\xf4\x90\x80\x80"), 0u);           // above U+10FFFF
  EXPECT_EQ(first_invalid_utf8("ab\xe2\x82"), 2u);                 // cut inside a character
  EXPECT_EQ(first_invalid_utf8("\x80"), 0u);                       // a lone continuation byte
  EXPECT_NO_THROW(require_utf8("caf\xc3\xa9", "x"));
}

TEST(PlanLibrary, RotationFlapTurnsIntoTheDefect) {
  // Radius 12 mm, defect angle 40 deg, arc 120 deg: arc segments about half the defect's base
  // (4.10 mm) long gives m = 6. Points F0 O1 S2, A1..A5 = 3..7, P8 (worked by hand in docs/plan.md).
  const Plan plan = placed("rotation-flap", {{"radius", 12}, {"defect_angle", 40}, {"arc_angle", 120}});
  EXPECT_EQ(plan.parameters.at("segments"), 6);
  const BorderLoop loop = border_loop(plan);
  EXPECT_EQ(loop.point, incision_to_loop(9));
  EXPECT_EQ(plan.excisions.size(), 1u);
  EXPECT_EQ(plan.excisions[0].loop_index, 15);  // the twin of O
  EXPECT_EQ(plan.sutures, pairs({{0, 1, 1, 2},                                      // corner O
                                 {2, 3, 15, 0}, {3, 4, 14, 15}, {4, 5, 13, 14},   // flap arc
                                 {5, 6, 12, 13}, {6, 7, 11, 12}, {7, 8, 10, 11},  // to outer
                                 {8, 9, 9, 10}}));                                 // corner A5'
  const WoundBorder w = wound_border(plan);
  EXPECT_EQ(w.sutures[0], (std::array<int, 4>{0, 1, 2, 1}));    // F meets S, corner O
  EXPECT_EQ(w.sutures[1], (std::array<int, 4>{2, 3, 0, 15}));   // S meets F, A1 meets M
  EXPECT_EQ(w.sutures[6], (std::array<int, 4>{7, 8, 11, 10}));  // A5 meets A3', P meets A4'
  EXPECT_EQ(w.sutures[7], (std::array<int, 4>{8, 9, 10, 9}));   // corner A5': P meets A4'
  expect_closed(plan);
  // The defect: O' sits in the middle of the base F-S, 2 R sin(20 deg) = 8.21 mm wide.
  const double base = 2 * 12 * std::sin(deg_to_rad(20.0));
  EXPECT_NEAR((loop.local_mm[0] - loop.local_mm[2]).norm(), base, 1e-9);
  EXPECT_LT((loop.local_mm[15] - (loop.local_mm[0] + loop.local_mm[2]) / 2).norm(), 1e-9);
  for (int k = 2; k <= 8; ++k) EXPECT_NEAR(loop.local_mm[k].norm(), 12.0, 1e-9);  // on the arc
  // On the skin: the leading edge and the far edge are both 12 mm; the first flap segments
  // (chord 2 R sin 10 deg = 4.17 mm) are sewn to the base halves (4.10 mm); no warnings.
  const PlanReport r = check_plan(plan, cylinder());
  EXPECT_TRUE(r.warnings.empty()) << r.warnings.front();
  EXPECT_NEAR(r.suture_lengths[0].first_mm, 12.0, 0.1);
  EXPECT_NEAR(r.suture_lengths[0].ratio(), 1.0, 0.01);
  EXPECT_NEAR(r.suture_lengths[1].first_mm, 2 * 12 * std::sin(deg_to_rad(10.0)), 0.05);
  EXPECT_NEAR(r.suture_lengths[1].second_mm, base / 2, 0.05);
  for (const auto& s : r.suture_lengths) EXPECT_LT(s.ratio(), 1.05);
  // What is left over: the outer arc (from F) is longer than the flap's arc by the base; the two
  // pivot-side outer edges closed as a corner take up about that much.
  double flap_mm = 0, outer_mm = base;
  for (int k = 2; k < 8; ++k) flap_mm += (loop.local_mm[k + 1] - loop.local_mm[k]).norm();
  for (int k = 8; k < 14; ++k) outer_mm += (loop.local_mm[k + 1] - loop.local_mm[k]).norm();
  EXPECT_NEAR(outer_mm - flap_mm, base, 1e-9);

  // A back-cut from the pivot towards the centre: path F O S A1..A5 P B, loop of 18; the flap's
  // arc gains the edge P-B, and the corner moves to P'.
  const Plan bc = placed("rotation-flap", {{"radius", 12}, {"defect_angle", 40}, {"arc_angle", 120},
                                           {"back_cut", 4}});
  const BorderLoop lb = border_loop(bc);
  EXPECT_EQ(lb.point, incision_to_loop(10));
  EXPECT_NEAR(lb.local_mm[9].norm(), 8.0, 1e-9);
  EXPECT_EQ(bc.excisions[0].loop_index, 17);
  EXPECT_EQ(bc.sutures, pairs({{0, 1, 1, 2}, {2, 3, 17, 0}, {3, 4, 16, 17}, {4, 5, 15, 16},
                               {5, 6, 14, 15}, {6, 7, 13, 14}, {7, 8, 12, 13}, {8, 9, 11, 12},
                               {9, 10, 10, 11}}));
  expect_closed(bc);
  EXPECT_TRUE(check_plan(bc, cylinder()).warnings.empty());

  // arc_side -1 is the mirror image: the path is reversed so that the same tissue stays on its left,
  // the loop is the same loop run backwards, and the sutured lengths are the same.
  const Plan mir = placed("rotation-flap", {{"radius", 12}, {"defect_angle", 40}, {"arc_angle", 120},
                                            {"arc_side", -1}});
  const BorderLoop lm = border_loop(mir);
  EXPECT_EQ(lm.point, (std::vector<int>{8, 7, 6, 5, 4, 3, 2, 1, 0, 1, 2, 3, 4, 5, 6, 7}));
  EXPECT_EQ(mir.excisions[0].loop_index, 9);
  expect_mirror_image(loop, lm, 9, 1e-9);
  expect_closed(mir);
  const PlanReport rm = check_plan(mir, cylinder());
  EXPECT_TRUE(rm.warnings.empty());
  ASSERT_EQ(rm.suture_lengths.size(), r.suture_lengths.size());

  // Every parameter across its range lays out a closed, checkable plan.
  for (double arc : {60.0, 90.0, 150.0, 180.0})
    for (double delta : {20.0, 40.0, 60.0}) {
      const Plan q = placed("rotation-flap", {{"radius", 15}, {"defect_angle", delta}, {"arc_angle", arc},
                                              {"back_cut", 5}});
      expect_closed(q);
      EXPECT_NO_THROW(check_plan(q, cylinder())) << arc << " " << delta;
    }
  expect_refused([] { layout_procedure("rotation-flap", {{"defect_angle", 75}}); },
                 {"defect_angle = 75", "[20, 60]"});
  expect_refused([] { layout_procedure("rotation-flap", {{"radius", 10}, {"back_cut", 6}}); },
                 {"back_cut = 6", "half the radius"});
  expect_refused([] { layout_procedure("rotation-flap", {{"arc_side", 0}}); }, {"arc_side = 0"});
  expect_refused([] { layout_procedure("rotation-flap", {{"arc_angle", 200}}); }, {"arc_angle = 200"});
}

// The bilobed flap (radius 6 mm, lobes at 45 deg, second lobe 0.75), worked by hand in
// docs/plan.md: path P0 k1..k4 t+5 a1 6 T1 7 a2 8 u+9 v-10 b1 11 T2 12 b2 13 w+14 Q15, loop of 30
// with the twins of k1..k4 (29..26) moved onto the defect's outline t-, c1, F, c2.
TEST(PlanLibrary, BilobedFlapTurnsItsLobesBackIntoARoundDefect) {
  const double r = 6, beta = deg_to_rad(45.0), d = r / std::sin(beta / 2);
  const Plan plan = placed("bilobed", {{"radius", r}});
  EXPECT_NEAR(plan.parameters.at("pivot_distance"), d, 1e-9);  // 15.68 mm = 2.61 r
  EXPECT_EQ(plan.parameters.at("total_angle"), 90);
  const BorderLoop loop = border_loop(plan);
  ASSERT_EQ(loop.point, incision_to_loop(16));
  ASSERT_EQ(plan.excisions.size(), 4u);
  for (int i = 0; i < 4; ++i) EXPECT_EQ(plan.excisions[i].loop_index, 29 - i);
  auto run = [](std::initializer_list<int> a, std::initializer_list<int> b) {
    return SuturePair{BorderRun(a), BorderRun(b)};
  };
  EXPECT_EQ(plan.sutures, (std::vector<SuturePair>{
                              run({0, 1, 2, 3, 4, 5}, {29, 0}),  // corner P: Burow's triangle
                              run({5, 6}, {28, 29}), run({6, 7}, {27, 28}),  // first lobe to
                              run({7, 8}, {26, 27}), run({8, 9}, {25, 26}),  // the defect
                              run({9, 10, 11, 12}, {23, 24, 25}),            // second lobe to the
                              run({12, 13, 14}, {20, 21, 22, 23}),           // first's donor site
                              run({17, 18}, {18, 19}),                       // corner T2'
                              run({16, 17}, {19, 20}),     // its donor site closed
                              run({14, 15}, {15, 16})}));  // corner Q
  expect_closed(plan);
  const WoundBorder w = wound_border(plan);
  EXPECT_EQ(w.sutures[2], (std::array<int, 4>{6, 7, 28, 27}));  // a1 meets c1, T1 meets F
  // The flat layout: P at d on the axis behind the defect's centre; the defect's outline (t-,
  // c1, F, c2, t+) on its circle, F on the axis; T1 at 45 deg and T2 at 90 deg from the axis
  // at P, T1 d + r and T2 d + 2 (0.75 r) from P (the second lobe's tip drawn out).
  const Eigen::Vector2d P = loop.local_mm[0];
  EXPECT_LT((P - Eigen::Vector2d(-d, 0)).norm(), 1e-9);
  for (int i : {25, 26, 27, 28, 29}) EXPECT_NEAR(loop.local_mm[i].norm(), r, 1e-9) << i;
  EXPECT_LT((loop.local_mm[27] - Eigen::Vector2d(r, 0)).norm(), 1e-9);
  auto polar = [&](int i) {
    const Eigen::Vector2d u = loop.local_mm[i] - P;
    return Eigen::Vector2d(u.norm(), rad_to_deg(std::atan2(u.y(), u.x())));
  };
  EXPECT_NEAR(polar(7)[0], d + r, 1e-9);
  EXPECT_NEAR(polar(7)[1], 45, 1e-9);
  EXPECT_NEAR(polar(12)[0], d + 1.5 * r, 1e-9);
  EXPECT_NEAR(polar(12)[1], 90, 1e-9);
  // The defect's teardrop spans the lobe angle at P, its sides tangent to the circle.
  EXPECT_NEAR(polar(29)[1], -22.5, 1e-9);
  EXPECT_NEAR(polar(5)[1], 22.5, 1e-9);
  EXPECT_NEAR(polar(5)[0], d * std::cos(beta / 2), 1e-9);
  // Turned back by the lobe angle about P, the first lobe's cap lies on the defect's: each node
  // lands on the node it is sewn to (t+ on t-, a1 on c1, T1 on F, a2 on c2, u+ on t+).
  const Eigen::Rotation2Dd back(-beta);
  for (int i = 0; i <= 4; ++i)
    EXPECT_LT((P + back * (loop.local_mm[5 + i] - P) - loop.local_mm[29 - i]).norm(), 1e-9) << i;
  // On the skin: no length warning; the Burow's side P..t+ and t-..P are both d cos(beta/2).
  const PlanReport rep = check_plan(plan, cylinder());
  EXPECT_TRUE(rep.warnings.empty()) << rep.warnings.front();
  EXPECT_NEAR(rep.suture_lengths[0].first_mm, d * std::cos(beta / 2), 0.15);
  EXPECT_NEAR(rep.suture_lengths[0].ratio(), 1.0, 0.01);
  for (const auto& s : rep.suture_lengths) EXPECT_LT(s.ratio(), 1.2);

  // lobe_side -1 is the mirror image, the path reversed so that the flap stays on its left.
  const Plan mir = placed("bilobed", {{"radius", r}, {"lobe_side", -1}});
  const BorderLoop lm = border_loop(mir);
  expect_mirror_image(loop, lm, 16, 1e-6);
  expect_closed(mir);
  const PlanReport rm = check_plan(mir, cylinder());
  EXPECT_TRUE(rm.warnings.empty());
  ASSERT_EQ(rm.suture_lengths.size(), rep.suture_lengths.size());
  for (std::size_t i = 0; i < rm.suture_lengths.size(); ++i)
    EXPECT_NEAR(rm.suture_lengths[i].first_mm + rm.suture_lengths[i].second_mm,
                rep.suture_lengths[i].first_mm + rep.suture_lengths[i].second_mm, 0.05)
        << i;

  // Across the parameters' ranges: closed, checkable plans. A second lobe of half the first's
  // width is sewn to the first's donor site at a ratio of 1.94 (suture 6: 7.1 against 13.7 mm at
  // radius 6), which the check warns of: the rest of that site closes by gathering the skin.
  for (double angle : {40.0, 45.0, 55.0})
    for (double k : {0.5, 0.67, 0.9})
      for (double radius : {3.0, 15.0}) {
        const Plan q =
            placed("bilobed", {{"radius", radius}, {"lobe_angle", angle}, {"second_lobe", k}});
        expect_closed(q);
        const PlanReport rq = check_plan(q, cylinder());
        if (k < 0.6) {
          ASSERT_EQ(rq.warnings.size(), 1u) << angle << " " << radius;
          EXPECT_NE(rq.warnings[0].find("suture 6"), std::string::npos) << rq.warnings[0];
        } else {
          EXPECT_TRUE(rq.warnings.empty()) << angle << " " << k << " " << radius;
        }
      }
  expect_refused(
      [] {
        layout_procedure("bilobed", {{"lobe_angle", 90}});
      },
      {"lobe_angle = 90", "[40, 55]"});
  expect_refused(
      [] {
        layout_procedure("bilobed", {{"second_lobe", 1}});
      },
      {"second_lobe = 1", "[0.5, 0.9]"});
  expect_refused([] { layout_procedure("bilobed", {{"lobe_side", 0}}); }, {"lobe_side = 0"});
}

TEST(PlanLibrary, VYAdvancementSewsEachFlapSideToTheOuterArmBeyondTheStem) {
  // Path A0 J1 P2 J3 B4 (apex P, arms 20 mm, J at the advance, 6 mm, from P); loop 0..4 on the
  // flap's side (inside the V, left of the path), twins 5 = J_B', 6 = P', 7 = J_A' outside.
  const Plan plan = placed("v-y-advancement", {{"length", 20}, {"angle", 50}, {"advance", 6}});
  const BorderLoop loop = border_loop(plan);
  EXPECT_EQ(loop.point, (std::vector<int>{0, 1, 2, 3, 4, 3, 2, 1}));
  // The stem (outer arms from the apex, corner P'), then each flap side P..A and P..B as a run
  // of two edges sewn to the single outer edge J'..A and J'..B.
  const std::vector<SuturePair> expected = {{{5, 6}, {6, 7}}, {{0, 1, 2}, {0, 7}}, {{2, 3, 4}, {5, 4}}};
  EXPECT_EQ(plan.sutures, expected);
  // Which nodes meet: J_B' and J_A' (the stem's end), the flap's tip P with both of them (the
  // junction of the Y); P', A and B are closed corners.
  EXPECT_EQ(oriented_suture(plan.sutures[0], 8), (std::array<int, 4>{5, 6, 7, 6}));
  EXPECT_EQ(oriented_suture(plan.sutures[1], 8), (std::array<int, 4>{0, 2, 0, 7}));
  EXPECT_EQ(oriented_suture(plan.sutures[2], 8), (std::array<int, 4>{2, 4, 5, 4}));
  expect_closed(plan);
  // Geometry in the local frame: the V opens along the orientation (+x), 50 deg at the apex.
  const auto& xy = loop.local_mm;
  EXPECT_NEAR((xy[0] - xy[2]).norm(), 20, 1e-6);
  EXPECT_NEAR((xy[1] - xy[2]).norm(), 6, 1e-6);
  EXPECT_NEAR(std::atan2(xy[0].y(), xy[0].x() - xy[2].x()) * 180 / kPi, 25, 1e-6);
  EXPECT_NEAR(std::atan2(xy[4].y(), xy[4].x() - xy[2].x()) * 180 / kPi, -25, 1e-6);
  // Flap sides of 20 mm sewn to 14 mm of outer arm: lengths on the skin, no warning at 1.43;
  // an advance of 9 mm (ratio 1.8) is warned about; more than half the arm is refused.
  const PlanReport r = check_plan(plan, cylinder());
  ASSERT_EQ(r.suture_lengths.size(), 3u);
  EXPECT_NEAR(r.suture_lengths[1].first_mm, 20, 0.05);
  EXPECT_NEAR(r.suture_lengths[1].second_mm, 14, 0.05);
  EXPECT_NEAR(r.suture_lengths[0].first_mm, 6, 0.05);
  EXPECT_NEAR(r.suture_lengths[0].second_mm, 6, 0.05);
  for (const auto& w : r.warnings) EXPECT_EQ(w.find("ratio"), std::string::npos) << w;
  const PlanReport r9 = check_plan(placed("v-y-advancement", {{"advance", 9}}), cylinder());
  bool warned = false;
  for (const auto& w : r9.warnings) warned = warned || w.find("ratio 1.8") != std::string::npos;
  EXPECT_TRUE(warned);
  EXPECT_THROW(layout_procedure("v-y-advancement", {{"length", 20}, {"advance", 11}}), InvalidInput);
}

TEST(PlanRules, RunsAreCheckedAndOrientedLikeEdges) {
  // Runs written either way round mean the same pair; a run must follow the loop one way.
  EXPECT_EQ(oriented_suture({{2, 1, 0}, {7, 0}}, 8), (std::array<int, 4>{0, 2, 0, 7}));
  EXPECT_EQ(oriented_suture({{0, 1, 2}, {0, 7}}, 8), (std::array<int, 4>{0, 2, 0, 7}));
  EXPECT_EQ(oriented_suture({{0, 1}, {5, 6, 7}}, 8), (std::array<int, 4>{0, 1, 7, 5}));
  EXPECT_EQ(suture_edges({0, 2, 0, 7}, 8), (std::array<std::vector<int>, 2>{{{0, 1}, {7}}}));
  EXPECT_EQ(suture_edges({7, 1, 5, 3}, 8), (std::array<std::vector<int>, 2>{{{7, 0}, {3, 4}}}));
  EXPECT_THROW(oriented_suture({{0, 1, 0}, {3, 4}}, 8), InvalidInput);   // turns back
  EXPECT_THROW(oriented_suture({{0, 1, 3}, {5, 6}}, 8), InvalidInput);   // (1,3) not an edge
  EXPECT_THROW(oriented_suture({{0}, {5, 6}}, 8), InvalidInput);         // one node
  EXPECT_EQ(suture_text({{0, 1, 2}, {0, 7}}), "((0,1,2),(0,7))");
}

// Templates lay the geometry asked for, measured on the skin: lengths along the placed polyline
// (straight in (theta, z) between points, as the mesher and check_plan() draw it) and angles
// between the polyline's directions on the skin.
namespace {

double skin_length(const PatientModel& m, Eigen::Vector2d a, Eigen::Vector2d b) {
  b[0] = a[0] + std::remainder(b[0] - a[0], 360.0);
  double len = 0;
  Eigen::Vector3d last = m.skin_point(a[0], a[1]);
  for (int s = 1; s <= 400; ++s) {
    const Eigen::Vector2d t = a + (b - a) * (s / 400.0);
    const Eigen::Vector3d x = m.skin_point(t[0], t[1]);
    len += (x - last).norm();
    last = x;
  }
  return len;
}

// The direction in which the polyline leaves a towards b, on the skin (LPS unit vector).
Eigen::Vector3d skin_direction(const PatientModel& m, Eigen::Vector2d a, Eigen::Vector2d b) {
  b[0] = a[0] + std::remainder(b[0] - a[0], 360.0);
  const Eigen::Vector2d t = a + (b - a) * 1e-3;
  return (m.skin_point(t[0], t[1]) - m.skin_point(a[0], a[1])).normalized();
}

double angle_deg(const Eigen::Vector3d& u, const Eigen::Vector3d& v) {
  return rad_to_deg(std::acos(std::clamp(u.dot(v), -1.0, 1.0)));
}

Eigen::Vector2d tz(const SkinPoint& p) { return {p.theta_deg, p.z_mm}; }

// A curved head-like surface: a sphere of radius 90 mm about z = 0, flattened by 15 % across
// theta (r depends on theta and z), 8 mm of tissue.
const PatientModel& curved() {
  static const PatientModel model(caps_test::synthetic_maps(
      caps_test::grid(1440, 601, -75, 0.25),
      [](double t, double z) {
        return std::sqrt(90.0 * 90.0 - z * z) * (1.0 - 0.15 * std::sin(deg_to_rad(t)) * std::sin(deg_to_rad(t)));
      },
      [](double, double) { return 8.0; }));
  return model;
}

void expect_z_plasty_on_skin(const PatientModel& m, double theta, double z, double orientation) {
  for (double angle : {30.0, 45.0, 60.0, 75.0, 90.0}) {
    const Plan p = place_procedure(layout_procedure("z-plasty", {{"length", 15}, {"angle", angle}}),
                                   m, theta, z, orientation);
    SCOPED_TRACE(::testing::Message() << "angle " << angle << " at " << theta << "," << z);
    for (int i = 0; i < 3; ++i)
      EXPECT_NEAR(skin_length(m, tz(p.points[i]), tz(p.points[i + 1])), 15.0, 0.3) << "limb " << i;
    EXPECT_NEAR(angle_deg(skin_direction(m, tz(p.points[1]), tz(p.points[0])),
                          skin_direction(m, tz(p.points[1]), tz(p.points[2]))), angle, 1.0);
    EXPECT_NEAR(angle_deg(skin_direction(m, tz(p.points[2]), tz(p.points[3])),
                          skin_direction(m, tz(p.points[2]), tz(p.points[1]))), angle, 1.0);
  }
}

void expect_ellipse_on_skin(const PatientModel& m, double theta, double z) {
  // Horizontal (orientation 90): 30 x 10 mm, apex angle 2 atan(1/3) = 36.87 deg.
  const Plan q = place_procedure(layout_procedure("ellipse", {{"length", 30}, {"width", 10}}), m,
                                 theta, z, 90);
  const BorderLoop loop = border_loop(q);
  const auto& n = loop.theta_z;
  double axis_mm = 0;  // the surgeon's points 0..3 along the axis, apex to apex
  for (int i = 0; i < 3; ++i) axis_mm += skin_length(m, tz(q.points[i]), tz(q.points[i + 1]));
  EXPECT_NEAR(axis_mm, 30.0, 0.6);
  EXPECT_NEAR((m.skin_point(n[1][0], n[1][1]) - m.skin_point(n[5][0], n[5][1])).norm(), 10.0, 0.2);
  const double apex = rad_to_deg(2 * std::atan(10.0 / 30.0));
  EXPECT_NEAR(angle_deg(skin_direction(m, n[0], n[1]), skin_direction(m, n[0], n[5])), apex, 1.0);
  EXPECT_NEAR(angle_deg(skin_direction(m, n[3], n[2]), skin_direction(m, n[3], n[4])), apex, 1.0);
  // Horizontal: the apices at the same height (the axis tilted less than 1 deg).
  const Eigen::Vector3d a = m.skin_point(n[0][0], n[0][1]), b = m.skin_point(n[3][0], n[3][1]);
  const Eigen::Vector3d axis = m.to_lps(0, 1, 0) - m.to_lps(0, 0, 0);
  EXPECT_LT(std::abs(rad_to_deg(std::asin((b - a).normalized().dot(axis)))), 1.0);
}

}  // namespace

TEST(PlanGeometry, ZPlastyLimbsAndAnglesOnACylinder) {
  expect_z_plasty_on_skin(cylinder(), 0, 60, 90);
  expect_z_plasty_on_skin(cylinder(), 20, 60, 35);
}

TEST(PlanGeometry, ZPlastyLimbsAndAnglesOnACurvedSkin) {
  expect_z_plasty_on_skin(curved(), 45, 40, 90);
  expect_z_plasty_on_skin(curved(), -120, -30, 20);
}

TEST(PlanGeometry, EllipseWidthApexAndLevelOnTheSkin) {
  expect_ellipse_on_skin(cylinder(), 0, 60);
  expect_ellipse_on_skin(curved(), 45, 40);
  expect_ellipse_on_skin(curved(), 100, -35);
}

// The procedure library's declarations are data (data/procedures/library.json); the layouts are
// code. The shipped file declares every layout, in the library's order, with the clinical ranges
// docs/plan.md gives, and a file that does not match the code is refused, naming the entry.
namespace {

std::string shipped_library_text() {
  std::ifstream in(data_file("procedures/library.json"));
  std::ostringstream t;
  t << in.rdbuf();
  return t.str();
}

// Writes `text` as a library file and reads it; the message of the refusal, or "" if accepted.
std::string library_refusal(const std::string& text) {
  const auto file = std::filesystem::temp_directory_path() /
                    ("caps_test_library_" + std::to_string(::getpid()) + ".json");
  std::ofstream(file) << text;
  std::string message;
  try {
    read_procedure_library(file);
  } catch (const InvalidInput& e) {
    message = e.what();
  }
  std::filesystem::remove(file);
  return message;
}

std::string replaced(std::string s, const std::string& from, const std::string& to) {
  const auto at = s.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  if (at != std::string::npos) s.replace(at, from.size(), to);
  return s;
}

}  // namespace

TEST(ProcedureLibrary, TheShippedFileDeclaresEveryLayoutWithItsClinicalRanges) {
  const auto lib = read_procedure_library(data_file("procedures/library.json"));
  std::vector<std::string> names;
  for (const auto& p : lib) names.push_back(p.name);
  EXPECT_EQ(names, (std::vector<std::string>{"ellipse", "z-plasty", "multiple-z-plasty", "w-plasty",
                                             "rhomboid", "rotation-flap", "v-y-advancement",
                                             "bilobed"}));
  // Z-plasty: 30-90 deg (the textbooks' range, docs/plan.md), central limb 20 mm by default.
  const ParameterInfo& angle = lib[1].parameters[1];
  EXPECT_EQ(angle.name, "angle");
  EXPECT_EQ(angle.unit, "deg");
  EXPECT_EQ(angle.default_value, 60);
  EXPECT_EQ(angle.min, 30);
  EXPECT_EQ(angle.max, 90);
  EXPECT_EQ(lib[0].parameters[2].alternative_to, "width");  // the ellipse's apex angle
  // The registry serves what the file says: a default from the file lays the template out.
  EXPECT_EQ(procedure_library().size(), lib.size());
  const LocalProcedure z = layout_procedure("z-plasty", {});
  EXPECT_EQ(z.parameters.at("length"), lib[1].parameters[0].default_value);
  EXPECT_NEAR((z.points_mm[2] - z.points_mm[1]).norm(), 20.0, 1e-12);
}

TEST(ProcedureLibrary, AFileThatDoesNotMatchTheLayoutsIsRefusedNamingTheEntry) {
  const std::string text = shipped_library_text();
  EXPECT_EQ(library_refusal(text), "");
  EXPECT_NE(library_refusal(replaced(text, "\"name\": \"bilobed\"", "\"name\": \"trilobed\""))
                .find("'trilobed' has no layout"),
            std::string::npos);
  EXPECT_NE(library_refusal(R"({"format": "caps-procedure-library", "version": 1, "procedures": []})")
                .find("'bilobed' is missing"),
            std::string::npos);
  EXPECT_NE(library_refusal(replaced(text, "\"default\": 30, \"min\": 5", "\"default\": 3, \"min\": 5"))
                .find("ellipse: the default 3 mm of 'length' is outside its range [5, 150]"),
            std::string::npos);
  EXPECT_NE(library_refusal(replaced(text, "\"name\": \"bilobed\"", "\"name\": \"ellipse\""))
                .find("'ellipse' is listed twice"),
            std::string::npos);
  EXPECT_NE(library_refusal(replaced(text, "caps-procedure-library", "caps-procedure")).find("not a caps procedure library"),
            std::string::npos);
}

TEST(ProcedureLibrary, AMissingDataFolderIsAnErrorNamingCapsDataDir) {
  const auto empty = std::filesystem::temp_directory_path() /
                     ("caps_test_no_data_" + std::to_string(::getpid()));
  std::filesystem::create_directories(empty);
  ::setenv("CAPS_DATA_DIR", empty.c_str(), 1);
  try {
    data_file("procedures/library.json");
    ADD_FAILURE() << "a missing data file was accepted";
  } catch (const IoError& e) {
    EXPECT_NE(std::string(e.what()).find("CAPS_DATA_DIR"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(empty.string()), std::string::npos) << e.what();
  }
  ::unsetenv("CAPS_DATA_DIR");
  std::filesystem::remove_all(empty);
  EXPECT_NO_THROW(data_file("procedures/library.json"));
}

// The relaxed skin tension lines (plan/skin_lines.hpp) laid on the test cylinder (radius 80 mm)
// by a nasion at z 60 and a subnasale at z 10 on the midline theta 0 (h = 50 mm): a point's
// frame is u = 80 |sin theta| / 50 from the midsagittal plane, v = (z - 60) / 50; each zone
// gives the direction Borges's map draws there, mirrored on the patient's right.
// The face the skin lines are laid on: a nasion at z 60 and a subnasale at z 10 on the midline
// theta 0 of the test cylinder.
Landmarks nose_on_the_cylinder() {
  Landmarks lm;
  lm.midline_theta_deg = 0;
  for (const auto& [name, z] : {std::pair<const char*, double>{"nasion", 60.0}, {"subnasale", 10.0}}) {
    Landmark l;
    l.name = name;
    l.found = true;
    l.theta_deg = 0;
    l.z_mm = z;
    lm.items.push_back(l);
  }
  return lm;
}

TEST(SkinLines, BorgessMapLaidOnTheFaceByItsLandmarks) {
  const Landmarks lm = nose_on_the_cylinder();
  const SkinLineMap& map = borges_map();
  EXPECT_EQ(map.zones.size(), 10u);
  EXPECT_NE(map.source.find("Borges"), std::string::npos);
  const auto at = [&](double theta, double z) {
    return skin_line_direction(map, cylinder(), lm, theta, z);
  };
  // The forehead: horizontal; the glabella (6.97 mm from the midline, 10 mm up): vertical.
  EXPECT_EQ(at(0, 100).zone, "forehead");
  EXPECT_NEAR(at(0, 100).orientation_deg, 90, 1e-9);
  EXPECT_EQ(at(5, 70).zone, "glabella");
  EXPECT_NEAR(at(5, 70).orientation_deg, 0, 1e-9);
  // Below the eye, concentric about (0.55, -0.2): at u = 0.8 (theta 30), v = -0.7 (z 25) the
  // radius is (0.25, -0.5), the lines perpendicular to it: atan2(0.5, 0.25) = 63.43 deg from
  // superior towards the patient's left; on the right, mirrored, 116.57 deg.
  const SkinLineDirection cheek = at(30, 25);
  ASSERT_TRUE(cheek.found) << cheek.note;
  EXPECT_EQ(cheek.zone, "infraorbital cheek");
  EXPECT_NEAR(cheek.at.u, 0.8, 1e-3);
  EXPECT_NEAR(cheek.at.v, -0.7, 1e-9);
  EXPECT_NEAR(cheek.at.h_mm, 50, 1e-9);
  EXPECT_NEAR(cheek.orientation_deg, rad_to_deg(std::atan2(0.5, 0.25)), 0.05);
  EXPECT_NEAR(at(-30, 25).orientation_deg, 180 - rad_to_deg(std::atan2(0.5, 0.25)), 0.05);
  EXPECT_FALSE(at(-30, 25).at.left);
  // Beside the mouth, radial from it: at u = 0.3, v = -1.45 the lines run horizontally.
  const SkinLineDirection lips = at(rad_to_deg(std::asin(0.3 * 50 / kR)), 60 - 1.45 * 50);
  EXPECT_EQ(lips.zone, "lips");
  EXPECT_NEAR(lips.orientation_deg, 90, 0.01);
  // Behind the ear, and without a subnasale: not found, saying why.
  EXPECT_FALSE(at(120, 40).found);
  EXPECT_NE(at(120, 40).note.find("behind the ear"), std::string::npos);
  Landmarks no_sn = lm;
  no_sn.items.pop_back();
  const SkinLineDirection none = skin_line_direction(map, cylinder(), no_sn, 0, 100);
  EXPECT_FALSE(none.found);
  EXPECT_NE(none.note.find("subnasale"), std::string::npos);
  // Angles between lines (unoriented): 0..90.
  EXPECT_NEAR(angle_between_lines_deg(10, 170), 20, 1e-12);
  EXPECT_NEAR(angle_between_lines_deg(0, 90), 90, 1e-12);
  EXPECT_NEAR(angle_between_lines_deg(179, 1), 2, 1e-12);
  EXPECT_NEAR(angle_between_lines_deg(45, 45), 0, 1e-12);
  // A map file that is not one is refused, naming the file.
  namespace fs = std::filesystem;
  const fs::path bad =
      fs::temp_directory_path() / ("caps_test_plan_rstl_" + std::to_string(::getpid()) + ".json");
  std::ofstream(bad) << R"({"format": "caps-skin-lines", "zones": [{"name": "x", "u": [1, 0],
                           "v": [0, 1], "lines": {"fixed_deg": 0}}]})";
  try {
    read_skin_line_map(bad.string());
    ADD_FAILURE() << "a zone with u [1, 0] was read";
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find(bad.string()), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("min < max"), std::string::npos) << e.what();
  }
  fs::remove(bad);
}

// The map traced over the test cylinder's face (the landmarks of the test above): every step of
// a line runs along the map's direction at its middle, 1 mm along the skin (r dtheta across, dz
// up, the plan's frame); the forehead's lines keep their height, the glabella's their theta.
TEST(SkinLines, TracedOverTheFaceAlongTheMapsDirection) {
  const Landmarks lm = nose_on_the_cylinder();
  const SkinLineMap& map = borges_map();
  const PatientModel& model = cylinder();
  const std::vector<SkinLinePath> paths = trace_skin_lines(map, model, lm, 10, 5);
  std::map<std::string, int> per_zone;
  double worst_deg = 0;
  std::string worst_zone;
  for (const SkinLinePath& p : paths) {
    ++per_zone[p.zone];
    ASSERT_EQ(p.theta_deg.size(), p.z_mm.size());
    ASSERT_GE(p.theta_deg.size(), 2u);
    EXPECT_LE(p.theta_deg.size(), 11u);  // the seed and at most 5 steps either way
    for (std::size_t i = 1; i < p.theta_deg.size(); ++i) {
      const double across = kR * deg_to_rad(p.theta_deg[i] - p.theta_deg[i - 1]);
      const double up = p.z_mm[i] - p.z_mm[i - 1];
      EXPECT_NEAR(std::hypot(across, up), 1.0, 0.02) << p.zone;
      const SkinLineDirection d =
          skin_line_direction(map, model, lm, 0.5 * (p.theta_deg[i] + p.theta_deg[i - 1]),
                              0.5 * (p.z_mm[i] + p.z_mm[i - 1]));
      ASSERT_TRUE(d.found) << d.note;
      EXPECT_EQ(d.zone, p.zone) << "a line ends at its zone's border";
      const double step_deg = rad_to_deg(std::atan2(across, up));
      const double off = angle_between_lines_deg(step_deg, d.orientation_deg);
      if (off > worst_deg) worst_zone = cat(p.zone, " at u ", d.at.u, ", v ", d.at.v);
      worst_deg = std::max(worst_deg, off);
    }
    if (p.zone == "forehead")
      for (double z : p.z_mm) EXPECT_NEAR(z, p.z_mm.front(), 1e-9);
    if (p.zone == "glabella")
      for (double t : p.theta_deg) EXPECT_NEAR(t, p.theta_deg.front(), 1e-9);
  }
  std::cout << paths.size() << " lines; the steps' worst angle to the map " << worst_deg
            << " deg (" << worst_zone << ")\n";
  // Midpoint steps of 1 mm follow the field to a degree or two; the worst is 5 mm from the
  // outer eye corner, where the crow's feet radiate and a 1 mm step turns by 11 deg.
  EXPECT_LT(worst_deg, 2.5);
  for (const char* zone : {"forehead", "glabella", "nose", "lateral canthus", "eyelids and brows",
                           "infraorbital cheek", "nasolabial cheek", "lips", "preauricular cheek"})
    EXPECT_GT(per_zone[zone], 0) << zone;
  // Without a subnasale: no line, and the reason.
  Landmarks no_sn = lm;
  no_sn.items.pop_back();
  std::string note;
  EXPECT_TRUE(trace_skin_lines(map, model, no_sn, 10, 5, &note).empty());
  EXPECT_NE(note.find("subnasale"), std::string::npos) << note;
  EXPECT_THROW(trace_skin_lines(map, model, lm, 3, 5), InvalidParameter);
  EXPECT_THROW(trace_skin_lines(map, model, lm, 10, 0.5), InvalidParameter);
  EXPECT_THROW(trace_skin_lines(map, model, lm, 10, 31), InvalidParameter);
}
