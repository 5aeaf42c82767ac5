#include "caps/render/drawn_skin.hpp"

#include "caps/core/error.hpp"
#include "caps/core/units.hpp"
#include "caps/volume/cylindrical_map.hpp"
#include "caps/render/skin_surface.hpp"
#include "caps/volume/mesh_io.hpp"
#include "embree_scene.hpp"

#include <nlohmann/json.hpp>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>

namespace caps::render {
namespace {

constexpr double kGrazingUndercutDeg = 75.0;

// Radial rays against the isosurface, from outside it towards the model's axis.
class RadialCaster {
 public:
  RadialCaster(const PatientModel& model, const TriMesh& iso)
      : ax_(model.axis()), scene_(iso, model.axis().origin_lps) {
    double r_max = 0;
    for (Eigen::Index v = 0; v < iso.V.rows(); ++v) {
      const Eigen::Vector3d p = iso.V.row(v).transpose() - ax_.origin_lps;
      r_max = std::max(r_max, (p - p.dot(ax_.direction) * ax_.direction).norm());
    }
    start_ = r_max + 10.0;  // outside the surface
  }
  // The outermost crossing's r (mm, NaN if the ray misses); with `undercut`, also whether the ray
  // meets the surface again after leaving it through an air gap >= kUndercutMinGapMm.
  double cast(RTCIntersectContext& ctx, double theta_deg, double z_mm, bool* undercut) const {
    const Eigen::Vector3d e_r = ax_.ray(deg_to_rad(theta_deg));
    const Eigen::Vector3d org = z_mm * ax_.direction + start_ * e_r;
    double t_hit[3] = {0, 0, 0};
    double first_cos = 0;  // |cos| of the angle between the ray and the surface at the first hit
    int crossings = 0;
    for (double t = 0; crossings < (undercut ? 3 : 1);) {
      RTCRayHit rh = detail::make_ray(org, -e_r);
      rh.ray.tnear = static_cast<float>(t);
      rh.ray.tfar = static_cast<float>(start_);  // up to the axis
      rtcIntersect1(scene_.scene.get(), &ctx, &rh);
      if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) break;
      if (crossings == 0) {
        const Eigen::Vector3d ng(rh.hit.Ng_x, rh.hit.Ng_y, rh.hit.Ng_z);
        first_cos = ng.norm() > 0 ? std::abs(ng.normalized().dot(e_r)) : 0.0;
      }
      t_hit[crossings++] = rh.ray.tfar;
      t = rh.ray.tfar + 1e-3;
    }
    // A ray grazing the surface (more than kGrazingUndercutDeg from its normal: the top of the
    // head, the neck) may cross small bumps three times; that is not an undercut.
    if (undercut)
      *undercut = crossings == 3 && t_hit[2] - t_hit[1] >= kUndercutMinGapMm &&
                  first_cos >= std::cos(deg_to_rad(kGrazingUndercutDeg));
    return crossings > 0 ? start_ - t_hit[0] : std::numeric_limits<double>::quiet_NaN();
  }

 private:
  const CylinderAxis& ax_;  // not owned
  detail::EmbreeScene scene_;
  double start_ = 0;
};

constexpr int kBoxRays = 8;  // rays per sample across the terrace filter's window

// r_skin resampled from the isosurface, box-filtered along z over w_mm by rays of its own (none:
// w_mm = 0); samples where a ray misses or strays more than kDrawnSkinMaxShiftMm from the model
// keep the model's value (unfiltered). Also the undercut samples.
void resample(const PatientModel& model, const TriMesh& iso, double w_mm, std::vector<float>& r,
              std::vector<char>& undercut) {
  const CylinderGrid& g = model.grid();
  const RadialCaster caster(model, iso);
  undercut.assign(g.size(), 0);
  const auto& measured = model.maps().r_skin;
  r = measured;
  tbb::parallel_for(tbb::blocked_range<int>(0, g.n_z), [&](const tbb::blocked_range<int>& rows) {
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    for (int k = rows.begin(); k < rows.end(); ++k)
      for (int j = 0; j < g.n_theta; ++j) {
        const std::size_t c = g.index(j, k);
        bool under = false;
        const double r0 = caster.cast(ctx, g.theta_deg(j), g.z_mm(k), &under);
        undercut[c] = under;
        auto near_model = [&](double x) {
          return std::isfinite(x) && std::abs(x - measured[c]) <= kDrawnSkinMaxShiftMm;
        };
        if (!near_model(r0)) continue;
        if (!(w_mm > 0)) {
          r[c] = static_cast<float>(r0);
          continue;
        }
        const int kp = std::min(k + 1, g.n_z - 1), km = std::max(k - 1, 0);
        const double slope =
            std::abs(measured[g.index(j, kp)] - measured[g.index(j, km)]) / ((kp - km) * g.dz_mm);
        double sum = 0;
        bool all = true;
        for (int s = 0; s < kBoxRays && all; ++s) {
          const double z = g.z_mm(k) + ((s + 0.5) / kBoxRays - 0.5) * w_mm;
          const double rs = caster.cast(ctx, g.theta_deg(j), z, nullptr);
          // the same sheet of the surface as the sample's own ray: within the shift allowed plus
          // twice what the model's slope along z accounts for (the top of the head is steep in
          // r(z): 5-10 mm of r per mm of z)
          all = std::isfinite(rs) &&
                std::abs(rs - r0) <= kDrawnSkinMaxShiftMm + 2.0 * slope * std::abs(z - g.z_mm(k));
          sum += rs;
        }
        r[c] = static_cast<float>(all ? sum / kBoxRays : r0);
      }
  });
}

// The box filter one slice long along z for a range image without isosurface: r linear between
// rows, z clamped at the first and last rows.
std::vector<float> box_filter_z(const std::vector<float>& r, const CylinderGrid& g, double w_mm) {
  std::vector<float> out(r.size());
  for (int k = 0; k < g.n_z; ++k)
    for (int j = 0; j < g.n_theta; ++j) {
      double sum = 0;
      for (int s = 0; s < 2 * kBoxRays; ++s) {
        const double v = std::clamp(k + ((s + 0.5) / (2 * kBoxRays) - 0.5) * w_mm / g.dz_mm, 0.0,
                                    double(g.n_z - 1));
        const int k0 = std::min(static_cast<int>(std::floor(v)), std::max(g.n_z - 2, 0));
        const int k1 = std::min(k0 + 1, g.n_z - 1);
        const double f = v - k0;
        sum += (1 - f) * r[g.index(j, k0)] + f * r[g.index(j, k1)];
      }
      out[g.index(j, k)] = static_cast<float>(sum / (2 * kBoxRays));
    }
  return out;
}

// Cells (j, k), k < n_z - 1, with an undercut corner, dilated by `by` cells (periodic in theta).
std::vector<std::uint8_t> undercut_cells(const CylinderGrid& g, const std::vector<char>& undercut,
                                         int by) {
  std::vector<std::uint8_t> cells(g.size(), 0);
  for (int k = 0; k + 1 < g.n_z; ++k)
    for (int j = 0; j < g.n_theta; ++j) {
      const int j1 = (j + 1) % g.n_theta;
      if (!(undercut[g.index(j, k)] || undercut[g.index(j1, k)] || undercut[g.index(j, k + 1)] ||
            undercut[g.index(j1, k + 1)]))
        continue;
      for (int dk = -by; dk <= by; ++dk)
        for (int dj = -by; dj <= by; ++dj) {
          const int kk = k + dk;
          if (kk < 0 || kk + 1 >= g.n_z) continue;
          cells[g.index(((j + dj) % g.n_theta + g.n_theta) % g.n_theta, kk)] = 1;
        }
    }
  return cells;
}

// The isosurface's triangles whose centroid lies in a flagged cell, with their vertex normals.
void undercut_triangles(const PatientModel& model, const TriMesh& iso,
                        const std::vector<std::uint8_t>& cells, DrawnSkin& out) {
  const CylinderGrid& g = model.grid();
  const Eigen::MatrixX3d N = vertex_normals(iso);
  std::vector<int> index(static_cast<std::size_t>(iso.V.rows()), -1);
  std::vector<Eigen::Vector3d> V, VN;
  std::vector<Eigen::Vector3i> F;
  for (Eigen::Index f = 0; f < iso.F.rows(); ++f) {
    const Eigen::Vector3d c =
        (iso.V.row(iso.F(f, 0)) + iso.V.row(iso.F(f, 1)) + iso.V.row(iso.F(f, 2))).transpose() / 3.0;
    const CylindricalPoint cp = model.to_cylindrical(c);
    double u = (cp.theta_deg - g.theta0_deg) / g.dtheta_deg();
    u -= g.n_theta * std::floor(u / g.n_theta);
    const int j = std::min(static_cast<int>(std::floor(u)), g.n_theta - 1);
    const int k = static_cast<int>(std::floor((cp.z_mm - g.z0_mm) / g.dz_mm));
    if (k < 0 || k + 1 >= g.n_z || !cells[g.index(j, k)]) continue;
    Eigen::Vector3i t;
    for (int a = 0; a < 3; ++a) {
      int& id = index[static_cast<std::size_t>(iso.F(f, a))];
      if (id < 0) {
        id = static_cast<int>(V.size());
        V.push_back(iso.V.row(iso.F(f, a)).transpose());
        VN.push_back(N.row(iso.F(f, a)).transpose());
      }
      t[a] = id;
    }
    F.push_back(t);
  }
  out.undercuts.V.resize(static_cast<Eigen::Index>(V.size()), 3);
  out.undercut_normals.resize(static_cast<Eigen::Index>(V.size()), 3);
  for (std::size_t i = 0; i < V.size(); ++i) {
    out.undercuts.V.row(static_cast<Eigen::Index>(i)) = V[i].transpose();
    out.undercut_normals.row(static_cast<Eigen::Index>(i)) = VN[i].transpose();
  }
  out.undercuts.F.resize(static_cast<Eigen::Index>(F.size()), 3);
  for (std::size_t i = 0; i < F.size(); ++i) out.undercuts.F.row(static_cast<Eigen::Index>(i)) = F[i].transpose();
}

}  // namespace

DrawnSkin drawn_skin(const PatientModel& model, const TriMesh* isosurface,
                     const DrawnSkinOptions& o) {
  if (!(o.slice_spacing_mm >= 0) || !std::isfinite(o.slice_spacing_mm))
    throw InvalidInput(cat("drawn skin: slice spacing ", o.slice_spacing_mm,
                           " mm must be >= 0 (0: no terrace filter)"));
  CylindricalMaps maps = model.maps();
  const CylinderGrid& g = maps.grid;
  DrawnSkin out{model, {}, {}, {}};
  const bool iso = isosurface && isosurface->V.rows() > 0 && isosurface->F.rows() > 0;
  if (iso) {
    std::vector<char> undercut;
    resample(model, *isosurface, g.n_z > 1 ? o.slice_spacing_mm : 0.0, maps.r_skin, undercut);
    for (std::size_t c = 0; c < g.size(); ++c)
      maps.flags[c] = static_cast<std::uint8_t>(undercut[c] ? (maps.flags[c] | kUndercut)
                                                            : (maps.flags[c] & ~kUndercut));
    // The isosurface is drawn where the range image cannot show the skin: the undercuts, and
    // the samples whose ray grazes the skin (kGrazing: the top of the head, the sides of a
    // local chart's band), which a range image draws as a staircase of streaks.
    std::vector<char> by_isosurface = undercut;
    for (std::size_t c = 0; c < g.size(); ++c)
      if (model.maps().flags[c] & kGrazing) by_isosurface[c] = 1;
    if (std::any_of(by_isosurface.begin(), by_isosurface.end(), [](char u) { return u != 0; })) {
      out.undercut_cells = undercut_cells(g, by_isosurface, 2);
      undercut_triangles(model, *isosurface, undercut_cells(g, by_isosurface, 3), out);
    }
  } else if (o.slice_spacing_mm > 0 && g.n_z > 1) {
    maps.r_skin = box_filter_z(maps.r_skin, g, o.slice_spacing_mm);
  }
  out.range = PatientModel(std::move(maps), model.color(), model.source_kind(), model.thickness_kind());
  return out;
}

DrawnSkin load_drawn_skin(const PatientModel& model, const std::filesystem::path& dir,
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
    return drawn_skin(model, nullptr, o);
  }
  const TriMesh iso = read_ply(dir / mesh_name);
  return drawn_skin(model, &iso, o);
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
