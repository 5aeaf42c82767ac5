// `caps model from-scan` and `caps model pick` as a user runs them: bad inputs give exit code 2,
// a message that says what to do, and no output directory.
#include <gtest/gtest.h>

#include "cli_run.hpp"

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

namespace fs = std::filesystem;

namespace {

using caps_test::CliRun;
using caps_test::caps;

const fs::path kTmp = fs::temp_directory_path() / "caps_test_cli_surface";
const std::string kScan = std::string(CAPS_SHARED_DATA) + "/scan/leeperrysmith/";

void write(const fs::path& p, const std::string& text) {
  fs::create_directories(p.parent_path());
  std::ofstream(p) << text;
}

// A refused run: exit code 2, the message contains `what`, no output directory.
void expect_refused(const std::string& args, const std::string& what) {
  const fs::path out = kTmp / "model";
  fs::remove_all(out);
  const CliRun r = caps("model from-scan " + args + " -o " + out.string());
  EXPECT_EQ(r.code, 2) << args << "\n" << r.out;
  EXPECT_NE(r.out.find(what), std::string::npos) << args << "\n" << r.out;
  EXPECT_FALSE(fs::exists(out)) << args;
}

const char* kTetra =  // a closed tetrahedron, ~200 units tall, outward faces
    "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
    "element face 4\nproperty list uchar int vertex_indices\nend_header\n"
    "-80 -100 60\n80 -100 60\n0 -100 -90\n0 100 0\n3 0 2 1\n3 0 1 3\n3 1 2 3\n3 2 0 3\n";

}  // namespace

TEST(CliSurface, BadScansExitTwoWithoutOutput) {
  write(kTmp / "noface.ply", "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
                             "property float y\nproperty float z\nend_header\n0 0 0\n1 0 0\n0 1 0\n");
  expect_refused((kTmp / "noface.ply").string() + " --thickness 6", "no faces");
  std::string nan = kTetra;
  nan.replace(nan.find("0 100 0"), 7, "0 nan 0");
  write(kTmp / "nan.ply", nan);
  expect_refused((kTmp / "nan.ply").string() + " --thickness 6", "non-finite");
  std::string inside = kTetra;
  inside.replace(inside.find("3 0 2 1"), 7, "3 0 1 2");
  inside.replace(inside.find("3 0 1 3"), 7, "3 0 3 1");
  inside.replace(inside.find("3 1 2 3"), 7, "3 1 3 2");
  inside.replace(inside.find("3 2 0 3"), 7, "3 2 3 0");
  write(kTmp / "inside.ply", inside);
  expect_refused((kTmp / "inside.ply").string() + " --thickness 6", "inside-out");
  std::string fin = kTetra;
  fin.replace(fin.find("element vertex 4"), 16, "element vertex 5");
  fin.replace(fin.find("element face 4"), 14, "element face 5");
  fin.replace(fin.find("0 100 0\n"), 8, "0 100 0\n0 0 100\n");
  fin += "3 0 1 4\n";
  write(kTmp / "fin.ply", fin);
  expect_refused((kTmp / "fin.ply").string() + " --thickness 6", "non-manifold");
  expect_refused((kTmp / "inside.ply").string() + " --thickness 6 --scale 1000", "--head-height-mm");
  expect_refused((kTmp / "noface.ply").string() + "x --thickness 6", "no such file");
}

TEST(CliSurface, GlbUnitsAndTexturesAreChecked) {
  if (!fs::exists(kScan + "LeePerrySmith.glb")) GTEST_SKIP() << "no shared scan data";
  // glTF says metres: this scan is in arbitrary units and would be 8 m tall.
  expect_refused(kScan + "LeePerrySmith.glb --thickness 6", "--head-height-mm");
  expect_refused(kScan + "LeePerrySmith.glb --thickness 6 --head-height-mm 230 --texture " +
                     (kTmp / "missing.jpg").string(), "missing.jpg");
  write(kTmp / "broken.jpg", "\xff\xd8\xff this is not really a JPEG");
  expect_refused(kScan + "LeePerrySmith.glb --thickness 6 --head-height-mm 230 --texture " +
                     (kTmp / "broken.jpg").string(), "JPEG");
  expect_refused(kScan + "LeePerrySmith.glb --thickness 6 --head-height-mm 230 --up +y --front +y",
                 "perpendicular");
}

TEST(CliSurface, BuildsAndPicksTheLeePerrySmithScan) {
  if (!fs::exists(kScan + "LeePerrySmith.glb")) GTEST_SKIP() << "no shared scan data";
  const fs::path out = kTmp / "lps";
  fs::remove_all(out);
  const CliRun r = caps("model from-scan " + kScan + "LeePerrySmith.glb --texture " + kScan + "Map-COL.jpg --flip-v "
                     "--head-height-mm 230 --thickness 6 --n-theta 256 --n-z 128 --quiet -o " +
                     out.string());
  ASSERT_EQ(r.code, 0) << r.out;
  for (const char* f : {"model.json", "color.png", "skin.png", "skin.ply", "bone.ply", "r_skin.nrrd"})
    EXPECT_TRUE(fs::exists(out / f)) << f;
  // A ray from in front of the face, along LPS +y (posterior), hits the face near theta = 0.
  const CliRun p = caps("model pick " + out.string() + " --ray 0,-400,20,0,1,0 --json");
  EXPECT_EQ(p.code, 0) << p.out;
  EXPECT_NE(p.out.find("\"hit\": true"), std::string::npos) << p.out;
  const CliRun miss = caps("model pick " + out.string() + " --ray 0,-400,20,1,0,0 --json");
  EXPECT_NE(miss.out.find("\"hit\": false"), std::string::npos) << miss.out;
  EXPECT_EQ(caps("model pick " + out.string() + " --ray 1,2,3").code, 2);
  fs::remove_all(out);
}
