#include "caps/surface/scan_model.hpp"

#include <nlohmann/json.hpp>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <sstream>
#include <atomic>
#include <cmath>
#include <limits>
#include <unordered_map>

#include "caps/core/error.hpp"
#include "caps/core/reporter.hpp"
#include "caps/core/units.hpp"
#include "caps/surface/picking.hpp"
#include "caps/surface/range_mesh.hpp"

namespace fs = std::filesystem;
using nlohmann::json;

namespace caps {
namespace {

std::uint64_t edge_key(int a, int b) {
  if (a > b) std::swap(a, b);
  return (std::uint64_t(std::uint32_t(a)) << 32) | std::uint32_t(b);
}

// Bilinear texture lookup at image-convention (u, v) in [0, 1] (clamped at the borders).
Eigen::Vector3d sample_texture(const RgbImage& t, double u, double v) {
  const double x = std::clamp(u * t.width - 0.5, 0.0, t.width - 1.0);
  const double y = std::clamp(v * t.height - 0.5, 0.0, t.height - 1.0);
  const int x0 = std::min(static_cast<int>(x), t.width - 1), y0 = std::min(static_cast<int>(y), t.height - 1);
  const int x1 = std::min(x0 + 1, t.width - 1), y1 = std::min(y0 + 1, t.height - 1);
  const double fx = x - x0, fy = y - y0;
  auto px = [&](int xx, int yy) {
    const std::size_t o = (std::size_t(yy) * t.width + xx) * 3;
    return Eigen::Vector3d(t.rgb[o], t.rgb[o + 1], t.rgb[o + 2]);
  };
  return (1 - fy) * ((1 - fx) * px(x0, y0) + fx * px(x1, y0)) + fy * ((1 - fx) * px(x0, y1) + fx * px(x1, y1));
}

// Barycentric coordinates of p in triangle (a, b, c).
Eigen::Vector3d barycentric(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                            const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  const Eigen::Vector3d v0 = b - a, v1 = c - a, v2 = p - a;
  const double d00 = v0.dot(v0), d01 = v0.dot(v1), d11 = v1.dot(v1), d20 = v2.dot(v0), d21 = v2.dot(v1);
  const double den = d00 * d11 - d01 * d01;
  if (std::abs(den) < 1e-300) return {1, 0, 0};
  const double v = (d11 * d20 - d01 * d21) / den, w = (d00 * d21 - d01 * d20) / den;
  return {1 - v - w, v, w};
}

std::string axis_name(const Eigen::Vector3d& v) {
  for (int a = 0; a < 3; ++a)
    if (std::abs(std::abs(v[a]) - 1) < 1e-12) return cat(v[a] > 0 ? "+" : "-", "xyz"[a]);
  return cat(v.transpose());
}

// The axis as for volumes: parallel to superior (LPS +z), front anterior (LPS -y), through the
// centre of the head's cross-sections in 2 mm bands (those with at least 30 % of the largest
// band's surface area). A scan is a surface, so each band's centre is the least-squares circle
// through its surface (Kasa fit, area-weighted triangle centroids): for a whole head this is the
// cross-section's centre, and it stays inside the head for a face-only patch.
CylinderAxis fit_scan_axis(const TriMesh& m) {
  constexpr double kBand = 2.0;
  const double zmin = m.V.col(2).minCoeff();
  const int n_bands = static_cast<int>((m.V.col(2).maxCoeff() - zmin) / kBand) + 1;
  std::vector<Eigen::Matrix4d> normal(n_bands, Eigen::Matrix4d::Zero());
  std::vector<double> area(n_bands, 0.0);
  for (Eigen::Index f = 0; f < m.n_faces(); ++f) {
    const Eigen::Vector3d a = m.V.row(m.F(f, 0)), b = m.V.row(m.F(f, 1)), c = m.V.row(m.F(f, 2));
    const double w = 0.5 * (b - a).cross(c - a).norm();
    const Eigen::Vector3d p = (a + b + c) / 3.0;
    const int band = std::clamp(static_cast<int>((p[2] - zmin) / kBand), 0, n_bands - 1);
    // x^2 + y^2 + D x + E y + F = 0 in the least-squares sense.
    const Eigen::Vector4d row(p[0], p[1], 1.0, -(p[0] * p[0] + p[1] * p[1]));
    normal[band] += w * row * row.transpose();
    area[band] += w;
  }
  const double max_area = *std::max_element(area.begin(), area.end());
  double w = 0;
  Eigen::Vector2d centre(0, 0);
  for (int b = 0; b < n_bands; ++b) {
    if (area[b] < 0.3 * max_area) continue;
    const Eigen::Matrix3d A = normal[b].topLeftCorner<3, 3>();
    const Eigen::Vector3d rhs = normal[b].topRightCorner<3, 1>();
    const Eigen::Vector3d def = A.ldlt().solve(rhs);
    if (!def.allFinite()) continue;
    centre += area[b] * Eigen::Vector2d(-0.5 * def[0], -0.5 * def[1]);
    w += area[b];
  }
  if (!(w > 0)) throw InvalidInput("scan: cannot fit the cylinder axis (no usable cross-section)");
  CylinderAxis axis;
  axis.origin_lps = {centre[0] / w, centre[1] / w, 0.0};
  return axis;
}

}  // namespace

Eigen::Vector3d parse_axis_name(const std::string& name, const std::string& option) {
  if (name.size() == 2 && (name[0] == '+' || name[0] == '-') && name[1] >= 'x' && name[1] <= 'z') {
    Eigen::Vector3d v = Eigen::Vector3d::Zero();
    v[name[1] - 'x'] = name[0] == '+' ? 1.0 : -1.0;
    return v;
  }
  std::array<double, 3> v{};
  char c1 = 0, c2 = 0;
  std::istringstream in(name);
  if ((in >> v[0] >> c1 >> v[1] >> c2 >> v[2]) && c1 == ',' && c2 == ',' && in.eof()) {
    const Eigen::Vector3d d(v[0], v[1], v[2]);
    if (d.allFinite() && d.norm() > 1e-9) return d.normalized();
  }
  throw InvalidInput(cat(option, " '", name, "': give a file axis as +x, -x, +y, -y, +z or -z, "
                         "or a direction X,Y,Z"));
}

Eigen::Matrix3d scan_to_lps_rotation(const Eigen::Vector3d& up, const Eigen::Vector3d& front) {
  if (std::abs(up.norm() - 1) > 1e-9 || std::abs(front.norm() - 1) > 1e-9 ||
      std::abs(up.dot(front)) > 1e-6)
    throw InvalidInput(cat("--up ", axis_name(up), " and --front ", axis_name(front),
                           " must be two different, perpendicular axes (e.g. --up +y --front +z)"));
  Eigen::Matrix3d R;
  R.row(0) = up.cross(front).transpose();  // patient's left
  R.row(1) = -front.transpose();           // posterior
  R.row(2) = up.transpose();               // superior
  return R;
}

void check_scan_mesh(const ScanMesh& s) {
  const TriMesh& m = s.mesh;
  if (m.n_faces() == 0)
    throw InvalidInput(cat(s.source, ": the mesh has no faces; a scan must be a triangle surface, "
                               "not a point cloud (mesh it first, e.g. screened Poisson in MeshLab)"));
  for (Eigen::Index i = 0; i < m.n_vertices(); ++i)
    if (!m.V.row(i).allFinite())
      throw InvalidInput(cat(s.source, ": vertex ", i, " has a non-finite coordinate (",
                             m.V.row(i), "); repair or re-export the scan"));
  if (m.F.minCoeff() < 0 || m.F.maxCoeff() >= m.n_vertices())
    throw InvalidInput(cat(s.source, ": a face refers to a vertex that does not exist"));
  std::unordered_map<std::uint64_t, int> edges;
  edges.reserve(static_cast<std::size_t>(m.n_faces()) * 3);
  for (Eigen::Index f = 0; f < m.n_faces(); ++f)
    for (int c = 0; c < 3; ++c) {
      const int a = m.F(f, c), b = m.F(f, (c + 1) % 3);
      if (a == b) continue;
      if (++edges[edge_key(a, b)] == 3)
        throw InvalidInput(cat(s.source, ": non-manifold geometry: the edge between vertices ", a,
                               " and ", b, " is shared by 3 or more faces; clean the scan (e.g. "
                               "MeshLab: Repair non-manifold edges)"));
    }
}

ScanModel build_scan_model(const ScanMesh& scan, const ScanModelOptions& o, Reporter* reporter) {
  check_scan_mesh(scan);
  if (!(o.thickness_mm > 0 && o.thickness_mm <= 50))
    throw InvalidInput(cat("--thickness ", o.thickness_mm, " mm: give the assumed soft-tissue "
                           "thickness in (0, 50] mm (the 1992 system used a constant thickness)"));
  const auto& mo = o.maps;
  if (mo.n_theta < 8 || mo.n_theta > 8192 || mo.n_z < 4 || mo.n_z > 8192)
    throw InvalidInput(cat("cylindrical grid ", mo.n_theta, " x ", mo.n_z,
                           " is out of range (theta 8..8192, z 4..8192)"));
  ScanModel out;
  out.options = o;
  out.rotation = scan_to_lps_rotation(o.up, o.front);
  // Units.
  const Eigen::VectorXd up_coord = scan.mesh.V * o.up;
  const double extent = up_coord.maxCoeff() - up_coord.minCoeff();
  std::string how;
  if (o.mm_per_unit && o.head_height_mm)
    throw InvalidInput("give either --scale or --head-height-mm, not both");
  if (o.mm_per_unit) {
    if (!(*o.mm_per_unit > 0 && std::isfinite(*o.mm_per_unit)))
      throw InvalidInput(cat("--scale ", *o.mm_per_unit, ": give millimetres per file unit (> 0)"));
    out.mm_per_unit = *o.mm_per_unit;
    how = cat("--scale ", out.mm_per_unit);
  } else if (o.head_height_mm) {
    if (!(*o.head_height_mm > 0) || !(extent > 0))
      throw InvalidInput(cat("--head-height-mm ", *o.head_height_mm, ": must be positive"));
    out.mm_per_unit = *o.head_height_mm / extent;
    how = cat("--head-height-mm ", *o.head_height_mm);
  } else if (scan.mm_per_unit > 0) {
    out.mm_per_unit = scan.mm_per_unit;
    how = cat("the ", scan.format, " unit (", scan.mm_per_unit, " mm)");
  } else {
    out.mm_per_unit = 1.0;
    how = cat("no unit in the ", scan.format, " file, taken as mm");
  }
  out.height_mm = extent * out.mm_per_unit;
  if (!(out.height_mm >= o.min_height_mm && out.height_mm <= o.max_height_mm))
    throw InvalidInput(cat(scan.source, ": the scan would be ", out.height_mm, " mm tall along --up ",
                           axis_name(o.up), " (", how, "); a head is about 200-300 mm. Give the "
                           "units with --scale MM_PER_UNIT (e.g. --scale 1000 for metres) or the "
                           "height with --head-height-mm (e.g. --head-height-mm 230); check --up"));

  out.scan = scan;
  out.scan.texture = {};
  TriMesh& skin = out.skin;
  skin.F = scan.mesh.F;
  if (o.flip_faces) skin.F.col(1).swap(skin.F.col(2));
  skin.V = (scan.mesh.V * out.rotation.transpose()) * out.mm_per_unit;

  CylindricalMaps& maps = out.maps;
  maps.axis = o.axis ? *o.axis : fit_scan_axis(skin);
  auto& g = maps.grid;
  g.n_theta = mo.n_theta;
  g.n_z = mo.n_z;
  if (o.grid) {
    g.z0_mm = o.grid->z0_mm;
    g.dz_mm = o.grid->dz_mm;
  } else {
    const Eigen::VectorXd z = (skin.V.rowwise() - maps.axis.origin_lps.transpose()) * maps.axis.direction;
    g.z0_mm = z.minCoeff();
    g.dz_mm = (z.maxCoeff() - z.minCoeff()) / (g.n_z - 1);
  }
  const std::size_t n = g.size();
  maps.allocate();

  // Faces touching the scan's open border: a hit there is on a cut edge of the scan.
  std::unordered_map<std::uint64_t, int> edges;
  for (Eigen::Index f = 0; f < skin.n_faces(); ++f)
    for (int c = 0; c < 3; ++c) ++edges[edge_key(skin.F(f, c), skin.F(f, (c + 1) % 3))];
  std::vector<std::uint8_t> border_vertex(skin.n_vertices(), 0);
  for (const auto& [key, count] : edges)
    if (count == 1) {
      border_vertex[key >> 32] = 1;
      border_vertex[key & 0xffffffffu] = 1;
    }

  const bool has_texture = !scan.texture.rgb.empty() && scan.FUV.rows() == skin.n_faces();
  const bool has_vertex_colors = scan.vertex_colors.rows() == skin.n_vertices() && skin.n_vertices() > 0;
  if (!has_texture && !has_vertex_colors)
    warn(reporter, cat(scan.source, ": the scan has no colour (no texture with coordinates, no vertex colours); "
             "color.png is not written. Give a texture with --texture"));
  std::vector<Eigen::Vector3f> colour(n, Eigen::Vector3f(128, 128, 128));

  Progress progress(reporter, "casting rays against the scan", 1.0);
  const MeshRayCaster caster(skin);
  std::atomic<std::size_t> inside_out{0};
  tbb::parallel_for(0, g.n_z, [&](int k) {
    for (int j = 0; j < g.n_theta; ++j) {
      const std::size_t c = g.index(j, k);
      const double theta = deg_to_rad(g.theta_deg(j));
      const Ray ray{maps.axis.to_lps(theta, g.z_mm(k), 0.0), maps.axis.ray(theta)};
      const auto hits = caster.all_hits(ray);
      if (hits.empty()) {
        maps.flags[c] = kNoSkin;
        continue;
      }
      auto facing = [&](const MeshHit& h) {
        const Eigen::Vector3d a = skin.V.row(skin.F(h.face, 0)), b = skin.V.row(skin.F(h.face, 1)),
                              cc = skin.V.row(skin.F(h.face, 2));
        return (b - a).cross(cc - a).dot(ray.direction);  // > 0: the face looks away from the axis
      };
      const MeshHit& outer = hits.back();
      if (facing(outer) < 0) ++inside_out;
      // Inward from the outermost crossing: a face looking at the axis starts an air gap, the
      // next face looking away ends it (the same rule as volumes: a gap of kUndercutMinGapMm).
      double air_from = std::numeric_limits<double>::quiet_NaN();
      for (auto it = hits.rbegin() + 1; it != hits.rend(); ++it) {
        const double s = facing(*it);
        if (s < 0 && !std::isfinite(air_from)) {
          air_from = it->t;
        } else if (s > 0 && std::isfinite(air_from)) {
          if (air_from - it->t >= kUndercutMinGapMm) {
            maps.flags[c] |= kUndercut;
            break;
          }
          air_from = std::numeric_limits<double>::quiet_NaN();
        }
      }
      maps.r_skin[c] = static_cast<float>(outer.t);
      maps.measured_skin[c] = 1;
      const auto f = outer.face;
      if (border_vertex[skin.F(f, 0)] || border_vertex[skin.F(f, 1)] || border_vertex[skin.F(f, 2)])
        maps.flags[c] |= kTruncated;
      const Eigen::Vector3d b = barycentric(outer.point, skin.V.row(skin.F(f, 0)),
                                            skin.V.row(skin.F(f, 1)), skin.V.row(skin.F(f, 2)));
      if (has_texture) {
        Eigen::Vector2d uv = Eigen::Vector2d::Zero();
        for (int q = 0; q < 3; ++q) uv += b[q] * scan.UV.row(scan.FUV(f, q)).transpose();
        colour[c] = sample_texture(scan.texture, uv[0], uv[1]).cast<float>();
      } else if (has_vertex_colors) {
        Eigen::Vector3d col = Eigen::Vector3d::Zero();
        for (int q = 0; q < 3; ++q) col += b[q] * scan.vertex_colors.row(skin.F(f, q)).transpose().cast<double>();
        colour[c] = col.cast<float>();
      }
    }
  });
  progress.update(0.8);
  std::size_t n_measured = 0;
  for (auto m : maps.measured_skin) n_measured += m;
  if (n_measured == 0)
    throw InvalidInput(cat(scan.source, ": no ray from the fitted axis meets the scan; check --up"));
  out.inside_out_cells = inside_out;
  if (out.inside_out_cells * 2 > n_measured)
    throw InvalidInput(cat(scan.source, ": the mesh is inside-out: on ", out.inside_out_cells, " of ",
                           n_measured, " rays the outermost face looks towards the head's axis. "
                           "Pass --flip-faces (or invert the faces in MeshLab) if the file's "
                           "normals point inward, or check --up/--front"));
  flag_grazing(maps, mo.grazing_deg);
  harmonic_fill(maps.r_skin, maps.measured_skin, g);
  // The bone is the skin moved inward by the constant thickness (radially, as the extruder
  // uses it); where the head is thinner than that, there is no bone.
  const double dth = deg_to_rad(g.dtheta_deg());
  for (int k = 0; k < g.n_z; ++k)
    for (int j = 0; j < g.n_theta; ++j) {
      const std::size_t c = g.index(j, k);
      const double r = maps.r_skin[c];
      double t = o.thickness_mm;
      if (r - t < 0.5) {
        t = std::max(0.0, r);
        if (maps.measured_skin[c]) maps.flags[c] |= kNoBone;
      }
      maps.thickness[c] = static_cast<float>(t);
      maps.r_bone[c] = static_cast<float>(r - t);
      maps.measured_bone[c] = maps.measured_skin[c] && !(maps.flags[c] & kNoBone);
      // Distance to the radially shifted surface: t cos(angle between ray and normal).
      const int jl = (j + g.n_theta - 1) % g.n_theta, jr = (j + 1) % g.n_theta;
      const int kd = std::max(0, k - 1), ku = std::min(g.n_z - 1, k + 1);
      const double r_th = (maps.r_skin[g.index(jr, k)] - maps.r_skin[g.index(jl, k)]) / (2 * dth);
      const double r_z = (maps.r_skin[g.index(j, ku)] - maps.r_skin[g.index(j, kd)]) / ((ku - kd) * g.dz_mm);
      const double rr = std::max(r, 1e-6);
      maps.thickness_normal[c] =
          static_cast<float>(t / std::sqrt(1.0 + std::pow(r_th / rr, 2) + r_z * r_z));
    }
  out.stats = model_statistics(maps);
  out.bone = range_mesh(maps, RangeSurface::Bone, {true});
  if (has_texture || has_vertex_colors) {
    out.color.width = g.n_theta;
    out.color.height = g.n_z;
    out.color.rgb.resize(n * 3);
    for (int k = 0; k < g.n_z; ++k)
      for (int j = 0; j < g.n_theta; ++j)
        for (int q = 0; q < 3; ++q)
          out.color.rgb[((std::size_t(g.n_z - 1 - k) * g.n_theta) + j) * 3 + q] = static_cast<std::uint8_t>(
              std::clamp(std::lround(colour[g.index(j, k)][q]), 0L, 255L));
  }
  progress.done();
  return out;
}

void write_scan_model(const ScanModel& m, const fs::path& dir, bool force, Reporter* reporter) {
  const auto& o = m.options;
  ModelProvenance c;
  c.name = fs::path(m.scan.source).filename().string();
  c.credit = o.credit;
  json R = json::array();
  for (int r = 0; r < 3; ++r) R.push_back({m.rotation(r, 0), m.rotation(r, 1), m.rotation(r, 2)});
  c.source_json = json{{"kind", "scan"},
                       {"path", m.scan.source},
                       {"format", m.scan.format},
                       {"modality", "surface scan"},
                       {"vertices", m.scan.mesh.n_vertices()},
                       {"faces", m.scan.mesh.n_faces()},
                       {"texture", m.scan.texture_source},
                       {"mm_per_unit", m.mm_per_unit},
                       {"height_mm", m.height_mm},
                       {"up", axis_name(o.up)},
                       {"front", axis_name(o.front)},
                       {"faces_flipped", o.flip_faces},
                       {"to_lps", R},
                       {"credit", o.credit},
                       {"notes", m.scan.notes}}
                      .dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
  c.segmentation_json = json{{"skin_method", "surface scan: outermost hit of the ray from the axis"},
                             {"bone_method", cat("skin moved inward by a constant ", o.thickness_mm,
                                                 " mm")},
                             {"bone_is_approximate", true},
                             {"inside_out_cells", m.inside_out_cells}}
                            .dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
  c.thickness_json = json{{"kind", "constant"},
                          {"thickness_mm", o.thickness_mm},
                          {"assumption", "a constant soft-tissue thickness, as the 1992 CAPS "
                                         "system assumed for surface scans: r_bone = r_skin - "
                                         "thickness_mm (radially)"},
                          {"radial", "r_skin - r_bone along the ray from the axis"},
                          {"normal", "distance from the skin point to the bone surface: "
                                     "thickness_mm x cos(angle between the ray and the skin normal)"},
                          {"fill", "cells without skin: r_skin filled by harmonic interpolation; "
                                   "see validity.nrrd"}}
                         .dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
  write_model_directory(m, c, dir, force, reporter);
}

}  // namespace caps
