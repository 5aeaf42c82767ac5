// caps plan sheet: the operating-room sheet of a plan.
//   caps plan sheet ellipse.json -o ellipse-sheet.pdf --png
//   caps plan sheet z.json --model cranium --result z -o z-sheet.pdf --paper letter --force
#include "caps/app/sheet.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>
#include <filesystem>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <set>

#include "caps/app/loaded_model.hpp"
#include "caps/core/atomic_output.hpp"
#include "caps/core/error.hpp"
#include "caps/core/json_file.hpp"
#include "caps/image/canvas.hpp"
#include "caps/image/image_io.hpp"
#include "caps/plan/check.hpp"
#include "caps/plan/placement.hpp"
#include "caps/plan/plan_io.hpp"
#include "caps/plan/skin_walk.hpp"
#include "caps/surface/feature_lines.hpp"
#include "caps/surface/landmarks.hpp"
#include "caps/surface/patient_model.hpp"
#include "caps/volume/cylindrical_map.hpp"
#include "caps/volume/model_dir.hpp"
#include "json_fields.hpp"
#include "model_result.hpp"
#include "numbers.hpp"
#include "output_check.hpp"
#include "skin_place.hpp"

CAPS_APP_REQUEST_JSON(caps::app::SheetRequest)
CAPS_APP_RESULT_JSON(caps::app::SheetResult)

namespace caps::app {

namespace fs = std::filesystem;
using nlohmann::json;
using V2 = Eigen::Vector2d;
using V3 = Eigen::Vector3d;

namespace {

constexpr double kPngDpi = 150;
constexpr double kMarginMm = 12;
// The skin around the plan shown beyond its extent, and the drawing's least size (mm): enough
// to see the brow or an eye corner near a plan on the forehead.
constexpr double kViewMarginMm = 18, kMinViewHeightMm = 90;
// Landmarks farther than this (straight, mm) from the plan's centre are not measured from: a
// tape around half the head is no guide.
constexpr double kMaxLandmarkMm = 120;
constexpr int kMaxLandmarks = 4;
constexpr double kLowConfidence = 0.5;
// The identity lines' text size and line pitch (mm).
constexpr double kIdentityMm = 2.6, kIdentityLineMm = 3.6;

const V3 kInk(0.1, 0.1, 0.1), kGrey(0.45, 0.45, 0.45), kCut(0.8, 0.05, 0.05),
    kFeature(0.1, 0.3, 0.8), kLandmark(0.0, 0.45, 0.2), kWarn(0.75, 0.2, 0.0);

struct Paper {
  std::string name;
  double width_mm, height_mm;
};

Paper paper_of(const std::string& s) {
  std::string l = s;
  for (char& c : l) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (l == "a4") return {"A4", 210.0, 297.0};
  if (l == "letter") return {"Letter", 215.9, 279.4};
  throw InvalidParameter(cat("{paper} \"", s, "\": give a4 or letter"));
}

// The skin around a point laid flat as caps walks on it (sheet.hpp): paper (right, up) mm ->
// (theta deg, z mm) by a walk from the point, and back by the skin length and the initial
// direction of the line straight in (theta, z).
class Flat {
 public:
  Flat(const PatientModel& model, const V2& centre)
      : model_(model), centre_(centre), frame_(plan::skin_frame(model, centre[0], centre[1], 90.0)) {}

  V2 to_paper(const V2& tz) const { return plan::step_on_skin(model_, frame_, tz); }
  V2 to_skin(const V2& xy) const {
    if (xy.norm() < 1e-9) return centre_;
    const V2 tz = plan::walk_on_skin(model_, frame_, xy).theta_z;
    return {std::remainder(tz[0], 360.0), tz[1]};
  }
  const plan::SkinFrame& frame() const { return frame_; }

 private:
  const PatientModel& model_;  // not owned; outlives the Flat
  V2 centre_;
  plan::SkinFrame frame_;
};

// The shortest path on the skin between a and b (theta deg, z mm; b's theta unwrapped next to
// a's), its length in mm: what a tape held to the skin reads where the skin is convex. The line
// straight in (theta, z) relaxed on the skin: each point moved in the skin's tangent plane to the
// midpoint of its neighbours until none moves 1e-5 mm (a discrete geodesic), on 8, 16, then 32
// segments.
double skin_geodesic_mm(const PatientModel& model, const V2& a, const V2& b) {
  std::vector<V2> q{a, b};
  std::vector<V3> p;
  for (int level = 0; level < 3; ++level) {
    // Each segment split in 4, then 2, then 2: 8, 16, 32.
    const int split = level == 0 ? 8 : 2;
    std::vector<V2> finer;
    for (std::size_t i = 0; i + 1 < q.size(); ++i)
      for (int k = 0; k < split; ++k) finer.push_back(q[i] + (q[i + 1] - q[i]) * (double(k) / split));
    finer.push_back(q.back());
    q = std::move(finer);
    const int n = static_cast<int>(q.size()) - 1;
    p.resize(q.size());
    for (int i = 0; i <= n; ++i) p[i] = model.skin_point(q[i][0], q[i][1]);
    for (int it = 0; it < 4 * n * n; ++it) {
      double moved = 0;
      for (int i = 1; i < n; ++i) {
        const V3 d = 0.5 * (p[i - 1] + p[i + 1]) - p[i];
        const plan::SkinTangent t = plan::skin_tangent(model, q[i][0], q[i][1]);
        q[i] += t.to_theta_z(d - d.dot(t.normal) * t.normal);
        const V3 next = model.skin_point(q[i][0], q[i][1]);
        moved = std::max(moved, (next - p[i]).norm());
        p[i] = next;
      }
      if (moved < 1e-5) break;
    }
  }
  double length = 0;
  for (std::size_t i = 0; i + 1 < p.size(); ++i) length += (p[i + 1] - p[i]).norm();
  return length;
}

// A landmark a surgeon can palpate, on the model.
struct Palpable {
  std::string name;  // as caps names it: "exocanthion_left"
  V2 theta_z;
  V3 lps;
  double confidence = 1;
};

std::string spoken(std::string name) {
  for (char& c : name)
    if (c == '_') c = ' ';
  return name;
}

std::string fixed(double x, int digits = 1) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*f", digits, std::abs(x) < 0.5 * std::pow(10.0, -digits) ? 0.0 : x);
  return buf;
}

std::string utc_now() {
  const std::time_t t = std::chrono::system_clock::to_time_t(std::chrono::system_clock::now());
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%d %H:%M UTC", &tm);
  return buf;
}

// The key points of the incision: the border loop's distinct positions (ends, corners, the
// excision's border) in loop order, then the plan's centre.
struct KeyPoint {
  std::string label, kind;
  V2 theta_z;
  V3 lps;
  V2 paper;  // on the sheet (embed_key_points())
  V2 flat;   // where the flattened view puts it (Flat::to_paper())
  std::vector<int> loop_nodes;
};

std::vector<KeyPoint> key_points(const plan::Plan& p, const plan::BorderLoop& loop,
                                 const PatientModel& model, const Flat& flat) {
  std::map<int, int> degree;
  for (const auto& path : p.paths)
    for (std::size_t i = 0; i < path.size(); ++i) degree[path[i]] += (i == 0 || i + 1 == path.size()) ? 1 : 2;
  std::set<int> excised;
  for (const auto& e : p.excisions) excised.insert(e.loop_index);
  std::vector<KeyPoint> out;
  for (int i = 0; i < loop.size(); ++i) {
    const V2 tz = loop.theta_z[i];
    const V2 xy = flat.to_paper(tz);
    auto same = std::find_if(out.begin(), out.end(),
                             [&](const KeyPoint& k) { return (k.paper - xy).norm() < 0.05; });
    if (same != out.end()) {
      same->loop_nodes.push_back(i);
      continue;
    }
    KeyPoint k;
    k.kind = excised.count(i) ? "excision border" : degree[loop.point[i]] <= 1 ? "end" : "corner";
    k.theta_z = {std::remainder(tz[0], 360.0), tz[1]};
    k.lps = model.skin_point(k.theta_z[0], k.theta_z[1]);
    k.paper = k.flat = xy;
    k.loop_nodes = {i};
    out.push_back(k);
  }
  // The centre, unless a point of the cut is there already (a V-Y's stem).
  KeyPoint c;
  c.kind = "centre";
  c.theta_z = {p.frame.theta_deg, p.frame.z_mm};
  c.lps = model.skin_point(c.theta_z[0], c.theta_z[1]);
  c.paper = c.flat = flat.to_paper(c.theta_z);
  auto at_centre = std::find_if(out.begin(), out.end(),
                                [&](const KeyPoint& k) { return (k.paper - c.paper).norm() < 0.5; });
  if (at_centre != out.end()) at_centre->kind += ", centre";
  else out.push_back(c);
  for (std::size_t i = 0; i < out.size(); ++i) out[i].label = std::string(1, char('A' + i % 26));
  return out;
}

// The key points laid on paper keeping their skin distances (as caps measures them,
// segment_length_on_skin()) as well as a plane can: least squares over every pair, the loop's
// edges (the lines a surgeon draws) weighted most, started from and weakly held to the
// flattened view (which fixes the position and the turn), by Gauss-Newton. Returns the largest
// difference between a loop edge on paper and on the skin (mm).
double embed_key_points(std::vector<KeyPoint>& points, const PatientModel& model) {
  const int n = static_cast<int>(points.size());
  if (n < 2) return 0;
  std::map<std::pair<int, int>, double> edge;  // key point pairs joined by a loop edge
  std::map<int, int> of_node;
  for (int i = 0; i < n; ++i)
    for (int node : points[i].loop_nodes) of_node[node] = i;
  const int loop_size = static_cast<int>(of_node.size());
  for (int node = 0; node < loop_size; ++node) {
    const int a = of_node[node], b = of_node[(node + 1) % loop_size];
    if (a != b) edge[{std::min(a, b), std::max(a, b)}] = 1.0;
  }
  struct Pair {
    int a, b;
    double length, weight;
  };
  std::vector<Pair> pairs;
  for (int a = 0; a < n; ++a)
    for (int b = a + 1; b < n; ++b) {
      const V2 ta = points[a].theta_z;
      const V2 tb(ta[0] + std::remainder(points[b].theta_z[0] - ta[0], 360.0), points[b].theta_z[1]);
      pairs.push_back({a, b, plan::segment_length_on_skin(model, ta, tb), edge.count({a, b}) ? 1.0 : 0.1});
    }
  std::vector<V2> start(n);
  for (int i = 0; i < n; ++i) start[i] = points[i].paper;
  constexpr double kHold = 0.01;
  Eigen::VectorXd x(2 * n);
  for (int i = 0; i < n; ++i) x.segment<2>(2 * i) = start[i];
  for (int it = 0; it < 30; ++it) {
    Eigen::MatrixXd J = Eigen::MatrixXd::Zero(static_cast<int>(pairs.size()) + 2 * n, 2 * n);
    Eigen::VectorXd res(J.rows());
    for (std::size_t k = 0; k < pairs.size(); ++k) {
      const Pair& q = pairs[k];
      const V2 d = x.segment<2>(2 * q.b) - x.segment<2>(2 * q.a);
      const double len = std::max(d.norm(), 1e-9);
      const double w = std::sqrt(q.weight);
      res[static_cast<int>(k)] = w * (len - q.length);
      J.block<1, 2>(static_cast<int>(k), 2 * q.b) = w * d.transpose() / len;
      J.block<1, 2>(static_cast<int>(k), 2 * q.a) = -w * d.transpose() / len;
    }
    for (int i = 0; i < n; ++i) {
      const int row = static_cast<int>(pairs.size()) + 2 * i;
      res.segment<2>(row) = std::sqrt(kHold) * (x.segment<2>(2 * i) - start[i]);
      J.block<2, 2>(row, 2 * i) = std::sqrt(kHold) * Eigen::Matrix2d::Identity();
    }
    const Eigen::VectorXd step = (J.transpose() * J).ldlt().solve(-J.transpose() * res);
    x += step;
    if (step.norm() < 1e-9) break;
  }
  for (int i = 0; i < n; ++i) points[i].paper = x.segment<2>(2 * i);
  double worst = 0;
  for (const Pair& q : pairs)
    if (edge.count({q.a, q.b}))
      worst = std::max(worst, std::abs((points[q.b].paper - points[q.a].paper).norm() - q.length));
  return worst;
}

// The palpable landmarks the model in `dir` has (glabella, nasion, exocanthions, tragions; the
// oral commissures from its feature lines), in its (theta, z), nearest the centre first, within
// kMaxLandmarkMm; at most kMaxLandmarks.
std::vector<Palpable> palpable_landmarks(const std::string& dir, const PatientModel& model,
                                         const V3& centre_lps, std::vector<std::string>& notes) {
  std::vector<Palpable> all;
  auto add = [&](const std::string& name, const V2& tz, double confidence) {
    all.push_back({name, tz, model.skin_point(tz[0], tz[1]), confidence});
  };
  const Landmarks landmarks = plan::model_landmarks(dir, model);
  for (const char* name : {"glabella", "nasion", "exocanthion_left", "exocanthion_right",
                           "tragion_left", "tragion_right"})
    if (const Landmark* l = landmarks.find(name); l && l->found)
      add(name, {l->theta_deg, l->z_mm}, l->confidence);
  if (const auto lines = loaded_feature_lines(dir))
    for (const char* name : {"oral_commissure_left", "oral_commissure_right"})
      if (const FeatureLine* f = lines->find(name); f && f->found && !f->theta_z.empty())
        add(name, f->theta_z.front(), f->confidence);
  std::sort(all.begin(), all.end(), [&](const Palpable& a, const Palpable& b) {
    return (a.lps - centre_lps).norm() < (b.lps - centre_lps).norm();
  });
  std::vector<Palpable> out;
  for (const Palpable& l : all)
    if ((l.lps - centre_lps).norm() <= kMaxLandmarkMm && static_cast<int>(out.size()) < kMaxLandmarks)
      out.push_back(l);
  if (out.empty())
    notes.push_back(cat("no palpable landmark (glabella, nasion, exocanthion, tragion, oral "
                        "commissure) within ", kMaxLandmarkMm, " mm of the plan: run caps model "
                        "landmarks on the model, or measure from the drawing"));
  return out;
}

// Text wrapped to `width` (canvas units) at spaces.
std::vector<std::string> wrap(const Canvas& c, const std::string& text, double size, double width) {
  std::vector<std::string> lines;
  std::string line;
  std::size_t i = 0;
  while (i < text.size()) {
    std::size_t j = text.find(' ', i);
    if (j == std::string::npos) j = text.size();
    const std::string word = text.substr(i, j - i);
    const std::string trial = line.empty() ? word : line + " " + word;
    if (!line.empty() && c.text_width(trial, size) > width) {
      lines.push_back(line);
      line = word;
    } else {
      line = trial;
    }
    i = j + 1;
  }
  if (!line.empty()) lines.push_back(line);
  return lines;
}

// What a result folder says about the closure.
struct Closure {
  bool present = false;
  std::string dir;
  double closing_force_n = 0, max_suture_force_n = 0, spacing_mm = 0, force_per_mm_n = 0;
  int sutures = 0;
  bool features_recorded = false;
  json features = json::array();
  std::vector<std::string> warnings;
};

// The parts of a plan that decide its closure, as the plan file writes them.
json closure_defining(const plan::Plan& p) {
  const json j = json::parse(plan::plan_to_json(p, nullptr));
  json out = json::object();
  for (const char* k : {"procedure", "frame", "points", "paths", "excisions", "sutures"})
    if (j.contains(k)) out[k] = j[k];
  return out;
}

Closure read_closure(const std::string& dir, const plan::Plan& plan) {
  Closure c;
  if (dir.empty()) return c;
  std::error_code ec;
  if (!fs::is_directory(dir, ec))
    throw InvalidInput(cat("--result ", dir, ": not a folder; give the folder caps simulate "
                           "wrote for this plan"));
  const fs::path rj = fs::path(dir) / "result.json";
  if (!fs::is_regular_file(rj, ec))
    throw InvalidInput(cat("--result ", dir, ": no result.json in it; give the folder caps "
                           "simulate wrote for this plan"));
  const json r = read_json_file<json>(rj, "is this the folder caps simulate wrote?");
  if (!r.is_object() || !r.contains("total_suture_force_n") || !r["total_suture_force_n"].is_number())
    throw InvalidInput(cat(rj.string(), ": no total_suture_force_n; is this a caps result?"));
  // The plan the result closed (caps simulate keeps it beside the result): another plan's
  // forces on this plan's sheet would be read as this plan's.
  const fs::path closed = fs::path(dir) / "plan.json";
  if (fs::is_regular_file(closed, ec)) {
    if (closure_defining(plan::read_plan(closed)) != closure_defining(plan))
      throw InvalidInput(cat("--result ", dir, ": that result closed another plan (its plan.json "
                             "differs from this plan's procedure, place or sutures); give the "
                             "folder caps simulate wrote for this plan, or simulate it again"));
  } else {
    c.warnings.push_back(cat("the result folder ", dir, " does not say which plan it closed (made "
                             "before caps simulate kept the plan beside its result): make sure "
                             "its forces are this plan's"));
  }
  c.present = true;
  c.dir = dir;
  c.closing_force_n = r["total_suture_force_n"].get<double>();
  if (r.contains("sutures_at_spacing") && r["sutures_at_spacing"].is_object()) {
    const json& s = r["sutures_at_spacing"];
    c.max_suture_force_n = s.value("max_suture_force_n", 0.0);
    c.spacing_mm = s.value("spacing_mm", 0.0);
    c.force_per_mm_n = s.value("force_per_mm_n", 0.0);
    c.sutures = s.value("n_sutures", 0);
  }
  auto add_warnings = [&](const json& j) {
    if (j.contains("warnings") && j["warnings"].is_array())
      for (const json& w : j["warnings"])
        if (w.is_string() &&
            std::find(c.warnings.begin(), c.warnings.end(), w.get<std::string>()) == c.warnings.end())
          c.warnings.push_back(w.get<std::string>());
  };
  add_warnings(r);
  // caps simulate's own answer (summary.json) carries the feature lines' displacements.
  const fs::path sj = fs::path(dir) / "summary.json";
  if (fs::is_regular_file(sj, ec)) {
    const json s = read_json_file<json>(sj, "is this the folder caps simulate wrote?");
    if (s.is_object() && s.contains("features") && s["features"].is_array()) {
      c.features = s["features"];
      c.features_recorded = true;
    }
    add_warnings(s);
  }
  return c;
}

// Everything the page shows, measured before anything is drawn.
struct Sheet {
  Paper paper;
  std::string title, model_dir, model_name, plan_file, procedure_line, placement_line, date;
  std::vector<std::string> identity;
  std::string credit;
  const PatientModel* model = nullptr;  // not owned
  plan::Plan plan;
  plan::BorderLoop loop;
  std::vector<KeyPoint> points;
  std::vector<Palpable> landmarks;
  // distance[i][j]: key point i from landmark j
  struct Distance {
    double skin_mm = 0, straight_mm = 0, left_mm = 0, up_mm = 0;
  };
  std::vector<std::vector<Distance>> distance;
  std::shared_ptr<const FeatureLines> features;
  std::vector<Palpable> all_landmarks;  // every found landmark, for the drawing
  V2 view_lo, view_hi;                  // paper mm (right, up) of the drawing
  double view_x = 0, view_y = 0;        // the drawing's top-left corner on the page (mm)
  double max_segment_error_mm = 0, max_offset_mm = 0;
  Closure closure;
  std::vector<std::string> warnings;
  double bar_x = 0, bar_y = 0;
};

// The skin under the drawing, shaded as lit from the viewer and above (grey for a CT model,
// its colour lightened for a scan), 6 pixels per mm; hatched where the model has no skin.
RgbImage skin_picture(const Sheet& s, const Flat& flat) {
  constexpr double kPpm = 6.0, kGridMm = 2.0;
  const V2 size = s.view_hi - s.view_lo;
  const int W = static_cast<int>(std::ceil(size.x() * kPpm));
  const int H = static_cast<int>(std::ceil(size.y() * kPpm));
  // (theta, z) on a coarse grid of walks, interpolated between: the map is smooth.
  const int gw = static_cast<int>(std::ceil(size.x() / kGridMm)) + 1;
  const int gh = static_cast<int>(std::ceil(size.y() / kGridMm)) + 1;
  std::vector<V2> grid(std::size_t(gw) * gh, V2(NAN, NAN));
  const V2 c(s.plan.frame.theta_deg, s.plan.frame.z_mm);
  for (int j = 0; j < gh; ++j)
    for (int i = 0; i < gw; ++i) {
      const V2 xy(s.view_lo.x() + i * kGridMm, s.view_hi.y() - j * kGridMm);
      try {
        V2 tz = flat.to_skin(xy);
        tz[0] = c[0] + std::remainder(tz[0] - c[0], 360.0);
        grid[std::size_t(j) * gw + i] = tz;
      } catch (const Error&) {
        // the walk leaves the model: no skin there
      }
    }
  const PatientModel& m = *s.model;
  const V3 n0 = m.skin_normal(c[0], c[1]);
  const V3 light = (n0 + 0.6 * flat.frame().ey).normalized();
  const bool colour = m.has_color();
  RgbImage img = make_image(W, H);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const double gx = (x + 0.5) / kPpm / kGridMm, gy = (y + 0.5) / kPpm / kGridMm;
      const int i = std::min(static_cast<int>(gx), gw - 2), j = std::min(static_cast<int>(gy), gh - 2);
      const double fx = gx - i, fy = gy - j;
      const V2 tz = (1 - fx) * (1 - fy) * grid[std::size_t(j) * gw + i] +
                    fx * (1 - fy) * grid[std::size_t(j) * gw + i + 1] +
                    (1 - fx) * fy * grid[std::size_t(j + 1) * gw + i] +
                    fx * fy * grid[std::size_t(j + 1) * gw + i + 1];
      V3 rgb;
      if (!tz.allFinite() || !m.has_z(tz[1])) {
        rgb = ((x + y) / 12) % 2 ? V3(0.8, 0.8, 0.8) : V3(0.92, 0.92, 0.92);
      } else {
        const double t = std::remainder(tz[0], 360.0);
        const double lambert = std::max(0.0, m.skin_normal(t, tz[1]).dot(light));
        const double g = 0.55 + 0.42 * lambert;
        rgb = colour ? V3(0.35 * V3::Ones() + 0.65 * m.color_at(t, tz[1]) * g) : V3(g, g, g);
        if (!flags_valid(m.flags_at(t, tz[1]))) rgb = 0.5 * rgb + V3(0.45, 0.45, 0.45);
      }
      img.set(x, y, rgb);
    }
  return img;
}

// The page, drawn in mm (the canvas scaled from its own units).
void draw_sheet(Canvas& c, const Sheet& s, const Flat& flat, const RgbImage& skin) {
  const double W = s.paper.width_mm, left = kMarginMm, right = W - kMarginMm;
  const double width = right - left;
  auto text = [&](double x, double y, const std::string& t, double size = 2.8,
                  const V3& colour = kInk, double align = 0, bool halo = false) {
    c.text(x, y, t, {.size_px = size, .colour = colour, .align = align, .halo = halo});
  };
  double y = kMarginMm + 5;
  text(left, y, s.title, 5.2);
  y += 6;
  for (const std::string& line : s.identity) {
    for (const std::string& l : wrap(c, line, kIdentityMm, width)) {
      text(left, y, l, kIdentityMm);
      y += kIdentityLineMm;
    }
  }
  // The drawing, 1:1.
  const V2 size = s.view_hi - s.view_lo;
  const double vx = s.view_x, vy = s.view_y;
  auto page = [&](const V2& xy) -> V2 {
    return {vx + (xy.x() - s.view_lo.x()), vy + (s.view_hi.y() - xy.y())};
  };
  c.draw_image_in(skin, vx, vy, size.x(), size.y());
  c.push_clip(vx, vy, size.x(), size.y());
  // Feature lines and landmarks around the plan, for orientation.
  if (s.features)
    for (const FeatureLine& f : s.features->items) {
      if (!f.found || f.theta_z.size() < 2) continue;
      std::vector<V2> line;
      for (const V2& tz : f.theta_z) line.push_back(page(flat.to_paper(tz)));
      c.polyline(line, {.colour = kFeature, .width_px = 0.3, .dash_px = {1.2, 0.8}});
      const auto inside = std::find_if(line.begin(), line.end(), [&](const V2& p) {
        return p.x() > vx + 2 && p.x() < vx + size.x() - 20 && p.y() > vy + 4 && p.y() < vy + size.y() - 2;
      });
      if (inside != line.end())
        text(inside->x(), inside->y() - 1.2, spoken(f.name), 2.2, kFeature, 0, true);
    }
  for (const Palpable& l : s.all_landmarks) {
    const V2 p = page(flat.to_paper(l.theta_z));
    c.line(p - V2(1.5, 0), p + V2(1.5, 0), {.colour = kLandmark, .width_px = 0.35});
    c.line(p - V2(0, 1.5), p + V2(0, 1.5), {.colour = kLandmark, .width_px = 0.35});
    text(p.x() + 2, p.y() - 1.5, spoken(l.name), 2.4, kLandmark, 0, true);
  }
  // The cutting paths (dashed: where the knife runs when nothing is excised; the axis of an
  // excision) and the border of the wound (solid: the lines to mark on the skin).
  // A point of a path on the sheet: where the flattened view puts it, moved with the key point
  // nearest it (the cut is laid at its skin lengths, embed_key_points()).
  auto on_sheet = [&](const V2& tz) -> V2 {
    const V2 xy = flat.to_paper(tz);
    const KeyPoint* near = &s.points.front();
    for (const KeyPoint& k : s.points)
      if ((k.flat - xy).norm() < (near->flat - xy).norm()) near = &k;
    return xy + near->paper - near->flat;
  };
  // The labels first: the lines are drawn over their white boxes.
  V2 mid = V2::Zero();
  for (const auto& k : s.points) mid += k.paper;
  mid /= static_cast<double>(s.points.size());
  for (const auto& k : s.points) {
    const V2 p = page(k.paper);
    if (k.kind == "centre") {
      text(p.x() + 1.6, p.y() + 3.6, k.label, 2.8, kInk, 0, true);
      continue;
    }
    V2 out = k.paper - mid;
    out = out.norm() > 1e-6 ? V2(out.normalized()) : V2(1, 0);
    const V2 q = p + 3.4 * V2(out.x(), -out.y());
    text(q.x(), q.y() + 1.0, k.label, 2.8, kInk, 0.5, true);
  }
  for (const auto& path : s.plan.paths) {
    std::vector<V2> line;
    for (int k : path) line.push_back(page(on_sheet({s.plan.points[k].theta_deg, s.plan.points[k].z_mm})));
    c.polyline(line, {.colour = kGrey, .width_px = 0.2, .dash_px = {1.0, 1.0}});
  }
  std::vector<V2> border(s.loop.size());
  for (const KeyPoint& k : s.points)
    for (int node : k.loop_nodes) border[node] = page(k.paper);
  // The key points' dots under the line, so that the line runs to its ends.
  for (const auto& k : s.points)
    if (k.kind != "centre") c.fill_circle(page(k.paper), 0.45, kInk);
  c.polyline(border, {.colour = kCut, .width_px = 0.3, .round_joins = true}, true);
  for (const auto& k : s.points)
    if (k.kind == "centre") {
      const V2 p = page(k.paper);
      c.stroke_circle(p, 0.9, {.colour = kInk, .width_px = 0.2});
      c.line(p - V2(1.6, 0), p + V2(1.6, 0), {.colour = kInk, .width_px = 0.15});
      c.line(p - V2(0, 1.6), p + V2(0, 1.6), {.colour = kInk, .width_px = 0.15});
    }
  // Orientation.
  text(vx + size.x() / 2, vy + 4, "\u2191 superior", 2.8, kInk, 0.5, true);
  text(vx + size.x() - 2, vy + size.y() / 2, "patient's left \u2192", 2.8, kInk, 1, true);
  text(vx + 2, vy + size.y() / 2, "\u2190 patient's right", 2.8, kInk, 0, true);
  c.pop_clip();
  c.stroke_rect(vx, vy, size.x(), size.y(), {.colour = kInk, .width_px = 0.25});
  // The 10 mm scale bar inside the drawing's lower left corner, on white.
  c.fill_rect(s.bar_x - 2, s.bar_y - 5, 24, 8, {1, 1, 1}, 0.85);
  c.fill_rect(s.bar_x, s.bar_y - 0.6, 10, 1.2, kInk);
  text(s.bar_x + 11.5, s.bar_y + 1.0, "10 mm", 2.6);
  text(s.bar_x, s.bar_y - 1.8, "1:1", 2.4);
  // A ruler under the drawing, millimetre ticks: print at 100 % and check it.
  const double ruler = std::floor(std::min(size.x(), 150.0) / 10) * 10;
  const double ry = vy + size.y() + 1;
  c.line({vx, ry}, {vx + ruler, ry}, {.colour = kInk, .width_px = 0.15});
  for (int mm = 0; mm <= static_cast<int>(ruler); ++mm) {
    const double len = mm % 10 == 0 ? 2.5 : mm % 5 == 0 ? 1.7 : 1.0;
    c.line({vx + mm, ry}, {vx + mm, ry + len}, {.colour = kInk, .width_px = 0.1});
    if (mm % 10 == 0) text(vx + mm, ry + 5, std::to_string(mm), 2.0, kInk, 0.5);
  }
  text(vx + ruler + 3, ry + 2.2, cat(static_cast<int>(ruler), " mm"), 2.4);
  y = ry + 9.5;
  text(left, y, cat("Print at 100 % (actual size, no fit to page) and check the ruler: ",
                    static_cast<int>(ruler), " mm."), 2.6);
  y += 3.6;
  for (const std::string& l :
       wrap(c, cat("The drawing: the skin around the plan laid flat from its centre as caps walks "
                   "on it; up is superior, right the patient's left (facing the patient). Each "
                   "line of the cut has its length on the skin (within ",
                   fixed(s.max_segment_error_mm, 2), " mm) and sits within ",
                   fixed(s.max_offset_mm, 2), " mm of where the skin picture puts it. Red: the lines to mark (the wound's border); "
                   "grey dashes: the cutting paths; blue dashes: the skin's feature lines; green "
                   "crosses: landmarks."),
            2.3, width)) {
    text(left, y, l, 2.3, kGrey);
    y += 3.2;
  }
  // The key points from the landmarks.
  y += 2.5;
  text(left, y, "Key points from palpable landmarks (mm)", 3.4);
  y += 5;
  const double col0 = 30;
  const int nl = static_cast<int>(s.landmarks.size());
  const double colw = nl > 0 ? (width - col0) / nl : 0;
  for (int j = 0; j < nl; ++j) {
    const Palpable& l = s.landmarks[j];
    text(left + col0 + j * colw, y,
         cat("from the ", spoken(l.name), l.confidence < kLowConfidence ? " *" : ""), 2.6);
  }
  y += 3.4;
  for (int j = 0; j < nl; ++j)
    text(left + col0 + j * colw, y, "skin | straight; L/R, U/D", 2.2, kGrey);
  y += 1.2;
  c.line({left, y}, {right, y}, {.colour = kGrey, .width_px = 0.15});
  for (std::size_t i = 0; i < s.points.size(); ++i) {
    const KeyPoint& k = s.points[i];
    y += 3.8;
    text(left, y, k.label, 3.0);
    text(left + 5, y, k.kind, 2.4, kGrey);
    for (int j = 0; j < nl; ++j) {
      const Sheet::Distance& d = s.distance[i][j];
      text(left + col0 + j * colw, y,
           cat(std::isfinite(d.skin_mm) ? fixed(d.skin_mm) : std::string("\u2013"), " | ",
               fixed(d.straight_mm)),
           2.8);
    }
    y += 3.3;
    for (int j = 0; j < nl; ++j) {
      const Sheet::Distance& d = s.distance[i][j];
      if (!std::isfinite(d.left_mm)) continue;
      text(left + col0 + j * colw, y,
           cat(fixed(std::abs(d.left_mm)), d.left_mm >= 0 ? " L, " : " R, ", fixed(std::abs(d.up_mm)),
               d.up_mm >= 0 ? " U" : " D"),
           2.4, kGrey);
    }
    y += 1.2;
    c.line({left, y}, {right, y}, {.colour = V3(0.8, 0.8, 0.8), .width_px = 0.1});
  }
  y += 3.5;
  std::string how =
      "skin: the shortest path on the skin (a tape held to the skin; where it bridges a hollow, "
      "such as the nasion, it reads less); straight: a caliper's straight line; L/R, U/D: from "
      "the landmark, mm towards the patient's left or right, then up or down along the skin: the "
      "walk caps plan new --at LANDMARK+L,U makes to the point.";
  bool low = false;
  for (const Palpable& l : s.landmarks) low = low || l.confidence < kLowConfidence;
  if (low) how += " *: found with low confidence on this model: confirm by palpation.";
  for (const std::string& l : wrap(c, how, 2.3, width)) {
    text(left, y, l, 2.3, kGrey);
    y += 3.1;
  }
  // The closure's prediction.
  y += 2.5;
  if (s.closure.present) {
    text(left, y, cat("Predicted closure (", s.closure.dir, ")"), 3.4);
    y += 4.6;
    text(left, y,
         cat("closing force ", fixed(s.closure.closing_force_n, 2),
             " N (the suture pairs' forces added); largest suture ",
             fixed(s.closure.max_suture_force_n, 2), " N (", s.closure.sutures, " sutures every ",
             fixed(s.closure.spacing_mm, 1), " mm, ", fixed(s.closure.force_per_mm_n, 3),
             " N per mm of wound)"),
         2.7);
    y += 4;
    if (!s.closure.features_recorded) {
      text(left, y, "feature distortions: not recorded in this result (run caps simulate again)",
           2.6, kGrey);
      y += 3.6;
    } else {
      int shown = 0;
      std::string still;  // the lines the closure moves less than 0.05 mm
      for (const json& f : s.closure.features) {
        if (!f.value("has_value", false)) continue;
        if (f.contains("max_mm") && f["max_mm"].is_number() && f["max_mm"].get<double>() < 0.05) {
          still += cat(still.empty() ? "" : ", ", spoken(f.value("name", std::string())));
          ++shown;
          continue;
        }
        const std::string sentence = f.value("sentence", std::string());
        const std::string warning = f.contains("warning") && f["warning"].is_string()
                                        ? f["warning"].get<std::string>()
                                        : std::string();
        for (const std::string& l : wrap(c, cat("\u2022 ", sentence), 2.6, width)) {
          text(left, y, l, 2.6);
          y += 3.4;
        }
        if (!warning.empty())
          for (const std::string& l : wrap(c, cat("  WARNING: ", warning), 2.6, width)) {
            text(left, y, l, 2.6, kWarn);
            y += 3.4;
          }
        ++shown;
      }
      if (!still.empty())
        for (const std::string& l : wrap(c, cat("\u2022 moved less than 0.05 mm: ", still), 2.6, width)) {
          text(left, y, l, 2.6);
          y += 3.4;
        }
      if (shown == 0) {
        text(left, y, "feature distortions: the closure reaches no feature line (brows, eyelid "
                      "margins, lips, alae)", 2.6);
        y += 3.6;
      }
    }
  } else {
    text(left, y, "No closure given (caps plan sheet --result RESULT_DIR adds the predicted forces "
                  "and feature distortions).", 2.6, kGrey);
    y += 3.6;
  }
  if (!s.warnings.empty()) {
    y += 1.5;
    text(left, y, "Warnings", 3.0, kWarn);
    y += 3.8;
    for (const std::string& w : s.warnings)
      for (const std::string& l : wrap(c, cat("\u2022 ", w), 2.4, width)) {
        text(left, y, l, 2.4, kWarn);
        y += 3.1;
      }
  }
  // Footer.
  const double fy = s.paper.height_mm - kMarginMm + 4;
  c.line({left, fy - 4}, {right, fy - 4}, {.colour = kGrey, .width_px = 0.1});
  text(left, fy, cat("caps plan sheet, ", s.date, ". A plan for a surgeon to check, not a "
                     "prescription: confirm every landmark by palpation."), 2.2, kGrey);
  if (!s.credit.empty()) text(right, fy, s.credit, 2.2, kGrey, 1);
}

// The page's height the sheet needs below the drawing (mm), to size the drawing.
double text_below_mm(const Sheet& s) {
  double h = 18 + 14 + 9 + s.points.size() * 8.3 + 14;
  if (s.closure.present) {
    h += 14;
    for (const json& f : s.closure.features)
      if (f.value("has_value", false)) h += f.contains("warning") ? 14 : 7;
  } else {
    h += 6;
  }
  h += s.warnings.empty() ? 0 : 6 + 6.5 * s.warnings.size();
  return h + 10;
}

}  // namespace

SheetResult run_plan_sheet(const SheetRequest& r, Reporter* reporter) {
  detail::refuse_output_over_inputs(r);
  Sheet s;
  s.paper = paper_of(r.paper);
  if (r.output.empty()) throw InvalidInput("-o: give the sheet to write (SHEET.pdf)");
  const fs::path pdf_path(r.output);
  std::string ext = pdf_path.extension().string();
  for (char& ch : ext) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
  if (ext != ".pdf")
    throw InvalidInput(cat("-o ", r.output, ": the sheet is a PDF; name it .pdf"));
  fs::path png_path = pdf_path;
  png_path.replace_extension(".png");
  std::error_code ec;
  for (const fs::path& p : r.png ? std::vector<fs::path>{pdf_path, png_path} : std::vector<fs::path>{pdf_path}) {
    if (fs::exists(p, ec) && !r.force)
      throw InvalidInput(cat(p.string(), " exists; use --force to replace it"));
    if (fs::exists(p, ec) && !fs::is_regular_file(p, ec))
      throw InvalidInput(cat(p.string(), " is not a regular file; caps replaces only files"));
  }
  if (!pdf_path.parent_path().empty() && !fs::is_directory(pdf_path.parent_path(), ec))
    throw InvalidInput(cat("-o ", r.output, ": the folder ", pdf_path.parent_path().string(),
                           " does not exist"));

  s.plan = plan::read_plan(r.plan);
  const plan::Plan& p = s.plan;
  if (p.model.empty() && r.model.empty())
    throw InvalidInput(cat(r.plan, ": names no model; give --model MODEL_DIR"));
  s.model_dir = detail::plan_model_dir(!r.model.empty() ? r.model : p.model, p.model, p.model_hash);
  const auto loaded = loaded_model(s.model_dir);
  const PatientModel& model = *loaded;
  s.model = &model;
  plan::PlanReport report = plan::check_plan(p, model);
  if (std::string doubt = placement_doubt(s.model_dir, model, p.placement); !doubt.empty())
    report.warnings.push_back(std::move(doubt));
  s.closure = read_closure(r.result, s.plan);
  s.loop = plan::border_loop(p);

  const V2 centre(p.frame.theta_deg, p.frame.z_mm);
  const Flat flat(model, centre);
  s.points = key_points(p, s.loop, model, flat);
  std::vector<std::string> notes;
  // A plan on a local chart (caps plan new beside the plan) is measured from its parent's
  // landmarks on the parent, the head, where they were found: the chart holds the skin around the
  // plan only. A point the head's image does not hold (undercut) gets its straight distance only.
  const std::string parent = detail::chart_parent(s.model_dir);
  const std::string landmark_dir = parent.empty() ? s.model_dir : parent;
  const std::shared_ptr<const PatientModel> parent_model = parent.empty() ? nullptr : loaded_model(parent);
  const PatientModel& measure = parent_model ? *parent_model : model;
  s.landmarks = palpable_landmarks(landmark_dir, measure, model.skin_point(centre[0], centre[1]), notes);
  s.distance.assign(s.points.size(), std::vector<Sheet::Distance>(s.landmarks.size()));
  std::vector<std::string> unheld;
  for (std::size_t i = 0; i < s.points.size(); ++i) {
    V2 tz = s.points[i].theta_z;
    bool held = true;
    if (parent_model) {
      const CylindricalPoint c = measure.to_cylindrical(s.points[i].lps);
      tz = {c.theta_deg, c.z_mm};
      held = measure.has_z(tz[1]) && (measure.skin_point(tz[0], tz[1]) - s.points[i].lps).norm() < 1.0;
      if (!held) unheld.push_back(s.points[i].label);
    }
    for (std::size_t j = 0; j < s.landmarks.size(); ++j) {
      Sheet::Distance& d = s.distance[i][j];
      d.straight_mm = (s.points[i].lps - s.landmarks[j].lps).norm();
      if (!held) {
        d.skin_mm = d.left_mm = d.up_mm = std::numeric_limits<double>::quiet_NaN();
        continue;
      }
      const V2 l = s.landmarks[j].theta_z;
      const V2 lu = Flat(measure, l).to_paper(tz);
      const V2 to(l[0] + std::remainder(tz[0] - l[0], 360.0), tz[1]);
      // The geodesic, never longer than the walk it starts from (round-off aside).
      d.skin_mm = std::min(skin_geodesic_mm(measure, l, to), lu.norm());
      d.left_mm = lu.x();
      d.up_mm = lu.y();
    }
  }
  if (!unheld.empty() && !s.landmarks.empty()) {
    std::string labels;
    for (const std::string& l : unheld) labels += cat(labels.empty() ? "" : ", ", l);
    notes.push_back(cat("point", unheld.size() > 1 ? "s " : " ", labels, ": the head's image does "
                        "not hold the skin there (the plan is on a local chart); only the straight "
                        "distances are given"));
  }
  // The cut on paper keeps its skin lengths; how far that moves it over the skin picture.
  s.max_segment_error_mm = embed_key_points(s.points, model);
  for (const KeyPoint& k : s.points)
    s.max_offset_mm = std::max(s.max_offset_mm, (k.paper - k.flat).norm());

  // Every found landmark and feature line is drawn where it falls in the view.
  // On a chart, a landmark is drawn where the chart holds its skin point.
  if (parent.empty()) s.features = loaded_feature_lines(landmark_dir);
  for (const Landmark& l : plan::model_landmarks(landmark_dir, measure).items) {
    if (!l.found) continue;
    V2 tz(l.theta_deg, l.z_mm);
    if (parent_model) {
      const CylindricalPoint c = model.to_cylindrical(l.lps);
      tz = {c.theta_deg, c.z_mm};
      if (!model.has_z(tz[1]) || (model.skin_point(tz[0], tz[1]) - l.lps).norm() > 1.0) continue;
    }
    s.all_landmarks.push_back({l.name, tz, l.lps, l.confidence});
  }

  // Identity.
  const ModelInfo info = read_model_info(s.model_dir);
  const json source = json::parse(info.source_json, nullptr, false);
  s.model_name = fs::path(s.model_dir).lexically_normal().filename().string();
  if (s.model_name.empty()) s.model_name = fs::path(s.model_dir).lexically_normal().parent_path().filename().string();
  if (!parent.empty())
    s.model_name = cat(fs::path(parent).lexically_normal().filename().string(), " (its local chart ",
                       s.model_name, ")");
  s.credit = source.is_object() ? source.value("credit", std::string()) : std::string();
  std::string source_line;
  if (source.is_object()) {
    source_line = source.value("path", std::string());
    const std::string modality = source.value("modality", std::string());
    const std::string format = source.value("format", std::string());
    if (!modality.empty() || !format.empty())
      source_line += cat(" (", modality, modality.empty() || format.empty() ? "" : ", ", format, ")");
  }
  std::string params;
  for (const auto& [k, v] : p.parameters)
    params += cat(params.empty() ? "" : ", ", spoken(k), " ", round_sig(v, 4));
  s.title = cat("Operating-room sheet: ", spoken(p.procedure), " on ", s.model_name);
  s.date = utc_now();
  s.identity.push_back(cat("Patient model: ", s.model_dir, ", built from ", source_line,
                           "; content ", info.content_hash, "; ", info.created_by));
  s.identity.push_back(cat("Plan: ", r.plan, "; ", spoken(p.procedure),
                           params.empty() ? "" : cat(" (", params, ")"), "; centre theta ",
                           fixed(p.frame.theta_deg), " deg, z ", fixed(p.frame.z_mm), " mm",
                           p.placement ? cat(" (placed at ", p.placement->landmark,
                                             p.placement->left_mm < 0 ? "-" : "+",
                                             fixed(std::abs(p.placement->left_mm)), ",",
                                             fixed(p.placement->up_mm), ")")
                                       : std::string(),
                           ", orientation ", fixed(p.frame.orientation_deg), " deg from superior "
                           "towards the patient's left; cut ", fixed(report.cut_length_mm), " mm"));
  s.identity.push_back(cat("Made ", s.date, " on ", s.paper.name, " (", fixed(s.paper.width_mm), " x ",
                           fixed(s.paper.height_mm), " mm); the drawing is 1:1: a millimetre on "
                           "paper is a millimetre of skin."));

  // The drawing's extent: the plan and a margin, the page's width, as tall as the page allows.
  V2 lo(1e30, 1e30), hi(-1e30, -1e30);
  for (int i = 0; i < s.loop.size(); ++i) {
    const V2 xy = flat.to_paper(s.loop.theta_z[i]);
    lo = lo.cwiseMin(xy);
    hi = hi.cwiseMax(xy);
  }
  const double width = s.paper.width_mm - 2 * kMarginMm;
  // The header's height: the identity lines wrapped as draw_sheet() wraps them.
  double header = 11 + 2 + kIdentityLineMm;
  {
    Canvas measure(1, 1);
    measure.scale(kPngDpi / 25.4);
    for (const std::string& line : s.identity)
      header += kIdentityLineMm * wrap(measure, line, kIdentityMm, width).size();
  }
  const double room = s.paper.height_mm - 2 * kMarginMm - header - text_below_mm(s);
  const V2 extent = hi - lo;
  if (extent.x() + 2 * 5 > width || extent.y() + 2 * 5 > room)
    throw InvalidInput(cat(r.plan, ": the plan spans ", fixed(extent.x()), " x ", fixed(extent.y()),
                           " mm of skin; the 1:1 drawing on ", s.paper.name, " holds at most ",
                           fixed(width - 10), " x ", fixed(room - 10), " mm"));
  const double view_h = std::min(room, std::max(kMinViewHeightMm, extent.y() + 2 * kViewMarginMm));
  const V2 mid = 0.5 * (lo + hi);
  s.view_lo = V2(mid.x() - width / 2, mid.y() - view_h / 2);
  s.view_hi = V2(mid.x() + width / 2, mid.y() + view_h / 2);
  s.view_x = kMarginMm;
  s.view_y = kMarginMm + header;
  s.bar_x = s.view_x + 4;
  s.bar_y = s.view_y + view_h - 4;

  s.warnings = report.warnings;
  for (const std::string& n : notes) s.warnings.push_back(n);
  for (const std::string& w : s.closure.warnings)
    if (std::find(s.warnings.begin(), s.warnings.end(), w) == s.warnings.end()) s.warnings.push_back(w);
  for (const Palpable& l : s.landmarks)
    if (l.confidence < kLowConfidence)
      s.warnings.push_back(cat("the ", spoken(l.name), " was found with low confidence (",
                               fixed(l.confidence, 2), "): confirm it by palpation before "
                               "measuring from it"));

  // Draw: the PDF in points, the PNG at kPngDpi; both in mm.
  const RgbImage skin = skin_picture(s, flat);
  Canvas pdf = Canvas::pdf_page(s.paper.width_mm * 72 / 25.4, s.paper.height_mm * 72 / 25.4);
  pdf.scale(72 / 25.4);
  draw_sheet(pdf, s, flat, skin);
  const std::string pdf_bytes = pdf.pdf();
  std::optional<RgbImage> png;
  if (r.png) {
    Canvas raster(static_cast<int>(std::lround(s.paper.width_mm / 25.4 * kPngDpi)),
                  static_cast<int>(std::lround(s.paper.height_mm / 25.4 * kPngDpi)));
    raster.scale(kPngDpi / 25.4);
    draw_sheet(raster, s, flat, skin);
    png = raster.image();
  }
  write_text_atomic(pdf_path, pdf_bytes);
  if (png) write_png(png_path, *png);

  SheetResult out;
  out.output = r.output;
  out.png = png ? png_path.string() : std::string();
  out.paper = s.paper.name;
  out.page_width_mm = s.paper.width_mm;
  out.page_height_mm = s.paper.height_mm;
  out.view_x_mm = s.view_x;
  out.view_y_mm = s.view_y;
  out.view_width_mm = s.view_hi.x() - s.view_lo.x();
  out.view_height_mm = s.view_hi.y() - s.view_lo.y();
  out.view_left_mm = s.view_lo.x();
  out.view_top_mm = s.view_hi.y();
  out.scale_bar_x_mm = s.bar_x;
  out.scale_bar_y_mm = s.bar_y;
  json points = json::array();
  for (std::size_t i = 0; i < s.points.size(); ++i) {
    const KeyPoint& k = s.points[i];
    json d = json::array();
    for (std::size_t j = 0; j < s.landmarks.size(); ++j)
      d.push_back({{"name", s.landmarks[j].name},
                   {"skin_mm", s.distance[i][j].skin_mm},
                   {"straight_mm", s.distance[i][j].straight_mm},
                   {"walk_mm", std::hypot(s.distance[i][j].left_mm, s.distance[i][j].up_mm)},
                   {"left_mm", s.distance[i][j].left_mm},
                   {"up_mm", s.distance[i][j].up_mm}});
    points.push_back({{"label", k.label},
                      {"kind", k.kind},
                      {"loop_nodes", k.loop_nodes},
                      {"theta_deg", k.theta_z[0]},
                      {"z_mm", k.theta_z[1]},
                      {"lps", {k.lps.x(), k.lps.y(), k.lps.z()}},
                      {"paper_mm", {k.paper.x(), k.paper.y()}},
                      {"flat_mm", {k.flat.x(), k.flat.y()}},
                      {"landmarks", d}});
  }
  out.points_json = detail::dump(points);
  for (const Palpable& l : s.landmarks) out.landmarks.push_back(l.name);
  out.max_segment_error_mm = s.max_segment_error_mm;
  out.max_offset_mm = s.max_offset_mm;
  out.has_result = s.closure.present;
  out.closing_force_n = s.closure.closing_force_n;
  out.max_suture_force_n = s.closure.max_suture_force_n;
  out.sutures = s.closure.sutures;
  out.suture_spacing_mm = s.closure.spacing_mm;
  out.features_recorded = s.closure.features_recorded;
  out.features_json = detail::dump(s.closure.features);
  out.warnings = s.warnings;
  for (const std::string& w : s.warnings) warn(reporter, w);
  return out;
}

std::string summary(const SheetResult& r) {
  return cat("caps plan sheet: ", r.paper, " page, the incision 1:1 in a ", fixed(r.view_width_mm, 0),
             " x ", fixed(r.view_height_mm, 0), " mm view, ", r.landmarks.size(),
             " landmarks measured from",
             r.has_result ? cat(", closing force ", fixed(r.closing_force_n, 2), " N") : std::string(),
             " -> ", r.output, r.png.empty() ? std::string() : cat(" and ", r.png));
}

}  // namespace caps::app
