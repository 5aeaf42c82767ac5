// The operating-room sheet (caps plan sheet, app/sheet.hpp) on the analytic face phantom: the
// PDF's page is A4 (or Letter) by its header; poppler's pdftoppm rasterises it at a known
// resolution and the 10 mm scale bar and the ellipse's long axis measure their true lengths;
// pdftotext finds the distances and forces the sheet computed; those distances agree with the
// same measurements made on the phantom's analytic skin; the left/up components walk back to the
// point (caps plan new --at LANDMARK+L,U); bad input exits 2 and writes nothing. Skipped without
// poppler-utils (scripts/setup.sh installs it).

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include "caps/app/loaded_model.hpp"
#include "caps/app/sheet.hpp"
#include "caps/core/error.hpp"
#include "caps/image/canvas.hpp"
#include "caps/plan/placement.hpp"
#include "caps/surface/landmarks.hpp"
#include "caps/surface/patient_model.hpp"
#include "caps/volume/phantom.hpp"
#include "cli_run.hpp"
#include "phantom_model.hpp"

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

const fs::path& folder() { return caps_test::program_folder("caps_test_sheet"); }

bool have_poppler() {
  return std::system("command -v pdftoppm >/dev/null 2>&1 && command -v pdftotext >/dev/null 2>&1") == 0;
}

std::string read_file(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// The face phantom in 1.2 mm voxels, its model, an ellipse on the forehead 25 mm to the
// patient's left of the glabella and 30 mm up, and its closure (the clamped patch, linear: the
// sheet reads the forces, any closure will do). Made once. The model has no whole-face tissue
// model (--no-tissue): nothing here closes a wound in the whole face, and making it took 7.7 of
// from-volume's 11.7 s of CPU (test_app_tissue and test_app_face test it).
struct Fixture {
  std::string model, plan, result;
};
const Fixture& fixture() {
  static const Fixture f = [] {
    Fixture x;
    const fs::path d = folder();
    const auto ph = caps_test::caps("phantom --face --no-holder --voxels 200,200,190 --spacing 1.2,1.2,1.2 -o " +
                         (d / "face.nii.gz").string() + " -q");
    EXPECT_EQ(ph.code, 0) << ph.out;
    x.model = (d / "face").string();
    const auto m = caps_test::caps("model from-volume " + (d / "face.nii.gz").string() + " -o " + x.model +
                        " --n-theta 720 --n-z 320 --no-tissue -q");
    EXPECT_EQ(m.code, 0) << m.out;
    x.plan = (d / "ellipse.json").string();
    const auto p = caps_test::caps("plan new ellipse --model " + x.model + " --at glabella+25,30 --length 30 "
                        "--width 10 -o " + x.plan + " -q");
    EXPECT_EQ(p.code, 0) << p.out;
    x.result = (d / "ellipse").string();
    const auto s = caps_test::caps("simulate -q --domain patch --material linear --model " + x.model +
                        " --plan " + x.plan + " -o " + x.result);
    EXPECT_EQ(s.code, 0) << s.out;
    return x;
  }();
  return f;
}

caps::app::SheetResult sheet(const std::string& name, const std::string& paper = "a4") {
  caps::app::SheetRequest r;
  r.plan = fixture().plan;
  r.result = fixture().result;
  r.output = (folder() / (name + ".pdf")).string();
  r.paper = paper;
  r.png = true;
  r.force = true;
  return caps::app::run_plan_sheet(r);
}

// An RGB raster from pdftoppm (binary PPM, P6).
struct Ppm {
  int width = 0, height = 0;
  std::vector<unsigned char> rgb;
  const unsigned char* at(int x, int y) const { return &rgb[(std::size_t(y) * width + x) * 3]; }
};
Ppm rasterise(const fs::path& pdf, int dpi) {
  const fs::path stem = pdf.parent_path() / (pdf.stem().string() + "_" + std::to_string(dpi));
  const std::string cmd = "pdftoppm -r " + std::to_string(dpi) + " -singlefile " + pdf.string() +
                          " " + stem.string();
  EXPECT_EQ(std::system(cmd.c_str()), 0) << cmd;
  std::ifstream in(stem.string() + ".ppm", std::ios::binary);
  std::string magic;
  int maxval = 0;
  Ppm p;
  in >> magic >> p.width >> p.height >> maxval;
  in.get();
  EXPECT_EQ(magic, "P6");
  EXPECT_EQ(maxval, 255);
  p.rgb.resize(std::size_t(p.width) * p.height * 3);
  in.read(reinterpret_cast<char*>(p.rgb.data()), static_cast<std::streamsize>(p.rgb.size()));
  in.close();
  fs::remove(stem.string() + ".ppm");  // 100 MB at 600 dpi
  return p;
}

std::string one_decimal(double x) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.1f", std::abs(x) < 0.05 ? 0.0 : x);
  return buf;
}

// The phantom's analytic skin point on the ray (about its axis) through an LPS point.
Eigen::Vector3d analytic_skin(const caps::HeadPhantom& ph, const Eigen::Vector3d& p) {
  const Eigen::Vector3d a = ph.axis_point();
  const double theta = std::atan2(p.x() - a.x(), -(p.y() - a.y()));
  const double r = ph.skin_radius(theta, p.z());
  return a + r * caps::HeadPhantom::ray_direction(theta) + Eigen::Vector3d(0, 0, p.z());
}

// The geodesic between two points of the phantom's analytic skin given by their (theta rad, z
// mm) about its axis: a polyline of 32 segments relaxed on the surface (each point moved, in the
// skin's tangent plane, to the midpoint of its neighbours until nothing moves), its length (mm).
double analytic_geodesic_mm(const caps::HeadPhantom& ph, const Eigen::Vector2d& a,
                            const Eigen::Vector2d& b) {
  auto at = [&](const Eigen::Vector2d& q) -> Eigen::Vector3d {
    return ph.axis_point() + ph.skin_radius(q[0], q[1]) * caps::HeadPhantom::ray_direction(q[0]) +
           Eigen::Vector3d(0, 0, q[1]);
  };
  constexpr int n = 32;
  std::vector<Eigen::Vector2d> q(n + 1);
  for (int i = 0; i <= n; ++i) q[i] = a + (b - a) * (double(i) / n);
  for (int it = 0; it < 4000; ++it) {
    double moved = 0;
    for (int i = 1; i < n; ++i) {
      const Eigen::Vector3d p = at(q[i]);
      const Eigen::Vector3d d = 0.5 * (at(q[i - 1]) + at(q[i + 1])) - p;
      constexpr double h = 1e-6;
      Eigen::Matrix<double, 3, 2> T;
      T.col(0) = (at(q[i] + Eigen::Vector2d(h, 0)) - at(q[i] - Eigen::Vector2d(h, 0))) / (2 * h);
      T.col(1) = (at(q[i] + Eigen::Vector2d(0, h)) - at(q[i] - Eigen::Vector2d(0, h))) / (2 * h);
      const Eigen::Vector2d dq = (T.transpose() * T).ldlt().solve(T.transpose() * d);
      q[i] += dq;
      moved = std::max(moved, (T * dq).norm());
    }
    if (moved < 1e-7) break;
  }
  double length = 0;
  for (int i = 0; i < n; ++i) length += (at(q[i + 1]) - at(q[i])).norm();
  return length;
}

// (theta rad, z mm) about the phantom's axis of an LPS point.
Eigen::Vector2d phantom_cylindrical(const caps::HeadPhantom& ph, const Eigen::Vector3d& p) {
  const Eigen::Vector3d a = ph.axis_point();
  return {std::atan2(p.x() - a.x(), -(p.y() - a.y())), p.z()};
}

}  // namespace

TEST(Canvas, PdfPageIsAVectorPageWithoutPixels) {
  caps::Canvas page = caps::Canvas::pdf_page(100, 50);
  page.line({10, 10}, {90, 40});
  page.text(10, 30, "caps");
  EXPECT_THROW(page.image(), caps::Error);
  const std::string pdf = page.pdf();
  EXPECT_EQ(pdf.rfind("%PDF-", 0), 0u);
  EXPECT_NE(pdf.find("/MediaBox [ 0 0 100 50 ]"), std::string::npos);
  caps::Canvas raster(10, 10);
  EXPECT_THROW(raster.pdf(), caps::Error);
  EXPECT_THROW(caps::Canvas::pdf_page(0, 50), caps::InvalidInput);
}

TEST(Sheet, PageSizeFromTheHeaderAndTheScaleBarMeasuresTenMillimetres) {
  if (!have_poppler()) GTEST_SKIP() << "pdftoppm/pdftotext missing (poppler-utils)";
  const auto r = sheet("a4");
  const std::string pdf = read_file(r.output);
  // cairo writes the page's MediaBox in points (1/72 in): A4 is 595.28 x 841.89.
  const std::regex box(R"(/MediaBox \[ 0 0 ([0-9.]+) ([0-9.]+) \])");
  std::smatch m;
  ASSERT_TRUE(std::regex_search(pdf, m, box));
  EXPECT_NEAR(std::stod(m[1]), 210.0 / 25.4 * 72, 0.01);
  EXPECT_NEAR(std::stod(m[2]), 297.0 / 25.4 * 72, 0.01);
  EXPECT_EQ(r.paper, "A4");
  const auto letter = sheet("letter", "letter");
  const std::string lp = read_file(letter.output);
  ASSERT_TRUE(std::regex_search(lp, m, box));
  EXPECT_NEAR(std::stod(m[1]), 612, 0.01);
  EXPECT_NEAR(std::stod(m[2]), 792, 0.01);

  // At 600 dpi a pixel is 0.042 mm: the bar's dark run along its centre line is 10 mm.
  constexpr int kDpi = 600;
  const double px_per_mm = kDpi / 25.4;
  const Ppm img = rasterise(r.output, kDpi);
  ASSERT_EQ(img.width, static_cast<int>(std::lround(210 / 25.4 * kDpi)));
  const int row = static_cast<int>(r.scale_bar_y_mm * px_per_mm);
  int first = -1, last = -1;
  for (int x = static_cast<int>((r.scale_bar_x_mm - 1) * px_per_mm);
       x < static_cast<int>((r.scale_bar_x_mm + 11) * px_per_mm); ++x)
    if (img.at(x, row)[0] < 128) {
      if (first < 0) first = x;
      last = x;
    }
  ASSERT_GE(first, 0);
  EXPECT_NEAR((last - first + 1) / px_per_mm, 10.0, 0.5);
  EXPECT_NEAR((last - first + 1) / px_per_mm, 10.0, 0.1);  // in fact to a pixel or two

  // The ellipse (orientation 0: its long axis runs superior-inferior, up the page): the red line
  // spans its 30 mm length plus the line's width (0.3 mm), within the view.
  int top = img.height, bottom = -1;
  const int x0 = static_cast<int>(r.view_x_mm * px_per_mm), x1 = static_cast<int>((r.view_x_mm + r.view_width_mm) * px_per_mm);
  const int y0 = static_cast<int>(r.view_y_mm * px_per_mm), y1 = static_cast<int>((r.view_y_mm + r.view_height_mm) * px_per_mm);
  for (int y = y0; y < y1; ++y)
    for (int x = x0; x < x1; ++x) {
      const unsigned char* p = img.at(x, y);
      if (p[0] > 150 && p[1] < 90 && p[2] < 90) {
        top = std::min(top, y);
        bottom = std::max(bottom, y);
      }
    }
  ASSERT_GT(bottom, top);
  const double drawn_mm = (bottom - top + 1) / px_per_mm - 0.3;
  EXPECT_NEAR(drawn_mm, 30.0, 0.5);
  // And the same from the key points on paper: the ends (loop nodes 0 and 3).
  const json pts = json::parse(r.points_json);
  Eigen::Vector2d e0, e3;
  for (const json& k : pts) {
    for (int n : k["loop_nodes"]) {
      if (n == 0) e0 = {k["paper_mm"][0].get<double>(), k["paper_mm"][1].get<double>()};
      if (n == 3) e3 = {k["paper_mm"][0].get<double>(), k["paper_mm"][1].get<double>()};
    }
  }
  EXPECT_NEAR((e3 - e0).norm(), 30.0, 0.3);
  std::printf("at %d dpi: the scale bar %.3f mm, the ellipse's long axis %.3f mm (line width "
              "taken off), its ends on paper %.3f mm apart\n",
              kDpi, (last - first + 1) / px_per_mm, drawn_mm, (e3 - e0).norm());
  EXPECT_NEAR(drawn_mm, (e3 - e0).norm(), 0.2);
  // The PNG is the same page at 150 dpi.
  EXPECT_TRUE(fs::is_regular_file(r.png));
}

TEST(Sheet, TextCarriesTheDistancesAndTheForces) {
  if (!have_poppler()) GTEST_SKIP() << "pdftoppm/pdftotext missing (poppler-utils)";
  const auto r = sheet("text");
  ASSERT_TRUE(r.has_result);
  ASSERT_FALSE(r.landmarks.empty());
  EXPECT_EQ(r.landmarks.front(), "glabella");  // the nearest
  const fs::path txt = folder() / "text.txt";
  ASSERT_EQ(std::system(("pdftotext -layout " + r.output + " " + txt.string()).c_str()), 0);
  const std::string text = read_file(txt);
  const json pts = json::parse(r.points_json);
  ASSERT_GE(pts.size(), 7u);  // the ellipse's six border nodes and its centre
  for (const json& k : pts)
    for (const json& d : k["landmarks"]) {
      const std::string cell = one_decimal(d["skin_mm"].get<double>()) + " | " +
                               one_decimal(d["straight_mm"].get<double>());
      EXPECT_NE(text.find(cell), std::string::npos) << k["label"] << " " << d["name"] << ": " << cell;
    }
  char force[64];
  std::snprintf(force, sizeof force, "closing force %.2f N", r.closing_force_n);
  EXPECT_NE(text.find(force), std::string::npos) << force << "\n" << text;
  std::snprintf(force, sizeof force, "largest suture %.2f N", r.max_suture_force_n);
  EXPECT_NE(text.find(force), std::string::npos) << force;
  // The forces are the result's.
  const json res = json::parse(read_file(fs::path(fixture().result) / "result.json"));
  EXPECT_DOUBLE_EQ(r.closing_force_n, res["total_suture_force_n"].get<double>());
  EXPECT_DOUBLE_EQ(r.max_suture_force_n, res["sutures_at_spacing"]["max_suture_force_n"].get<double>());
  EXPECT_TRUE(r.features_recorded);  // simulate keeps them in summary.json
  for (const char* s : {"Operating-room sheet", "ellipse", "superior", "patient's left", "10 mm",
                        "glabella", "Predicted closure"})
    EXPECT_NE(text.find(s), std::string::npos) << s;
}

TEST(Sheet, DistancesAgreeWithTheAnalyticSkin) {
  const auto r = sheet("distances");
  const auto model = caps::app::loaded_model(fixture().model);
  const caps::Landmarks landmarks = caps::plan::model_landmarks(fixture().model, *model);
  const caps::HeadPhantom ph(false, false, true);
  const json pts = json::parse(r.points_json);
  int checked = 0;
  double worst_straight = 0, worst_skin = 0, worst_walk = 0, longest_excess = 0;
  for (const json& k : pts) {
    const Eigen::Vector2d p_tz(k["theta_deg"].get<double>(), k["z_mm"].get<double>());
    const Eigen::Vector3d p = model->skin_point(p_tz[0], p_tz[1]);
    for (const json& d : k["landmarks"]) {
      const caps::Landmark* l = landmarks.find(d["name"].get<std::string>());
      ASSERT_NE(l, nullptr);
      const Eigen::Vector2d l_tz(l->theta_deg, l->z_mm);
      // Straight: between the two points on the analytic skin.
      const double straight = (analytic_skin(ph, p) - analytic_skin(ph, l->lps)).norm();
      EXPECT_NEAR(d["straight_mm"].get<double>(), straight, 0.5) << k["label"] << " " << l->name;
      worst_straight = std::max(worst_straight, std::abs(d["straight_mm"].get<double>() - straight));
      // The walk (caps plan new --at LANDMARK+L,U): its path (straight in the model's theta, z)
      // taken to the analytic skin, summed in 4000 steps.
      const Eigen::Vector2d to(l_tz[0] + std::remainder(p_tz[0] - l_tz[0], 360.0), p_tz[1]);
      double along = 0;
      Eigen::Vector3d prev = analytic_skin(ph, model->skin_point(l_tz[0], l_tz[1]));
      for (int i = 1; i <= 4000; ++i) {
        const Eigen::Vector2d tz = l_tz + (to - l_tz) * (i / 4000.0);
        const Eigen::Vector3d q = analytic_skin(ph, model->skin_point(tz[0], tz[1]));
        along += (q - prev).norm();
        prev = q;
      }
      EXPECT_NEAR(d["walk_mm"].get<double>(), along, 0.5) << k["label"] << " " << l->name;
      EXPECT_NEAR(std::hypot(d["left_mm"].get<double>(), d["up_mm"].get<double>()),
                  d["walk_mm"].get<double>(), 1e-9);
      worst_walk = std::max(worst_walk, std::abs(d["walk_mm"].get<double>() - along));
      // Along the skin: the geodesic, against the analytic skin's own (relaxed there).
      const double geodesic = analytic_geodesic_mm(ph, phantom_cylindrical(ph, l->lps),
                                                   phantom_cylindrical(ph, p));
      EXPECT_NEAR(d["skin_mm"].get<double>(), geodesic, 0.5) << k["label"] << " " << l->name;
      worst_skin = std::max(worst_skin, std::abs(d["skin_mm"].get<double>() - geodesic));
      EXPECT_LE(geodesic, along + 0.05) << k["label"] << " " << l->name;
      EXPECT_LE(d["skin_mm"].get<double>(), d["walk_mm"].get<double>() + 1e-9);
      EXPECT_GE(d["skin_mm"].get<double>() + 1e-6, d["straight_mm"].get<double>());
      longest_excess = std::max(longest_excess, d["walk_mm"].get<double>() - d["skin_mm"].get<double>());
      // Left and up are the walk caps plan new --at LANDMARK+L,U makes: it lands on the point.
      const Eigen::Vector2d back = caps::plan::resolve_placement(
          *model, landmarks, {l->name, d["left_mm"].get<double>(), d["up_mm"].get<double>()});
      EXPECT_LT((model->skin_point(back[0], back[1]) - p).norm(), 0.2) << k["label"] << " " << l->name;
      ++checked;
    }
  }
  EXPECT_GE(checked, 7 * 2);
  std::printf("%d distances against the analytic skin's: straight within %.3f mm, the geodesic "
              "within %.3f mm, the walk within %.3f mm; the walk up to %.3f mm longer than the "
              "geodesic\n", checked, worst_straight, worst_skin, worst_walk, longest_excess);
  // The cut keeps its skin lengths on paper.
  EXPECT_LT(r.max_segment_error_mm, 0.05);
}

TEST(Sheet, BadInputExitsTwoAndWritesNothing) {
  const fs::path d = folder() / "refused";
  fs::create_directories(d);
  const std::string base = "plan sheet " + fixture().plan + " ";
  struct Case {
    std::string args, says;
  } cases[] = {
      {"-o " + (d / "sheet.png").string(), "name it .pdf"},
      {"--paper a5 -o " + (d / "sheet.pdf").string(), "--paper"},
      {"--result " + d.string() + " -o " + (d / "sheet.pdf").string(), "no result.json"},
      {"--result " + (d / "nowhere").string() + " -o " + (d / "sheet.pdf").string(), "not a folder"},
      {"--model " + (d / "nowhere").string() + " -o " + (d / "sheet.pdf").string(), "nowhere"},
      {"-o " + (d / "missing" / "sheet.pdf").string(), "does not exist"},
  };
  for (const Case& c : cases) {
    const auto run = caps_test::caps(base + c.args);
    EXPECT_EQ(run.code, 2) << c.args << "\n" << run.out;
    EXPECT_NE(run.out.find(c.says), std::string::npos) << c.args << "\n" << run.out;
    EXPECT_TRUE(fs::is_empty(d)) << c.args;
  }
  // Another plan's result: its forces would be read as this plan's. Refused (the result folder
  // keeps the plan it closed).
  const std::string other = (folder() / "other.json").string();
  ASSERT_EQ(caps_test::caps("plan new ellipse --model " + fixture().model + " --at glabella+25,36 "
                            "--length 30 --width 10 -o " + other + " --force -q")
                .code,
            0);
  const auto foreign = caps_test::caps("plan sheet " + other + " --result " + fixture().result +
                                       " -o " + (d / "sheet.pdf").string());
  EXPECT_EQ(foreign.code, 2) << foreign.out;
  EXPECT_NE(foreign.out.find("that result closed another plan"), std::string::npos) << foreign.out;
  EXPECT_TRUE(fs::is_empty(d));
  const auto missing = caps_test::caps("plan sheet " + (d / "none.json").string() + " -o " + (d / "s.pdf").string());
  EXPECT_EQ(missing.code, 2) << missing.out;
  EXPECT_TRUE(fs::is_empty(d));
  // An existing sheet is replaced only with --force; its PNG counts too.
  std::ofstream(d / "sheet.png") << "keep";
  const auto kept = caps_test::caps(base + "--png -o " + (d / "sheet.pdf").string());
  EXPECT_EQ(kept.code, 2) << kept.out;
  EXPECT_NE(kept.out.find("--force"), std::string::npos) << kept.out;
  EXPECT_FALSE(fs::exists(d / "sheet.pdf"));
  EXPECT_EQ(read_file(d / "sheet.png"), "keep");
  const auto forced = caps_test::caps(base + "--png --force -o " + (d / "sheet.pdf").string());
  EXPECT_EQ(forced.code, 0) << forced.out;
  EXPECT_EQ(read_file(d / "sheet.pdf").rfind("%PDF-", 0), 0u);
}

TEST(Sheet, APlanOnALocalChartIsMeasuredFromTheHeadsLandmarks) {
  // The phantom's vertex, where the head's rays graze the skin: caps plan new places the plan on
  // a local chart beside it. The sheet measures from the head's landmarks: the straight
  // distances are the analytic skin's; along the skin where the head's image holds the point,
  // else the sheet says so and gives the straight distance only.
  const fs::path d = folder() / "vertex";
  fs::create_directories(d);
  const std::string plan = (d / "vertex.json").string();
  const auto made = caps_test::caps("plan new ellipse --model " + fixture().model +
                                    " --at 0,99 --length 12 --width 4 -o " + plan + " -q");
  ASSERT_EQ(made.code, 0) << made.out;
  ASSERT_TRUE(fs::is_directory(d / "vertex.chart"));
  caps::app::SheetRequest r;
  r.plan = plan;
  r.output = (d / "sheet.pdf").string();
  const caps::app::SheetResult s = caps::app::run_plan_sheet(r);
  ASSERT_FALSE(s.landmarks.empty());
  EXPECT_EQ(s.landmarks.front(), "glabella");
  const auto model = caps::app::loaded_model(fixture().model);
  const caps::Landmarks landmarks = caps::plan::model_landmarks(fixture().model, *model);
  const caps::HeadPhantom ph(false, false, true);
  bool unheld = false;
  for (const json& k : json::parse(s.points_json)) {
    const Eigen::Vector3d p(k["lps"][0].get<double>(), k["lps"][1].get<double>(), k["lps"][2].get<double>());
    for (const json& dist : k["landmarks"]) {
      const caps::Landmark* l = landmarks.find(dist["name"].get<std::string>());
      ASSERT_NE(l, nullptr);
      // The head's landmark (model.json keeps its LPS point rounded to 1e-3 mm).
      EXPECT_NEAR(dist["straight_mm"].get<double>(), (p - l->lps).norm(), 0.01);
      EXPECT_NEAR(dist["straight_mm"].get<double>(),
                  (analytic_skin(ph, p) - analytic_skin(ph, l->lps)).norm(), 0.5);
      if (dist["skin_mm"].is_null()) {
        unheld = true;
        continue;
      }
      EXPECT_GE(dist["skin_mm"].get<double>() + 1e-6, dist["straight_mm"].get<double>());
      EXPECT_LE(dist["skin_mm"].get<double>(), dist["walk_mm"].get<double>() + 1e-9);
    }
  }
  bool said = false;
  for (const std::string& w : s.warnings) said |= w.find("only the straight") != std::string::npos;
  EXPECT_EQ(said, unheld);
  EXPECT_EQ(read_file(s.output).rfind("%PDF-", 0), 0u);
}
