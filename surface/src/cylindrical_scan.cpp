#include "caps/surface/cylindrical_scan.hpp"

#include <cmath>
#include <fstream>
#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>

#include "caps/core/atomic_output.hpp"
#include "caps/core/error.hpp"
#include "caps/core/json_file.hpp"
#include "caps/core/units.hpp"
#include "caps/image/image_io.hpp"

namespace fs = std::filesystem;

namespace caps {
namespace {

void check_spec(const CylindricalScanSpec& s, const std::string& where) {
  if (!(s.r_scale_mm > 0 && s.r_scale_mm <= 100))
    throw InvalidInput(cat(where, ": r_scale_mm ", s.r_scale_mm, " must be in (0, 100] mm per "
                           "range unit (--r-scale)"));
  if (!(s.z_scale_mm > 0 && s.z_scale_mm <= 100))
    throw InvalidInput(cat(where, ": z_scale_mm ", s.z_scale_mm, " must be in (0, 100] mm per "
                           "line (--z-scale)"));
  if (!(s.theta_span_deg > 0 && s.theta_span_deg <= 360))
    throw InvalidInput(cat(where, ": theta_span_deg ", s.theta_span_deg, " must be in (0, 360]"));
  if (!std::isfinite(s.r_offset_mm))
    throw InvalidInput(cat(where, ": r_offset_mm must be a number"));
}

}  // namespace

CylindricalScanSpec read_cylindrical_sidecar(const fs::path& json_path) {
  const auto j = read_json_file<nlohmann::json>(
      json_path, "give the range image's sidecar .json (caps model export-range writes one)");
  CylindricalScanSpec s;
  const fs::path dir = json_path.parent_path();
  try {
    if (!j.contains("range"))
      throw InvalidInput(cat(json_path.string(), ": the field \"range\" (the range image) is missing"));
    s.range = dir / j.at("range").get<std::string>();
    if (j.contains("color")) s.color = dir / j.at("color").get<std::string>();
    s.r_scale_mm = j.value("r_scale_mm", 0.0);
    s.r_offset_mm = j.value("r_offset_mm", 0.0);
    s.z_scale_mm = j.value("z_scale_mm", 0.0);
    s.theta_span_deg = j.value("theta_span_deg", 360.0);
    const std::string axis = j.value("theta_axis", std::string("columns"));
    if (axis != "columns" && axis != "rows")
      throw InvalidInput(cat(json_path.string(), ": theta_axis \"", axis, "\" must be \"columns\" "
                             "or \"rows\""));
    s.theta_along_rows = axis == "rows";
    s.theta_reverse = j.value("theta_reverse", false);
    s.top_first = j.value("top_first", true);
    if (j.contains("void_value")) {
      // A whole number a 16-bit range image can hold; any other JSON number would be cast to
      // unsigned out of range.
      const auto& v = j.at("void_value");
      if (!v.is_number_integer() || v.get<long long>() < 0 || v.get<long long>() > 65535)
        throw InvalidInput(cat(json_path.string(), ": void_value ", v.dump(), " must be a whole "
                               "number from 0 to 65535 (the range value of a missing sample)"));
      s.void_value = static_cast<unsigned>(v.get<long long>());
    }
    s.top_z_mm = j.value("top_z_mm", 0.0);
  } catch (const nlohmann::json::exception& e) {
    throw InvalidInput(cat(json_path.string(), ": a field has the wrong type (", e.what(), ")"));
  }
  check_spec(s, json_path.string());
  return s;
}

ScanMesh cylindrical_scan_mesh(const CylindricalScanSpec& s) {
  check_spec(s, s.range.string());
  const GreyImage range = read_grey_png(s.range, "range image");
  ScanMesh out;
  out.source = s.range.string();
  out.format = "cylindrical range image";
  out.mm_per_unit = 1.0;
  if (!s.color.empty()) {
    out.texture = read_image(s.color);
    out.texture_source = s.color.string();
    if (out.texture.width != range.width || out.texture.height != range.height)
      throw InvalidInput(cat(s.color.string(), ": the colour image is ", out.texture.width, "x",
                             out.texture.height, " but the range image is ", range.width, "x",
                             range.height, "; they must share one layout"));
  }
  // (t, z) grid indices of the image: t along theta, h along height, h = 0 at the top.
  const int n_t = s.theta_along_rows ? range.height : range.width;
  const int n_h = s.theta_along_rows ? range.width : range.height;
  const bool closed = std::abs(s.theta_span_deg - 360.0) < 1e-9;
  const double dtheta = deg_to_rad(s.theta_span_deg) / (closed ? n_t : std::max(1, n_t - 1));
  auto pixel = [&](int t, int h) {  // (x, y) in the image
    const int tt = s.theta_reverse ? n_t - 1 - t : t;
    const int hh = s.top_first ? h : n_h - 1 - h;
    return s.theta_along_rows ? std::pair<int, int>{hh, tt} : std::pair<int, int>{tt, hh};
  };
  std::vector<int> vertex(std::size_t(n_t) * n_h, -1);
  std::vector<Eigen::Vector3d> V;
  std::vector<Eigen::Vector2d> UV;
  for (int h = 0; h < n_h; ++h)
    for (int t = 0; t < n_t; ++t) {
      const auto [x, y] = pixel(t, h);
      const unsigned value = range.value[std::size_t(y) * range.width + x];
      if (value == s.void_value) continue;
      const double r = s.r_offset_mm + s.r_scale_mm * value;
      if (!(r > 0)) continue;
      const double theta = t * dtheta, height = s.top_z_mm - h * s.z_scale_mm;
      vertex[std::size_t(h) * n_t + t] = static_cast<int>(V.size());
      V.emplace_back(r * std::sin(theta), height, r * std::cos(theta));
      UV.emplace_back((x + 0.5) / range.width, (y + 0.5) / range.height);
    }
  // Quads of four neighbouring samples, counter-clockwise seen from outside.
  std::vector<Eigen::Vector3i> F;
  for (int h = 0; h + 1 < n_h; ++h)
    for (int t = 0; t < (closed ? n_t : n_t - 1); ++t) {
      const int t1 = (t + 1) % n_t;
      const int a = vertex[std::size_t(h) * n_t + t], b = vertex[std::size_t(h) * n_t + t1];
      const int c = vertex[std::size_t(h + 1) * n_t + t1], d = vertex[std::size_t(h + 1) * n_t + t];
      // Outward: theta grows towards +x and h downwards, so (a, d, c) faces away from the axis.
      if (a >= 0 && d >= 0 && c >= 0) F.emplace_back(a, d, c);
      if (a >= 0 && c >= 0 && b >= 0) F.emplace_back(a, c, b);
    }
  if (F.empty())
    throw InvalidInput(cat(s.range.string(), ": the range image has no two neighbouring samples "
                           "(every value is the void value ", s.void_value, "?)"));
  out.mesh.V.resize(static_cast<Eigen::Index>(V.size()), 3);
  out.UV.resize(static_cast<Eigen::Index>(UV.size()), 2);
  for (std::size_t i = 0; i < V.size(); ++i) {
    out.mesh.V.row(static_cast<Eigen::Index>(i)) = V[i].transpose();
    out.UV.row(static_cast<Eigen::Index>(i)) = UV[i].transpose();
  }
  out.mesh.F.resize(static_cast<Eigen::Index>(F.size()), 3);
  for (std::size_t i = 0; i < F.size(); ++i) out.mesh.F.row(static_cast<Eigen::Index>(i)) = F[i].transpose();
  if (!out.texture.rgb.empty()) out.FUV = out.mesh.F;
  out.notes.push_back(cat("cylindrical range image ", range.width, "x", range.height, ", ", V.size(),
                          " samples, theta span ", s.theta_span_deg, " deg"));
  return out;
}

fs::path write_cylindrical_scan(const PatientModel& model, const fs::path& dir, double r_scale_mm) {
  if (!(r_scale_mm > 0)) throw InvalidInput(cat("range scale ", r_scale_mm, " mm must be positive"));
  const auto& g = model.grid();
  const auto& maps = model.maps();
  const int w = g.n_theta, h = g.n_z;
  const int j0 = static_cast<int>(std::lround(-g.theta0_deg / g.dtheta_deg()));  // theta = 0
  GreyImage range{w, h, std::vector<std::uint16_t>(std::size_t(w) * h, 0)};
  RgbImage color;
  if (model.has_color()) {
    color.width = w;
    color.height = h;
    color.rgb.assign(std::size_t(w) * h * 3, 0);
  }
  for (int row = 0; row < h; ++row)
    for (int col = 0; col < w; ++col) {
      const int j = (col + j0) % w, k = h - 1 - row;
      const std::size_t c = g.index(j, k);
      if (!maps.measured_skin.empty() && !maps.measured_skin[c]) continue;
      const double value = std::round(maps.r_skin[c] / r_scale_mm);
      if (!(value >= 1 && value <= 65535))
        throw InvalidInput(cat("r_skin ", maps.r_skin[c], " mm does not fit 16 bits at ", r_scale_mm,
                               " mm per unit; choose a larger scale"));
      range.value[std::size_t(row) * w + col] = static_cast<std::uint16_t>(value);
      if (model.has_color()) {
        // color.png of a model has superior on top, like the range image.
        const auto& src = model.color();
        for (int ch = 0; ch < 3; ++ch)
          color.rgb[(std::size_t(row) * w + col) * 3 + ch] = src.rgb[(std::size_t(row) * src.width + j) * 3 + ch];
      }
    }
  write_grey16_png(dir / "range.png", range);
  nlohmann::json j = {{"range", "range.png"},       {"r_scale_mm", r_scale_mm},
                      {"r_offset_mm", 0.0},         {"z_scale_mm", g.dz_mm},
                      {"theta_span_deg", 360.0},    {"theta_axis", "columns"},
                      {"theta_reverse", false},     {"top_first", true},
                      {"void_value", 0},
                      {"top_z_mm", g.z_mm(g.n_z - 1)}};
  if (model.has_color()) {
    write_png(dir / "color.png", color);
    j["color"] = "color.png";
  }
  write_text_atomic(dir / "range.json", j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) + "\n");
  return dir / "range.json";
}

}  // namespace caps
