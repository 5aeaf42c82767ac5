#include "caps/volume/cylindrical_map.hpp"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "caps/core/error.hpp"
#include "caps/core/reporter.hpp"
#include "caps/core/units.hpp"
#include "caps/volume/morphology.hpp"

namespace caps {

Eigen::Vector3d CylinderAxis::ray(double theta_rad) const {
  return std::cos(theta_rad) * front + std::sin(theta_rad) * left();
}

Eigen::Vector3d CylinderAxis::to_lps(double theta_rad, double z_mm, double r_mm) const {
  return origin_lps + z_mm * direction + r_mm * ray(theta_rad);
}

Eigen::Vector3d CylinderAxis::to_cylindrical(const Eigen::Vector3d& p) const {
  const Eigen::Vector3d q = p - origin_lps;
  const double z = q.dot(direction);
  const Eigen::Vector3d radial = q - z * direction;
  double theta = std::atan2(radial.dot(left()), radial.dot(front));
  if (theta >= kPi) theta -= 2 * kPi;
  return {theta, z, radial.norm()};
}

void CylindricalMaps::allocate() {
  const std::size_t n = grid.size();
  for (auto* img : {&r_skin, &r_bone, &thickness, &thickness_normal}) img->assign(n, 0.0f);
  for (auto* img : {&flags, &measured_skin, &measured_bone}) img->assign(n, 0);
}

std::string describe_flags(std::uint8_t flags) {
  if (flags == 0) return "valid";
  static const std::pair<std::uint8_t, const char*> kNames[] = {
      {kNoSkin, "no_skin"}, {kNoBone, "no_bone"}, {kUndercut, "undercut"},
      {kGrazing, "grazing"}, {kTruncated, "truncated"}};
  std::string s;
  for (const auto& [bit, name] : kNames)
    if (flags & bit) s += (s.empty() ? "" : "|") + std::string(name);
  return s;
}

CylinderAxis fit_axis(const Segmentation& seg) {
  const Mask& m = seg.skin;
  const auto& g = m.geom;
  // Area-weighted centre of the head's cross-sections in 2 mm bands of LPS z.
  constexpr double kBand = 2.0;
  struct Band { double n = 0, x = 0, y = 0; };
  std::vector<Band> bands;
  double zmin = std::numeric_limits<double>::max();
  std::vector<Eigen::Vector3d> pts;
  for (int k = 0; k < g.dims[2]; ++k)
    for (int j = 0; j < g.dims[1]; ++j)
      for (int i = 0; i < g.dims[0]; ++i)
        if (m.at(i, j, k)) {
          const Eigen::Vector3d p = g.index_to_lps(Eigen::Vector3d(i, j, k));
          zmin = std::min(zmin, p[2]);
          const auto b = static_cast<std::size_t>(std::max(0.0, (p[2] + 1000.0) / kBand));
          if (b >= bands.size()) bands.resize(b + 1);
          bands[b].n += 1; bands[b].x += p[0]; bands[b].y += p[1];
        }
  double max_n = 0;
  for (const auto& b : bands) max_n = std::max(max_n, b.n);
  if (max_n == 0) throw InvalidInput(cat(seg.working.source, ": cannot fit an axis: no head"));
  double w = 0, cx = 0, cy = 0;
  for (const auto& b : bands)
    if (b.n >= 0.3 * max_n) { w += b.n; cx += b.x; cy += b.y; }
  CylinderAxis axis;
  axis.origin_lps = {cx / w, cy / w, 0.0};
  return axis;
}

namespace {

// Trilinear sampling of a volume at LPS points.
struct Field {
  const Volume* v;
  Eigen::Matrix3d to_index;
  Eigen::Vector3d origin;
  float outside;
  std::ptrdiff_t sj, sk;
  Field(const Volume& vol, float outside_value) : v(&vol), outside(outside_value) {
    to_index = Eigen::Matrix3d(vol.geom.direction * vol.geom.spacing_mm.asDiagonal()).inverse();
    origin = vol.geom.origin_lps;
    sj = vol.geom.dims[0];
    sk = std::ptrdiff_t(vol.geom.dims[0]) * vol.geom.dims[1];
  }
  // The same value as sample_trilinear(), inlined: this is the ray caster's innermost call.
  float operator()(const Eigen::Vector3d& p) const {
    const Eigen::Vector3d q = to_index * (p - origin);
    const auto& d = v->geom.dims;
    if (!(q[0] >= 0 && q[1] >= 0 && q[2] >= 0 && q[0] < d[0] - 1 && q[1] < d[1] - 1 &&
          q[2] < d[2] - 1))
      return sample_trilinear(*v, q, outside);  // the grid's last layer, or outside
    const int i = static_cast<int>(q[0]), j = static_cast<int>(q[1]), k = static_cast<int>(q[2]);
    const double fx = q[0] - i, fy = q[1] - j, fz = q[2] - k;
    const float* c = v->data.data() + (k * sk + j * sj + i);
    const double c00 = c[0] + fx * (c[1] - c[0]);
    const double c10 = c[sj] + fx * (c[sj + 1] - c[sj]);
    const double c01 = c[sk] + fx * (c[sk + 1] - c[sk]);
    const double c11 = c[sk + sj] + fx * (c[sk + sj + 1] - c[sk + sj]);
    const double c0 = c00 + fy * (c10 - c00), c1 = c01 + fy * (c11 - c01);
    return static_cast<float>(c0 + fz * (c1 - c0));
  }
};

// Nearest-voxel lookup in a mask at LPS points (0 outside the grid).
struct MaskAt {
  const Mask* m;
  Eigen::Matrix3d to_index;
  Eigen::Vector3d origin;
  explicit MaskAt(const Mask& mask) : m(&mask) {
    to_index = Eigen::Matrix3d(mask.geom.direction * mask.geom.spacing_mm.asDiagonal()).inverse();
    origin = mask.geom.origin_lps;
  }
  long index(const Eigen::Vector3d& p) const {
    const Eigen::Vector3d q = to_index * (p - origin);
    // floor(x + 0.5): nearest voxel; much cheaper than lround on this hot path.
    const int i = static_cast<int>(std::floor(q[0] + 0.5)), j = static_cast<int>(std::floor(q[1] + 0.5)),
              k = static_cast<int>(std::floor(q[2] + 0.5));
    return m->geom.contains(i, j, k) ? static_cast<long>(m->geom.linear(i, j, k)) : -1;
  }
  bool operator()(const Eigen::Vector3d& p) const {
    const long n = index(p);
    return n >= 0 && m->data[static_cast<std::size_t>(n)];
  }
};

// The parameter interval [t0, t1] where the ray c + t d is inside the grid's box.
bool clip_to_grid(const VolumeGeometry& g, const Eigen::Vector3d& c, const Eigen::Vector3d& d,
                  double& t0, double& t1) {
  const Eigen::Matrix3d to_index = Eigen::Matrix3d(g.direction * g.spacing_mm.asDiagonal()).inverse();
  const Eigen::Vector3d q = to_index * (c - g.origin_lps), e = to_index * d;
  t0 = 0.0;
  t1 = std::numeric_limits<double>::max();
  for (int a = 0; a < 3; ++a) {
    const double lo = 0.0, hi = g.dims[a] - 1.0;
    if (std::abs(e[a]) < 1e-12) {
      if (q[a] < lo || q[a] > hi) return false;
      continue;
    }
    double ta = (lo - q[a]) / e[a], tb = (hi - q[a]) / e[a];
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
  }
  return t1 > t0;
}

// Outermost r in [r_lo, r_hi] where f(r) >= level, searching inward with `step`, refined by
// bisection. Returns NaN if f stays below the level.
template <typename F>
double crossing_inward(const F& f, double r_hi, double r_lo, double step, double level) {
  double prev = r_hi;
  if (f(r_hi) >= level) return r_hi;
  for (double r = r_hi - step;; r -= step) {
    if (r < r_lo) r = r_lo;
    if (f(r) >= level) {
      double a = r, b = prev;  // f(a) >= level > f(b)
      for (int it = 0; it < 30 && b - a > 1e-4; ++it) {
        const double m = 0.5 * (a + b);
        (f(m) >= level ? a : b) = m;
      }
      return 0.5 * (a + b);
    }
    if (r <= r_lo) break;
    prev = r;
  }
  return std::numeric_limits<double>::quiet_NaN();
}

double median(std::vector<double>& xs) {
  std::nth_element(xs.begin(), xs.begin() + xs.size() / 2, xs.end());
  return xs[xs.size() / 2];
}

}  // namespace

// Fills cells where known == 0 smoothly from the known ones: a pull-push pyramid (Gortler et al.
// 1996, "The Lumigraph", sec. 3.4) gives every cell a value from its nearest known
// neighbourhood, then Gauss-Seidel sweeps of Laplace's equation (known cells fixed, periodic in
// theta, no flux at the z ends) smooth the filled region towards the harmonic interpolant.
void harmonic_fill(std::vector<float>& img, const std::vector<std::uint8_t>& known,
                   const CylinderGrid& g) {
  std::size_t n_known = 0;
  for (auto k : known) n_known += k != 0;
  if (n_known == img.size() || n_known == 0) return;
  // Pull: weighted means over 2x2 blocks, level by level, until one cell is left.
  struct Level { int w, h; std::vector<double> v, wt; };
  std::vector<Level> levels(1);
  levels[0] = {g.n_theta, g.n_z, std::vector<double>(img.size()), std::vector<double>(img.size())};
  for (std::size_t i = 0; i < img.size(); ++i) {
    levels[0].wt[i] = known[i] ? 1.0 : 0.0;
    levels[0].v[i] = known[i] ? img[i] : 0.0;
  }
  while (levels.back().w > 1 || levels.back().h > 1) {
    const Level& f = levels.back();
    Level c{(f.w + 1) / 2, (f.h + 1) / 2, {}, {}};
    c.v.assign(std::size_t(c.w) * c.h, 0.0);
    c.wt.assign(c.v.size(), 0.0);
    for (int y = 0; y < f.h; ++y)
      for (int x = 0; x < f.w; ++x) {
        const std::size_t fi = std::size_t(y) * f.w + x, ci = std::size_t(y / 2) * c.w + x / 2;
        c.v[ci] += f.v[fi] * f.wt[fi];
        c.wt[ci] += f.wt[fi];
      }
    for (std::size_t i = 0; i < c.v.size(); ++i) {
      if (c.wt[i] > 0) c.v[i] /= c.wt[i];
      c.wt[i] = std::min(1.0, c.wt[i]);
    }
    levels.push_back(std::move(c));
  }
  // Push: cells without weight take their parent's value.
  for (std::size_t l = levels.size() - 1; l-- > 0;) {
    Level& f = levels[l];
    const Level& c = levels[l + 1];
    for (int y = 0; y < f.h; ++y)
      for (int x = 0; x < f.w; ++x) {
        const std::size_t fi = std::size_t(y) * f.w + x, ci = std::size_t(y / 2) * c.w + x / 2;
        if (f.wt[fi] < 1.0) f.v[fi] = f.wt[fi] * f.v[fi] + (1.0 - f.wt[fi]) * c.v[ci];
      }
  }
  for (std::size_t i = 0; i < img.size(); ++i)
    if (!known[i]) img[i] = static_cast<float>(levels[0].v[i]);
  for (int sweep = 0; sweep < 40; ++sweep)
    for (int k = 0; k < g.n_z; ++k)
      for (int j = 0; j < g.n_theta; ++j) {
        const std::size_t c = g.index(j, k);
        if (known[c]) continue;
        const int jl = (j + g.n_theta - 1) % g.n_theta, jr = (j + 1) % g.n_theta;
        const int kd = std::max(0, k - 1), ku = std::min(g.n_z - 1, k + 1);
        img[c] = 0.25f * (img[g.index(jl, k)] + img[g.index(jr, k)] + img[g.index(j, kd)] +
                          img[g.index(j, ku)]);
      }
}

// Marks measured cells whose ray meets the skin at more than `limit_deg` from its normal. The
// normal is that of the range surface r(theta, z): in the (radial, tangential, axial) frame it is
// (1, -r_theta / r, -r_z), so cos(angle) = 1 / sqrt(1 + (r_theta / r)^2 + r_z^2). Differences are
// central where both neighbours were measured, one-sided otherwise.
void flag_grazing(CylindricalMaps& maps, double limit_deg) {
  const auto& g = maps.grid;
  const double cos_limit = std::cos(deg_to_rad(limit_deg));
  const double dth = deg_to_rad(g.dtheta_deg());
  auto derivative = [&](std::size_t c, std::size_t lo, std::size_t hi, bool lo_ok, bool hi_ok,
                        double h) {
    if (lo_ok && hi_ok) return (maps.r_skin[hi] - maps.r_skin[lo]) / (2 * h);
    if (hi_ok) return (maps.r_skin[hi] - maps.r_skin[c]) / h;
    if (lo_ok) return (maps.r_skin[c] - maps.r_skin[lo]) / h;
    return 0.0;
  };
  for (int k = 0; k < g.n_z; ++k)
    for (int j = 0; j < g.n_theta; ++j) {
      const std::size_t c = g.index(j, k);
      if (!maps.measured_skin[c]) continue;
      const std::size_t l = g.index((j + g.n_theta - 1) % g.n_theta, k);
      const std::size_t r = g.index((j + 1) % g.n_theta, k);
      const std::size_t d = g.index(j, std::max(0, k - 1)), u = g.index(j, std::min(g.n_z - 1, k + 1));
      const double r_th = derivative(c, l, r, maps.measured_skin[l], maps.measured_skin[r], dth);
      const double r_z = derivative(c, d, u, k > 0 && maps.measured_skin[d],
                                    k + 1 < g.n_z && maps.measured_skin[u], g.dz_mm);
      const double rr = std::max<double>(maps.r_skin[c], 1e-6);
      const double cos_angle = 1.0 / std::sqrt(1.0 + std::pow(r_th / rr, 2) + r_z * r_z);
      if (cos_angle < cos_limit) maps.flags[c] |= kGrazing;
    }
}

CylindricalMaps cylindrical_maps(const Volume& v, const Segmentation& seg, const CylinderAxis& axis,
                                 const MapOptions& o, Reporter* reporter) {
  if (o.n_theta < 8 || o.n_theta > 8192 || o.n_z < 4 || o.n_z > 8192)
    throw InvalidInput(cat("cylindrical grid ", o.n_theta, " x ", o.n_z,
                           " is out of range (theta 8..8192, z 4..8192)"));
  if (!(o.bone_cap_mm > 0 && o.bone_cap_mm <= 200))
    throw InvalidInput(cat("bone cap ", o.bone_cap_mm, " mm must be in (0, 200]"));
  Progress progress(reporter, "casting cylindrical rays", 1.0);
  CylindricalMaps maps;
  maps.axis = axis;
  auto& grid = maps.grid;
  grid.n_theta = o.n_theta;
  grid.n_z = o.n_z;

  // z extent: the head's extent along the axis.
  const auto& wg = seg.skin.geom;
  double zlo = std::numeric_limits<double>::max(), zhi = -zlo;
  for (int k = 0; k < wg.dims[2]; ++k)
    for (int j = 0; j < wg.dims[1]; ++j)
      for (int i = 0; i < wg.dims[0]; ++i)
        if (seg.skin.at(i, j, k)) {
          const double z = (wg.index_to_lps(Eigen::Vector3d(i, j, k)) - axis.origin_lps)
                               .dot(axis.direction);
          zlo = std::min(zlo, z);
          zhi = std::max(zhi, z);
        }
  if (!(zhi > zlo)) throw InvalidInput(cat(v.source, ": no head found for the cylindrical map"));
  if (o.z_min_mm) zlo = *o.z_min_mm;
  if (o.z_max_mm) zhi = *o.z_max_mm;
  if (!(zhi > zlo))
    throw InvalidInput(cat("cylindrical grid: z range ", zlo, " .. ", zhi, " mm is empty"));
  grid.z0_mm = zlo;
  grid.dz_mm = (zhi - zlo) / (grid.n_z - 1);

  // The head's largest radius near each row (within a working voxel's diagonal in z), so that
  // every ray starts its walk just outside the head rather than at the grid's far corner.
  std::vector<double> row_r_max(static_cast<std::size_t>(grid.n_z), 0.0);
  {
    const double reach = wg.spacing_mm.norm();
    for (int k = 0; k < wg.dims[2]; ++k)
      for (int j = 0; j < wg.dims[1]; ++j)
        for (int i = 0; i < wg.dims[0]; ++i) {
          if (!seg.skin.at(i, j, k)) continue;
          const Eigen::Vector3d q = wg.index_to_lps(Eigen::Vector3d(i, j, k)) - axis.origin_lps;
          const double z = q.dot(axis.direction);
          const double r = (q - z * axis.direction).norm() + reach;
          const int k0 = std::max(0, static_cast<int>(std::floor((z - reach - grid.z0_mm) / grid.dz_mm)));
          const int k1 = std::min(grid.n_z - 1, static_cast<int>(std::ceil((z + reach - grid.z0_mm) / grid.dz_mm)));
          for (int kk = k0; kk <= k1; ++kk) row_r_max[kk] = std::max(row_r_max[kk], r);
        }
  }

  const std::size_t n = grid.size();
  maps.allocate();

  const float lowest = *std::min_element(v.data.begin(), v.data.end());
  const Field intensity(v, lowest);
  const MaskAt skin_at(seg.skin), bone_at(seg.bone);
  const bool bone_by_threshold = std::isfinite(seg.bone_threshold);
  // Bone given as a mask (MR): its surface is the 0.5 level of the trilinearly sampled mask.
  Volume bone_float;
  bone_float.geom = seg.bone.geom;
  bone_float.data.assign(seg.bone.data.begin(), seg.bone.data.end());
  const Field bone_mask_field(bone_float, 0.0f);
  const float bone_level_default =
      bone_by_threshold ? static_cast<float>(seg.bone_threshold) : 0.5f;
  auto bone_value = [&](const Eigen::Vector3d& p) {
    return bone_by_threshold ? intensity(p) : bone_mask_field(p);
  };

  std::vector<std::int64_t> nearest_bone;
  squared_distance_mm2(seg.bone, &nearest_bone);

  const double w = wg.spacing_mm.maxCoeff();             // working voxel
  const double coarse = 0.5 * wg.spacing_mm.minCoeff();  // mask marching step
  const double fine = 0.25 * v.geom.spacing_mm.minCoeff();
  const double edge_span = std::max(1.5, 1.5 * v.geom.spacing_mm.maxCoeff());
  const double ramp = v.geom.spacing_mm.maxCoeff();  // width of an edge's partial-volume ramp
  const bool is_ct = v.modality == Modality::CT;
  // Physical ranges of CT plateaus (HU): air, and soft tissue from fat to muscle.
  constexpr double kCtAirHu[2] = {-1024.0, -850.0};
  constexpr double kCtTissueHu[2] = {-200.0, 150.0};
  const float skin_thr = static_cast<float>(seg.skin_threshold);

  tbb::parallel_for(0, grid.n_z, [&](int k) {
    std::vector<double> samples;
    for (int j = 0; j < grid.n_theta; ++j) {
      const std::size_t c = grid.index(j, k);
      const double theta = deg_to_rad(grid.theta_deg(j));
      const Eigen::Vector3d centre = axis.origin_lps + grid.z_mm(k) * axis.direction;
      const Eigen::Vector3d d = axis.ray(theta);
      auto at = [&](double r) { return Eigen::Vector3d(centre + r * d); };
      double t0, t1;
      if (!clip_to_grid(wg, centre, d, t0, t1)) { maps.flags[c] = kNoSkin; continue; }
      t1 = std::min(t1, std::max(t0, row_r_max[k]));
      // 1. Walk the envelope mask inward: the outermost entry, and any re-entry (undercut).
      double r_entry = std::numeric_limits<double>::quiet_NaN();
      // A re-entry counts as an undercut only after a real air gap (kMinGapMm): a ledge in the
      // mask between thick slices is not an ear.
      constexpr double kMinGapMm = kUndercutMinGapMm;
      bool inside = skin_at(at(t1));
      if (inside) maps.flags[c] |= kTruncated;
      if (inside) r_entry = t1;
      int entries = inside ? 1 : 0;
      double r_left = t1;  // where the ray last left the mask
      // Below the outermost skin, only the bone cap's depth matters for undercuts.
      double r_stop = t0;
      for (double r = t1 - coarse; r >= r_stop; r -= coarse) {
        const bool now = skin_at(at(r));
        if (now && !inside) {
          if (entries == 0) {
            r_entry = r + 0.5 * coarse;
            entries = 1;
            r_stop = std::max(t0, r_entry - o.bone_cap_mm);
          } else if (r_left - r >= kMinGapMm) {
            ++entries;
          }
        }
        if (!now && inside) r_left = r;
        inside = now;
      }
      if (entries == 0) { maps.flags[c] = kNoSkin; continue; }
      if (entries > 1) maps.flags[c] |= kUndercut;
      // 2. Refine on the full-resolution intensities near the mask's edge, seen only through
      // the mask's boundary layer (one working voxel outward), so an object lying just outside
      // the head (a head holder on its pad) cannot be taken for the skin.
      const auto I = [&](double r) { return intensity(at(r)); };
      const auto I_gated = [&](double r) {
        return skin_at(at(r)) || skin_at(at(r - w)) ? intensity(at(r)) : lowest;
      };
      double r_s = crossing_inward(I_gated, r_entry + 2 * w, std::max(0.0, r_entry - 2 * w), fine,
                                   skin_thr);
      if (!std::isfinite(r_s)) r_s = r_entry;
      // 3. First bone inward from the skin, within the cap.
      double r_b = std::numeric_limits<double>::quiet_NaN();
      for (double r = r_s; r >= std::max(0.0, r_s - o.bone_cap_mm); r -= coarse)
        if (bone_at(at(r))) { r_b = r; break; }
      const auto B = [&](double r) { return bone_value(at(r)); };
      if (std::isfinite(r_b)) {
        const double rb = crossing_inward(B, std::min(r_s, r_b + 2 * w), std::max(0.0, r_b - 2 * w),
                                          fine, bone_level_default);
        if (std::isfinite(rb)) r_b = rb;
      }
      // 4. Half-maximum edges: the threshold finds an edge, the level halfway between the
      // plateaus on either side locates it, independent of the threshold's value.
      // The soft-tissue plateau is sampled between the two edges' ramps where at least 1 mm is
      // left free of both; thinner tissue on coarse voxels has no plateau, and CT then falls back
      // on soft tissue's physical value. CT plateaus are kept within their physical ranges.
      double air = I_gated(r_s + edge_span);
      double tissue = std::numeric_limits<double>::quiet_NaN();
      if (std::isfinite(r_b) && (r_s - r_b) - ramp >= 1.0) {
        samples.clear();
        // About 16 samples: a median needs no more, and thick tissue would otherwise cost 100s.
        const double step = std::max(fine, (r_s - r_b - ramp) / 16.0);
        for (double r = r_b + 0.5 * ramp; r <= r_s - 0.5 * ramp; r += step) samples.push_back(I(r));
        if (samples.size() >= 3) tissue = median(samples);
      } else if (!std::isfinite(r_b)) {
        tissue = I(std::max(0.0, r_s - edge_span));
      }
      if (is_ct) {
        tissue = std::isfinite(tissue) ? std::clamp(tissue, kCtTissueHu[0], kCtTissueHu[1]) : 0.0;
        air = std::clamp(air, kCtAirHu[0], kCtAirHu[1]);
      } else if (!std::isfinite(tissue)) {
        tissue = I(std::max(0.0, r_s - edge_span));
      }
      if (air < skin_thr && tissue > skin_thr) {
        const double rs = crossing_inward(I_gated, r_s + edge_span, std::max(0.0, r_s - edge_span),
                                          fine, 0.5 * (air + tissue));
        if (std::isfinite(rs)) r_s = rs;
      }
      double bone_level = bone_level_default;
      if (std::isfinite(r_b) && bone_by_threshold) {
        double peak = -std::numeric_limits<double>::max();
        for (double r = r_b; r >= std::max(0.0, r_b - 4.0); r -= fine) peak = std::max<double>(peak, I(r));
        if (tissue < bone_level_default && peak > bone_level_default) {
          const double rb = crossing_inward(I, std::min(r_s, r_b + edge_span),
                                            std::max(0.0, r_b - edge_span), fine,
                                            0.5 * (tissue + peak));
          if (std::isfinite(rb)) {
            r_b = rb;
            bone_level = 0.5 * (tissue + peak);
          }
        }
      }
      maps.r_skin[c] = static_cast<float>(r_s);
      maps.measured_skin[c] = 1;
      const Eigen::Vector3d p = at(r_s);
      // The skin point sits on the edge of the acquired data: a cut face, not skin.
      if (near_data_edge(v, p, 1.5)) maps.flags[c] |= kTruncated;
      if (!std::isfinite(r_b)) {
        maps.flags[c] |= kNoBone;
        continue;
      }
      maps.r_bone[c] = static_cast<float>(r_b);
      maps.thickness[c] = static_cast<float>(r_s - r_b);
      maps.measured_bone[c] = 1;
      // 5. Thickness along the normal: distance to the nearest bone, found through the exact
      // feature transform on the working grid and refined on the bone's edge.
      const long cell = skin_at.index(p);
      const std::int64_t q_idx = cell >= 0 ? nearest_bone[static_cast<std::size_t>(cell)] : -1;
      double tn = r_s - r_b;
      if (q_idx >= 0) {
        const auto& bg = seg.bone.geom;
        const int qi = static_cast<int>(q_idx % bg.dims[0]);
        const int qj = static_cast<int>((q_idx / bg.dims[0]) % bg.dims[1]);
        const int qk = static_cast<int>(q_idx / (std::int64_t(bg.dims[0]) * bg.dims[1]));
        const Eigen::Vector3d q = bg.index_to_lps(Eigen::Vector3d(qi, qj, qk));
        const double len = (q - p).norm();
        if (len > 1e-6) {
          const Eigen::Vector3d u = (q - p) / len;
          const auto Bs = [&](double s) { return bone_value(Eigen::Vector3d(p + (len - s) * u)); };
          // Parameterised so "inward" runs from the skin (s = len) to past the bone site. q is
          // the nearest bone voxel, so the edge lies within two working voxels of it.
          const double s = crossing_inward(Bs, std::min(len, 2 * w), -w, fine, bone_level);
          if (std::isfinite(s)) tn = std::min(tn, len - s);
        }
      }
      maps.thickness_normal[c] = static_cast<float>(tn);
    }
  });
  progress.update(0.8);

  flag_grazing(maps, o.grazing_deg);
  std::size_t n_measured = 0;
  for (auto m : maps.measured_skin) n_measured += m;
  if (n_measured == 0)
    throw InvalidInput(cat(v.source, ": no ray from the axis met the skin; the head was not found"));
  harmonic_fill(maps.r_skin, maps.measured_skin, grid);
  harmonic_fill(maps.thickness, maps.measured_bone, grid);
  harmonic_fill(maps.thickness_normal, maps.measured_bone, grid);
  for (std::size_t i = 0; i < n; ++i) {
    maps.thickness[i] = std::max(0.0f, maps.thickness[i]);
    maps.r_bone[i] = maps.r_skin[i] - maps.thickness[i];
  }
  progress.done();
  return maps;
}

}  // namespace caps
