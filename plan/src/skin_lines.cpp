#include "caps/plan/skin_lines.hpp"

#include <nlohmann/json.hpp>

#include <cmath>

#include "caps/core/data_dir.hpp"
#include "caps/core/error.hpp"
#include "caps/core/json_file.hpp"

namespace caps::plan {
namespace {

using nlohmann::json;

constexpr double kPi = 3.14159265358979323846;

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

double angle_between_lines_deg(double a_deg, double b_deg) {
  const double d = wrap_line(a_deg - b_deg);
  return std::min(d, 180.0 - d);
}

}  // namespace caps::plan
