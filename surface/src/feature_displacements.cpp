#include "caps/surface/feature_lines.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <iomanip>
#include <map>
#include <memory>
#include <sstream>

#include "caps/core/error.hpp"
#include "caps/core/point_bins.hpp"

namespace caps {
namespace {

using nlohmann::json;

}  // namespace

// "lower_eyelid_margin_left" -> "the left lower eyelid margin"; "oral_commissure_right" -> "the
// right oral commissure"; "upper_lip_vermilion" -> "the upper lip's vermilion border".
std::string feature_line_words(const std::string& name) {
  std::string base = name, side;
  for (const char* sfx : {"_left", "_right"}) {
    const std::string s(sfx);
    if (base.size() > s.size() && base.compare(base.size() - s.size(), s.size(), s) == 0) {
      side = s.substr(1) + " ";
      base = base.substr(0, base.size() - s.size());
    }
  }
  if (base == "upper_lip_vermilion") return "the upper lip's vermilion border";
  if (base == "lower_lip_vermilion") return "the lower lip's vermilion border";
  if (base == "eyebrow") base = "brow";
  std::replace(base.begin(), base.end(), '_', ' ');
  return "the " + side + base;
}

AnatomicalFrame anatomical_frame(const PatientModel& model) {
  const auto& ax = model.axis();
  AnatomicalFrame fr;
  fr.up = ax.direction.normalized();
  fr.front = ax.front.normalized();
  fr.left = ax.left().normalized();
  return fr;
}

DisplacementAt displacement_from_samples(const Eigen::MatrixX3d& points,
                                         const Eigen::MatrixX3d& displacements, double radius_mm) {
  if (points.rows() != displacements.rows())
    throw InvalidInput(cat("displacement_from_samples: ", points.rows(), " points but ",
                           displacements.rows(), " displacements"));
  if (!(radius_mm > 0) || !std::isfinite(radius_mm))
    throw InvalidInput(
        cat("displacement_from_samples: radius ", radius_mm, " mm must be positive"));
  auto s = std::make_shared<const PointBins>(points, radius_mm);
  return [s, U = displacements](const Eigen::Vector3d& x) -> std::optional<Eigen::Vector3d> {
    if (!x.allFinite()) return std::nullopt;
    const double r2 = s->size() * s->size();
    Eigen::Vector3d sum(0, 0, 0);
    double wsum = 0;
    Eigen::Index at = -1;  // a sample the point is (its own value)
    s->near(x, [&](Eigen::Index n, double d2) {
      if (at >= 0 || d2 > r2) return;
      if (d2 < 1e-18) {
        at = n;
        return;
      }
      sum += U.row(n).transpose() / d2;
      wsum += 1.0 / d2;
    });
    if (at >= 0) return Eigen::Vector3d(U.row(at).transpose());
    if (wsum == 0) return std::nullopt;
    return Eigen::Vector3d(sum / wsum);
  };
}

DisplacementAt blend_across_seam(DisplacementAt far, const Eigen::MatrixX3d& points,
                                 const Eigen::MatrixX3d& values, double width_mm) {
  if (points.rows() != values.rows())
    throw InvalidInput(cat("blend_across_seam: ", points.rows(), " points but ", values.rows(),
                           " values"));
  if (!(width_mm > 0) || !std::isfinite(width_mm))
    throw InvalidInput(cat("blend_across_seam: width ", width_mm, " mm must be positive"));
  if (!far) throw InvalidInput("blend_across_seam: no field to blend into");
  // The samples whose value is known too.
  auto s = std::make_shared<const PointBins>(
      points, width_mm, [&values](Eigen::Index i) { return values.row(i).allFinite(); });
  return [s, U = values, far = std::move(far)](
             const Eigen::Vector3d& x) -> std::optional<Eigen::Vector3d> {
    const std::optional<Eigen::Vector3d> f = far(x);
    if (!x.allFinite()) return f;
    double best = s->size() * s->size();
    Eigen::Index nearest = -1;
    s->near(x, [&](Eigen::Index n, double d2) {
      if (d2 < best) best = d2, nearest = n;
    });
    if (nearest < 0) return f;
    const double t = std::sqrt(best) / s->size();  // 0 on the seam, 1 a width away
    return Eigen::Vector3d((1 - t) * U.row(nearest).transpose() +
                           t * f.value_or(Eigen::Vector3d::Zero()));
  };
}

const std::vector<ClinicalThreshold>& clinical_thresholds() {
  // docs/landmarks.md, "Feature lines and what a closure does to them", has the table with its
  // sources; the sources were read, the numbers are theirs.
  static const std::vector<ClinicalThreshold> t = {
      {"lower_eyelid_margin", "down", 1.0,
       "scleral show, ectropion: the margin rests at or up to 1 mm above the inferior corneal "
       "limbus",
       "Dutton, Surgical management of eyelid retraction in thyroid eye disease (Taylor & Francis, "
       "doi:10.3109/9780203908983-43); EyeWiki, Lower Eyelid Retraction (AAO 2024)"},
      {"upper_eyelid_margin", "down", 2.0,
       "ptosis: the margin rests about 2 mm above the pupil's margin",
       "GPnotebook, Ptosis (reviewed 2018); Dutton (upper margin 2-3 mm below the superior "
       "limbus)"},
      {"upper_eyelid_margin", "up", 2.0,
       "upper scleral show, lagophthalmos: the margin rests 2-3 mm below the superior limbus",
       "Dutton, Surgical management of eyelid retraction in thyroid eye disease"},
      {"eyebrow", "vertical", 2.0,
       "a brow height change beyond the natural left-right brow asymmetry (1.8 mm on average "
       "at the central brow)",
       "Eyelid and brow asymmetry in patients evaluated for upper lid blepharoplasty, J "
       "Otolaryngol Head Neck Surg 2014 (doi:10.1186/s40463-014-0036-4)"},
      {"oral_commissure", "vertical", 2.5,
       "a canted lip line: 2.5 mm of vertical lip asymmetry made a smile less attractive, 2 mm "
       "did not",
       "Batwa, McDonald, Cash 2013, Cleft Palate Craniofac J"},
      {"oral_commissure", "any", 3.0, "a visible facial asymmetry (noticed above 3 mm)",
       "Analysis of Facial Asymmetry, Arch Craniofac Surg (PMC5556787)"},
      {"upper_lip_vermilion", "vertical", 2.5, "a canted or notched lip line",
       "Batwa, McDonald, Cash 2013, Cleft Palate Craniofac J"},
      {"lower_lip_vermilion", "vertical", 2.5, "a canted lip line",
       "Batwa, McDonald, Cash 2013, Cleft Palate Craniofac J"},
      {"alar_rim", "up", 1.0,
       "alar retraction: the rim lies 1-2 mm above the nostril's long axis, more than 2 mm is a "
       "retracted ala",
       "Gunter, Rohrich, Friedman 1996, Plast Reconstr Surg 97:643"},
      {"alar_rim", "down", 1.0, "a hanging ala (the rim less than 1 mm above the nostril's axis)",
       "Gunter, Rohrich, Friedman 1996, Plast Reconstr Surg 97:643"},
  };
  return t;
}

std::vector<FeatureDisplacement> feature_displacements(const FeatureLines& lines,
                                                       const DisplacementAt& displacement_at,
                                                       const AnatomicalFrame& frame) {
  if (!displacement_at) throw InvalidInput("feature_displacements: no displacement field");
  std::vector<FeatureDisplacement> out;
  for (const auto& l : lines.items) {
    if (l.name == "hairline" && !l.found) continue;
    FeatureDisplacement d;
    d.name = l.name;
    d.found = l.found;
    d.n_points = static_cast<int>(l.lps.size());
    const std::string who = feature_line_words(l.name);
    if (!l.found || l.lps.empty()) {
      d.sentence = who + " was not found on the model (" + l.note + ")";
      out.push_back(d);
      continue;
    }
    // The lateral direction: away from the midline for a paired line, the patient's left for a
    // midline one.
    const double lat_sign = l.side == "right" ? -1.0 : 1.0;
    const bool paired = l.side == "left" || l.side == "right";
    // Arc-length weights (half of each adjacent segment; a single point weighs 1).
    const std::size_t np = l.lps.size();
    std::vector<double> w(np, np == 1 ? 1.0 : 0.0), s(np, 0.0);
    for (std::size_t i = 1; i < np; ++i) {
      const double seg = (l.lps[i] - l.lps[i - 1]).norm();
      w[i - 1] += 0.5 * seg;
      w[i] += 0.5 * seg;
      s[i] = s[i - 1] + seg;
    }
    double wsum = 0, lsum = 0, max_down = 0, max_up = 0, min_len = 1e300;
    std::size_t imax = 0;
    for (std::size_t i = 0; i < np; ++i) {
      const auto u = displacement_at(l.lps[i]);
      if (!u || !u->allFinite()) continue;
      ++d.n_with_value;
      const double len = u->norm();
      min_len = std::min(min_len, len);
      wsum += w[i];
      lsum += w[i] * len;
      const double up = u->dot(frame.up);
      max_down = std::max(max_down, -up);
      max_up = std::max(max_up, up);
      if (!d.has_value || len > d.max_mm) {
        d.max_mm = len;
        d.max_lps = *u;
        imax = i;
      }
      d.has_value = true;
    }
    if (!d.has_value) {
      d.sentence = who + " has no displacement: the closure's model does not reach it";
      out.push_back(d);
      continue;
    }
    d.mean_mm = wsum > 0 ? lsum / wsum : d.max_mm;
    d.max_at_lps = l.lps[imax];
    d.up_mm = d.max_lps.dot(frame.up);
    d.lateral_mm = lat_sign * d.max_lps.dot(frame.left);
    d.forward_mm = d.max_lps.dot(frame.front);
    // Words: the dominant component, and the second where it is at least half of it.
    struct Part {
      double v;
      std::string pos, neg;
    };
    std::vector<Part> parts = {{d.up_mm, "up", "down"},
                               {d.lateral_mm, paired ? "laterally" : "to the patient's left",
                                paired ? "medially" : "to the patient's right"},
                               {d.forward_mm, "forward", "back"}};
    std::sort(parts.begin(), parts.end(),
              [](const Part& a, const Part& b) { return std::abs(a.v) > std::abs(b.v); });
    auto word = [](const Part& p) { return p.v >= 0 ? p.pos : p.neg; };
    d.direction = word(parts[0]);
    if (std::abs(parts[1].v) >= 0.5 * std::abs(parts[0].v) && std::abs(parts[1].v) > 0)
      d.direction += " and " + word(parts[1]);
    // Where: the third of the line (by arc length) the largest displacement is in.
    const bool whole = d.n_with_value == d.n_points && min_len >= 0.9 * d.max_mm;
    if (l.along == "point" || np == 1) {
      d.where = "the mouth's corner";
    } else if (whole) {
      d.where = "whole length";  // within 10 % of the largest everywhere: no third stands out
    } else {
      const double frac = s.back() > 0 ? s[imax] / s.back() : 0.5;
      std::string lo = "medial", hi = "lateral";
      if (l.along == "right-left") lo = "right", hi = "left";
      if (l.along == "inferior-superior") lo = "inferior", hi = "superior";
      d.where = (frac < 1.0 / 3 ? lo : frac > 2.0 / 3 ? hi : std::string("middle")) + " third";
    }
    std::ostringstream num;
    num << std::fixed << std::setprecision(1) << d.max_mm;
    d.sentence = who + " is pulled " + num.str() + " mm " + d.direction +
                 (whole ? " along its whole length" : " at its " + d.where);
    if (l.along == "point") d.sentence = who + " is pulled " + num.str() + " mm " + d.direction;
    // Warnings: every threshold of this feature that is passed.
    for (const auto& t : clinical_thresholds()) {
      if (l.name.rfind(t.feature, 0) != 0) continue;
      double v = 0;
      std::string how;
      if (t.direction == "down")
        v = max_down, how = "down";
      else if (t.direction == "up")
        v = max_up, how = "up";
      else if (t.direction == "vertical")
        v = std::max(max_down, max_up), how = max_down >= max_up ? "down" : "up";
      else
        v = d.max_mm, how = d.direction;
      if (v < t.threshold_mm) continue;
      std::ostringstream w1;
      w1 << std::fixed << std::setprecision(1) << who << " moves " << v << " mm " << how << " (at "
         << t.threshold_mm << " mm: " << t.risk << "; " << t.source << ")";
      if (!d.warning.empty()) d.warning += "; ";
      d.warning += w1.str();
    }
    out.push_back(d);
  }
  return out;
}

std::string feature_displacements_summary(const std::vector<FeatureDisplacement>& ds) {
  const FeatureDisplacement* most = nullptr;
  int warned = 0;
  for (const auto& d : ds) {
    if (!d.has_value) continue;
    if (!d.warning.empty()) ++warned;
    if (!most || d.max_mm > most->max_mm) most = &d;
  }
  if (!most) return {};
  std::string s = most->sentence;
  if (warned > 0) s += cat("; ", warned, warned == 1 ? " feature warning" : " feature warnings");
  return s;
}

std::string feature_displacements_to_json(const std::vector<FeatureDisplacement>& ds) {
  auto r3 = [](double x) { return std::round(x * 1000.0) / 1000.0; };
  json a = json::array();
  for (const auto& d : ds) {
    json o = {
        {"name", d.name}, {"found", d.found}, {"has_value", d.has_value}, {"sentence", d.sentence}};
    if (d.has_value) {
      o["max_mm"] = r3(d.max_mm);
      o["mean_mm"] = r3(d.mean_mm);
      o["direction_lps"] = {r3(d.max_lps[0]), r3(d.max_lps[1]), r3(d.max_lps[2])};
      o["at_lps"] = {r3(d.max_at_lps[0]), r3(d.max_at_lps[1]), r3(d.max_at_lps[2])};
      o["components_mm"] = {
          {"up", r3(d.up_mm)}, {"lateral", r3(d.lateral_mm)}, {"forward", r3(d.forward_mm)}};
      o["direction"] = d.direction;
      o["where"] = d.where;
      o["points_with_value"] = d.n_with_value;
    } else {
      o["max_mm"] = nullptr;
      o["mean_mm"] = nullptr;
    }
    o["points"] = d.n_points;
    if (!d.warning.empty()) o["warning"] = d.warning;
    a.push_back(o);
  }
  return a.dump(-1, ' ', false, json::error_handler_t::replace);
}

}  // namespace caps
