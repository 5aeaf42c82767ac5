#include "caps/surface/landmarks.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <map>
#include <iomanip>
#include <optional>
#include <sstream>

#include "caps/core/error.hpp"
#include "caps/core/plane_geometry.hpp"
#include "caps/core/json_file.hpp"
#include "caps/core/units.hpp"

namespace caps {
namespace {

using nlohmann::json;


// The vertex offset (in steps, within [-1, 1]) of the parabola through f(-1), f(0), f(1).
double parabola_offset(double fm, double f0, double fp) {
  const double d = fm - 2 * f0 + fp;
  if (std::abs(d) < 1e-12) return 0.0;
  return std::clamp(0.5 * (fm - fp) / d, -1.0, 1.0);
}

// A profile sampled along z on the midline: z_i, values and whether they were measured.
struct Profile {
  std::vector<double> z, v;
  std::vector<bool> ok;
  int size() const { return static_cast<int>(z.size()); }
};

Profile profile(const SkinRangeView& view, double theta, double z0, double z1) {
  Profile p;
  z0 = std::max(z0, view.z_min_mm + view.dz_mm);
  z1 = std::min(z1, view.z_max_mm - view.dz_mm);
  for (double z = z0; z <= z1 + 1e-9; z += view.dz_mm) {
    p.z.push_back(z);
    p.v.push_back(view.r_mm(theta, z));
    p.ok.push_back(view.measured(theta, z));
  }
  return p;
}

// Interior local extrema (sign +1: maxima, -1: minima) with all three samples measured.
std::vector<int> extrema(const Profile& p, int sign) {
  std::vector<int> out;
  for (int i = 1; i + 1 < p.size(); ++i) {
    if (!(p.ok[i - 1] && p.ok[i] && p.ok[i + 1])) continue;
    const double a = sign * p.v[i - 1], b = sign * p.v[i], c = sign * p.v[i + 1];
    if (b >= a && b > c) out.push_back(i);
  }
  return out;
}

// The tragion's depth is read at the lowest skin (nearest the axis) up to this far in front of
// the ear's edge (mm of arc): the hollow before the tragus.
constexpr double kPreauricularMm = 15.0;

// The profile's value range over z in [za, zb] (measured samples): {min, max}.
std::pair<double, double> range_over(const Profile& p, double za, double zb) {
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  for (int i = 0; i < p.size(); ++i)
    if (p.ok[i] && p.z[i] >= za - 1e-9 && p.z[i] <= zb + 1e-9) {
      lo = std::min(lo, p.v[i]);
      hi = std::max(hi, p.v[i]);
    }
  return {lo, hi};
}

// z of the extremum at sample i, refined by a parabola.
double refine_z(const Profile& p, int i) {
  return p.z[i] + parabola_offset(p.v[i - 1], p.v[i], p.v[i + 1]) * (p.z[1] - p.z[0]);
}

Landmark absent(const std::string& name, const std::string& why) {
  Landmark l;
  l.name = name;
  l.note = why;
  return l;
}

Landmark at(const std::string& name, double theta, double z, double confidence,
            const std::string& note) {
  Landmark l;
  l.name = name;
  l.found = true;
  l.theta_deg = wrap_degrees(theta);
  l.z_mm = z;
  l.confidence = std::clamp(confidence, 0.0, 1.0);
  l.note = note;
  return l;
}

std::string mm(double x) {
  std::ostringstream s;
  s << std::fixed << std::setprecision(1) << x << " mm";
  return s.str();
}

// Pronasale: the largest radius in front (|theta| <= 60 deg), refined in theta and z.
std::optional<Eigen::Vector2d> nose_tip(const SkinRangeView& view) {
  double best = -1;
  Eigen::Vector2d tz(0, 0);
  for (double z = view.z_min_mm + 2 * view.dz_mm; z <= view.z_max_mm - 2 * view.dz_mm;
       z += view.dz_mm)
    for (double t = -60.0; t <= 60.0; t += view.dtheta_deg) {
      if (!view.measured(t, z)) continue;
      const double r = view.r_mm(t, z);
      if (r > best) {
        best = r;
        tz = {t, z};
      }
    }
  if (best < 0) return std::nullopt;
  for (int pass = 0; pass < 3; ++pass) {
    const double ht = view.dtheta_deg, hz = view.dz_mm;
    tz[0] += ht * parabola_offset(view.r_mm(tz[0] - ht, tz[1]), view.r_mm(tz[0], tz[1]),
                                  view.r_mm(tz[0] + ht, tz[1]));
    tz[1] += hz * parabola_offset(view.r_mm(tz[0], tz[1] - hz), view.r_mm(tz[0], tz[1]),
                                  view.r_mm(tz[0], tz[1] + hz));
  }
  return tz;
}

double measured_factor(const SkinRangeView& view, double t, double z) {
  return view.measured(t, z) ? 1.0 : 0.3;
}

// The glabella above a nasion at zn on the midline profile: the index of the most prominent
// measured sample within `reach` mm above it, or -1 where that is the end of the window or of the
// profile (the forehead rises on: no brow prominence).
int brow_above(const Profile& mid, double zn, double reach = 30.0) {
  int best = -1;
  for (int i = 0; i < mid.size(); ++i)
    if (mid.ok[i] && mid.z[i] > zn && mid.z[i] <= zn + reach &&
        (best < 0 || mid.v[i] > mid.v[best]))
      best = i;
  if (best <= 0 || best + 1 >= mid.size() || mid.z[best + 1] > zn + reach ||
      !(mid.v[best] >= mid.v[best + 1]))
    return -1;
  return best;
}

// The face's midline without a nose tip: the theta within 45 deg of the front about which the
// skin is most left-right symmetric, the mean of (r(t + d, z) - r(t - d, z))^2 over d = 4..40
// deg and every z where both sides are measured (among the thetas with at least half the most
// pairs), refined by a parabola. Also the rms asymmetry there (mm). nullopt with fewer than 200
// measured pairs at the best theta.
std::optional<std::pair<double, double>> symmetric_midline(const SkinRangeView& view) {
  const double step = std::max(view.dtheta_deg, 0.5);
  std::vector<double> ts, cost;
  std::vector<int> count;
  for (double t = -45.0; t <= 45.0 + 1e-9; t += step) {
    double sum = 0;
    int n = 0;
    for (double z = view.z_min_mm + view.dz_mm; z <= view.z_max_mm - view.dz_mm;
         z += view.dz_mm)
      for (double d = 4.0; d <= 40.0 + 1e-9; d += 4.0) {
        if (!view.measured(t + d, z) || !view.measured(t - d, z)) continue;
        const double e = view.r_mm(t + d, z) - view.r_mm(t - d, z);
        sum += e * e;
        ++n;
      }
    ts.push_back(t);
    cost.push_back(n > 0 ? sum / n : std::numeric_limits<double>::infinity());
    count.push_back(n);
  }
  // Only thetas with at least half the most measured pairs compete (a few symmetric pairs at the
  // edge of a scan are not a face's symmetry).
  const int most = *std::max_element(count.begin(), count.end());
  int best = -1;
  for (int i = 0; i < static_cast<int>(ts.size()); ++i)
    if (2 * count[i] >= most && (best < 0 || cost[i] < cost[best])) best = i;
  if (best < 0 || count[best] < 200) return std::nullopt;
  double t = ts[best];
  if (best > 0 && best + 1 < static_cast<int>(ts.size()) && std::isfinite(cost[best - 1]) &&
      std::isfinite(cost[best + 1]))
    t += step * parabola_offset(cost[best - 1], cost[best], cost[best + 1]);
  return std::make_pair(t, std::sqrt(cost[best]));
}

// Without a pronasale: the glabella and the nasion on the symmetric midline where the scan shows
// them (docs/landmarks.md, "Without the nose tip"). The nasion is the deepest midline concavity
// with a brow at least 2 mm in front of it within 30 mm above and the skin measured for 6 mm
// below it and rising there (the nose's root) by 1 mm; the glabella the most prominent point
// within 40 mm above it, not at the scan's edge (a flat brow, ch2's, peaks near 30 mm above).
// Without such a nasion, the glabella is the most anterior midline point the skin falls away
// from by 2 mm both above (within 30 mm) and below (within the scan), on a band across the face
// (20 mm to either side the skin lies within 5 mm behind it: not a nose).
// Confidences are half (nasion, glabella above it) or a quarter (glabella alone) of the
// pronasale-based ones. Puts both landmarks; returns the midline theta used (NaN without one).
double brow_without_nose(const SkinRangeView& view, const std::string& why,
                         std::vector<Landmark>& put) {
  const std::string lost = "without the pronasale (" + why + "): ";
  const auto sym = symmetric_midline(view);
  if (!sym) {
    put.push_back(absent("glabella", lost + "too little measured skin in front to find the "
                                            "midline by left-right symmetry"));
    put.push_back(absent("nasion", lost + "too little measured skin in front to find the "
                                          "midline by left-right symmetry"));
    return std::numeric_limits<double>::quiet_NaN();
  }
  const double tm = sym->first;
  // The search's edge: a face turned that far has its nose tip in view, and a skin most
  // symmetric there is not a face's (a head leaning 25 deg in the scanner was most symmetric at
  // 45 deg and its "glabella" lay on the temple; issue 37).
  if (std::abs(tm) >= 45.0 - std::max(view.dtheta_deg, 0.5)) {
    const std::string edge =
        cat(lost, "the skin is most left-right symmetric at the edge of the search (theta ",
            std::round(tm), " deg, 45 deg off the front), where no face's midline lies: is the "
            "head turned or leaning in the scanner?");
    put.push_back(absent("glabella", edge));
    put.push_back(absent("nasion", edge));
    return std::numeric_limits<double>::quiet_NaN();
  }
  const std::string how = cat("midline theta ", std::round(tm * 10.0) / 10.0,
                              " deg from the left-right symmetry of the skin (rms asymmetry ",
                              mm(sym->second), ")");
  const Profile mid = profile(view, tm, view.z_min_mm, view.z_max_mm);
  const double h = view.dz_mm;
  int best = -1;
  double depth = 0;
  std::string refused;
  for (int i : extrema(mid, -1)) {
    const double d = range_over(mid, mid.z[i], mid.z[i] + 30.0).second - mid.v[i];
    if (d < 2.0) continue;
    bool below = true;
    for (double z = mid.z[i] - h; z >= mid.z[i] - 6.0 - 1e-9; z -= h)
      below = below && view.measured(tm, z);
    if (!below || view.r_mm(tm, mid.z[i] - 6.0) < mid.v[i] + 1.0) {
      refused = cat("the midline concavity at z ", std::round(mid.z[i]), " mm ", mm(d),
                    " below the brow has no measured nasal root 6 mm below it (the scan ends "
                    "too close to tell it from the scan's edge)");
      continue;
    }
    if (d > depth) {
      depth = d;
      best = i;
    }
  }
  if (best >= 0) {
    const double zn = refine_z(mid, best);
    int g = brow_above(mid, zn, 40.0);
    if (g >= 0 && !(mid.ok[g - 1] && mid.ok[g + 1])) g = -1;  // at the scan's edge
    // A brow stands a few millimetres in front of the nasion (Cranium 2.3 mm, the face phantom
    // 5 mm); a nose tip stands 15-20 mm in front of the subnasale. A "brow" more than
    // kMaxBrowMm in front is a nose over the concavity under it: on a head tilted forward in
    // the scanner the nasal root is no concavity along the axis, the tip was refused as a nose,
    // and the tip and the subnasale would be taken for the glabella and the nasion (issue 37).
    constexpr double kMaxBrowMm = 10.0;
    if (g >= 0 && mid.v[g] - view.r_mm(tm, zn) > kMaxBrowMm) {
      const std::string nose =
          cat("the most prominent midline point above the deepest concavity (z ",
              std::round(mid.z[g]), " mm) stands ", mm(mid.v[g] - view.r_mm(tm, zn)),
              " in front of it (z ", std::round(zn), " mm): a nose over the skin under it, not "
              "a brow over the nasion (a brow stands at most ", kMaxBrowMm,
              " mm in front); is the head tilted in the scanner?");
      put.push_back(absent("nasion", lost + nose));
      put.push_back(absent("glabella", lost + nose));
      return tm;
    }
    put.push_back(at("nasion", tm, zn,
                     0.5 * std::min(1.0, depth / 2.0) * measured_factor(view, tm, zn),
                     cat("without the pronasale: the deepest midline point below the brow, ",
                         mm(depth), " below it, the nasal root measured below; ", how)));
    std::optional<double> cut;  // the lowest unmeasured height within the window
    for (int i = 0; i < mid.size() && !cut; ++i)
      if (!mid.ok[i] && mid.z[i] > zn && mid.z[i] <= zn + 40.0) cut = mid.z[i];
    if (g < 0 && cut) {
      put.push_back(absent("glabella", lost + cat("the skin above the nasion is not measured "
                                                  "from z ", std::round(*cut), " mm (the edge "
                                                  "of the scan cuts the brow)")));
    } else if (g < 0) {
      put.push_back(absent("glabella", lost + "the forehead rises without a brow prominence "
                                              "within 40 mm above the nasion"));
    } else {
      const double z = refine_z(mid, g);
      const double d = mid.v[g] - view.r_mm(tm, zn);
      put.push_back(at("glabella", tm, z,
                       0.5 * std::min(1.0, d / 2.0) * measured_factor(view, tm, z),
                       cat("without the pronasale: the most prominent midline point above the "
                           "nasion, ", mm(d), " in front of it; ", how)));
    }
    return tm;
  }
  put.push_back(absent("nasion", lost + (refused.empty()
                                             ? std::string("no midline concavity 2 mm below a "
                                                           "brow with the nose's root below it")
                                             : refused)));
  int g = -1;
  double prominence = 0;
  for (int i : extrema(mid, +1)) {
    const double above = mid.v[i] - range_over(mid, mid.z[i], mid.z[i] + 30.0).first;
    int j = i;
    while (j > 0 && mid.ok[j - 1]) --j;
    const double below = mid.v[i] - range_over(mid, mid.z[j], mid.z[i]).first;
    // A brow is a band across the forehead, a nose (the plain phantom's, a nose tip cut off
    // by the scan) is not: 20 mm to either side the skin lies within 5 mm behind it.
    const double side = 20.0 / view.r_typical_mm * 180.0 / kPi;
    const double fall = mid.v[i] - std::max(view.r_mm(tm - side, mid.z[i]),
                                            view.r_mm(tm + side, mid.z[i]));
    if (above >= 2.0 && below >= 2.0 && fall <= 5.0 && (g < 0 || mid.v[i] > mid.v[g])) {
      g = i;
      prominence = std::min(above, below);
    }
  }
  if (g < 0) {
    put.push_back(absent("glabella", lost + "no midline brow prominence (a point the skin falls "
                                            "away from by 2 mm above and below within the scan)"));
  } else {
    const double z = refine_z(mid, g);
    put.push_back(at("glabella", tm, z,
                     0.25 * std::min(1.0, prominence / 2.0) * measured_factor(view, tm, z),
                     cat("without the pronasale or the nasion: the most anterior midline brow "
                         "point, the skin ", mm(prominence), " behind it above and below; ", how)));
  }
  return tm;
}

}  // namespace

const std::vector<std::string>& landmark_names() {
  static const std::vector<std::string> names = {
      "glabella",    "nasion",           "pronasale",         "subnasale",
      "pogonion",    "zygion_left",      "zygion_right",      "exocanthion_left",
      "exocanthion_right", "tragion_left", "tragion_right"};
  return names;
}

std::string landmark_in_words(const std::string& name) {
  static const std::pair<const char*, const char*> kWords[] = {
      {"glabella", "glabella"},
      {"nasion", "nasion"},
      {"pronasale", "nose tip (pronasale)"},
      {"subnasale", "base of the nose (subnasale)"},
      {"pogonion", "chin point (pogonion)"},
      {"zygion", "cheekbone (zygion)"},
      {"exocanthion", "outer eye corner (exocanthion)"},
      {"tragion", "tragus (tragion)"},
  };
  std::string base = name, side;
  for (const char* s : {"_left", "_right"})
    if (base.size() > std::strlen(s) && base.ends_with(s)) {
      side = std::string(s + 1) + " ";
      base.resize(base.size() - std::strlen(s));
    }
  for (const auto& [n, words] : kWords)
    if (base == n) return side + words;
  std::string out = name;
  std::replace(out.begin(), out.end(), '_', ' ');
  return out;
}

const Landmark* Landmarks::find(const std::string& name) const {
  for (const auto& l : items)
    if (l.name == name) return &l;
  return nullptr;
}

Landmarks find_landmarks(const SkinRangeView& view) {
  if (!view.r_mm || !view.measured || !(view.dz_mm > 0) || !(view.dtheta_deg > 0) ||
      !(view.z_max_mm > view.z_min_mm))
    throw InvalidInput("find_landmarks: the range view needs r, measured, positive steps and a z "
                       "extent");
  Landmarks out;
  std::vector<Landmark> found;
  auto put = [&](Landmark l) { found.push_back(std::move(l)); };
  const auto tip = nose_tip(view);
  if (!tip) {
    for (const auto& n : landmark_names())
      put(absent(n, "no measured skin in front of the axis (|theta| <= 60 deg)"));
    out.items = found;
    return out;
  }
  const double tm = (*tip)[0], zp = (*tip)[1];
  out.midline_theta_deg = wrap_degrees(tm);
  // The midsagittal profile, from 110 mm below the nose tip to 90 mm above it.
  const Profile mid = profile(view, tm, zp - 110.0, zp + 90.0);
  {
    // A nose tip, not the edge of a scan that ends at the nose or above it (the brow): the
    // skin is measured 6 mm below it and lies lower there, and above it the profile has a
    // nasal root (a concavity 8..70 mm above with the brow at least 2 mm in front of it) that
    // the tip stands at least 8 mm in front of.
    bool below = true;
    for (double z = zp - view.dz_mm; z >= zp - 6.0; z -= view.dz_mm)
      below = below && view.measured(tm, z);
    below = below && view.r_mm(tm, zp - 6.0) < view.r_mm(tm, zp) - 1.0;
    double projection = 0;
    for (int i : extrema(mid, -1))
      if (mid.z[i] >= zp + 8.0 && mid.z[i] <= zp + 70.0 &&
          range_over(mid, mid.z[i], mid.z[i] + 30.0).second - mid.v[i] >= 2.0)
        projection = std::max(projection, view.r_mm(tm, zp) - mid.v[i]);
    std::string why;
    if (!below)
      why = cat("the most prominent point in front (theta ", std::round(tm), " deg, z ",
                std::round(zp), " mm) lies at the edge of the scan: the scan ends at or above "
                "the nose tip");
    else if (!(projection >= 8.0))
      why = cat("the most prominent point in front (theta ", std::round(tm), " deg, z ",
                std::round(zp), " mm) has no nasal root above it that it stands 8 mm in front "
                "of: not a nose (the scan may end above the nose tip)");
    if (!why.empty()) {
      const double t = brow_without_nose(view, why, found);
      if (std::isfinite(t)) out.midline_theta_deg = wrap_degrees(t);
      for (const auto& n : landmark_names())
        if (n != "glabella" && n != "nasion")
          put(absent(n, n == "pronasale" ? why
                                         : "found from the pronasale, which is absent: " + why));
      for (const auto& n : landmark_names())
        for (const auto& l : found)
          if (l.name == n) out.items.push_back(l);
      return out;
    }
    put(at("pronasale", tm, zp, std::min(1.0, projection / 15.0) * measured_factor(view, tm, zp),
           cat("the most prominent point in front (largest radius), ", mm(projection),
               " in front of the nasal root")));
  }

  // Nasion: the deepest midline concavity 8..70 mm above the nose tip, depth against the
  // highest point within 30 mm above it (the brow).
  std::optional<double> zn;
  {
    int best = -1;
    double depth = 0;
    for (int i : extrema(mid, -1)) {
      if (mid.z[i] < zp + 8.0 || mid.z[i] > zp + 70.0) continue;
      const double d = range_over(mid, mid.z[i], mid.z[i] + 30.0).second - mid.v[i];
      if (d > depth) {
        depth = d;
        best = i;
      }
    }
    if (best < 0 || depth < 2.0) {
      put(absent("nasion", "no concavity between the forehead and the nose on the midline "
                           "(8..70 mm above the pronasale)"));
    } else {
      zn = refine_z(mid, best);
      put(at("nasion", tm, *zn, std::min(1.0, depth / 2.0) * measured_factor(view, tm, *zn),
             cat("the deepest midline point between the brow and the nose, ", mm(depth),
                 " below the brow")));
    }
  }
  // Glabella: the most prominent midline point within 30 mm above the nasion.
  if (!zn) {
    put(absent("glabella", "found from the nasion, which is absent"));
  } else {
    const int best = brow_above(mid, *zn);
    if (best < 0)
      put(absent("glabella", "the forehead rises without a brow prominence within 30 mm above "
                             "the nasion"));
    else {
      const double z = refine_z(mid, best);
      const double depth = mid.v[best] - view.r_mm(tm, *zn);
      put(at("glabella", tm, z, std::min(1.0, depth / 2.0) * measured_factor(view, tm, z),
             cat("the most prominent midline point above the nasion, ", mm(depth),
                 " in front of it")));
    }
  }
  // Subnasale: the vertex of the nasolabial angle, where the midline profile turns most sharply
  // concave (the columella meeting the upper lip) 4..40 mm below the nose tip: the largest
  // turning angle atan((r(z + h) - r(z)) / h) - atan((r(z) - r(z - h)) / h), h = 3 mm.
  std::optional<double> zs;
  {
    constexpr double h = 3.0;
    auto measured3 = [&](double z) {
      return view.measured(tm, z) && view.measured(tm, z - h) && view.measured(tm, z + h);
    };
    auto turning = [&](double z) {
      const double r0 = view.r_mm(tm, z);
      return std::atan((view.r_mm(tm, z + h) - r0) / h) - std::atan((r0 - view.r_mm(tm, z - h)) / h);
    };
    double best = 0;
    std::optional<double> zb;
    for (double z = zp - 40.0; z <= zp - 4.0; z += view.dz_mm)
      if (z - h >= view.z_min_mm && measured3(z) && turning(z) > best) {
        best = turning(z);
        zb = z;
      }
    if (!zb || best < 0.1) {
      put(absent("subnasale", "no concave angle between the nose and the upper lip on the "
                              "midline (4..40 mm below the pronasale)"));
    } else {
      const double hz = view.dz_mm;
      zs = *zb + hz * parabola_offset(turning(*zb - hz), turning(*zb), turning(*zb + hz));
      put(at("subnasale", tm, *zs, std::min(1.0, best / 0.5) * measured_factor(view, tm, *zs),
             cat("the sharpest concave turn of the midline profile below the pronasale (",
                 std::round(best * 180.0 / kPi), " deg over 3 mm)")));
    }
  }
  // Pogonion: the lowest prominent midline point 15..75 mm below the subnasale.
  if (!zs) {
    put(absent("pogonion", "found below the subnasale, which is absent"));
  } else {
    int best = -1;
    double prominence = 0;
    for (int i : extrema(mid, +1)) {
      if (mid.z[i] > *zs - 15.0 || mid.z[i] < *zs - 75.0) continue;
      const double below = range_over(mid, mid.z[i] - 12.0, mid.z[i]).first;
      const double above = range_over(mid, mid.z[i], mid.z[i] + 12.0).first;
      const double p = mid.v[i] - std::max(below, above);
      if (p >= 1.0 && (best < 0 || mid.z[i] < mid.z[best])) {
        best = i;
        prominence = p;
      }
    }
    if (best < 0)
      put(absent("pogonion", "no measured chin prominence 15..75 mm below the subnasale (the "
                             "scan may end above the chin)"));
    else {
      const double z = refine_z(mid, best);
      put(at("pogonion", tm, z, std::min(1.0, prominence / 3.0) * measured_factor(view, tm, z),
             cat("the lowest midline prominence below the lips, ", mm(prominence),
                 " above its surroundings")));
    }
  }

  const double z_lo = zs ? *zs : zp - 20.0, z_hi = zn ? *zn : zp + 45.0;
  const double deg_per_mm = 180.0 / (kPi * view.r_typical_mm);
  std::vector<Landmark> zyg, exo, tra;
  for (int side : {+1, -1}) {
    const std::string suffix = side > 0 ? "_left" : "_right";
    auto theta_of = [&](double dt) { return tm + side * dt; };
    // Tragion: the ear stands out of the chord from 70 to 135 deg off the midline (or crosses
    // the ray twice); its front edge at the height of its centroid.
    std::optional<double> ear_front;
    {
      const double a = 70.0, b = 135.0;
      const double za = z_lo - 20.0, zb = z_hi + 20.0;
      auto excess = [&](double dt, double z) {
        const double ra = view.r_mm(theta_of(a), z), rb = view.r_mm(theta_of(b), z);
        return view.r_mm(theta_of(dt), z) - (ra + (rb - ra) * (dt - a) / (b - a));
      };
      auto is_ear = [&](double dt, double z) {
        return (view.undercut && view.undercut(theta_of(dt), z)) ||
               (view.measured(theta_of(dt), z) && excess(dt, z) >= 4.0);
      };
      double area = 0, wz = 0, w = 0;
      for (double z = std::max(za, view.z_min_mm); z <= std::min(zb, view.z_max_mm);
           z += view.dz_mm)
        for (double dt = a; dt <= b; dt += view.dtheta_deg)
          if (is_ear(dt, z)) {
            area += view.dz_mm * view.dtheta_deg / deg_per_mm;
            const double e = std::clamp(excess(dt, z), 4.0, 20.0);
            wz += e * z;
            w += e;
          }
      // A real ear stands out over several hundred mm^2 (Cranium: 850-910); the small face
      // phantom's (caps phantom --face --scale 0.9) over 70-80.
      if (area < 50.0) {
        tra.push_back(absent("tragion" + suffix,
                             cat("no ear 70..135 deg off the midline (", mm(area),
                                 "^2 stand out 4 mm): the scan may not cover it")));
      } else {
        const double zc = wz / w;
        double prev = a, e_prev = excess(a, zc);
        // The ear goes on behind its front edge: a ray or two crossing the skin twice in
        // front of it (grazing the ear's base through the voxels' staircase) are not its edge.
        const double behind = 2.0 * deg_per_mm;
        for (double dt = a; dt <= b; dt += 0.25 * view.dtheta_deg) {
          if (is_ear(dt, zc) && is_ear(dt + behind, zc)) {
            const double e = excess(dt, zc);
            double f = dt;
            if (!(view.undercut && view.undercut(theta_of(dt), zc)) && e > e_prev && dt > a)
              f = prev + (dt - prev) * (4.0 - e_prev) / (e - e_prev);
            ear_front = f;
            break;
          }
          prev = dt;
          e_prev = excess(dt, zc);
        }
        if (!ear_front) {
          tra.push_back(absent("tragion" + suffix, "the ear's row has no front edge"));
        } else {
          // The depth in front of the ear: where the skin lies lowest (nearest the axis) within
          // kPreauricularMm in front of the ear's edge, the hollow before the tragus.
          const auto& depth_measured = view.depth_measured ? view.depth_measured : view.measured;
          double dt = *ear_front, r_low = std::numeric_limits<double>::infinity();
          for (double d = *ear_front; d >= std::max(a, *ear_front - kPreauricularMm * deg_per_mm);
               d -= 0.25 * view.dtheta_deg) {
            if (!depth_measured(theta_of(d), zc)) continue;
            if (const double r = view.r_mm(theta_of(d), zc); r < r_low) {
              r_low = r;
              dt = d;
            }
          }
          Landmark t =
              at("tragion" + suffix, theta_of(*ear_front), zc,
                 0.6 * measured_factor(view, theta_of(*ear_front), zc),
                 cat("the front edge of the ear at its centroid's height (", mm(area),
                     "^2 of ear); its depth read ",
                     std::isfinite(r_low) ? cat(mm((*ear_front - dt) / deg_per_mm),
                                                " in front of it, where the skin lies lowest")
                                          : "at the edge (no measured tissue in front of it)"));
          t.depth_theta_deg = theta_of(dt);
          tra.push_back(t);
        }
      }
    }
    // Zygion: the most lateral point between the subnasale's and the nasion's heights, 30 deg off
    // the midline up to 8 deg in front of the ear.
    {
      const double a = 30.0, b = ear_front ? *ear_front - 8.0 : 85.0;
      double best = -1;
      Eigen::Vector2d tz(0, 0);
      for (double z = z_lo; z <= z_hi; z += view.dz_mm)
        for (double dt = a; dt <= b; dt += view.dtheta_deg) {
          if (!view.measured(theta_of(dt), z)) continue;
          const double lat = view.r_mm(theta_of(dt), z) * std::sin(dt * kPi / 180.0);
          if (lat > best) {
            best = lat;
            tz = {dt, z};
          }
        }
      const double h = view.dtheta_deg;
      if (best < 0) {
        zyg.push_back(absent("zygion" + suffix, "no measured skin on the side of the face"));
      } else if (tz[0] + h > b || tz[0] - h < a) {
        zyg.push_back(absent("zygion" + suffix,
                             cat("the face is widest at the edge of the search (", tz[0],
                                 " deg off the midline): no zygomatic prominence")));
      } else {
        auto lat = [&](double dt, double z) {
          return view.r_mm(theta_of(dt), z) * std::sin(dt * kPi / 180.0);
        };
        for (int pass = 0; pass < 3; ++pass) {
          tz[0] += h * parabola_offset(lat(tz[0] - h, tz[1]), lat(tz[0], tz[1]),
                                       lat(tz[0] + h, tz[1]));
          const double hz = view.dz_mm;
          tz[1] += hz * parabola_offset(lat(tz[0], tz[1] - hz), lat(tz[0], tz[1]),
                                        lat(tz[0], tz[1] + hz));
        }
        const bool z_edge = tz[1] < z_lo + view.dz_mm || tz[1] > z_hi - view.dz_mm;
        zyg.push_back(at("zygion" + suffix, theta_of(tz[0]), tz[1],
                         (z_edge ? 0.4 : 0.8) * measured_factor(view, theta_of(tz[0]), tz[1]),
                         cat("the most lateral point of the face between the subnasale's and "
                             "the nasion's heights", z_edge ? " (at the edge of that band)" : "")));
      }
    }
    // Exocanthion: the lateral end of the eye's depression (its depth against the skin 12 mm to
    // either side falls to half) on the row of its deepest point, 8..55 deg off the midline
    // from 20 mm below to 8 mm above the nasion's height, and no lower than halfway from the
    // nasion down to the nose tip (lower, the flank of the nose is the deepest concavity beside
    // the midline; on a short nose, such as a small head's, it is within 20 mm of the nasion).
    {
      const double z_eye_lo = std::max({zp, z_hi - 20.0, 0.5 * (z_hi + zp)});
      const double half = 12.0 * deg_per_mm;
      auto depth = [&](double dt, double z) {
        return 0.5 * (view.r_mm(theta_of(dt - half), z) + view.r_mm(theta_of(dt + half), z)) -
               view.r_mm(theta_of(dt), z);
      };
      double best = 0;
      Eigen::Vector2d tz(0, 0);
      for (double z = z_eye_lo; z <= z_hi + 8.0; z += view.dz_mm)
        for (double dt = 8.0; dt <= 55.0; dt += view.dtheta_deg)
          if (view.measured(theta_of(dt), z) && depth(dt, z) > best) {
            best = depth(dt, z);
            tz = {dt, z};
          }
      if (best < 0.5) {
        exo.push_back(absent("exocanthion" + suffix, "no eye depression beside the nose"));
      } else {
        const double hz = view.dz_mm;
        tz[1] += hz * parabola_offset(depth(tz[0], tz[1] - hz), depth(tz[0], tz[1]),
                                      depth(tz[0], tz[1] + hz));
        const double dmax = depth(tz[0], tz[1]);
        const double step = 0.25 * view.dtheta_deg;
        std::optional<double> edge;
        for (double dt = tz[0]; dt <= 75.0; dt += step)
          if (depth(dt + step, tz[1]) <= 0.5 * dmax) {
            const double d0 = depth(dt, tz[1]), d1 = depth(dt + step, tz[1]);
            edge = dt + step * (d0 - 0.5 * dmax) / std::max(1e-12, d0 - d1);
            break;
          }
        if (!edge)
          exo.push_back(absent("exocanthion" + suffix, "the eye's depression has no lateral end"));
        else
          exo.push_back(at("exocanthion" + suffix, theta_of(*edge), tz[1],
                           0.3 * std::min(1.0, dmax / 2.0) *
                               measured_factor(view, theta_of(*edge), tz[1]),
                           cat("the lateral end (half depth) of the eye's depression, ",
                               mm(dmax), " deep")));
      }
    }
  }
  for (auto& l : zyg) put(l);
  for (auto& l : exo) put(l);
  for (auto& l : tra) put(l);
  // In the order of landmark_names().
  for (const auto& n : landmark_names())
    for (const auto& l : found)
      if (l.name == n) out.items.push_back(l);
  return out;
}

SkinRangeView skin_range_view(const PatientModel& model) {
  const auto& g = model.grid();
  SkinRangeView v;
  const PatientModel* m = &model;
  v.r_mm = [m](double t, double z) { return m->r_skin(t, z); };
  v.measured = [m](double t, double z) {
    if (!m->has_z(z)) return false;
    const auto& maps = m->maps();
    const auto& gg = maps.grid;
    const int j = static_cast<int>(std::lround((wrap_degrees(t) - gg.theta0_deg) / gg.dtheta_deg())) %
                  gg.n_theta;
    const int k = std::clamp(static_cast<int>(std::lround((z - gg.z0_mm) / gg.dz_mm)), 0,
                             gg.n_z - 1);
    const std::size_t c = gg.index((j + gg.n_theta) % gg.n_theta, k);
    // The skin was measured (no bone under it does not matter for the skin's shape).
    constexpr std::uint8_t kNotSkin = kNoSkin | kUndercut | kTruncated;
    return (m->flags_at(t, z) & kNotSkin) == 0 &&
           (maps.measured_skin.empty() || maps.measured_skin[c] != 0);
  };
  v.undercut = [m](double t, double z) {
    return m->has_z(z) && (m->flags_at(t, z) & kUndercut) != 0;
  };
  v.depth_measured = [m](double t, double z) {
    return m->has_z(z) && flags_valid(m->flags_at(t, z));
  };
  v.z_min_mm = g.z0_mm;
  v.z_max_mm = g.z_mm(g.n_z - 1);
  v.dtheta_deg = g.dtheta_deg();
  v.dz_mm = g.dz_mm;
  std::vector<float> r = model.maps().r_skin;
  if (!r.empty()) {
    std::nth_element(r.begin(), r.begin() + r.size() / 2, r.end());
    if (r[r.size() / 2] > 10.0) v.r_typical_mm = r[r.size() / 2];
  }
  return v;
}

std::string landmark_doubt(const Landmark& l) {
  if (!l.found) return {};
  const auto mm = [](double x) { return std::round(10 * x) / 10; };
  struct Norm {
    const char* name;
    double mean, sd;
  };
  static constexpr Norm kTTable[] = {{"glabella", 5.5, 1.0}, {"nasion", 6.0, 1.5}};
  for (const Norm& n : kTTable)
    if (l.name == n.name && std::abs(l.thickness_mm - n.mean) > 4 * n.sd)
      return cat(mm(l.thickness_mm), " mm of soft tissue: the adult ", n.name, " has ", n.mean,
                 " +- ", n.sd, " mm (T-Table); the depth measured here is not this landmark's");
  if (l.name == "pronasale" && l.thickness_mm > 15.0)
    return cat(mm(l.thickness_mm), " mm to the bone: the nose's tip stands on cartilage, not on a "
               "soft-tissue layer over bone; this depth is not one a flap is raised in");
  return tissue_doubt(l.thickness_mm, l.skin_mm);
}

std::string tissue_doubt(double thickness_mm, double skin_mm) {
  const auto mm = [](double x) { return std::round(10 * x) / 10; };
  if (thickness_mm > kMaxFacialTissueMm)
    return cat(mm(thickness_mm), " mm of soft tissue: deeper than any facial landmark's in the "
               "T-Table (the philtrum's 11.5 +- 2.5 mm is the deepest); the ray meets the nose's "
               "cartilage, the orbit or a cavity, not a soft-tissue layer over bone");
  if (std::isfinite(skin_mm) && skin_mm > kMaxSkinLayerMm)
    return cat("the CT's skin layer reads ", mm(skin_mm), " mm (dermis is 1-4 mm): the layers "
               "here are not the dermis, fat and deep tissue");
  return {};
}

const std::vector<LandmarkOrder>& landmark_orders() {
  static const std::vector<LandmarkOrder> orders = {
      {"glabella", "nasion", 5, 35},           {"nasion", "pronasale", 15, 60},
      {"nasion", "subnasale", 30, 70},         {"pronasale", "subnasale", 5, 35},
      {"subnasale", "pogonion", 25, 90},       {"nasion", "exocanthion_left", -10, 30},
      {"nasion", "exocanthion_right", -10, 30}};
  return orders;
}

int withdraw_contradicted(Landmarks& landmarks) {
  std::string broken;  // the first relation the found landmarks break
  for (const LandmarkOrder& o : landmark_orders()) {
    const Landmark* up = landmarks.find(o.upper);
    const Landmark* low = landmarks.find(o.lower);
    if (!up || !low || !up->found || !low->found) continue;
    const double above = up->z_mm - low->z_mm;
    if (above >= o.min_mm && above <= o.max_mm) continue;
    broken = cat("the ", o.upper, " lies ", std::round(above * 10) / 10, " mm above the ",
                 o.lower, " along the head's axis, where a face has ", o.min_mm, "..", o.max_mm,
                 " mm");
    break;
  }
  if (broken.empty()) return 0;
  // Every landmark is found from the midline profile and from each other: one out of place
  // leaves none to trust.
  int n = 0;
  for (Landmark& l : landmarks.items)
    if (l.found) {
      const std::string was = cat(" (found at theta ", std::round(l.theta_deg * 10) / 10,
                                  " deg, z ", std::round(l.z_mm * 10) / 10, " mm)");
      l = absent(l.name, cat("withdrawn: the landmarks contradict each other (", broken,
                             "; docs/landmarks.md), so some are not where their names say; is "
                             "the head tilted in the scanner?", was));
      ++n;
    }
  return n;
}

int withdraw_narrow_eyes(Landmarks& landmarks) {
  Landmark* left = nullptr;
  Landmark* right = nullptr;
  for (Landmark& l : landmarks.items) {
    if (l.name == "exocanthion_left") left = &l;
    if (l.name == "exocanthion_right") right = &l;
  }
  if (!left || !right || !left->found || !right->found) return 0;
  const double apart = (left->lps - right->lps).norm();
  if (!(apart < kMinBiocularWidthMm)) return 0;
  for (Landmark* l : {left, right}) {
    const std::string was = cat(" (found at theta ", std::round(l->theta_deg * 10) / 10, " deg, z ",
                                std::round(l->z_mm * 10) / 10, " mm)");
    *l = absent(l->name, cat("withdrawn: the two outer eye corners found lie ",
                             std::round(apart * 10) / 10, " mm apart, where a face's are more than ",
                             kMinBiocularWidthMm, " mm apart (an adult's 85-95 mm; docs/landmarks.md): "
                             "the depressions found are not the eyes' outer ends", was));
  }
  return 2;
}

Landmarks find_landmarks(const PatientModel& model) {
  Landmarks out = find_landmarks(skin_range_view(model));
  withdraw_contradicted(out);
  const auto& maps = model.maps();
  for (auto& l : out.items) {
    if (!l.found) continue;
    l.lps = model.skin_point(l.theta_deg, l.z_mm);
    const double td = std::isnan(l.depth_theta_deg) ? l.theta_deg : l.depth_theta_deg;
    l.thickness_mm = model.thickness_normal(td, l.z_mm);
    l.measured = flags_valid(model.flags_at(td, l.z_mm));
    if (maps.has_layers() && !maps.thickness_skin_normal.empty()) {
      l.skin_mm = model.sample(maps.thickness_skin_normal, td, l.z_mm);
      l.fat_mm = model.sample(maps.thickness_fat_normal, td, l.z_mm);
      l.deep_mm = model.sample(maps.thickness_deep_normal, td, l.z_mm);
    }
    l.doubt = landmark_doubt(l);
  }
  withdraw_narrow_eyes(out);  // on their LPS points
  return out;
}

std::string landmarks_to_json(const Landmarks& landmarks) {
  json items = json::object();
  auto r3 = [](double x) { return std::round(x * 1000.0) / 1000.0; };
  for (const auto& l : landmarks.items) {
    json o = {{"found", l.found}, {"note", l.note}};
    if (l.found) {
      o["theta_deg"] = r3(l.theta_deg);
      o["z_mm"] = r3(l.z_mm);
      o["lps"] = {r3(l.lps[0]), r3(l.lps[1]), r3(l.lps[2])};
      o["confidence"] = r3(l.confidence);
      if (std::isfinite(l.depth_theta_deg)) o["depth_theta_deg"] = r3(l.depth_theta_deg);
      o["thickness_mm"] = r3(l.thickness_mm);
      o["measured"] = l.measured;
      if (std::isfinite(l.skin_mm))
        o["layers_mm"] = {{"skin", r3(l.skin_mm)}, {"fat", r3(l.fat_mm)}, {"deep", r3(l.deep_mm)}};
      if (!l.doubt.empty()) o["doubt"] = l.doubt;
    }
    items[l.name] = o;
  }
  return json{{"definitions", "docs/landmarks.md (soft-tissue landmarks after Farkas)"},
              {"midline_theta_deg", r3(landmarks.midline_theta_deg)},
              {"items", items}}
      .dump(-1, ' ', false, json::error_handler_t::replace);
}

Landmarks landmarks_from_json(const std::string& text, const std::string& source) {
  Landmarks out;
  json j;
  try {
    j = parse_json<json>(text, cat(source, ": landmarks"));  // nesting bounded as every reader's
  } catch (const InvalidInput& e) {
    throw InvalidInput(cat(e.what(), "; recompute them with `caps model landmarks MODEL_DIR`"));
  }
  try {
    out.midline_theta_deg = j.value("midline_theta_deg", 0.0);
    const json& items = j.at("items");
    if (!items.is_object()) throw InvalidInput(cat(source, ": landmarks: \"items\" must be an object"));
    for (const auto& n : landmark_names()) {
      if (!items.contains(n)) {
        out.items.push_back(absent(n, "not in the model's landmarks"));
        continue;
      }
      const json& o = items.at(n);
      Landmark l;
      l.name = n;
      l.found = o.at("found").get<bool>();
      l.note = o.value("note", std::string());
      if (l.found) {
        l.theta_deg = o.at("theta_deg").get<double>();
        l.z_mm = o.at("z_mm").get<double>();
        const auto& p = o.at("lps");
        l.lps = {p.at(0).get<double>(), p.at(1).get<double>(), p.at(2).get<double>()};
        l.confidence = o.at("confidence").get<double>();
        l.thickness_mm = o.at("thickness_mm").get<double>();
        l.depth_theta_deg = o.value("depth_theta_deg", std::numeric_limits<double>::quiet_NaN());
        l.measured = o.value("measured", false);
        if (o.contains("layers_mm")) {
          l.skin_mm = o["layers_mm"].at("skin").get<double>();
          l.fat_mm = o["layers_mm"].at("fat").get<double>();
          l.deep_mm = o["layers_mm"].at("deep").get<double>();
        }
        l.doubt = landmark_doubt(l);  // models made before the check get it too
      }
      out.items.push_back(l);
    }
  } catch (const json::exception& e) {
    throw InvalidInput(cat(source, ": landmarks: ", e.what(),
                           "; recompute them with `caps model landmarks MODEL_DIR`"));
  }
  withdraw_contradicted(out);  // models made before the checks get them too
  withdraw_narrow_eyes(out);
  return out;
}

std::string landmarks_table(const Landmarks& landmarks) {
  std::ostringstream s;
  s << std::fixed << std::setprecision(1);
  for (const auto& l : landmarks.items) {
    s << std::left << std::setw(18) << l.name;
    if (!l.found) {
      s << "absent: " << l.note << "\n";
      continue;
    }
    s << "theta " << std::setw(6) << l.theta_deg << " z " << std::setw(6) << l.z_mm << " LPS ("
      << l.lps[0] << ", " << l.lps[1] << ", " << l.lps[2] << ")  confidence "
      << std::setprecision(2) << l.confidence << std::setprecision(1) << "  thickness "
      << l.thickness_mm << " mm";
    if (std::isfinite(l.skin_mm))
      s << " (skin " << l.skin_mm << ", fat " << l.fat_mm << ", deep " << l.deep_mm << ")";
    if (!l.measured) s << "  [filled, not measured]";
    if (!l.doubt.empty()) s << "  [implausible: " << l.doubt << "]";
    s << "\n";
  }
  return s.str();
}

}  // namespace caps
