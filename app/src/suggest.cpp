#include "caps/app/suggest.hpp"

#include <algorithm>
#include <atomic>
#include <exception>
#include <mutex>
#include <thread>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>

#include "caps/app/loaded_model.hpp"
#include "caps/core/atomic_output.hpp"
#include "caps/core/error.hpp"
#include "caps/core/plane_geometry.hpp"
#include "caps/core/units.hpp"
#include "caps/fem/blas.hpp"
#include "caps/image/canvas.hpp"
#include "caps/plan/check.hpp"
#include "caps/plan/placement.hpp"
#include "caps/plan/plan_io.hpp"
#include "caps/plan/procedures.hpp"
#include "caps/plan/skin_lines.hpp"
#include "caps/plan/skin_walk.hpp"
#include "caps/surface/feature_lines.hpp"
#include "caps/surface/patient_model.hpp"
#include "json_fields.hpp"
#include "model_result.hpp"
#include "numbers.hpp"
#include "output_check.hpp"
#include "skin_place.hpp"

CAPS_APP_REQUEST_JSON(caps::app::SuggestRequest)
CAPS_APP_RESULT_JSON(caps::app::SuggestResult)

namespace caps::app {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

/// The closures suggest lays around a lesion: each one's template parameters for a lesion whose
/// excised disc (the lesion and its margin) has radius `r_mm`, the orientations that differ
/// (an ellipse is the same turned 180 deg; a rhomboid's flap is not), and a flap's two mirror
/// images where turning it does not give them (a bilobed flap's lobes, a rotation flap's arc, to
/// either side).
struct Fit {
  std::map<std::string, double> parameters;
  double turn_deg = 180;  ///< orientations are taken in [0, turn_deg)
  std::string side_parameter;    ///< the template's parameter for the side ("" where none)
  std::vector<double> sides{0};  ///< its values tried (1: left of the orientation, -1: right)
  /// The template's origin from the lesion's centre (mm along the design's frame's ex and ey,
  /// side 1; the mirror image's is mirrored): where the template's origin is not its defect's
  /// centre (a rotation flap's is its arc's centre, the defect's apex).
  Eigen::Vector2d origin_mm{0, 0};
  /// An ellipse around a drawn outline: the outline in the skin's plane at the lesion's centre
  /// (mm along orientation 0 and 90: LesionOutline::local), its margin and the ellipse's ratio;
  /// its length and width then depend on the orientation (design_parameters()).
  std::vector<Eigen::Vector2d> outline_mm;
  double margin_mm = 0, ratio = 3;
};

/// A lesion drawn as an outline on the skin (--outline): its points, and where they lie in the
/// plane of the skin at the lesion's centre.
struct LesionOutline {
  std::vector<Eigen::Vector2d> theta_z;  ///< as given (deg, mm); empty: a round lesion
  std::vector<Eigen::Vector3d> lps;      ///< their skin points (--outline-xyz's as given)
  std::vector<Eigen::Vector2d> offsets_mm;  ///< --outline-mm's (left, up) as given
  /// The points in the skin's tangent plane at the centre: mm along the frames of orientation 0
  /// (superior) and 90 (towards +theta) there.
  std::vector<Eigen::Vector2d> local;
  double area_mm2 = 0;     ///< the outline's area in that plane
  double diameter_mm = 0;  ///< its largest diameter (between skin points)
  double reach_mm = 0;     ///< its farthest point from the centre
};

/// One outline field's points as given into `points`: 3 to 200 of them, a point repeated next
/// to itself (or the first again at the end) taken once.
template <int N>
void read_outline(const std::string& text, const std::string& field, const std::string& meaning,
                  std::vector<Eigen::Matrix<double, N, 1>>& points) {
  try {
    for (const auto& p : parse_point_list<N>(text, field, meaning)) {
      const Eigen::Matrix<double, N, 1> q = Eigen::Map<const Eigen::Matrix<double, N, 1>>(p.data());
      if (points.empty() || (q - points.back()).norm() > 0) points.push_back(q);
    }
  } catch (const InvalidParameter&) {
    throw;
  } catch (const InvalidInput& e) {  // the field named as each front end spells it
    throw InvalidParameter(e.what());
  }
  if (points.size() > 1 && points.front() == points.back()) points.pop_back();
  if (points.size() < 3 || points.size() > 200)
    throw InvalidParameter(cat(field, ": ", points.size(),
                               " distinct points; draw the lesion's outline with 3 to 200 points ",
                               meaning, " in order around it"));
}

/// --outline "THETA,Z;THETA,Z;..." (theta_z), --outline-xyz "X,Y,Z;..." (lps, LPS on the skin)
/// or --outline-mm "LEFT,UP;..." (offsets_mm about the centre), whichever is given; theta_z is
/// filled from the other two once the model is read.
LesionOutline parse_outline(const std::string& theta_z, const std::string& xyz,
                            const std::string& mm) {
  LesionOutline o;
  if (!theta_z.empty())
    read_outline<2>(theta_z, "{outline}", "THETA,Z in degrees and mm", o.theta_z);
  else if (!mm.empty())
    read_outline<2>(mm, "{outline_mm}", "LEFT,UP in mm", o.offsets_mm);
  else
    read_outline<3>(xyz, "{outline_xyz}", "LPS X,Y,Z in mm", o.lps);
  return o;
}

/// The area centroid of the outline in (theta, z) (an affine image of the skin's plane near
/// the lesion, so the centroid is the same point), theta taken about the first point.
Eigen::Vector2d outline_centre(const LesionOutline& o) {
  std::vector<Eigen::Vector2d> q = o.theta_z;
  for (auto& p : q) p.x() = q.front().x() + wrap_degrees(p.x() - q.front().x());
  return area_centroid(q);
}

/// The outline's skin points on `model` and their place in its skin's plane at (theta, z).
void project_outline(LesionOutline& o, const PatientModel& model, const Eigen::Vector2d& tz) {
  o.lps.clear();
  o.local.clear();
  const Eigen::Vector3d c = model.skin_point(tz[0], tz[1]);
  const Eigen::Vector3d up = plan::skin_frame(model, tz[0], tz[1], 0).ex;
  const Eigen::Vector3d right = plan::skin_frame(model, tz[0], tz[1], 90).ex;
  for (const Eigen::Vector2d& p : o.theta_z) {
    const Eigen::Vector3d x = model.skin_point(p.x(), p.y());
    if (!x.allFinite() || !c.allFinite())
      throw InvalidParameter(cat("{outline}: the point ", p.x(), ",", p.y(),
                                 " is not on the model's skin; draw the outline on the skin"));
    o.lps.push_back(x);
    o.local.emplace_back((x - c).dot(up), (x - c).dot(right));
  }
  o.reach_mm = o.diameter_mm = 0;
  for (std::size_t i = 0; i < o.local.size(); ++i) {
    o.reach_mm = std::max(o.reach_mm, o.local[i].norm());
    for (std::size_t j = i + 1; j < o.lps.size(); ++j)
      o.diameter_mm = std::max(o.diameter_mm, (o.lps[i] - o.lps[j]).norm());
  }
  o.area_mm2 = std::abs(signed_area(o.local));
}

/// An ellipse of `ratio` (length / width): the library's outline is the rhombus of its length,
/// width and apex angle (plan/procedures.cpp), whose inscribed circle has radius
/// L W / (2 sqrt(L^2 + W^2)); it is the excised disc when W = 2 r sqrt(k^2 + 1) / k.
/// A Limberg rhomboid (60 and 120 deg) of side s has an inscribed circle of radius s sin 60 / 2
/// (half its height): s = 4 r / sqrt 3.
/// A bilobed flap's defect is a disc of its radius about the template's origin (with its
/// Burow's triangle towards the pivot): the radius is r; the lobes (Zitelli's 45 deg apart, the
/// second 0.75 of the first) to the left or the right of the axis from the pivot through the
/// defect, which is the orientation.
Fit fit(const std::string& procedure, double r_mm, double ratio) {
  Fit f;
  if (procedure == "ellipse") {
    const double w = 2 * r_mm * std::sqrt(ratio * ratio + 1) / ratio;
    f.parameters = {{"length", ratio * w}, {"width", w}};
    return f;
  }
  f.turn_deg = 360;  // the flaps differ turned by 180 deg
  if (procedure == "rhomboid") {
    f.parameters = {{"side", 4 * r_mm / std::sqrt(3.0)}};
    return f;
  }
  f.sides = {1, -1};
  if (procedure == "bilobed") {
    f.parameters = {{"radius", r_mm}};
    f.side_parameter = "lobe_side";
    return f;
  }
  if (procedure == "rotation-flap") {
    // The triangular defect O F S (legs R, the library's default 40 deg at O): its inscribed
    // circle, radius R sin(delta) / (2 (1 + sin(delta / 2))), is the lesion and its margin, and
    // its centre lies on the bisector at that radius over sin(delta / 2) from O.
    const double delta = deg_to_rad(40.0);
    const double R = 2 * r_mm * (1 + std::sin(delta / 2)) / std::sin(delta);
    const double from_o = r_mm / std::sin(delta / 2);
    f.parameters = {{"radius", R}, {"defect_angle", 40.0}};
    f.side_parameter = "arc_side";
    f.origin_mm = -from_o * Eigen::Vector2d(std::cos(delta / 2), -std::sin(delta / 2));
    return f;
  }
  throw InvalidParameter(
      cat("{procedures} ", procedure,
          ": give ellipse, rhomboid, bilobed or "
          "rotation-flap (the closures suggest can lay around a lesion so far)"));
}

/// A design's template parameters: its procedure's fit, its side, and for an ellipse around a
/// drawn outline its size at this orientation. The ellipse's outline is a rhombus (its length L
/// along the orientation, width W, L = ratio W); a point at (x, y) in its frame lies at least
/// the margin m inside it when W / 2 >= |x| / ratio + |y| + m sqrt(1 + 1 / ratio^2), its
/// distance from the side x / (L/2) + y / (W/2) = 1. (For a round lesion of radius rho this is
/// the disc fit above with r = rho + m.)
std::map<std::string, double> design_parameters(const Fit& f, double side, double orientation_deg) {
  std::map<std::string, double> p = f.parameters;
  if (!f.side_parameter.empty()) p[f.side_parameter] = side;
  if (!f.outline_mm.empty()) {
    const double a = deg_to_rad(orientation_deg);
    const Eigen::Vector2d along(std::cos(a), std::sin(a)), across(-std::sin(a), std::cos(a));
    double half = 0;
    for (const Eigen::Vector2d& u : f.outline_mm)
      half = std::max(half, std::abs(u.dot(along)) / f.ratio + std::abs(u.dot(across)));
    const double w = 2 * (half + f.margin_mm * std::sqrt(1 + 1 / (f.ratio * f.ratio)));
    p["length"] = f.ratio * w;
    p["width"] = w;
  }
  return p;
}

/// A flap's side in words ("lobes left", "arc right"); "" for a design without one.
std::string side_words(const SuggestedDesign& d) {
  if (d.side == 0) return "";
  return cat(d.procedure == "bilobed" ? "lobes " : "arc ", d.side > 0 ? "left" : "right");
}

/// The family a design is drawn in: its procedure, and its side where it has one.
std::string family(const SuggestedDesign& d) {
  const std::string side = side_words(d);
  return side.empty() ? d.procedure : cat(d.procedure, " (", side, ")");
}

/// The orientation (deg from superior towards +theta) of the skin's tangent direction `v` at
/// (theta, z) on `model`, as plan frames measure it.
double orientation_at(const PatientModel& model, double theta_deg, double z_mm,
                      const Eigen::Vector3d& v) {
  const Eigen::Vector3d up = plan::skin_frame(model, theta_deg, z_mm, 0).ex;
  const Eigen::Vector3d right = plan::skin_frame(model, theta_deg, z_mm, 90).ex;
  return rad_to_deg(std::atan2(v.dot(right), v.dot(up)));
}

std::vector<std::string> split_list(const std::string& text) {
  std::vector<std::string> out;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ',')) {
    item.erase(0, item.find_first_not_of(" \t"));
    item.erase(item.find_last_not_of(" \t") + 1);
    if (!item.empty() && std::find(out.begin(), out.end(), item) == out.end()) out.push_back(item);
  }
  return out;
}

struct Objective {
  const char* name;
  const char* meaning;
  const char* unit;
};
constexpr Objective kObjectives[] = {
    {"force", "the largest force on one suture", "N"},
    {"features", "the largest displacement of a feature line (eyelid margin, brow, lip, nostril "
                 "rim)", "mm"},
    {"scar", "the scar's length", "mm"},
    {"excised", "the healthy skin excised around the lesion and its margin", "mm2"},
    {"rstl", "the angle between the scar and the relaxed skin tension lines (Borges's map)", "deg"},
};

const Objective& objective_named(const std::string& name) {
  for (const Objective& o : kObjectives)
    if (name == o.name) return o;
  throw InvalidParameter(cat("{objective} ", name, ": give force, features, scar, excised or "
                             "rstl"));
}

double objective_value(const std::string& name, const SuggestedDesign& d,
                       const SuggestedDesign::Closure& c) {
  if (name == "force") return c.max_force_per_suture_n;
  if (name == "features") return c.max_feature_mm;
  if (name == "scar") return d.scar_length_mm;
  if (name == "rstl") return d.angle_to_skin_lines_deg;
  return d.healthy_excised_mm2;
}

/// A reporter that reports nothing but passes on its parent's cancellation: the sweep's closures
/// would each draw a progress bar.
class Quiet : public Reporter {
 public:
  explicit Quiet(Reporter* parent) : parent_(parent) {}
  bool is_cancelled() const override { return parent_ && parent_->is_cancelled(); }

 private:
  Reporter* parent_;
};

SuggestedDesign::Closure figures(const closure::Simulation& sim) {
  SuggestedDesign::Closure c;
  c.max_force_per_suture_n = sim.sutures.max_suture_force_n;
  c.closing_force_n = sim.result.total_suture_force_n;
  for (const FeatureDisplacement& f : sim.features) {
    if (!f.warning.empty()) ++c.feature_warnings;
    if (f.has_value && f.max_mm > c.max_feature_mm) {
      c.max_feature_mm = f.max_mm;
      c.feature = f.name;
    }
  }
  c.warnings = sim.wound.continuum.mesh.warnings;
  return c;
}

json closure_json(const SuggestedDesign::Closure& c) {
  json j = {{"max_force_per_suture_n", round_to(c.max_force_per_suture_n, 3)},
            {"closing_force_n", round_to(c.closing_force_n, 3)},
            {"max_feature_mm", round_to(c.max_feature_mm, 3)},
            {"feature_warnings", c.feature_warnings},
            {"warnings", c.warnings}};
  j["feature"] = c.feature.empty() ? json(nullptr) : json(c.feature);
  j["feature_words"] = c.feature.empty() ? json(nullptr) : json(feature_line_words(c.feature));
  return j;
}

/// The polar plot of one figure of the designs: per procedure, the sweep's value against
/// orientation as a curve (superior up, the patient's left to the right, as the surgeon faces
/// the patient; an ellipse drawn at both ends of its axis), the refined closures' values as
/// rings, the best design's ringed in green, the orientations not possible as grey ticks.
void draw_polar(Canvas& canvas, double cx, double cy, double radius,
                const std::vector<SuggestedDesign>& designs, const std::string& title,
                const std::string& unit,
                const std::function<double(const SuggestedDesign::Closure&)>& value,
                const std::string& best, double skin_lines_deg) {
  const Eigen::Vector3d grey(0.6, 0.6, 0.6);
  double top = 0;
  for (const SuggestedDesign& d : designs)
    if (d.rank > 0) top = std::max({top, value(d.sweep), d.refined ? value(d.full) : 0.0});
  TextStyle t;
  t.size_px = 15;
  t.align = 0.5;
  canvas.text(cx, cy - radius - 34, title, t);
  if (!(top > 0)) {
    t.size_px = 13;
    canvas.text(cx, cy, "no design reaches it", t);
    return;
  }
  top = round_sig(top * 1.1, 2);
  const auto at = [&](double orientation_deg, double r) {
    const double a = deg_to_rad(orientation_deg);
    return Eigen::Vector2d(cx + r * std::sin(a), cy - r * std::cos(a));
  };
  for (int ring = 1; ring <= 4; ++ring) {
    Pen p;
    p.colour = Eigen::Vector3d(0.85, 0.85, 0.85);
    canvas.stroke_circle({cx, cy}, radius * ring / 4.0, p);
    TextStyle s;
    s.size_px = 10;
    s.colour = grey;
    const Eigen::Vector2d q = at(135, radius * ring / 4.0);
    canvas.text(q.x() + 3, q.y() + 10, cat(round_sig(top * ring / 4.0, 2), " ", unit), s);
  }
  TextStyle s;
  s.size_px = 11;
  s.align = 0.5;
  s.colour = Eigen::Vector3d(0.3, 0.3, 0.3);
  canvas.text(cx, cy - radius - 8, "superior", s);
  canvas.text(cx, cy + radius + 16, "inferior", s);
  s.rotate_deg = 90;
  canvas.text(cx + radius + 10, cy, "patient's left", s);
  s.rotate_deg = -90;
  canvas.text(cx - radius - 10, cy, "patient's right", s);
  if (std::isfinite(skin_lines_deg)) {
    // The relaxed skin tension lines at the lesion: a dashed line through the centre.
    Pen p;
    p.colour = Eigen::Vector3d(0.55, 0.35, 0.2);
    p.width_px = 1.5;
    p.dash_px = {6, 4};
    canvas.line(at(skin_lines_deg, radius), at(skin_lines_deg + 180, radius), p);
    TextStyle l;
    l.size_px = 12;
    l.colour = p.colour;
    l.align = 1;
    canvas.text(cx + radius, cy + radius + 44, "- - skin lines (Borges)", l);
  }
  // One colour per family: the ellipse, the rhomboid and each side of the two flaps.
  const Eigen::Vector3d colours[] = {{0.12, 0.47, 0.71}, {0.84, 0.37, 0.0}, {0.55, 0.25, 0.6},
                                     {0.0, 0.55, 0.55},  {0.7, 0.1, 0.3},   {0.45, 0.45, 0.1}};
  std::vector<std::string> procedures;  // the families drawn
  for (const SuggestedDesign& d : designs)
    if (std::find(procedures.begin(), procedures.end(), family(d)) == procedures.end())
      procedures.push_back(family(d));
  // Both ends of an ellipse's axis; a flap's one orientation.
  const auto ends = [](const SuggestedDesign& d) {
    return d.procedure == "ellipse" ? std::vector<double>{d.orientation_deg, d.orientation_deg + 180}
                                    : std::vector<double>{d.orientation_deg};
  };
  for (std::size_t k = 0; k < procedures.size(); ++k) {
    const Eigen::Vector3d colour = colours[k % std::size(colours)];
    std::vector<std::pair<double, double>> points;  // orientation, the sweep's value
    double step = 360;
    for (const SuggestedDesign& d : designs) {
      if (family(d) != procedures[k]) continue;
      for (const double o : ends(d)) {
        if (d.rank == 0) {
          Pen p;
          p.colour = grey;
          p.width_px = 2;
          canvas.line(at(o, radius * 0.95), at(o, radius * 1.05), p);
          continue;
        }
        points.emplace_back(o, value(d.sweep));
        if (d.refined) {
          Pen p;
          p.colour = colour;
          p.width_px = 1.5;
          canvas.stroke_circle(at(o, radius * value(d.full) / top), 5, p);
        }
      }
    }
    std::sort(points.begin(), points.end());
    for (std::size_t q = 0; q + 1 < points.size(); ++q)
      step = std::min(step, points[q + 1].first - points[q].first);
    Pen p;
    p.colour = colour;
    p.width_px = 1.5;
    // Lines join orientations one step apart; a gap (an orientation not possible) stays open.
    for (std::size_t i = 0; i < points.size(); ++i) {
      canvas.fill_circle(at(points[i].first, radius * points[i].second / top), 2.5, colour);
      const std::size_t j = (i + 1) % points.size();
      if (j == i || std::abs(std::remainder(points[j].first - points[i].first, 360.0)) > step * 1.5)
        continue;
      canvas.line(at(points[i].first, radius * points[i].second / top),
                  at(points[j].first, radius * points[j].second / top), p);
    }
    TextStyle l;
    l.size_px = 12;
    l.colour = colour;
    canvas.text(cx - radius, cy + radius + 44 + 16.0 * static_cast<double>(k), procedures[k], l);
  }
  for (const SuggestedDesign& d : designs)
    if (d.name == best) {
      Pen p;
      p.colour = Eigen::Vector3d(0.1, 0.6, 0.2);
      p.width_px = 2.5;
      for (const double o : ends(d))
        canvas.stroke_circle(at(o, radius * value(d.refined ? d.full : d.sweep) / top), 9, p);
    }
}

/// Calls f(i) for i in [0, n) on `workers` threads (the caller's among them), reporting each
/// one done to `progress`. f must catch what a design may throw; anything else (Cancelled, out
/// of memory) stops the others after their current item and is rethrown here.
void for_each_parallel(std::size_t n, unsigned workers, Progress& progress,
                       const std::function<void(std::size_t)>& f) {
  std::mutex mutex;  // progress, the first error
  std::atomic<std::size_t> next{0};
  std::atomic<bool> stop{false};
  std::exception_ptr error;
  std::size_t done = 0;
  const auto work = [&] {
    try {
      for (std::size_t i; !stop && (i = next++) < n;) {
        f(i);
        const std::lock_guard lock(mutex);
        progress.update(static_cast<double>(++done));
      }
    } catch (...) {
      stop = true;
      const std::lock_guard lock(mutex);
      if (!error) error = std::current_exception();
    }
  };
  std::vector<std::thread> threads;
  for (unsigned k = 1; k < workers && k < n; ++k) threads.emplace_back(work);
  work();
  for (std::thread& t : threads) t.join();
  if (error) std::rethrow_exception(error);
  progress.done();
}

}  // namespace

SuggestResult run_plan_suggest(const SuggestRequest& r, Reporter* reporter) {
  detail::refuse_output_over_inputs(r);
  require_utf8(r.model, "the model folder");
  const int outlines = !r.outline.empty() + !r.outline_xyz.empty() + !r.outline_mm.empty();
  const bool drawn = outlines > 0;
  if (outlines > 1)
    throw InvalidParameter(
        "give the lesion's outline once: {outline} THETA,Z;..., {outline_xyz} X,Y,Z;... or "
        "{outline_mm} LEFT,UP;...");
  if (!r.outline_mm.empty() && r.at.empty() && r.at_xyz.empty())
    throw InvalidParameter(
        "{outline_mm} is the outline in mm about the lesion's centre: give the centre too, "
        "with {at} THETA,Z, {at} LANDMARK+LEFT,UP or {at_xyz} X,Y,Z");
  if ((!r.at.empty() && !r.at_xyz.empty()) || (!drawn && r.at.empty() && r.at_xyz.empty()))
    throw InvalidParameter(
        "give the lesion's centre with {at} THETA,Z, {at} LANDMARK+LEFT,UP or "
        "{at_xyz} X,Y,Z (or draw its outline: {outline})");
  if (drawn && r.diameter != 0)
    throw InvalidParameter(cat("{diameter} ", r.diameter,
                               " and an {outline}: give one, the "
                               "diameter of a round lesion or the outline of any other (its "
                               "largest diameter is then its own)"));
  LesionOutline outline;
  if (drawn) outline = parse_outline(r.outline, r.outline_xyz, r.outline_mm);
  if (!drawn && !(r.diameter > 0 && r.diameter <= 50))
    throw InvalidParameter(cat("{diameter} ", r.diameter,
                               ": give the lesion's largest diameter "
                               "in mm, more than 0 and at most 50, or its {outline}"));
  if (!(r.margin >= 0 && r.margin <= 20))
    throw InvalidParameter(cat("{margin} ", r.margin, ": give the margin in mm, 0 to 20"));
  if (!(r.step >= 5 && r.step <= 90))
    throw InvalidParameter(cat("{step} ", r.step, ": give 5 to 90 degrees between orientations"));
  if (!(r.ratio >= 2.5 && r.ratio <= 4.5))
    throw InvalidParameter(cat("{ratio} ", r.ratio, ": give an ellipse's length over its width, "
                               "2.5 to 4.5"));
  if (r.refine < 0 || r.refine > 12)
    throw InvalidParameter(cat("{refine} ", r.refine, ": give 0 to 12 designs"));
  if (!(r.sweep_size >= 0 && r.sweep_size <= 10))
    throw InvalidParameter(cat("{sweep_size} ", r.sweep_size, ": give mm, 0 (twice --size) to 10"));
  if (!(r.sweep_time_limit >= 0 && r.sweep_time_limit <= 3600))
    throw InvalidParameter(cat("{sweep_time_limit} ", r.sweep_time_limit, ": give seconds, 0 "
                               "(none) to 3600"));
  if (!(r.refine_time_limit >= 0 && r.refine_time_limit <= 3600))
    throw InvalidParameter(cat("{refine_time_limit} ", r.refine_time_limit, ": give seconds, 0 "
                               "(none) to 3600"));
  const Objective& objective = objective_named(r.objective);
  if (r.sweep_material != "auto" && r.sweep_material != "linear" &&
      r.sweep_material != "neo-hookean" && r.sweep_material != "goh")
    throw InvalidParameter(cat("{sweep_material} ", r.sweep_material, ": give auto, linear, "
                               "neo-hookean or goh"));
  const std::vector<std::string> procedures = split_list(r.procedures);
  if (procedures.empty())
    throw InvalidParameter(
        "{procedures}: give one or more of ellipse, rhomboid, bilobed and "
        "rotation-flap");

  // The full closure's options (the user's simulate) and the sweep's coarser mesh.
  closure::SimulateOptions full = simulate_options(r.meshing, r.solver);
  const std::string domain_warning = set_domain(full, r.domain, r.model);
  MeshingFields coarse_mesh = r.meshing;
  coarse_mesh.mesh_size = r.sweep_size > 0 ? r.sweep_size : 2 * r.meshing.mesh_size;
  SolverFields sweep_solver = r.solver;
  sweep_solver.material = r.sweep_material == "auto"
                              ? (r.solver.material == "goh" ? "goh" : "linear")
                              : r.sweep_material;
  closure::SimulateOptions sweep = simulate_options(coarse_mesh, sweep_solver);
  set_domain(sweep, r.domain, r.model);
  if (r.solver.time_limit == 0 && sweep_solver.material != "linear")
    sweep.solve.time_limit_s = r.sweep_time_limit;
  // A design whose finite-strain closure would take minutes keeps the sweep's answer (issue 35:
  // a bounded worst case): the side of the nose's ellipse took 101 s on Cranium.
  if (r.solver.time_limit == 0 && r.solver.material != "linear")
    full.solve.time_limit_s = r.refine_time_limit;

  OutputDirectory out(r.output, r.force);
  fs::create_directories(out.path() / "designs");
  const auto loaded = loaded_model(r.model);
  const PatientModel& model = *loaded;
  if (drawn && outline.theta_z.empty() && outline.offsets_mm.empty())  // given as LPS points
    for (const Eigen::Vector3d& x : outline.lps) {
      const CylindricalPoint c = model.to_cylindrical(x);
      outline.theta_z.emplace_back(c.theta_deg, c.z_mm);
    }
  std::optional<plan::LandmarkPlacement> placement;
  const Eigen::Vector2d tz = !r.at.empty() || !r.at_xyz.empty()
                                 ? resolve_at(r.model, model, r.at, r.at_xyz, &placement)
                                 : outline_centre(outline);
  if (!outline.offsets_mm.empty()) {
    for (const Eigen::Vector2d& step : outline.offsets_mm) {  // as a landmark's offsets are
      Eigen::Vector2d p = plan::walk_left_up(model, tz, step);
      p.x() = tz[0] + wrap_degrees(p.x() - tz[0]);
      if (!model.has_z(p.y()))
        throw InvalidParameter(cat("{outline_mm}: the point ", step.x(), ",", step.y(),
                                   " mm from the centre lies at z = ", round_to(p.y(), 1),
                                   " mm, outside the model; draw a smaller outline"));
      outline.theta_z.push_back(p);
    }
  }
  if (drawn) {
    project_outline(outline, model, tz);
    if (!(outline.diameter_mm <= 50) || !(outline.reach_mm <= 50))
      throw InvalidParameter(cat("{outline}: the lesion drawn is ",
                                 round_to(outline.diameter_mm, 1), " mm across and reaches ",
                                 round_to(outline.reach_mm, 1),
                                 " mm from its centre; draw a lesion at most 50 mm across, "
                                 "with the centre ({at}) inside it"));
  }
  // The lesion's largest diameter, and the radius of the disc about its centre that holds it
  // and its margin (the flaps' defect; an ellipse's for a round lesion).
  const double diameter = drawn ? outline.diameter_mm : r.diameter;
  const double r_mm = drawn ? outline.reach_mm + r.margin : r.diameter / 2 + r.margin;
  const std::string lesion_words = drawn
                                       ? cat("the drawn lesion (", round_to(diameter, 1),
                                             " mm across, ", round_to(outline.area_mm2, 0), " mm2)")
                                       : cat("a lesion of ", r.diameter, " mm");
  // Every layout once before any closure: a lesion too large or small for a template's clinical
  // range is refused here, naming it.
  std::map<std::string, Fit> fits;
  for (const std::string& p : procedures) {
    Fit f = fit(p, r_mm, r.ratio);
    if (drawn && p == "ellipse") {
      f.outline_mm = outline.local;
      f.margin_mm = r.margin;
      f.ratio = r.ratio;
    }
    try {
      for (const double side : f.sides)
        for (double o = 0; o < f.turn_deg - 1e-9; o += r.step)
          plan::layout_procedure(p, design_parameters(f, side, o));
    } catch (const InvalidInput& e) {
      throw InvalidParameter(
          cat(drawn ? cat("{outline}: ", lesion_words) : cat("{diameter} ", r.diameter, " mm"),
              " with a {margin} of ", r.margin, " mm: the ", p,
              " around it is outside its range: ", e.what()));
    }
    fits.emplace(p, std::move(f));
  }
  std::vector<std::string> common;  // carried into every closure's warnings
  if (!domain_warning.empty()) {
    warn(reporter, domain_warning);
    common.push_back(domain_warning);
  }
  if (std::string doubt = placement_doubt(r.model, model, placement); !doubt.empty()) {
    warn(reporter, doubt);
    common.push_back(std::move(doubt));
  }

  SuggestResult result;
  result.output = r.output;
  std::vector<SuggestedDesign>& designs = result.designs;
  std::map<std::string, plan::Plan> plans;
  for (const std::string& p : procedures)
    for (const double side : fits.at(p).sides)
      for (double o = 0; o < fits.at(p).turn_deg - 1e-9; o += r.step) {
        SuggestedDesign d;
        d.procedure = p;
        d.side = side;
        d.orientation_deg = o;
        d.name = cat(p, side < 0 ? "-mirrored" : "", "-",
                     std::string(o < 10    ? "00"
                                 : o < 100 ? "0"
                                           : ""),
                     static_cast<int>(std::lround(o)));
        designs.push_back(d);
      }

  Quiet quiet(reporter);
  // Where the head's cylindrical image cannot hold the skin under a design (the side of the
  // nose), every design is laid on one local chart facing the lesion (as caps plan new makes for
  // one plan), made in the output folder as chart/ and closed in the head's whole face.
  std::shared_ptr<const PatientModel> on = loaded;
  std::string plan_model = r.model;  // the plans' model, as they name it
  std::string chart_note;
  const auto lay = [&](const SuggestedDesign& d) {
    const Fit& f = fits.at(d.procedure);
    double theta = chart_note.empty() ? tz[0] : 0.0, z = chart_note.empty() ? tz[1] : 0.0;
    double orientation = d.orientation_deg;
    if (f.origin_mm.norm() > 0) {
      // The template's origin walked to from the lesion on the skin, the frame carried along.
      const Eigen::Vector2d step(f.origin_mm.x(), d.side < 0 ? -f.origin_mm.y() : f.origin_mm.y());
      const plan::SkinFrame o =
          plan::walk_on_skin(*on, plan::skin_frame(*on, theta, z, orientation), step);
      theta = o.theta_z.x();
      z = o.theta_z.y();
      orientation = orientation_at(*on, theta, z, o.ex);
    }
    plan::Plan plan = plan::place_procedure(
        plan::layout_procedure(d.procedure, design_parameters(f, d.side, d.orientation_deg)), *on,
        theta, z, orientation);
    plan.placement = placement;
    plan.model = plan_model;
    plan.model_hash = on->content_hash();
    return plan;
  };
  if (detail::chart_parent(r.model).empty() && [&] {
        try {
          detail::refuse_unchartable(r.model);
          return true;
        } catch (const Error&) {
          return false;
        }
      }()) {
    for (const SuggestedDesign& d : designs) {
      try {
        plan::check_plan(lay(d), model);
      } catch (const plan::SkinNotHeld& e) {
        ChartRequest cr;
        cr.model = fs::absolute(r.model).lexically_normal().string();
        cr.at = cat(round_to(tz[0], 3), ",", round_to(tz[1], 3));
        cr.output = (out.path() / "chart").string();
        cr.force = true;
        run_chart(cr, &quiet);
        on = std::make_shared<const PatientModel>(PatientModel::load(cr.output));
        // The chart's frame at its centre (the lesion's) holds the outline from now on.
        if (drawn && fits.count("ellipse")) {
          LesionOutline on_chart = outline;
          on_chart.theta_z.clear();
          for (const Eigen::Vector3d& x : outline.lps) {
            const CylindricalPoint c = on->to_cylindrical(x);
            on_chart.theta_z.emplace_back(c.theta_deg, c.z_mm);
          }
          project_outline(on_chart, *on, Eigen::Vector2d(0, 0));
          fits.at("ellipse").outline_mm = on_chart.local;
        }
        plan_model = (fs::path(r.output) / "chart").string();
        chart_note = cat("the model's cylindrical image cannot hold the skin around the lesion (",
                         e.what(), "): every design is laid on a local chart facing it, made in ",
                         plan_model, " (as caps model chart ", r.model, " --at ", cr.at,
                         "), and closed in ", r.model, "'s whole face");
        warn(reporter, chart_note);
        common.push_back(chart_note);
        break;
      } catch (const Error&) {
      }
    }
  }

  // The relaxed skin tension lines at the lesion, on the head (a chart's parent: its landmarks),
  // turned into the designs' frame; each ellipse's angle to them.
  SuggestedSkinLines& lines = result.skin_lines;
  {
    const Eigen::Vector2d on_tz = chart_note.empty() ? tz : Eigen::Vector2d(0, 0);
    const Eigen::Vector3d lesion = on->skin_point(on_tz[0], on_tz[1]);
    const std::string parent = detail::chart_parent(r.model);
    const std::string head_dir = parent.empty() ? r.model : parent;
    std::shared_ptr<const PatientModel> head = loaded;
    try {
      if (!parent.empty()) head = loaded_model(parent);
      const CylindricalPoint hc = head->to_cylindrical(lesion);
      const plan::SkinLineDirection dir =
          plan::skin_line_direction(plan::borges_map(), *head,
                                    plan::model_landmarks(head_dir, *head), hc.theta_deg, hc.z_mm);
      lines.note = dir.note;
      if (dir.found) {
        const Eigen::Vector3d v =
            plan::skin_frame(*head, hc.theta_deg, hc.z_mm, dir.orientation_deg).ex;
        const double o =
            round_to(std::fmod(orientation_at(*on, on_tz[0], on_tz[1], v) + 360.0, 180.0), 1);
        lines.found = true;
        lines.orientation_deg = o >= 180.0 ? o - 180.0 : o;
        lines.zone = dir.zone;
        lines.words = dir.words;
        lines.says = dir.says;
      }
    } catch (const Error& e) {
      lines.note = cat("the skin lines could not be laid here: ", e.what());
    }
    for (SuggestedDesign& d : designs)
      if (lines.found && d.procedure == "ellipse")
        d.angle_to_skin_lines_deg =
            plan::angle_between_lines_deg(d.orientation_deg, lines.orientation_deg);
    if (r.objective == "rstl" && !lines.found)
      throw InvalidParameter(cat("{objective} rstl: the relaxed skin tension lines are not known "
                                 "at this lesion (", lines.note, "); rank by force, features, "
                                 "scar or excised"));
    if (r.objective == "rstl" && std::any_of(procedures.begin(), procedures.end(),
                                             [](const std::string& p) { return p != "ellipse"; }))
      throw InvalidParameter(
          "{objective} rstl ranks ellipses by their scar's angle to the skin "
          "lines; a flap's scars (rhomboid, bilobed, rotation) run several ways: give "
          "--procedures ellipse, or rank by force");
  }

  // The sweep: each design laid, checked and closed on the sweep's mesh, two at a time where the
  // machine has two cores (each closure's factorization runs on one): with CHOLMOD, whose
  // factorizations are independent in two threads (MUMPS's are not: every call into MUMPS, the
  // ordering CHOLMOD is given among them, holds one lock, fem/src/direct_solver.cpp), and
  // OpenBLAS kept to one thread each.
  const unsigned workers = std::min(2u, std::max(1u, std::thread::hardware_concurrency()));
  if (workers > 1) {
    sweep.solve.solver = fem::SolverKind::Cholmod;
    sweep.solve.blas_threads = 1;
  }
  const Clock::time_point t_sweep = Clock::now();
  {
    // One BLAS thread for the whole sweep, held here: each solve's own guard then never changes
    // OpenBLAS's thread count while the other worker is inside a BLAS call (a SIGFPE in a test
    // under load, once).
    const fem::BlasThreads one_blas_thread(workers > 1 ? 1 : 0);
    Progress progress(reporter, "closing each design in the sweep",
                      static_cast<double>(designs.size()));
    std::mutex mutex;  // plans
    const auto sweep_one = [&](SuggestedDesign& d) {
      try {
        plan::Plan plan = lay(d);
        const plan::PlanReport report = plan::check_plan(plan, *on);
        d.plan = cat("designs/", d.name, ".json");
        plan::write_plan(out.path() / d.plan, plan, &report);
        // The wound's border on the skin (LPS): its vector area and its length.
        Eigen::Vector3d area2 = Eigen::Vector3d::Zero();
        double perimeter = 0;
        const auto& loop = plan::wound_border(plan).loop_theta_z;
        for (std::size_t i = 0; i < loop.size(); ++i) {
          const auto& ta = loop[i];
          const auto& tb = loop[(i + 1) % loop.size()];
          const Eigen::Vector3d a = on->skin_point(ta.x(), ta.y());
          const Eigen::Vector3d b = on->skin_point(tb.x(), tb.y());
          area2 += a.cross(b);
          perimeter += (b - a).norm();
        }
        d.excised_mm2 = area2.norm() / 2;
        d.healthy_excised_mm2 = std::max(
            0.0, d.excised_mm2 - (drawn ? outline.area_mm2 : kPi * r.diameter * r.diameter / 4));
        d.scar_length_mm = perimeter / 2;  // each sutured edge meets its twin: one scar line
        check_mesh_budget(plan::wound_border(plan), *on, coarse_mesh);
        const closure::Simulation sim = closure::simulate(*on, plan, sweep, &quiet);
        d.sweep = figures(sim);
        d.sweep.warnings.insert(d.sweep.warnings.end(), common.begin(), common.end());
        const std::lock_guard lock(mutex);
        plans.emplace(d.name, std::move(plan));
      } catch (const Cancelled&) {
        throw;
      } catch (const Error& e) {
        // The places a refusal names are the chart's (theta, z) where the designs lie on one.
        d.refused = chart_note.empty() ? std::string(e.what())
                                       : cat("on the local chart chart/: ", e.what());
      }
    };
    for_each_parallel(designs.size(), workers, progress,
                      [&](std::size_t i) { sweep_one(designs[i]); });
  }
  result.sweep_s = seconds_since(t_sweep);

  // The ranking: by the sweep's figures, then the best `refine` closed again at the full mesh
  // and ranked ahead of the others by their own.
  const auto by_objective = [&](const SuggestedDesign& a, const SuggestedDesign& b) {
    if ((a.refused.empty()) != (b.refused.empty())) return a.refused.empty();
    if (a.refined != b.refined) return a.refined;
    if (a.objective != b.objective) return a.objective < b.objective;
    // A tie (two orientations at the same angle to the skin lines, scars of one length) goes
    // to the smaller force on one suture.
    const double fa = (a.refined ? a.full : a.sweep).max_force_per_suture_n;
    const double fb = (b.refined ? b.full : b.sweep).max_force_per_suture_n;
    if (fa != fb) return fa < fb;
    return a.name < b.name;
  };
  for (SuggestedDesign& d : designs)
    if (d.refused.empty()) d.objective = objective_value(r.objective, d, d.sweep);
  std::stable_sort(designs.begin(), designs.end(), by_objective);
  const Clock::time_point t_refine = Clock::now();
  {
    std::size_t n = 0;  // the ranked designs come first
    while (n < designs.size() && n < static_cast<std::size_t>(r.refine) && designs[n].refused.empty())
      ++n;
    // One at a time, each as caps simulate closes it: two finite-strain closures at once, with
    // one BLAS thread each, took as long as one after the other with two (the forehead's best
    // three: 28.7 against 26.5 s).
    Progress progress(reporter, "closing the best designs again", static_cast<double>(n));
    for_each_parallel(n, 1, progress, [&](std::size_t i) {
      SuggestedDesign& d = designs[i];
      const plan::Plan& plan = plans.at(d.name);
      try {
        closure::Simulation sim = closure::simulate(*on, plan, full, &quiet);
        for (const std::string& w : common) sim.wound.continuum.mesh.warnings.push_back(w);
        d.result = d.name;
        const fs::path dir = out.path() / d.result;
        fs::create_directories(dir);
        SimulateResult s = write_closure(sim, full, plan, (fs::path(r.output) / d.plan).string(),
                                         *on, plan_model, dir, false);
        s.output = (fs::path(r.output) / d.result).string();
        write_text_atomic(dir / "summary.json", to_json(s) + "\n");
        d.full = figures(sim);
        d.refined = true;
        d.objective = objective_value(r.objective, d, d.full);
      } catch (const Cancelled&) {
        throw;
      } catch (const Error& e) {
        // Closed in the sweep but not again: kept with the sweep's figures.
        d.full.warnings.push_back(cat("not closed again at full accuracy: ", e.what()));
      }
    });
  }
  result.refine_s = seconds_since(t_refine);
  std::stable_sort(designs.begin(), designs.end(), by_objective);
  int rank = 0;
  for (SuggestedDesign& d : designs)
    if (d.refused.empty()) d.rank = ++rank;
  const std::string best = rank > 0 ? designs.front().name : std::string();
  for (SuggestedDesign& d : designs)
    d.near_best = d.rank > 1 && d.refined == designs.front().refined &&
                  d.objective <= (1 + kNearBest) * designs.front().objective;
  if (rank == 0)
    result.warnings.push_back("no design could be laid and closed around this lesion here: "
                              "see each one's reason");

  // The cross-check: the ellipse of least force in the sweep (every design's figures from the
  // same closure) against the skin lines.
  if (lines.found) {
    const SuggestedDesign* least = nullptr;
    for (const SuggestedDesign& d : designs)
      if (d.rank > 0 && d.procedure == "ellipse" &&
          (!least || d.sweep.max_force_per_suture_n < least->sweep.max_force_per_suture_n))
        least = &d;
    const std::string map_words =
        cat("Borges's relaxed skin tension lines ", lines.words, " run ", lines.says, " (",
            std::fmod(std::round(lines.orientation_deg), 180.0), " deg)");
    if (least) {
      lines.least_force_deg = least->orientation_deg;
      lines.least_force_angle_deg = least->angle_to_skin_lines_deg;
      const double tolerance = std::max(r.step, 20.0);
      const std::string least_words =
          cat(map_words, "; the model's least force on one suture is at ", least->orientation_deg,
              " deg, ", round_to(lines.least_force_angle_deg, 0), " deg from them");
      lines.sentence =
          lines.least_force_angle_deg <= 20.0 ? cat(least_words, ": they agree")
          : lines.least_force_angle_deg <= tolerance
              // Within one step of a coarse sweep: the sweep cannot tell (--step 45 put the least
              // force 45 deg from the forehead's lines and called it agreement).
              ? cat(least_words, ": within the sweep's step of ", r.step,
                    " deg, too coarse to tell; a finer --step would")
              : cat(least_words,
                    ": they disagree here (the model sees this patient's anatomy "
                    "and the designs that fit; the map is the textbook's average face)");
    } else {
      lines.sentence = cat(map_words, "; no ellipse was closed to compare with");
    }
    note(reporter, lines.sentence);
  }

  // suggestions.json
  json j;
  j["format"] = "caps-suggestions";
  j["version"] = 1;
  j["model"] = r.model;
  j["lesion"] = {{"theta_deg", round_to(tz[0], 3)},
                 {"z_mm", round_to(tz[1], 3)},
                 {"at", r.at.empty() ? r.at_xyz : r.at},
                 {"diameter_mm", round_to(diameter, 2)},
                 {"margin_mm", r.margin},
                 {"excised_radius_mm", round_to(r_mm, 3)}};
  if (drawn) {
    json points = json::array();
    for (const Eigen::Vector2d& p : outline.theta_z)
      points.push_back({round_to(p.x(), 3), round_to(p.y(), 3)});
    j["lesion"]["outline_theta_z"] = points;
    j["lesion"]["area_mm2"] = round_to(outline.area_mm2, 1);
  } else {
    j["lesion"]["outline_theta_z"] = nullptr;
    j["lesion"]["area_mm2"] = round_to(kPi * r.diameter * r.diameter / 4, 1);
  }
  j["objective"] = {{"name", objective.name}, {"meaning", objective.meaning},
                    {"unit", objective.unit}, {"least_first", true}};
  j["material"] = r.solver.material;
  j["domain"] = closure::domain_name(full.domain);
  j["sweep"] = {{"mesh_size_mm", coarse_mesh.mesh_size}, {"material", sweep_solver.material},
                {"designs", designs.size()}};
  j["refine"] = {{"mesh_size_mm", r.meshing.mesh_size}, {"designs", r.refine}};
  j["best"] = best.empty() ? json(nullptr) : json(best);
  const auto number_or_null = [](double v, int digits) {
    return std::isfinite(v) ? json(round_to(v, digits)) : json(nullptr);
  };
  j["skin_lines"] = {{"found", lines.found},
                     {"source", plan::borges_map().source},
                     {"orientation_deg", lines.found ? json(round_to(lines.orientation_deg, 1))
                                                     : json(nullptr)},
                     {"zone", lines.found ? json(lines.zone) : json(nullptr)},
                     {"words", lines.found ? json(lines.words) : json(nullptr)},
                     {"says", lines.found ? json(lines.says) : json(nullptr)},
                     {"least_force_orientation_deg", number_or_null(lines.least_force_deg, 1)},
                     {"least_force_angle_deg", number_or_null(lines.least_force_angle_deg, 1)},
                     {"sentence", lines.sentence}};
  if (!lines.found) j["skin_lines"]["note"] = lines.note;
  json a = json::array();
  for (const SuggestedDesign& d : designs) {
    json o = {{"name", d.name}, {"procedure", d.procedure},
              {"orientation_deg", d.orientation_deg}, {"rank", d.rank},
              {"near_best", d.near_best},
              {"angle_to_skin_lines_deg", number_or_null(d.angle_to_skin_lines_deg, 1)}};
    json params = json::object();
    for (const auto& [k, v] : design_parameters(fits.at(d.procedure), d.side, d.orientation_deg))
      params[k] = round_to(v, 3);
    o["parameters"] = params;
    o["side"] = d.side == 0 ? json(nullptr) : json(side_words(d));
    o["plan"] = d.plan.empty() ? json(nullptr) : json(d.plan);
    if (!d.refused.empty()) {
      o["refused"] = d.refused;
    } else {
      o["objective"] = round_to(d.objective, 3);
      o["scar_length_mm"] = round_to(d.scar_length_mm, 2);
      o["excised_mm2"] = round_to(d.excised_mm2, 1);
      o["healthy_excised_mm2"] = round_to(d.healthy_excised_mm2, 1);
      o["sweep"] = closure_json(d.sweep);
      o["full"] = d.refined ? closure_json(d.full) : json(nullptr);
      o["ranked_by"] = d.refined ? "full" : "sweep";
      if (!d.refined && !d.full.warnings.empty()) o["full_warnings"] = d.full.warnings;
      o["result"] = d.result.empty() ? json(nullptr) : json(d.result);
    }
    a.push_back(o);
  }
  j["designs"] = a;
  j["warnings"] = result.warnings;
  j["picture"] = "suggestions.png";
  j["timings_s"] = {{"sweep", round_to(result.sweep_s, 2)}, {"refine", round_to(result.refine_s, 2)}};
  result.suggestions_json = detail::dump(j);
  write_text_atomic(out.path() / "suggestions.json", result.suggestions_json + "\n");

  // suggestions.png: the objective and the feature lines' displacement against orientation.
  Canvas canvas(1100, 600);
  draw_polar(canvas, 275, 285, 180, designs, "the largest force on one suture (N)", "N",
             [](const SuggestedDesign::Closure& c) { return c.max_force_per_suture_n; }, best,
             lines.found ? lines.orientation_deg : std::numeric_limits<double>::quiet_NaN());
  draw_polar(canvas, 825, 285, 180, designs, "the largest feature-line displacement (mm)", "mm",
             [](const SuggestedDesign::Closure& c) { return c.max_feature_mm; }, best,
             lines.found ? lines.orientation_deg : std::numeric_limits<double>::quiet_NaN());
  TextStyle legend;
  legend.size_px = 11;
  legend.colour = Eigen::Vector3d(0.35, 0.35, 0.35);
  // The rings are the closures again that finished (one stopped at its time limit has none).
  const auto rings = std::count_if(designs.begin(), designs.end(),
                                   [](const SuggestedDesign& d) { return d.refined; });
  canvas.text(20, 566,
              cat("dots and line: the sweep (", sweep_solver.material, ", ", coarse_mesh.mesh_size,
                  " mm mesh); rings: ", rings, " closed again (", r.solver.material, ", ",
                  r.meshing.mesh_size,
                  " mm); green: the suggestion; grey ticks: not possible there; an ellipse's "
                  "orientation is its scar's"),
              legend);
  TextStyle foot;
  foot.size_px = 11;
  foot.colour = Eigen::Vector3d(0.35, 0.35, 0.35);
  canvas.text(
      20, 586,
      cat(lesion_words, " with a ", r.margin, " mm margin at theta ", round_to(tz[0], 1),
          " deg, z ", round_to(tz[1], 1), " mm, closed in the ",
          closure::domain_name(full.domain) == std::string("face") ? "whole face" : "clamped patch",
          "; ranked by ", objective.meaning,
          "; the suggestion: ", best.empty() ? std::string("none") : best),
      foot);
  canvas.write_png(out.path() / "suggestions.png");
  out.commit();
  return result;
}


std::string summary(const SuggestResult& s) {
  int ranked = 0;
  for (const SuggestedDesign& d : s.designs) ranked += d.rank > 0;
  std::string line = cat("caps plan suggest: ", ranked, " of ", s.designs.size(),
                         " designs closed around the lesion");
  if (ranked > 0) {
    const SuggestedDesign& b = s.designs.front();
    const SuggestedDesign::Closure& c = b.refined ? b.full : b.sweep;
    line += cat("; best ", b.name, " (", b.procedure, " along ", b.orientation_deg, " deg: up to ",
                round_to(c.max_force_per_suture_n, 2), " N a suture",
                c.feature.empty() ? std::string()
                                  : cat(", ", feature_line_words(c.feature), " moved ",
                                        round_to(c.max_feature_mm, 1), " mm"),
                ", scar ", round_to(b.scar_length_mm, 1), " mm",
                b.refined                 ? std::string()
                : b.full.warnings.empty() ? std::string("; the sweep's figures, not closed again")
                                          : std::string("; the sweep's figures: its closure at "
                                                        "full accuracy did not finish, see "
                                                        "suggestions.json"),
                ")");
    std::string near;
    for (const SuggestedDesign& d : s.designs)
      if (d.near_best) near += cat(near.empty() ? "" : ", ", d.name);
    if (!near.empty())
      line += cat("; within ", kNearBest * 100, " % of it: ", near);
  }
  if (s.skin_lines.found)
    line += cat("; the relaxed skin tension lines (Borges) run at ",
                std::fmod(std::round(s.skin_lines.orientation_deg), 180.0), " deg here");
  return cat(line, " -> ", s.output);
}

}  // namespace caps::app
