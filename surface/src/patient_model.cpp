#include "caps/surface/patient_model.hpp"

#include <algorithm>
#include <cmath>

#include "caps/core/error.hpp"
#include "caps/core/units.hpp"
#include "caps/volume/model_dir.hpp"

namespace fs = std::filesystem;

namespace caps {

PatientModel PatientModel::load(const fs::path& dir) {
  const ModelInfo info = read_model_info(dir);
  return PatientModel(read_model_maps(dir, info), read_model_color(dir, info), info.source_kind(),
                      info.thickness_kind());
}

std::string PatientModel::content_hash() const { return caps::content_hash(maps_); }

PatientModel::PatientModel(CylindricalMaps maps, RgbImage color, std::string source_kind,
                           std::string thickness_kind)
    : maps_(std::move(maps)),
      color_(std::move(color)),
      source_kind_(std::move(source_kind)),
      thickness_kind_(std::move(thickness_kind)) {
  const auto n = maps_.grid.size();
  if (maps_.r_skin.size() != n || maps_.r_bone.size() != n || maps_.thickness.size() != n ||
      maps_.thickness_normal.size() != n || maps_.flags.size() != n)
    throw InvalidInput(cat("patient model: maps must hold ", n, " values (", maps_.grid.n_theta,
                           " x ", maps_.grid.n_z, ")"));
  if (!color_.rgb.empty() && (color_.width != maps_.grid.n_theta ||
                              color_.height != maps_.grid.n_z))
    throw InvalidInput("patient model: the colour image must be n_theta x n_z");
}

bool PatientModel::has_z(double z_mm) const {
  const auto& g = maps_.grid;
  return z_mm >= g.z0_mm - 1e-9 && z_mm <= g.z_mm(g.n_z - 1) + 1e-9;
}

PatientModel::Stencil PatientModel::stencil(double theta_deg, double z_mm) const {
  const auto& g = maps_.grid;
  double u = (theta_deg - g.theta0_deg) / g.dtheta_deg();
  u -= g.n_theta * std::floor(u / g.n_theta);  // periodic: [0, n_theta)
  int j0 = static_cast<int>(std::floor(u));
  if (j0 >= g.n_theta) j0 = 0;
  const int j1 = (j0 + 1) % g.n_theta;
  const double v = std::clamp((z_mm - g.z0_mm) / g.dz_mm, 0.0, double(g.n_z - 1));
  const int k0 = std::min(static_cast<int>(std::floor(v)), g.n_z - 2);
  return {g.index(j0, k0), g.index(j1, k0), g.index(j0, k0 + 1), g.index(j1, k0 + 1), u - j0,
          v - k0};
}

double PatientModel::sample(const std::vector<float>& img, double theta_deg, double z_mm) const {
  const Stencil s = stencil(theta_deg, z_mm);
  return (1 - s.fv) * ((1 - s.fu) * img[s.c00] + s.fu * img[s.c10]) +
         s.fv * ((1 - s.fu) * img[s.c01] + s.fu * img[s.c11]);
}

double PatientModel::r_skin(double t, double z) const { return sample(maps_.r_skin, t, z); }
double PatientModel::r_bone(double t, double z) const { return sample(maps_.r_bone, t, z); }
double PatientModel::thickness(double t, double z) const { return sample(maps_.thickness, t, z); }
double PatientModel::thickness_normal(double t, double z) const {
  return sample(maps_.thickness_normal, t, z);
}

Eigen::Vector3d PatientModel::color_at(double theta_deg, double z_mm) const {
  if (!has_color()) return {0.5, 0.5, 0.5};
  const Stencil s = stencil(theta_deg, z_mm);
  const auto& g = maps_.grid;
  // color.png has superior on top: grid row k is image row n_z - 1 - k.
  auto px = [&](std::size_t c) -> Eigen::Vector3d {
    const std::size_t j = c % g.n_theta, k = c / g.n_theta;
    const std::size_t o = ((g.n_z - 1 - k) * g.n_theta + j) * 3;
    return Eigen::Vector3d(color_.rgb[o], color_.rgb[o + 1], color_.rgb[o + 2]) / 255.0;
  };
  return (1 - s.fv) * ((1 - s.fu) * px(s.c00) + s.fu * px(s.c10)) +
         s.fv * ((1 - s.fu) * px(s.c01) + s.fu * px(s.c11));
}

std::uint8_t PatientModel::or_flags(const std::vector<std::uint8_t>& img, double theta_deg,
                                    double z_mm) const {
  const Stencil s = stencil(theta_deg, z_mm);
  std::uint8_t f = 0;
  const bool u_used = s.fu > 1e-12, v_used = s.fv > 1e-12;
  f |= img[s.c00];
  if (u_used) f |= img[s.c10];
  if (v_used) f |= img[s.c01];
  if (u_used && v_used) f |= img[s.c11];
  return f;
}

std::uint8_t PatientModel::flags_at(double theta_deg, double z_mm) const {
  return or_flags(maps_.flags, theta_deg, z_mm);
}

double PatientModel::thickness_skin(double t, double z) const {
  return has_layers() ? sample(maps_.thickness_skin, t, z) : 0.0;
}
double PatientModel::thickness_fat(double t, double z) const {
  return has_layers() ? sample(maps_.thickness_fat, t, z) : 0.0;
}
double PatientModel::thickness_deep(double t, double z) const {
  return has_layers() ? sample(maps_.thickness_deep, t, z) : 0.0;
}

std::uint8_t PatientModel::layer_flags_at(double theta_deg, double z_mm) const {
  if (!has_layers() || maps_.layer_flags.size() != maps_.grid.size()) return kLayerNoThickness;
  return or_flags(maps_.layer_flags, theta_deg, z_mm);
}

Eigen::Vector3d PatientModel::to_lps(double theta_deg, double z_mm, double r_mm) const {
  return maps_.axis.to_lps(deg_to_rad(theta_deg), z_mm, r_mm);
}

Eigen::Vector3d PatientModel::to_lps(const CylindricalPoint& c) const {
  return to_lps(c.theta_deg, c.z_mm, c.r_mm);
}

CylindricalPoint PatientModel::to_cylindrical(const Eigen::Vector3d& p) const {
  const Eigen::Vector3d c = maps_.axis.to_cylindrical(p);
  double theta = rad_to_deg(c[0]);
  if (theta >= 180.0) theta -= 360.0;
  if (c[2] < 1e-12) theta = 0.0;
  return {theta, c[1], c[2]};
}

Eigen::Vector3d PatientModel::skin_point(double theta_deg, double z_mm) const {
  return to_lps(theta_deg, z_mm, r_skin(theta_deg, z_mm));
}

Eigen::Vector3d PatientModel::bone_point(double theta_deg, double z_mm) const {
  return to_lps(theta_deg, z_mm, r_bone(theta_deg, z_mm));
}

Eigen::Vector3d PatientModel::skin_normal(double theta_deg, double z_mm) const {
  const auto& g = maps_.grid;
  const Stencil s = stencil(theta_deg, z_mm);
  const auto& r = maps_.r_skin;
  // Slopes of the bilinear patch at the sample point.
  const double dr_du = (1 - s.fv) * (r[s.c10] - r[s.c00]) + s.fv * (r[s.c11] - r[s.c01]);
  const double dr_dv = (1 - s.fu) * (r[s.c01] - r[s.c00]) + s.fu * (r[s.c11] - r[s.c10]);
  const double rr = r_skin(theta_deg, z_mm);
  const double dr_dth = dr_du / deg_to_rad(g.dtheta_deg());
  const double dr_dz = g.n_z > 1 ? dr_dv / g.dz_mm : 0.0;
  const double th = deg_to_rad(theta_deg);
  const Eigen::Vector3d e_r = maps_.axis.ray(th);
  const Eigen::Vector3d e_z = maps_.axis.direction;
  const Eigen::Vector3d e_th = e_z.cross(e_r);
  const double slope_th = rr > 1.0 ? dr_dth / rr : 0.0;
  return (e_r - slope_th * e_th - dr_dz * e_z).normalized();
}

}  // namespace caps
