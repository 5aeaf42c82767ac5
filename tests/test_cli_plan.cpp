// `caps plan` as a user runs it on a small phantom model: plans are made, checked and drawn; bad
// plans and bad options exit with code 2, a message naming the problem, and no output file.
#include <gtest/gtest.h>

#include "cli_run.hpp"

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

namespace fs = std::filesystem;

namespace {

using caps_test::CliRun;
using caps_test::caps;

const fs::path kTmp = fs::temp_directory_path() / "caps_test_cli_plan";
const std::string kModel = (kTmp / "model").string();

class CliPlan : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    fs::remove_all(kTmp);
    fs::create_directories(kTmp);
    const std::string ct = (kTmp / "ct.nii.gz").string();
    ASSERT_EQ(caps("phantom -q -o " + ct + " --size 96,96,90 --spacing 2.5,2.5,2.5").code, 0);
    ASSERT_EQ(caps("model from-volume -q " + ct + " -o " + kModel + " --n-theta 128 --n-z 64").code, 0);
  }
};

std::string p(const std::string& name) { return (kTmp / name).string(); }

void expect_refused(const std::string& args, const std::string& out, const std::string& what) {
  fs::remove(out);
  const CliRun r = caps(args);
  EXPECT_EQ(r.code, 2) << args << "\n" << r.out;
  EXPECT_NE(r.out.find(what), std::string::npos) << r.out << "\n  lacks: " << what;
  EXPECT_FALSE(fs::exists(out)) << out;
}

}  // namespace

TEST_F(CliPlan, MakesChecksAndDrawsEveryTemplate) {
  const CliRun t = caps("plan templates --json");
  ASSERT_EQ(t.code, 0);
  const auto lib = nlohmann::json::parse(t.out);
  ASSERT_GE(lib.size(), 5u);
  for (const auto& entry : lib) {
    const std::string name = entry["name"], plan = p(name + ".json"), png = p(name + ".png");
    const CliRun n = caps("plan new " + name + " --model " + kModel + " --at 0,60 --orientation 90 -q -o " + plan);
    ASSERT_EQ(n.code, 0) << n.out;
    EXPECT_EQ(caps("plan check -q " + plan).code, 0);
    const CliRun s = caps("plan show -q " + plan + " -o " + png);
    EXPECT_EQ(s.code, 0) << s.out;
    EXPECT_GT(fs::file_size(png), 1000u);
  }
  const auto z = nlohmann::json::parse(std::ifstream(p("z-plasty.json")));
  EXPECT_EQ(z["sutures"], nlohmann::json::parse("[[[5,0],[5,4]],[[2,1],[2,3]],[[0,1],[3,4]]]"));
  EXPECT_EQ(z["border_loop"].size(), 6u);
  // Runs of border nodes are written as longer lists (the V-Y flap's sides).
  const auto vy = nlohmann::json::parse(std::ifstream(p("v-y-advancement.json")));
  EXPECT_EQ(vy["sutures"], nlohmann::json::parse("[[[5,6],[6,7]],[[0,1,2],[0,7]],[[2,3,4],[5,4]]]"));
  EXPECT_EQ(vy["suture_quadruples"], nlohmann::json::parse("[[5,6,7,6],[0,2,0,7],[2,4,5,4]]"));
  // Every library parameter has its flag (--back-cut for back_cut), negative values included.
  const std::string rf = p("rf.json");
  const CliRun rot = caps("plan new rotation-flap --model " + kModel + " --at 0,60 --radius 12 "
                          "--defect-angle 40 --arc-angle 120 --back-cut 4 --arc-side -1 -q -o " + rf);
  ASSERT_EQ(rot.code, 0) << rot.out;
  const auto rj = nlohmann::json::parse(std::ifstream(rf));
  EXPECT_EQ(rj["procedure"]["parameters"]["arc_side"], -1);
  EXPECT_EQ(rj["procedure"]["parameters"]["back_cut"], 4);
  EXPECT_EQ(rj["border_loop"].size(), 18u);
  EXPECT_EQ(rj["sutures"].size(), 9u);
  // A saved procedure is reused elsewhere.
  ASSERT_EQ(caps("plan save-procedure -q " + p("z-plasty.json") + " -o " + p("my_z.json")).code, 0);
  EXPECT_EQ(caps("plan new " + p("my_z.json") + " --model " + kModel + " --at 40,50 -q -o " + p("z2.json")).code, 0);
}

TEST_F(CliPlan, RefusesBadPlansWithoutOutput) {
  const std::string out = p("bad.json");
  const std::string m = " --model " + kModel;
  expect_refused("plan new z-plasty" + m + " --at 0,60 --angle 20 -o " + out, out, "clinical range");
  expect_refused("plan new q-plasty" + m + " --at 0,60 -o " + out, out, "unknown procedure");
  expect_refused("plan new z-plasty" + m + " --at 0,900 -o " + out, out, "outside the model");
  expect_refused("plan new z-plasty" + m + " --at 0 -o " + out, out, "--at '0'");
  expect_refused("plan new z-plasty --model " + p("nowhere") + " --at 0,60 -o " + out, out, "nowhere");
  expect_refused("plan new ellipse" + m + " --at 0,95 --length 60 -o " + out, out, "loop node 3 (point 3)");
  // An LPS point far off the skin was taken for the skin along its ray (9000,0,0 became theta 91,
  // z 0); one on the skin is placed there.
  expect_refused("plan new z-plasty" + m + " --at-xyz 9000,0,40 -o " + out, out,
                 "mm from the skin");
  const CliRun site = caps("model site " + kModel + " --at 0,40 --json -q");
  ASSERT_EQ(site.code, 0) << site.out;
  const auto lps = nlohmann::json::parse(site.out).at("lps");
  const std::string on_skin = std::to_string(lps[0].get<double>()) + "," +
                              std::to_string(lps[1].get<double>()) + "," +
                              std::to_string(lps[2].get<double>());
  const CliRun placed = caps("plan new z-plasty" + m + " --at-xyz " + on_skin + " -q -o " + out);
  ASSERT_EQ(placed.code, 0) << placed.out;
  const auto frame = nlohmann::json::parse(std::ifstream(out)).at("frame");
  EXPECT_NEAR(frame.at("theta_deg").get<double>(), 0, 0.1);
  EXPECT_NEAR(frame.at("z_mm").get<double>(), 40, 0.1);
  fs::remove(out);
  // An existing output needs --force.
  ASSERT_EQ(caps("plan new z-plasty" + m + " --at 0,60 -q -o " + out).code, 0);
  EXPECT_EQ(caps("plan new z-plasty" + m + " --at 0,60 -q -o " + out).code, 2);
  // A hand-edited plan whose suture names an edge off the border.
  auto j = nlohmann::json::parse(std::ifstream(out));
  j["sutures"][0] = nlohmann::json::parse("[[0,2],[3,4]]");
  std::ofstream(p("edited.json")) << j.dump();
  const CliRun r = caps("plan check " + p("edited.json"));
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.out.find("(0,2) is not on the border"), std::string::npos) << r.out;
  expect_refused("plan show " + p("edited.json") + " -o " + p("edited.png"), p("edited.png"), "(0,2)");
}

TEST_F(CliPlan, SimulatesAVYFlapAndDrawsItsTension) {
  const std::string plan = p("vy_sim.json"), out = p("vy_sim");
  ASSERT_EQ(caps("plan new v-y-advancement --model " + kModel + " --at 0,60 --orientation 90 "
                 "--length 12 --advance 3 -q -o " + plan).code, 0);
  expect_refused("simulate --model " + kModel + " --plan " + plan + " -o " + out + " --tension-map",
                 out, "--render");
  const CliRun r = caps("simulate --model " + kModel + " --plan " + plan + " -o " + out +
                        " --render --tension-map --json");
  ASSERT_EQ(r.code, 0) << r.out;
  for (const char* f : {"pre_plan.png", "post_plan.png", "tension_plan.png", "tension_front.png"})
    EXPECT_GT(fs::file_size(fs::path(out) / f), 1000u) << f;
  const auto result = nlohmann::json::parse(std::ifstream(fs::path(out) / "result.json"));
  EXPECT_GT(result["total_suture_force_n"].get<double>(), 0.0);
  EXPECT_EQ(result["sizes"]["dofs"].get<long>() % 3, 0);
}
