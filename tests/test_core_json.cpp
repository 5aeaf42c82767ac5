// core/json_file.hpp (and core/plane_geometry.hpp, at the end): the one way caps reads a JSON
// file. A file that cannot be read names the reason and what to do; one too large or nested too
// deep is refused before parsing; a syntax error names the file, the line and the column.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "caps/core/error.hpp"
#include "caps/core/json_file.hpp"
#include "caps/core/plane_geometry.hpp"

namespace fs = std::filesystem;
using namespace caps;
using nlohmann::json;

namespace {

const fs::path kTmp = fs::temp_directory_path() / "caps_test_core_json";

fs::path write(const std::string& name, const std::string& text) {
  fs::create_directories(kTmp);
  const fs::path p = kTmp / name;
  std::ofstream(p, std::ios::binary) << text;
  return p;
}

// The message of the InvalidInput or IoError `f` throws ("" if none).
template <class E, class F>
std::string refusal(F&& f) {
  try {
    f();
  } catch (const E& e) {
    return e.what();
  }
  return "";
}

}  // namespace

TEST(JsonFile, ReadsAFileAndParsesIt) {
  const fs::path p = write("ok.json", R"({"a": [1, 2], "b": "x"})");
  const json j = read_json_file<json>(p, "what to do");
  EXPECT_EQ(j.at("a").at(1), 2);
  EXPECT_EQ(j.at("b"), "x");
}

TEST(JsonFile, AMissingFileOrAFolderNamesTheReasonAndWhatToDo) {
  const std::string missing =
      refusal<IoError>([] { read_json_text(kTmp / "none.json", "check the path"); });
  EXPECT_NE(missing.find("none.json: no such file or folder; check the path"), std::string::npos)
      << missing;
  fs::create_directories(kTmp / "folder.json");
  const std::string folder =
      refusal<IoError>([] { read_json_text(kTmp / "folder.json", "give a file"); });
  EXPECT_NE(folder.find("a folder, not a file"), std::string::npos) << folder;
}

TEST(JsonFile, AFileLargerThanTheLimitIsRefusedBeforeItIsRead) {
  const fs::path p = write("big.json", "[" + std::string(1000, ' ') + "]");
  const std::string m = refusal<InvalidInput>([&] { read_json_text(p, "what to do", 100); });
  EXPECT_NE(m.find("big.json: 1002 bytes, more than the 100"), std::string::npos) << m;
  EXPECT_NO_THROW(read_json_text(p, "what to do", 1002));
}

TEST(JsonFile, NestingDeeperThanTheLimitIsRefusedNamingTheFile) {
  const int deep = kMaxJsonDepth + 1;
  const fs::path p = write("deep.json", std::string(deep, '[') + std::string(deep, ']'));
  const std::string m = refusal<InvalidInput>([&] { read_json_file<json>(p, "what to do"); });
  EXPECT_NE(m.find("deep.json: JSON nested more than 100 levels deep"), std::string::npos) << m;
  const std::string text = std::string(kMaxJsonDepth, '[') + std::string(kMaxJsonDepth, ']');
  EXPECT_NO_THROW(parse_json<json>(text, "text"));
}

TEST(JsonFile, ASyntaxErrorNamesTheFileTheLineAndTheColumn) {
  // Line 3, column 8 is the ']' where a value should be.
  const fs::path p = write("bad.json", "{\n  \"a\": 1,\n  \"b\": ]\n}\n");
  const std::string m = refusal<InvalidInput>([&] { read_json_file<json>(p, "what to do"); });
  EXPECT_NE(m.find("bad.json: not valid JSON at line 3, column 8 ("), std::string::npos) << m;
  EXPECT_EQ(m.find("[json.exception"), std::string::npos) << m;  // said once, in the user's terms
  const std::string cut = refusal<InvalidInput>([] { parse_json<json>("{\"a\": ", "the request"); });
  EXPECT_NE(cut.find("the request: not valid JSON at line 1, column 7"), std::string::npos) << cut;
}

// caps/core/plane_geometry.hpp: the point-in-polygon tests the face domain, the renderer and the
// mesher share, on a concave polygon (an L) with points inside, outside, in the notch and on the
// outline; and angles wrapped into [-180, 180).
TEST(PlaneGeometry, PointInPolygonAndOnItsOutlineAndWrappedAngles) {
  const std::vector<Eigen::Vector2d> L{{0, 0}, {4, 0}, {4, 1}, {1, 1}, {1, 3}, {0, 3}};
  EXPECT_TRUE(caps::point_in_polygon(L, {0.5, 2.5}));
  EXPECT_TRUE(caps::point_in_polygon(L, {3.5, 0.5}));
  EXPECT_FALSE(caps::point_in_polygon(L, {2, 2}));    // the notch
  EXPECT_FALSE(caps::point_in_polygon(L, {5, 0.5}));  // beyond the foot
  EXPECT_FALSE(caps::point_in_polygon(L, {-0.1, 1}));
  EXPECT_TRUE(caps::point_in_or_on_polygon(L, {2, 1}));      // on the notch's edge
  EXPECT_TRUE(caps::point_in_or_on_polygon(L, {4, 0}));      // a corner
  EXPECT_FALSE(caps::point_in_or_on_polygon(L, {2, 1.001}));  // just off it, in the notch
  EXPECT_DOUBLE_EQ(caps::wrap_degrees(190), -170);
  EXPECT_DOUBLE_EQ(caps::wrap_degrees(-190), 170);
  EXPECT_DOUBLE_EQ(caps::wrap_degrees(180), -180);
  EXPECT_DOUBLE_EQ(caps::wrap_degrees(-180), -180);
  EXPECT_DOUBLE_EQ(caps::wrap_degrees(725), 5);
}
