#include "caps/render/drawn_skin.hpp"

#include "caps/core/error.hpp"
#include "caps/core/units.hpp"
#include "caps/volume/cylindrical_map.hpp"
#include "caps/volume/mesh_io.hpp"
#include "embree_scene.hpp"

#include <nlohmann/json.hpp>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <fstream>

namespace caps::render {
namespace {

// The outermost crossings of the radial rays of every grid sample with `iso`: r (mm, NaN where
// the ray misses it) and whether the ray crosses it three or more times (an undercut).
void resample(const PatientModel& model, const TriMesh& iso, std::vector<double>& r,
              std::vector<char>& undercut) {
  const CylinderGrid& g = model.grid();
  const CylinderAxis& ax = model.axis();
  double r_max = 0;
  for (Eigen::Index v = 0; v < iso.V.rows(); ++v) {
    const Eigen::Vector3d p = iso.V.row(v).transpose() - ax.origin_lps;
    r_max = std::max(r_max, (p - p.dot(ax.direction) * ax.direction).norm());
  }
  const double start = r_max + 10.0;  // outside the surface
  const detail::EmbreeScene scene(iso, ax.origin_lps);
  r.assign(g.size(), std::numeric_limits<double>::quiet_NaN());
  undercut.assign(g.size(), 0);
  tbb::parallel_for(tbb::blocked_range<int>(0, g.n_z), [&](const tbb::blocked_range<int>& rows) {
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    for (int k = rows.begin(); k < rows.end(); ++k)
      for (int j = 0; j < g.n_theta; ++j) {
        const Eigen::Vector3d e_r = ax.ray(deg_to_rad(g.theta_deg(j)));
        const Eigen::Vector3d org = g.z_mm(k) * ax.direction + start * e_r;
        int crossings = 0;
        double t_first = 0, t = 0;
        while (crossings < 3) {
          RTCRayHit rh = detail::make_ray(org, -e_r);
          rh.ray.tnear = static_cast<float>(t);
          rh.ray.tfar = static_cast<float>(start);  // up to the axis
          rtcIntersect1(scene.scene.get(), &ctx, &rh);
          if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) break;
          if (crossings == 0) t_first = rh.ray.tfar;
          t = rh.ray.tfar + 1e-3;
          ++crossings;
        }
        const std::size_t c = g.index(j, k);
        if (crossings > 0) r[c] = start - t_first;
        undercut[c] = crossings >= 3;
      }
  });
}

// The box filter one slice long along z (see drawn_skin.hpp), r linear between rows, z clamped
// at the first and last rows.
std::vector<float> box_filter_z(const std::vector<float>& r, const CylinderGrid& g, double w_mm) {
  constexpr int kSub = 16;  // midpoint rule over the window
  std::vector<float> out(r.size());
  for (int k = 0; k < g.n_z; ++k)
    for (int j = 0; j < g.n_theta; ++j) {
      double sum = 0;
      for (int s = 0; s < kSub; ++s) {
        const double v = std::clamp(k + ((s + 0.5) / kSub - 0.5) * w_mm / g.dz_mm, 0.0,
                                    double(g.n_z - 1));
        const int k0 = std::min(static_cast<int>(std::floor(v)), std::max(g.n_z - 2, 0));
        const int k1 = std::min(k0 + 1, g.n_z - 1);
        const double f = v - k0;
        sum += (1 - f) * r[g.index(j, k0)] + f * r[g.index(j, k1)];
      }
      out[g.index(j, k)] = static_cast<float>(sum / kSub);
    }
  return out;
}

}  // namespace

PatientModel drawn_skin_model(const PatientModel& model, const TriMesh* isosurface,
                              const DrawnSkinOptions& o) {
  if (!(o.slice_spacing_mm >= 0) || !std::isfinite(o.slice_spacing_mm))
    throw InvalidInput(cat("drawn skin: slice spacing ", o.slice_spacing_mm,
                           " mm must be >= 0 (0: no terrace filter)"));
  CylindricalMaps maps = model.maps();
  const CylinderGrid& g = maps.grid;
  if (isosurface && isosurface->V.rows() > 0 && isosurface->F.rows() > 0) {
    std::vector<double> r;
    std::vector<char> undercut;
    resample(model, *isosurface, r, undercut);
    for (std::size_t c = 0; c < g.size(); ++c) {
      if (std::isfinite(r[c]) && std::abs(r[c] - maps.r_skin[c]) <= kDrawnSkinMaxShiftMm)
        maps.r_skin[c] = static_cast<float>(r[c]);
      maps.flags[c] = static_cast<std::uint8_t>(undercut[c] ? (maps.flags[c] | kUndercut)
                                                            : (maps.flags[c] & ~kUndercut));
    }
  }
  if (o.slice_spacing_mm > 0 && g.n_z > 1) maps.r_skin = box_filter_z(maps.r_skin, g, o.slice_spacing_mm);
  return PatientModel(std::move(maps), model.color(), model.source_kind(), model.thickness_kind());
}

PatientModel load_drawn_skin(const PatientModel& model, const std::filesystem::path& dir,
                             Reporter* reporter) {
  const auto json_path = dir / "model.json";
  std::ifstream in(json_path);
  if (!in) throw IoError(cat(json_path.string(), ": cannot be read"));
  nlohmann::json j;
  try {
    in >> j;
  } catch (const std::exception& e) {
    throw IoError(cat(json_path.string(), ": ", e.what()));
  }
  DrawnSkinOptions o;
  const auto& src = j.value("source", nlohmann::json::object());
  if (src.value("kind", "") == "volume" && src.contains("spacing_mm") &&
      src["spacing_mm"].is_array() && src["spacing_mm"].size() == 3)
    o.slice_spacing_mm = src["spacing_mm"][2].get<double>();
  const std::string mesh_name =
      j.value("files", nlohmann::json::object()).value("skin_mesh", std::string());
  if (mesh_name.empty() || !std::filesystem::exists(dir / mesh_name)) {
    if (model.source_kind() == "volume")
      warn(reporter, cat(dir.string(), ": no skin mesh; the range image is drawn as measured "
                         "(with the terrace filter)"));
    return drawn_skin_model(model, nullptr, o);
  }
  const TriMesh iso = read_ply(dir / mesh_name);
  return drawn_skin_model(model, &iso, o);
}

double terrace_rms_deg(const PatientModel& skin, double theta_lo, double theta_hi, double z_lo,
                       double z_hi) {
  const CylinderGrid& g = skin.grid();
  const auto& r = skin.maps().r_skin;
  auto tilt = [&](int j, int k) {
    return std::atan((r[g.index(j, k + 1)] - r[g.index(j, k - 1)]) / (2 * g.dz_mm));
  };
  double sum = 0;
  long n = 0;
  for (int k = 2; k + 2 < g.n_z; ++k) {
    if (g.z_mm(k) < z_lo || g.z_mm(k) > z_hi) continue;
    for (int j = 0; j < g.n_theta; ++j) {
      const double th = g.theta_deg(j);
      if (th < theta_lo || th > theta_hi) continue;
      const double d2 = tilt(j, k + 1) - 2 * tilt(j, k) + tilt(j, k - 1);
      sum += d2 * d2;
      ++n;
    }
  }
  if (n == 0)
    throw InvalidInput(cat("terrace measure: no grid sample in theta ", theta_lo, "..", theta_hi,
                           " deg, z ", z_lo, "..", z_hi, " mm"));
  return rad_to_deg(std::sqrt(sum / n));
}

}  // namespace caps::render
