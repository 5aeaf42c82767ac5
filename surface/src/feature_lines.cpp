#include "caps/surface/feature_lines.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <limits>
#include <sstream>

#include "caps/core/error.hpp"
#include "caps/core/json_file.hpp"
#include "caps/core/units.hpp"
#include "caps/image/canvas.hpp"

namespace caps {
namespace {

using nlohmann::json;

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// Adult soft-tissue proportions (Farkas 1994, Anthropometry of the Head and Face, 2nd ed.; means
// of the North American Caucasian adults, rounded; distances are projective, as his calipers
// measure them): half the intercanthal width en-en 33 mm, half the biocular width ex-ex 90 mm,
// half the mouth width ch-ch 52 mm, half the nose width al-al 35 mm, the face width zy-zy 135 mm
// (the scale of the others where the zygia are found).
constexpr double kHalfEnEnMm = 16.5;
constexpr double kHalfExExMm = 45.0;
constexpr double kHalfChChMm = 26.0;
constexpr double kHalfAlAlMm = 17.5;
constexpr double kZyZyMm = 135.0;

// A curvature (1/mm) below which a crease or a ridge is not one: a radius of 20 mm.
constexpr double kMinCurvature = 0.05;
// A line fainter than this (its columns kept times its curvature against the reference) is not
// taken: the face phantom's nose flank, which has no alar crease, gave a zigzag at 0.14.
constexpr double kMinConfidence = 0.25;

std::string mm_text(double x) {
  std::ostringstream s;
  s << std::fixed << std::setprecision(1) << x << " mm";
  return s.str();
}

double wrap180(double t) {
  t = std::fmod(t + 180.0, 360.0);
  if (t < 0) t += 360.0;
  return t - 180.0;
}

// The face's reading of a range view: the midline theta, a scale from the landmarks' proportions,
// and the curvatures of the skin along the image's columns and rows.
struct Face {
  const SkinRangeView& view;
  double tm = 0;     // the midline theta (deg)
  double scale = 1;  // the face's size against Farkas' means

  double r(double t, double z) const { return view.r_mm(t, z); }
  bool ok(double t, double z) const {
    return z >= view.z_min_mm && z <= view.z_max_mm && view.measured(t, z);
  }
  // theta (deg) of the skin point `x_mm` from the midsagittal plane on the patient's `side` (+1
  // left, -1 right) at height z: r(theta, z) sin(theta - tm) = x, by bisection over 0..85 deg.
  double theta_at(double x_mm, int side, double z) const {
    double a = 0, b = 85;
    auto lateral = [&](double d) { return r(tm + side * d, z) * std::sin(d * kPi / 180.0); };
    if (lateral(b) < x_mm) return tm + side * b;
    for (int i = 0; i < 40; ++i) {
      const double c = 0.5 * (a + b);
      (lateral(c) < x_mm ? a : b) = c;
    }
    return tm + side * 0.5 * (a + b);
  }
  // The curvature of the skin's vertical profile r(z) at (t, z) over +-h mm: positive convex (a
  // ridge), negative concave (a crease): -r_zz / (1 + r_z^2)^(3/2).
  double kz(double t, double z, double h) const {
    const double a = r(t, z - h), b = r(t, z), c = r(t, z + h);
    const double rz = (c - a) / (2 * h), rzz = (a - 2 * b + c) / (h * h);
    return -rzz / std::pow(1 + rz * rz, 1.5);
  }
  // The curvature of the skin's horizontal section r(theta) at (t, z) over +-h mm along the
  // skin, as a polar curve: (r^2 + 2 r'^2 - r r'') / (r^2 + r'^2)^(3/2), theta in radians;
  // positive convex, negative concave.
  double kt(double t, double z, double h) const {
    const double r0 = r(t, z);
    if (!(r0 > 1)) return 0;
    const double dt = h / r0;  // rad
    const double dd = dt * 180.0 / kPi;
    const double a = r(t - dd, z), c = r(t + dd, z);
    const double r1 = (c - a) / (2 * dt), r2 = (a - 2 * r0 + c) / (dt * dt);
    return (r0 * r0 + 2 * r1 * r1 - r0 * r2) / std::pow(r0 * r0 + r1 * r1, 1.5);
  }
};

FeatureLine absent_line(const std::string& name, const std::string& side, const std::string& along,
                        const std::string& why) {
  FeatureLine l;
  l.name = name;
  l.side = side;
  l.along = along;
  l.note = why;
  return l;
}

// A horizontal line traced column by column: at lateral distances xs (mm from the midsagittal
// plane, signed: + the patient's left), the extremum of the vertical curvature kz (sign -1: the
// deepest crease, +1 the sharpest ridge) over z in window(x) = [z0, z1]. Columns whose extremum is
// weaker than kMinCurvature or not measured are dropped; then those more than `jump` mm from the
// median of their five neighbours.
struct Column {
  double x = 0, t = 0, z = 0, strength = 0;
  bool ok = false;
};

std::vector<Column> trace_rows(const Face& f, const std::vector<double>& xs,
                               const std::function<std::pair<double, double>(double)>& window,
                               int sign, double h, double jump = 1.0) {
  // The line is the path through the columns, at most `jump` mm up or down from one column to
  // the next (1 mm apart), that collects the most crease (or ridge) curvature: a dynamic
  // programme over z samples 0.25 mm apart, so that a stronger crease a few millimetres away in
  // one column (the lid-cheek junction below the fissure) does not pull the line off it.
  constexpr double dz = 0.25;
  const std::size_t nc = xs.size();
  std::vector<Column> cols(nc);
  std::vector<std::vector<double>> zs(nc), k(nc), acc(nc);
  std::vector<std::vector<int>> from(nc);
  for (std::size_t i = 0; i < nc; ++i) {
    const auto [z0, z1] = window(xs[i]);
    const int side = xs[i] >= 0 ? +1 : -1;
    cols[i].x = xs[i];
    cols[i].t = f.theta_at(std::abs(xs[i]), side, 0.5 * (z0 + z1));
    for (double z = z0; z <= z1 + 1e-9; z += dz) {
      zs[i].push_back(z);
      const bool ok = f.ok(cols[i].t, z) && f.ok(cols[i].t, z - h) && f.ok(cols[i].t, z + h);
      k[i].push_back(ok ? std::max(0.0, sign * f.kz(cols[i].t, z, h)) : 0.0);
    }
  }
  const int reach = static_cast<int>(std::lround(jump / dz));
  for (std::size_t i = 0; i < nc; ++i) {
    acc[i].assign(zs[i].size(), 0.0);
    from[i].assign(zs[i].size(), -1);
    for (std::size_t a = 0; a < zs[i].size(); ++a) {
      double best = 0;
      int arg = -1;
      if (i > 0)
        for (std::size_t b = 0; b < zs[i - 1].size(); ++b)
          if (std::abs(zs[i - 1][b] - zs[i][a]) <= reach * dz + 1e-9 &&
              (arg < 0 || acc[i - 1][b] > best)) {
            best = acc[i - 1][b];
            arg = static_cast<int>(b);
          }
      acc[i][a] = best + k[i][a];
      from[i][a] = arg;
    }
  }
  if (nc == 0) return cols;
  int a = static_cast<int>(std::max_element(acc[nc - 1].begin(), acc[nc - 1].end()) -
                           acc[nc - 1].begin());
  for (std::size_t i = nc; i-- > 0;) {
    if (a < 0 || zs[i].empty()) break;
    cols[i].z = zs[i][a];
    cols[i].strength = k[i][a];
    cols[i].ok = k[i][a] >= kMinCurvature;
    a = from[i][a];
  }
  return cols;
}

// The fraction of columns kept and their median strength.
std::pair<double, double> quality(const std::vector<Column>& cols) {
  std::vector<double> s;
  for (const auto& c : cols)
    if (c.ok) s.push_back(c.strength);
  if (s.empty()) return {0.0, 0.0};
  std::nth_element(s.begin(), s.begin() + s.size() / 2, s.end());
  return {static_cast<double>(s.size()) / cols.size(), s[s.size() / 2]};
}

std::vector<double> range_mm(double a, double b, double step) {
  std::vector<double> v;
  const int n = std::max(1, static_cast<int>(std::ceil(std::abs(b - a) / step)));
  for (int i = 0; i <= n; ++i) v.push_back(a + (b - a) * i / n);
  return v;
}

// How much of the window [x0, x1] x [z0, z1] (x lateral mm on `side`) is measured skin, 0..1;
// and the lowest and highest measured z seen (for the note).
double coverage(const Face& f, int side, double x0, double x1, double z0, double z1) {
  int n = 0, m = 0;
  for (double x : range_mm(x0, x1, 2.0))
    for (double z : range_mm(z0, z1, 1.0)) {
      ++n;
      if (f.ok(f.theta_at(x, side, z), z)) ++m;
    }
  return n ? static_cast<double>(m) / n : 0.0;
}

std::string fov_note(const Face& f, double z0, double z1) {
  if (z0 < f.view.z_min_mm)
    return cat("the scan ends at z ", std::round(f.view.z_min_mm),
               " mm, below which the window "
               "reaches (z ",
               std::round(z0), "..", std::round(z1), " mm): outside the field of view");
  if (z1 > f.view.z_max_mm)
    return cat("the scan ends at z ", std::round(f.view.z_max_mm),
               " mm, above which the window "
               "reaches (z ",
               std::round(z0), "..", std::round(z1), " mm): outside the field of view");
  return cat("the skin in the window (z ", std::round(z0), "..", std::round(z1),
             " mm) is mostly not measured (outside the scan, undercut or truncated)");
}

FeatureLine from_columns(const std::string& name, const std::string& side, const std::string& along,
                         const std::vector<Column>& cols, const std::string& method,
                         double ref_strength, double min_kept = 0.6) {
  const auto [kept, strength] = quality(cols);
  FeatureLine l;
  l.name = name;
  l.side = side;
  l.along = along;
  l.method = method;
  if (kept < min_kept) {
    l.note =
        cat("no continuous ", method.substr(0, method.find(':')), ": only ", std::round(kept * 100),
            " % of the columns show it (", std::round(min_kept * 100), " % needed)");
    return l;
  }
  const double confidence = std::clamp(kept * std::min(1.0, strength / ref_strength), 0.0, 1.0);
  if (confidence < kMinConfidence) {
    l.note = cat("too faint to be the ", method.substr(0, method.find(':')), ": confidence ",
                 std::round(confidence * 100) / 100, " (", std::round(kept * 100),
                 " % of the columns, median curvature ", std::round(strength * 1000) / 1000,
                 " /mm), below ", kMinConfidence);
    return l;
  }
  for (const auto& c : cols)
    if (c.ok) l.theta_z.emplace_back(wrap180(c.t), c.z);
  l.found = true;
  l.confidence = confidence;
  l.note = cat(std::round(kept * 100), " % of the columns, median curvature across it ",
               std::round(strength * 1000) / 1000, " /mm");
  return l;
}

struct Anchors {
  const Landmark* get(const Landmarks& l, const std::string& n) {
    const Landmark* p = l.find(n);
    return p && p->found ? p : nullptr;
  }
};

// The lateral distance (mm from the midsagittal plane) of a landmark.
double lateral_of(const Face& f, const Landmark& l) {
  return f.r(l.theta_deg, l.z_mm) * std::abs(std::sin((l.theta_deg - f.tm) * kPi / 180.0));
}

}  // namespace

const std::vector<std::string>& feature_line_names() {
  static const std::vector<std::string> names = {"eyebrow_left",
                                                 "eyebrow_right",
                                                 "upper_eyelid_margin_left",
                                                 "upper_eyelid_margin_right",
                                                 "lower_eyelid_margin_left",
                                                 "lower_eyelid_margin_right",
                                                 "upper_lip_vermilion",
                                                 "lower_lip_vermilion",
                                                 "oral_commissure_left",
                                                 "oral_commissure_right",
                                                 "alar_rim_left",
                                                 "alar_rim_right",
                                                 "hairline"};
  return names;
}

const FeatureLine* FeatureLines::find(const std::string& name) const {
  for (const auto& l : items)
    if (l.name == name) return &l;
  return nullptr;
}

FeatureLines find_feature_lines(const SkinRangeView& view, const Landmarks& landmarks,
                                const std::function<double(double, double)>& r_bone) {
  if (!view.r_mm || !view.measured || !(view.dz_mm > 0) || !(view.z_max_mm > view.z_min_mm))
    throw InvalidInput(
        "find_feature_lines: the range view needs r, measured, a step and a z extent");
  Anchors a;
  const Landmark* prn = a.get(landmarks, "pronasale");
  const Landmark* sn = a.get(landmarks, "subnasale");
  const Landmark* n = a.get(landmarks, "nasion");
  const Landmark* pg = a.get(landmarks, "pogonion");
  Face f{view, landmarks.midline_theta_deg, 1.0};
  std::vector<FeatureLine> found;
  auto put = [&](FeatureLine l) { found.push_back(std::move(l)); };

  // The face's scale: the zygia's width against Farkas' zy-zy (one zygion doubled), within
  // 0.7..1.3; else 1.
  {
    const Landmark* zl = a.get(landmarks, "zygion_left");
    const Landmark* zr = a.get(landmarks, "zygion_right");
    double w = 0;
    if (zl && zr)
      w = lateral_of(f, *zl) + lateral_of(f, *zr);
    else if (zl)
      w = 2 * lateral_of(f, *zl);
    else if (zr)
      w = 2 * lateral_of(f, *zr);
    if (w > 0) f.scale = std::clamp(w / kZyZyMm, 0.7, 1.3);
  }
  const double s = f.scale;

  // ---- eyes: the palpebral fissure, the eyelid margins at its edges, the brows above ----------
  std::vector<std::pair<int, double>> fissure_z;  // side, the fissure's mean z (for the brows)
  for (int side : {+1, -1}) {
    const std::string sfx = side > 0 ? "_left" : "_right";
    const std::string side_name = side > 0 ? "left" : "right";
    const Landmark* ex = a.get(landmarks, "exocanthion" + sfx);
    const std::string up_name = "upper_eyelid_margin" + sfx, lo_name = "lower_eyelid_margin" + sfx;
    std::optional<double> zc;
    std::string zc_from;
    if (ex) {
      zc = ex->z_mm;
      zc_from = "the exocanthion's height";
    } else if (n) {
      zc = n->z_mm - 10.0 * s;
      zc_from = "10 mm below the nasion (no exocanthion)";
    }
    if (!prn || !zc) {
      const std::string why = !prn ? "the face's midline is not known (no pronasale)"
                                   : "neither the exocanthion nor the nasion was found";
      put(absent_line(up_name, side_name, "medial-lateral", why));
      put(absent_line(lo_name, side_name, "medial-lateral", why));
      fissure_z.emplace_back(side, kNaN);
      continue;
    }
    const double x0 = kHalfEnEnMm * s, x1 = kHalfExExMm * s;
    const double z0 = *zc - 7.0 * s, z1 = *zc + 7.0 * s;
    if (coverage(f, side, x0, x1, z0, z1) < 0.5) {
      const std::string why = fov_note(f, z0, z1);
      put(absent_line(up_name, side_name, "medial-lateral", why));
      put(absent_line(lo_name, side_name, "medial-lateral", why));
      fissure_z.emplace_back(side, kNaN);
      continue;
    }
    std::vector<double> xs;
    for (double x : range_mm(x0, x1, 1.0)) xs.push_back(side * x);
    const std::string method =
        cat("palpebral fissure: the deepest crease across z (curvature of the vertical profile "
            "over +-1.5 mm) in ",
            mm_text(x0), "..", mm_text(x1), " from the midline (Farkas' en-en/2..ex-ex/2",
            s != 1.0 ? cat(" times ", std::round(s * 100) / 100) : std::string(), "), ",
            mm_text(7.0 * s), " about ", zc_from);
    const auto cols = trace_rows(
        f, xs, [&](double) { return std::make_pair(z0, z1); }, -1, 1.5);
    FeatureLine fissure = from_columns("fissure", side_name, "medial-lateral", cols, method, 0.3);
    if (!fissure.found) {
      put(absent_line(up_name, side_name, "medial-lateral", fissure.note));
      put(absent_line(lo_name, side_name, "medial-lateral", fissure.note));
      fissure_z.emplace_back(side, kNaN);
      continue;
    }
    // The margins: the edges of the fissure's crease, where the curvature across it turns from
    // concave to convex above and below it (at most 3 mm away; with the eyes closed in the CT
    // the two margins meet in the fissure).
    FeatureLine up = fissure, lo = fissure;
    up.name = up_name;
    lo.name = lo_name;
    up.theta_z.clear();
    lo.theta_z.clear();
    double zsum = 0;
    for (const auto& tz : fissure.theta_z) {
      zsum += tz[1];
      auto edge = [&](int dir) {
        for (double d = 0.25; d <= 3.0; d += 0.25)
          if (f.kz(tz[0], tz[1] + dir * d, 1.5) >= 0) return tz[1] + dir * d;
        return tz[1] + dir * 3.0;
      };
      up.theta_z.emplace_back(tz[0], edge(+1));
      lo.theta_z.emplace_back(tz[0], edge(-1));
    }
    fissure_z.emplace_back(side, zsum / fissure.theta_z.size());
    up.method = "upper edge of the " + method;
    lo.method = "lower edge of the " + method;
    put(up);
    put(lo);
  }
  for (int side : {+1, -1}) {
    const std::string sfx = side > 0 ? "_left" : "_right";
    const std::string side_name = side > 0 ? "left" : "right";
    const std::string name = "eyebrow" + sfx;
    double zf = kNaN;
    for (const auto& [sd, z] : fissure_z)
      if (sd == side) zf = z;
    std::string from = "the palpebral fissure";
    if (!std::isfinite(zf) && n && prn) {
      zf = n->z_mm - 10.0 * s;
      from = "10 mm below the nasion (no fissure)";
    }
    if (!std::isfinite(zf)) {
      put(absent_line(name, side_name, "medial-lateral",
                      "neither the palpebral fissure nor the nasion "
                      "was found"));
      continue;
    }
    const double x0 = 10.0 * s, x1 = 52.0 * s;
    double z0 = zf + 6.0 * s, z1 = zf + 30.0 * s;
    if (coverage(f, side, x0, x1, z0, z1) < 0.5) {
      put(absent_line(name, side_name, "medial-lateral", fov_note(f, z0, z1)));
      continue;
    }
    std::vector<double> xs;
    for (double x : range_mm(x0, x1, 1.0)) xs.push_back(side * x);
    // The supraorbital rim under it: the sharpest convex turn of the bone's vertical profile in
    // the same window, per column; the brow is looked for from 4 mm below to 12 mm above it (the
    // brow lies at the rim in men and above it in women).
    std::vector<double> rim(xs.size(), kNaN);
    int with_rim = 0;
    if (r_bone) {
      for (std::size_t i = 0; i < xs.size(); ++i) {
        const double t = f.theta_at(std::abs(xs[i]), side, 0.5 * (z0 + z1));
        double best = kMinCurvature;
        for (double z = z0; z <= z1; z += 0.5) {
          const double a0 = r_bone(t, z - 3), b0 = r_bone(t, z), c0 = r_bone(t, z + 3);
          if (!std::isfinite(a0) || !std::isfinite(b0) || !std::isfinite(c0)) continue;
          const double rz = (c0 - a0) / 6, k = -(a0 - 2 * b0 + c0) / 9 / std::pow(1 + rz * rz, 1.5);
          if (k > best) {
            best = k;
            rim[i] = z;
          }
        }
        if (std::isfinite(rim[i])) ++with_rim;
      }
    }
    const bool use_rim = with_rim >= static_cast<int>(xs.size()) / 2;
    auto window = [&](double x) {
      if (!use_rim) return std::make_pair(z0, z1);
      const std::size_t i = static_cast<std::size_t>(
          std::lround((std::abs(x) - x0) / ((x1 - x0) / std::max<std::size_t>(1, xs.size() - 1))));
      const double zr = i < rim.size() ? rim[i] : kNaN;
      if (!std::isfinite(zr)) return std::make_pair(z0, z1);
      return std::make_pair(std::max(z0, zr - 4.0), std::min(z1, zr + 12.0));
    };
    const std::string method =
        cat("brow ridge: the sharpest convex turn across z (curvature over +-3 mm) ", mm_text(x0),
            "..", mm_text(x1), " from the midline, ", mm_text(6.0 * s), "..", mm_text(30.0 * s),
            " above ", from,
            use_rim ? "; within 4 mm below to 12 mm above the supraorbital rim of the bone under it"
                    : "; the skin alone (no bone rim under it)");
    put(from_columns(name, side_name, "medial-lateral", trace_rows(f, xs, window, +1, 3.0, 0.5),
                     method, 0.1));
  }

  // ---- lips: the stomion crease from the midline out to the commissures, the vermilion
  // borders above and below it ---------------------------------------------------------------
  {
    const std::vector<std::string> lip_names = {"upper_lip_vermilion", "lower_lip_vermilion",
                                                "oral_commissure_left", "oral_commissure_right"};
    auto all_absent = [&](const std::string& why) {
      put(absent_line(lip_names[0], "midline", "right-left", why));
      put(absent_line(lip_names[1], "midline", "right-left", why));
      put(absent_line(lip_names[2], "left", "point", why));
      put(absent_line(lip_names[3], "right", "point", why));
    };
    if (!sn || !prn) {
      all_absent("found below the subnasale, which is absent");
    } else {
      // The stomion 8..30 mm below the subnasale (Farkas: sn-sto about 22 mm), above the chin.
      const double zs = sn->z_mm;
      double w0 = zs - 30.0 * s, w1 = zs - 8.0 * s;
      if (pg) w0 = std::max(w0, pg->z_mm + 15.0 * s);
      const double h = 1.5;
      double zsto = kNaN, k0 = 0;
      int unmeasured = 0, rows = 0;
      for (double z = w0; z <= w1; z += 0.25) {
        ++rows;
        if (!f.ok(f.tm, z) || !f.ok(f.tm, z - h) || !f.ok(f.tm, z + h)) {
          ++unmeasured;
          continue;
        }
        const double k = -f.kz(f.tm, z, h);
        if (k > k0) {
          k0 = k;
          zsto = z;
        }
      }
      if (2 * unmeasured > rows) {
        all_absent(fov_note(f, w0, w1) + " (the stomion's window, 8..30 mm below the subnasale)");
      } else if (!(k0 >= kMinCurvature)) {
        all_absent(
            cat("no crease between the lips on the midline 8..30 mm below the subnasale "
                "(strongest curvature ",
                std::round(k0 * 1000) / 1000, " /mm)"));
      } else {
        // Outwards on both sides: the crease followed within 2 mm of its last height, until it
        // weakens below 0.35 of the midline's or the skin is not measured; that end is the
        // commissure, accepted 0.55..1.4 times Farkas' ch-ch/2 from the midline.
        struct Side {
          std::vector<Column> cols;
          std::optional<Column> corner;
          std::string why;
        };
        Side sides[2];
        for (int si = 0; si < 2; ++si) {
          const int side = si == 0 ? +1 : -1;
          double zlast = zsto;
          for (double x = 1.0; x <= 1.6 * kHalfChChMm * s; x += 1.0) {
            Column c;
            c.x = side * x;
            c.t = f.theta_at(x, side, zlast);
            double best = 0;
            for (double z = zlast - 2.0; z <= zlast + 2.0; z += 0.25)
              if (f.ok(c.t, z - h) && f.ok(c.t, z + h)) {
                const double k = -f.kz(c.t, z, h);
                if (k > best) {
                  best = k;
                  c.z = z;
                }
              }
            c.strength = best;
            c.ok = best >= std::max(kMinCurvature, 0.35 * k0);
            if (!c.ok) break;
            zlast = c.z;
            sides[si].cols.push_back(c);
          }
          const double reach = sides[si].cols.empty() ? 0 : std::abs(sides[si].cols.back().x);
          if (reach < 0.55 * kHalfChChMm * s)
            sides[si].why = cat("the crease between the lips ends ", mm_text(reach),
                                " from the "
                                "midline, short of a mouth's corner (",
                                mm_text(0.55 * kHalfChChMm * s), " at least)");
          else if (reach > 1.4 * kHalfChChMm * s)
            sides[si].why =
                cat("the crease between the lips goes on beyond ", mm_text(1.4 * kHalfChChMm * s),
                    " from the midline: no corner found");
          else
            sides[si].corner = sides[si].cols.back();
        }
        const std::string sto_method = cat(
            "the stomion crease (curvature across z over +-1.5 mm) at z ",
            std::round(zsto * 10) / 10,
            " mm on the midline, followed outwards until it weakens below 0.35 of the midline's "
            "(Farkas' ch-ch/2 ",
            mm_text(kHalfChChMm * s), ")");
        for (int si = 0; si < 2; ++si) {
          const std::string side_name = si == 0 ? "left" : "right";
          FeatureLine c;
          c.name = si == 0 ? lip_names[2] : lip_names[3];
          c.side = side_name;
          c.along = "point";
          c.method = "the lateral end of " + sto_method;
          if (!sides[si].corner) {
            c.note = sides[si].why;
          } else {
            c.found = true;
            c.theta_z.emplace_back(wrap180(sides[si].corner->t), sides[si].corner->z);
            c.confidence = std::clamp(k0 / 0.3, 0.0, 1.0) * 0.7;
            c.note = cat(mm_text(std::abs(sides[si].corner->x)), " from the midline");
          }
          found.push_back(c);
        }
        // The vermilion borders: the sharpest convex turn across z above the crease (up to the
        // subnasale) and below it (14 mm), column by column between the commissures (or as far
        // as the crease went).
        const double xr = sides[1].cols.empty() ? 0 : std::abs(sides[1].cols.back().x);
        const double xl = sides[0].cols.empty() ? 0 : std::abs(sides[0].cols.back().x);
        auto crease_z = [&](double x) {
          const Side& sd = sides[x >= 0 ? 0 : 1];
          double z = zsto;
          for (const auto& c : sd.cols)
            if (std::abs(c.x) <= std::abs(x) + 1e-9) z = c.z;
          return z;
        };
        std::vector<double> xs;
        for (double x : range_mm(-xr, xl, 1.0)) xs.push_back(x);
        for (int upper : {1, 0}) {
          auto window = [&](double x) {
            const double zc = crease_z(x);
            // 3 mm off the crease: its own convex shoulders are not the border.
            return upper
                       ? std::make_pair(zc + 3.0, std::max(zc + 3.5, std::min(zc + 14.0, zs - 2.0)))
                       : std::make_pair(zc - 14.0, zc - 3.0);
          };
          const std::string method = cat(upper ? "upper" : "lower",
                                         " vermilion border: the sharpest convex turn across z "
                                         "(curvature over +-1.5 mm) ",
                                         upper ? "from 3 mm above the stomion crease up to "
                                                 "2 mm below the subnasale"
                                               : "from 3 to 14 mm below the stomion crease",
                                         ", between the mouth's corners (", mm_text(xr), " right, ",
                                         mm_text(xl), " left)");
          FeatureLine l = from_columns(upper ? lip_names[0] : lip_names[1], "midline", "right-left",
                                       trace_rows(f, xs, window, +1, 1.5), method, 0.2);
          put(l);
        }
      }
    }
  }

  // ---- alar rims: the crease between the ala and the cheek, row by row --------------------
  for (int side : {+1, -1}) {
    const std::string sfx = side > 0 ? "_left" : "_right";
    const std::string side_name = side > 0 ? "left" : "right";
    const std::string name = "alar_rim" + sfx;
    if (!sn || !prn) {
      put(absent_line(name, side_name, "inferior-superior",
                      "found beside the pronasale and the "
                      "subnasale; one is absent"));
      continue;
    }
    // From 2 mm above the subnasale (lower, the nostril sill is the deepest crease) up to 60 %
    // of the way to the pronasale and 6 mm on, 0.4..1.5
    // times Farkas' al-al/2 from the midline.
    const double z0 = sn->z_mm + 2.0 * s, z1 = sn->z_mm + 0.6 * (prn->z_mm - sn->z_mm) + 6.0 * s;
    const double x0 = 0.4 * kHalfAlAlMm * s, x1 = 1.5 * kHalfAlAlMm * s;
    if (coverage(f, side, x0, x1, z0, z1) < 0.5) {
      put(absent_line(name, side_name, "inferior-superior", fov_note(f, z0, z1)));
      continue;
    }
    std::vector<Column> rows;
    for (double z : range_mm(z0, z1, 1.0)) {
      Column c;
      c.z = z;
      double best = 0;
      for (double x = x0; x <= x1; x += 0.25) {
        const double t = f.theta_at(x, side, z);
        if (!f.ok(t, z)) continue;
        const double k = -f.kt(t, z, 1.5);
        if (k > best) {
          best = k;
          c.t = t;
          c.x = x;
        }
      }
      c.strength = best;
      c.ok = best >= kMinCurvature;
      rows.push_back(c);
    }
    for (std::size_t i = 0; i < rows.size(); ++i) {
      if (!rows[i].ok) continue;
      std::vector<double> v;
      for (std::size_t j = i >= 2 ? i - 2 : 0; j <= std::min(rows.size() - 1, i + 2); ++j)
        if (rows[j].ok) v.push_back(rows[j].x);
      std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
      if (std::abs(rows[i].x - v[v.size() / 2]) > 2.5) rows[i].ok = false;
    }
    const std::string method = cat(
        "alar crease: the deepest crease across theta (curvature of the horizontal section over "
        "+-1.5 mm) ",
        mm_text(x0), "..", mm_text(x1), " from the midline (Farkas' al-al/2 ",
        mm_text(kHalfAlAlMm * s),
        "), from 2 mm above the subnasale's height up to 60 % of the way to the "
        "pronasale's and ",
        mm_text(6.0 * s), " more");
    put(from_columns(name, side_name, "inferior-superior", rows, method, 0.3));
  }

  put(absent_line(
      "hairline", "midline", "right-left",
      "not visible in the CT: hair is near air density and is not part of the segmented "
      "skin (a surface scan's colour could show it; not looked for)"));

  FeatureLines out;
  for (const auto& nm : feature_line_names())
    for (const auto& l : found)
      if (l.name == nm) out.items.push_back(l);
  return out;
}

FeatureLines find_feature_lines(const PatientModel& model, const Landmarks& landmarks) {
  const SkinRangeView view = skin_range_view(model);
  const PatientModel* m = &model;
  auto bone = [m](double t, double z) {
    if (!m->has_z(z) || (m->flags_at(t, z) & (kNoBone | kNoSkin)) != 0) return kNaN;
    return m->r_bone(t, z);
  };
  FeatureLines out = find_feature_lines(view, landmarks, bone);
  for (auto& l : out.items) {
    l.lps.clear();
    for (const auto& tz : l.theta_z) l.lps.push_back(model.skin_point(tz[0], tz[1]));
  }
  return out;
}

std::string feature_lines_to_json(const FeatureLines& lines) {
  auto r3 = [](double x) { return std::round(x * 1000.0) / 1000.0; };
  json items = json::object();
  for (const auto& l : lines.items) {
    json o = {{"found", l.found}, {"side", l.side}, {"along", l.along}, {"note", l.note}};
    if (!l.method.empty()) o["method"] = l.method;
    if (l.found) {
      o["confidence"] = r3(l.confidence);
      json tz = json::array(), p = json::array();
      for (const auto& v : l.theta_z) tz.push_back({r3(v[0]), r3(v[1])});
      for (const auto& v : l.lps) p.push_back({r3(v[0]), r3(v[1]), r3(v[2])});
      o["theta_z"] = tz;
      o["lps"] = p;
    }
    items[l.name] = o;
  }
  return json{
      {"definitions", "docs/landmarks.md, \"Feature lines and what a closure does to them\""},
      {"items", items}}
      .dump(-1, ' ', false, json::error_handler_t::replace);
}

FeatureLines feature_lines_from_json(const std::string& text, const std::string& source) {
  FeatureLines out;
  json j;
  try {
    j = parse_json<json>(text, cat(source, ": features"));
  } catch (const InvalidInput& e) {
    throw InvalidInput(cat(e.what(), "; recompute them with `caps model features MODEL_DIR`"));
  }
  try {
    const json& items = j.at("items");
    if (!items.is_object())
      throw InvalidInput(cat(source, ": features: \"items\" must be an object"));
    for (const auto& nm : feature_line_names()) {
      FeatureLine l;
      l.name = nm;
      if (!items.contains(nm)) {
        l.note = "not in the model's features";
        out.items.push_back(l);
        continue;
      }
      const json& o = items.at(nm);
      l.found = o.at("found").get<bool>();
      l.side = o.value("side", std::string());
      l.along = o.value("along", std::string());
      l.note = o.value("note", std::string());
      l.method = o.value("method", std::string());
      if (l.found) {
        l.confidence = o.at("confidence").get<double>();
        for (const auto& v : o.at("theta_z"))
          l.theta_z.emplace_back(v.at(0).get<double>(), v.at(1).get<double>());
        for (const auto& v : o.at("lps"))
          l.lps.emplace_back(v.at(0).get<double>(), v.at(1).get<double>(), v.at(2).get<double>());
        if (l.lps.size() != l.theta_z.size())
          throw InvalidInput(cat(source, ": features: ", nm, " has ", l.lps.size(),
                                 " LPS points for ", l.theta_z.size(), " (theta, z)"));
      }
      out.items.push_back(l);
    }
  } catch (const json::exception& e) {
    throw InvalidInput(cat(source, ": features: ", e.what(),
                           "; recompute them with `caps model features MODEL_DIR`"));
  }
  return out;
}

namespace {

double polyline_length(const std::vector<Eigen::Vector3d>& p) {
  double s = 0;
  for (std::size_t i = 1; i < p.size(); ++i) s += (p[i] - p[i - 1]).norm();
  return s;
}

}  // namespace

std::string feature_lines_table(const FeatureLines& lines) {
  std::ostringstream s;
  s << std::fixed << std::setprecision(1);
  for (const auto& l : lines.items) {
    s << std::left << std::setw(27) << l.name;
    if (!l.found) {
      s << "absent: " << l.note << "\n";
      continue;
    }
    double z0 = 1e9, z1 = -1e9;
    for (const auto& tz : l.theta_z) {
      z0 = std::min(z0, tz[1]);
      z1 = std::max(z1, tz[1]);
    }
    s << l.theta_z.size() << " points";
    if (!l.lps.empty()) s << ", " << polyline_length(l.lps) << " mm long";
    s << ", z " << z0 << ".." << z1 << " mm";
    if (!l.lps.empty()) {
      const auto& m = l.lps[l.lps.size() / 2];
      s << ", middle LPS (" << m[0] << ", " << m[1] << ", " << m[2] << ")";
    }
    s << "  confidence " << std::setprecision(2) << l.confidence << std::setprecision(1) << "\n";
  }
  return s.str();
}

void write_feature_lines_png(const std::filesystem::path& path, const PatientModel& model,
                             const Landmarks& landmarks, const FeatureLines& lines,
                             const std::string& title) {
  const SkinRangeView view = skin_range_view(model);
  const Face f{view, landmarks.midline_theta_deg, 1.0};
  // The window: 80 mm to either side, from 20 mm below the lowest line or landmark (or the
  // scan's end) to 40 mm above the highest.
  double zlo = 1e9, zhi = -1e9;
  for (const auto& l : landmarks.items)
    if (l.found && std::abs(wrap180(l.theta_deg - f.tm)) < 60) {
      zlo = std::min(zlo, l.z_mm);
      zhi = std::max(zhi, l.z_mm);
    }
  for (const auto& l : lines.items)
    for (const auto& tz : l.theta_z) {
      zlo = std::min(zlo, tz[1]);
      zhi = std::max(zhi, tz[1]);
    }
  if (zlo > zhi) zlo = view.z_min_mm, zhi = view.z_max_mm;
  zlo = std::max(view.z_min_mm, zlo - 20.0);
  zhi = std::min(view.z_max_mm, zhi + 40.0);
  constexpr double kPx = 4.0, kHalfWidth = 80.0;
  constexpr int kTop = 40, kBottom = 60;
  const int w = static_cast<int>(2 * kHalfWidth * kPx), h = static_cast<int>((zhi - zlo) * kPx);
  RgbImage img = make_image(w, std::max(h, 1), {1, 1, 1});
  const AnatomicalFrame fr = anatomical_frame(model);
  const Eigen::Vector3d light = (fr.front + 0.5 * fr.up + 0.3 * fr.left).normalized();
  const Eigen::Vector3d tone(0.93, 0.76, 0.65);
  // Pixel column i is x = (i + 0.5) / kPx - kHalfWidth mm towards the patient's left: the
  // patient's right is on the picture's left, as one faces the patient.
  for (int i = 0; i < w; ++i) {
    const double x = (i + 0.5) / kPx - kHalfWidth;
    for (int k = 0; k < h; ++k) {
      const double z = zhi - (k + 0.5) / kPx;
      const double t = f.theta_at(std::abs(x), x >= 0 ? +1 : -1, z);
      if (std::abs(std::abs(x) - f.r(t, z) * std::abs(std::sin((t - f.tm) * kPi / 180.0))) > 0.5)
        continue;  // beyond the face's outline
      const Eigen::Vector3d nrm = model.skin_normal(t, z);
      const double shade = 0.25 + 0.75 * std::max(0.0, nrm.dot(light));
      img.set(i, k,
              view.measured(t, z) ? Eigen::Vector3d(tone * shade)
                                  : Eigen::Vector3d(Eigen::Vector3d::Constant(0.8 * shade)));
    }
  }
  Canvas c(w, h + kTop + kBottom);
  c.draw_image(img, 0, kTop);
  auto px = [&](double t, double z) {
    const double x = f.r(t, z) * std::sin((t - f.tm) * kPi / 180.0);
    return Eigen::Vector2d((x + kHalfWidth) * kPx, kTop + (zhi - z) * kPx);
  };
  auto colour = [](const std::string& n) -> Eigen::Vector3d {
    if (n.rfind("eyebrow", 0) == 0) return {0.55, 0.27, 0.07};
    if (n.rfind("upper_eyelid", 0) == 0) return {0.0, 0.35, 0.9};
    if (n.rfind("lower_eyelid", 0) == 0) return {0.0, 0.75, 0.9};
    if (n.find("lip") != std::string::npos) return {0.85, 0.0, 0.3};
    if (n.rfind("oral_commissure", 0) == 0) return {0.9, 0.5, 0.0};
    if (n.rfind("alar", 0) == 0) return {0.1, 0.6, 0.1};
    return {0.3, 0.3, 0.3};
  };
  for (const auto& l : lines.items) {
    if (!l.found) continue;
    std::vector<Eigen::Vector2d> p;
    for (const auto& tz : l.theta_z) p.push_back(px(tz[0], tz[1]));
    if (p.size() == 1) {
      c.fill_circle(p[0], 5, colour(l.name));
    } else {
      Pen pen;
      pen.colour = colour(l.name);
      pen.width_px = 2.5;
      c.polyline(p, pen);
    }
  }
  for (const auto& l : landmarks.items) {
    if (!l.found || std::abs(wrap180(l.theta_deg - f.tm)) > 85) continue;
    const Eigen::Vector2d p = px(l.theta_deg, l.z_mm);
    Pen pen;
    pen.colour = {0, 0, 0};
    pen.width_px = 1.5;
    c.line(p - Eigen::Vector2d(5, 5), p + Eigen::Vector2d(5, 5), pen);
    c.line(p - Eigen::Vector2d(5, -5), p + Eigen::Vector2d(5, -5), pen);
  }
  TextStyle ts;
  ts.size_px = 14;
  c.text(8, 24, title, ts);
  ts.size_px = 11;
  double lx = 8;
  for (const auto& [label, n] :
       std::vector<std::pair<std::string, std::string>>{{"brow", "eyebrow"},
                                                        {"upper lid", "upper_eyelid"},
                                                        {"lower lid", "lower_eyelid"},
                                                        {"lip border", "upper_lip"},
                                                        {"commissure", "oral_commissure"},
                                                        {"alar rim", "alar"},
                                                        {"x landmark", "none"}}) {
    c.fill_rect(lx, kTop + h + 14, 10, 10, colour(n));
    c.text(lx + 14, kTop + h + 23, label, ts);
    lx += 22 + c.text_width(label, 11);
  }
  Pen bar;
  bar.colour = {0, 0, 0};
  bar.width_px = 2;
  c.line({8, kTop + h + 42.0}, {8 + 20 * kPx, kTop + h + 42.0}, bar);
  c.text(8 + 20 * kPx + 6, kTop + h + 46, "20 mm; front view, the patient's right on the left", ts);
  c.write_png(path);
}

}  // namespace caps
