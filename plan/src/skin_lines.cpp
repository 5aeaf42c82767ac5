#include "caps/plan/skin_lines.hpp"

#include <nlohmann/json.hpp>

#include <Eigen/Core>

#include <algorithm>
#include <cmath>
#include <optional>

#include "caps/core/data_dir.hpp"
#include "caps/core/error.hpp"
#include "caps/core/json_file.hpp"
#include "caps/volume/cylindrical_map.hpp"

namespace caps::plan {
namespace {

using nlohmann::json;

constexpr double kPi = 3.14159265358979323846;
// The face trace_skin_lines() draws on, in nose heights (nasion to subnasale) from the nasion.
constexpr double kFaceBelow = 3.0;
constexpr double kFaceAbove = 1.6;

double wrap_line(double deg) {
  double d = std::fmod(deg, 180.0);
  if (d < 0) d += 180.0;
  return d >= 180.0 ? 0.0 : d;
}

// The orientation (deg, from +v towards +u) of the line along (du, dv).
double line_of(double du, double dv) { return wrap_line(std::atan2(du, dv) * 180.0 / kPi); }

std::pair<double, double> pair_of(const json& z, const char* key, const std::string& where) {
  if (!z.contains(key) || !z[key].is_array() || z[key].size() != 2 || !z[key][0].is_number() ||
      !z[key][1].is_number())
    throw InvalidInput(cat(where, ": \"", key, "\" must be two numbers"));
  return {z[key][0].get<double>(), z[key][1].get<double>()};
}

}  // namespace

SkinLineMap read_skin_line_map(const std::string& path) {
  const json j = read_json_file<json>(path, "a map of skin lines (data/rstl/)", 1 << 20);
  SkinLineMap m;
  if (j.value("format", "") != "caps-skin-lines")
    throw InvalidInput(cat(path, ": not a map of skin lines (\"format\" is not caps-skin-lines)"));
  m.name = j.value("name", "");
  m.source = j.value("source", "");
  if (!j.contains("zones") || !j["zones"].is_array() || j["zones"].empty())
    throw InvalidInput(cat(path, ": \"zones\" must be a list of zones"));
  for (std::size_t i = 0; i < j["zones"].size(); ++i) {
    const json& z = j["zones"][i];
    const std::string where = cat(path, ": zone ", i + 1);
    if (!z.is_object()) throw InvalidInput(cat(where, " must be an object"));
    SkinLineZone s;
    s.name = z.value("name", "");
    s.words = z.value("words", s.name);
    s.says = z.value("says", "");
    if (z.contains("within")) {
      const json& w = z["within"];
      if (!w.is_array() || w.size() != 3 || !w[0].is_number() || !w[1].is_number() ||
          !w[2].is_number() || !(w[2].get<double>() > 0))
        throw InvalidInput(cat(where, ": \"within\" must be [u, v, radius > 0]"));
      s.round = true;
      s.cu = w[0].get<double>();
      s.cv = w[1].get<double>();
      s.radius = w[2].get<double>();
    } else {
      std::tie(s.u_min, s.u_max) = pair_of(z, "u", where);
      std::tie(s.v_min, s.v_max) = pair_of(z, "v", where);
      if (!(s.u_min < s.u_max) || !(s.v_min < s.v_max))
        throw InvalidInput(cat(where, ": \"u\" and \"v\" must each be [min, max] with min < max"));
    }
    if (!z.contains("lines") || !z["lines"].is_object())
      throw InvalidInput(cat(where, ": \"lines\" must say fixed_deg, radial_from or concentric_about"));
    const json& l = z["lines"];
    if (l.contains("fixed_deg") && l["fixed_deg"].is_number()) {
      s.kind = SkinLineZone::Kind::Fixed;
      s.fixed_deg = wrap_line(l["fixed_deg"].get<double>());
    } else if (l.contains("radial_from")) {
      s.kind = SkinLineZone::Kind::Radial;
      std::tie(s.pu, s.pv) = pair_of(l, "radial_from", where);
    } else if (l.contains("concentric_about")) {
      s.kind = SkinLineZone::Kind::Concentric;
      std::tie(s.pu, s.pv) = pair_of(l, "concentric_about", where);
    } else {
      throw InvalidInput(cat(where, ": \"lines\" must say fixed_deg, radial_from or concentric_about"));
    }
    m.zones.push_back(std::move(s));
  }
  return m;
}

const SkinLineMap& borges_map() {
  static const SkinLineMap m = read_skin_line_map(data_file("rstl/borges-1984.json").string());
  return m;
}

SkinLineDirection skin_line_direction(const SkinLineMap& map, const PatientModel& model,
                                      const Landmarks& landmarks, double theta_deg, double z_mm) {
  SkinLineDirection out;
  const Landmark* n = landmarks.find("nasion");
  const Landmark* sn = landmarks.find("subnasale");
  if (!n || !n->found || !sn || !sn->found) {
    out.note = "the skin lines are laid on the face by the nasion and the subnasale, and the "
               "model has not found both";
    return out;
  }
  const double h = n->z_mm - sn->z_mm;
  if (!(h > 20 && h < 90)) {
    out.note = cat("the nasion lies ", h, " mm above the subnasale, not the 20-90 mm of a face: "
                   "the skin lines are not laid on it");
    return out;
  }
  // The distance from the midsagittal plane (the plane of the axis and the midline): the arc
  // on the skin would run over the nose at its height.
  const double mid = landmarks.midline_theta_deg;
  const double d_theta = std::remainder(theta_deg - mid, 360.0);
  if (std::abs(d_theta) > 90) {
    out.note = cat("the point lies ", std::round(std::abs(d_theta)), " deg from the face's "
                   "midline, behind the ear: the map covers the face");
    return out;
  }
  const double lateral = model.r_skin(theta_deg, z_mm) * std::abs(std::sin(d_theta * kPi / 180.0));
  if (!std::isfinite(lateral)) {
    out.note = "the model has no skin measured there";
    return out;
  }
  out.at = {lateral / h, (z_mm - n->z_mm) / h, h, d_theta >= 0};
  const double u = out.at.u, v = out.at.v;
  for (const SkinLineZone& z : map.zones) {
    const bool inside = z.round ? std::hypot(u - z.cu, v - z.cv) <= z.radius
                                : u >= z.u_min && u <= z.u_max && v >= z.v_min && v <= z.v_max;
    if (!inside) continue;
    double left = z.fixed_deg;
    if (z.kind == SkinLineZone::Kind::Radial) left = line_of(u - z.pu, v - z.pv);
    if (z.kind == SkinLineZone::Kind::Concentric) left = line_of(v - z.pv, -(u - z.pu));
    out.found = true;
    out.orientation_deg = out.at.left ? left : wrap_line(180.0 - left);
    out.zone = z.name;
    out.words = z.words;
    out.says = z.says;
    return out;
  }
  out.note = cat("the point lies outside the map's face (", std::round(u * h), " mm from the "
                 "midline, ", std::round(v * h), " mm above the nasion)");
  return out;
}

std::vector<SkinLinePath> trace_skin_lines(const SkinLineMap& map, const PatientModel& model,
                                           const Landmarks& landmarks, double spacing_mm,
                                           double half_length_mm, std::string* note) {
  if (!(spacing_mm >= 4 && spacing_mm <= 50))
    throw InvalidParameter(cat("the skin lines' spacing ", spacing_mm, " mm must be in [4, 50]"));
  if (!(half_length_mm >= 1 && half_length_mm <= 30))
    throw InvalidParameter(
        cat("the skin lines' half length ", half_length_mm, " mm must be in [1, 30]"));
  std::vector<SkinLinePath> out;
  const Landmark* n = landmarks.find("nasion");
  const Landmark* sn = landmarks.find("subnasale");
  if (!n || !n->found || !sn || !sn->found || !(n->z_mm - sn->z_mm > 20 && n->z_mm - sn->z_mm < 90)) {
    // skin_line_direction() says why, in its words.
    const SkinLineDirection d =
        skin_line_direction(map, model, landmarks, landmarks.midline_theta_deg, 0.0);
    if (note) *note = d.note;
    return out;
  }
  const double h = n->z_mm - sn->z_mm;
  // The face: the map's zones, from kFaceBelow h below the nasion (below the chin) to kFaceAbove
  // h above it (about the hairline; the map's forehead runs on over the scalp), within the
  // model's rows.
  double v_lo = 0, v_hi = 0;
  for (const SkinLineZone& z : map.zones) {
    v_lo = std::min(v_lo, z.round ? z.cv - z.radius : z.v_min);
    v_hi = std::max(v_hi, z.round ? z.cv + z.radius : z.v_max);
  }
  const CylinderGrid& g = model.grid();
  const double z_lo = std::max(n->z_mm + std::max(v_lo, -kFaceBelow) * h, g.z_mm(0));
  const double z_hi = std::min(n->z_mm + std::min(v_hi, kFaceAbove) * h, g.z_mm(g.n_z - 1));
  // Skin measured there (not above the vertex or below the neck's cut, not where the scan
  // ends), in `zone` if one is given: a line ends at its zone's border, where the map's
  // direction jumps.
  const auto on_skin = [&](double theta, double z, const std::string* zone) {
    if (!(z >= z_lo && z <= z_hi) || (model.flags_at(theta, z) & (kNoSkin | kTruncated)) != 0)
      return false;
    const SkinLineDirection d = skin_line_direction(map, model, landmarks, theta, z);
    return d.found && (!zone || d.zone == *zone);
  };
  const double mid = landmarks.midline_theta_deg;
  const double to_deg = 180.0 / kPi;
  // The step along the skin, dtheta per mm across at (theta, z), from the plan's frame.
  const auto across_deg_per_mm = [&](double theta, double z) {
    const double r = model.r_skin(theta, z);
    return std::isfinite(r) && r > 1 ? to_deg / r : NAN;
  };
  // The unit direction (mm towards the patient's left, mm up) of the lines of `zone` at
  // (theta, z), turned to agree with `along` (lines have no sense), or nothing.
  const auto direction = [&](double theta, double z, const Eigen::Vector2d& along,
                             const std::string& zone) -> std::optional<Eigen::Vector2d> {
    const SkinLineDirection d = skin_line_direction(map, model, landmarks, theta, z);
    const double k = across_deg_per_mm(theta, z);
    if (!d.found || d.zone != zone || !std::isfinite(k)) return std::nullopt;
    const double o = d.orientation_deg / to_deg;
    Eigen::Vector2d step(std::sin(o), std::cos(o));  // mm towards the patient's left, mm up
    if (step.dot(along) < 0) step = -step;
    return step;
  };
  const auto advance = [&](double& theta, double& z, const Eigen::Vector2d& s) {
    theta += across_deg_per_mm(theta, z) * s[0];
    z += s[1];
  };
  const int n_steps = static_cast<int>(std::floor(half_length_mm));
  for (double z0 = z_lo; z0 <= z_hi + 1e-9; z0 += spacing_mm) {
    const double k0 = across_deg_per_mm(mid, z0);
    if (!std::isfinite(k0)) continue;
    const double d_theta = spacing_mm * k0;
    const int n_side = static_cast<int>(std::floor(90.0 / d_theta));
    for (int j = -n_side; j <= n_side; ++j) {
      const double t0 = mid + j * d_theta;
      if (!on_skin(t0, z0, nullptr)) continue;
      const SkinLineDirection seed = skin_line_direction(map, model, landmarks, t0, z0);
      // Traced either way from the seed: midpoint (RK2) steps of 1 mm.
      std::vector<std::pair<double, double>> half[2];
      for (int sense = 0; sense < 2; ++sense) {
        double theta = t0, z = z0;
        const double o = seed.orientation_deg / to_deg;
        Eigen::Vector2d along = (sense ? -1.0 : 1.0) * Eigen::Vector2d(std::sin(o), std::cos(o));
        for (int i = 0; i < n_steps; ++i) {
          const std::optional<Eigen::Vector2d> d1 = direction(theta, z, along, seed.zone);
          if (!d1) break;
          double tm = theta, zm = z;
          advance(tm, zm, 0.5 * *d1);
          const std::optional<Eigen::Vector2d> d2 = direction(tm, zm, *d1, seed.zone);
          if (!d2) break;
          double tn = theta, zn = z;
          advance(tn, zn, *d2);
          if (!std::isfinite(tn) || !on_skin(tn, zn, &seed.zone)) break;
          theta = tn;
          z = zn;
          along = *d2;
          half[sense].emplace_back(theta, z);
        }
      }
      SkinLinePath path;
      path.zone = seed.zone;
      for (auto it = half[1].rbegin(); it != half[1].rend(); ++it) {
        path.theta_deg.push_back(it->first);
        path.z_mm.push_back(it->second);
      }
      path.theta_deg.push_back(t0);
      path.z_mm.push_back(z0);
      for (const auto& [theta, z] : half[0]) {
        path.theta_deg.push_back(theta);
        path.z_mm.push_back(z);
      }
      if (path.theta_deg.size() >= 2) out.push_back(std::move(path));
    }
  }
  if (out.empty() && note) *note = "no point of the map's face lies on the model's skin";
  return out;
}

double angle_between_lines_deg(double a_deg, double b_deg) {
  const double d = wrap_line(a_deg - b_deg);
  return std::min(d, 180.0 - d);
}

}  // namespace caps::plan
