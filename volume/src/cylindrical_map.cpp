#include "caps/volume/cylindrical_map.hpp"

#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <queue>

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

void CylindricalMaps::allocate_layers() {
  const std::size_t n = grid.size();
  for (auto* img : {&thickness_skin, &thickness_fat, &thickness_deep, &thickness_skin_normal,
                    &thickness_fat_normal, &thickness_deep_normal})
    img->assign(n, 0.0f);
  for (auto* img : {&layer_flags, &layer_flags_normal}) img->assign(n, kLayerNoThickness);
}

std::string describe_layer_flags(std::uint8_t flags) {
  if (flags == 0) return "measured";
  static const std::pair<std::uint8_t, const char*> kNames[] = {
      {kLayerNoThickness, "no_thickness"}, {kLayerNoFat, "no_fat"},
      {kLayerSeveralBands, "several_fat_bands"}, {kLayerNoContrast, "no_contrast"},
      {kLayerThinSkin, "thin_skin"}};
  std::string s;
  for (const auto& [bit, name] : kNames)
    if (flags & bit) s += (s.empty() ? "" : "|") + std::string(name);
  return s;
}

LayerSplit split_layers(const std::function<double(double)>& hu, double length_mm, double step_mm,
                        double ramp_mm, const LayerOptions& o) {
  LayerSplit out;
  out.skin_mm = std::max(0.0, length_mm);
  out.flags = kLayerNoFat;
  if (!(length_mm > 0) || !(step_mm > 0)) return out;
  const double level = o.fat_level_hu;
  const int n = std::max(1, static_cast<int>(std::ceil(length_mm / step_mm)));
  const double h = length_mm / n;
  thread_local std::vector<double> f;
  f.resize(static_cast<std::size_t>(n) + 1);
  for (int i = 0; i <= n; ++i) f[i] = hu(i * h);
  // The crossing of the level between samples i - 1 and i: linear interpolation, then one more
  // interpolation inside the part of the interval that still holds the crossing.
  auto crossing = [&](int i) {
    double a = (i - 1) * h, b = i * h, fa = f[i - 1] - level, fb = f[i] - level;
    const double s = a + (b - a) * fa / (fa - fb);
    const double fs = hu(s) - level;
    if ((fs < 0) == (fa < 0)) { a = s; fa = fs; } else { b = s; fb = fs; }
    return fa == fb ? s : a + (b - a) * fa / (fa - fb);
  };
  // Past the skin's partial-volume ramp: the first rise to the level. A profile still below it
  // two ramps and a millimetre deep has fat from the skin's ramp on: the dermis is not resolved.
  const double window = std::min(length_mm, 2.0 * ramp_mm + 1.0);
  int i0 = -1;
  for (int i = 0; i <= n && i * h <= window; ++i)
    if (f[i] >= level) { i0 = i; break; }
  struct Band { double top, bottom; };
  std::vector<Band> bands;
  double top = 0.0;
  bool in_fat = i0 < 0;
  for (int i = std::max(1, i0 + 1); i <= n; ++i) {
    const bool below = f[i] < level;
    if (below && !in_fat) top = crossing(i);
    if (!below && in_fat) bands.push_back({top, crossing(i)});
    in_fat = below;
  }
  if (in_fat) bands.push_back({top, length_mm});
  std::vector<Band> merged;
  for (const Band& b : bands) {
    if (!merged.empty() && b.top - merged.back().bottom < o.merge_gap_mm)
      merged.back().bottom = b.bottom;
    else
      merged.push_back(b);
  }
  std::erase_if(merged, [&](const Band& b) { return b.bottom - b.top < o.min_band_mm; });
  if (merged.empty()) return out;
  out.skin_mm = merged.front().top;
  out.fat_mm = merged.back().bottom - merged.front().top;
  out.deep_mm = length_mm - merged.back().bottom;
  out.flags = merged.size() > 1 ? kLayerSeveralBands : 0;
  if (i0 < 0 && merged.front().top == 0.0) out.flags |= kLayerThinSkin;
  return out;
}

std::string describe_flags(std::uint8_t flags) {
  if (flags == 0) return "valid";
  static const std::pair<std::uint8_t, const char*> kNames[] = {
      {kNoSkin, "no_skin"}, {kNoBone, "no_bone"}, {kUndercut, "undercut"},
      {kGrazing, "grazing"}, {kTruncated, "truncated"}, {kBaseCavity, "base_cavity"},
      {kEye, "eye"}, {kBaseTissue, "base_tissue"}};
  std::string s;
  for (const auto& [bit, name] : kNames)
    if (flags & bit) s += (s.empty() ? "" : "|") + std::string(name);
  return s;
}

std::string invalid_flags_advice(std::uint8_t flags) {
  if (flags_valid(flags)) return {};
  const std::string names = describe_flags(flags & kInvalidFlags);
  if (flags & kEye)
    return cat("is not operable here: it lies on the eye (", names, "; the lids over the globe, "
               "which is no tissue to close a wound on); move the plan off the eye");
  if (flags & (kNoSkin | kTruncated))
    return cat("is not operable here: the scan does not cover the skin there (", names,
               "; the scan's field of view ends or cuts the head, or metal streaks hide the "
               "slices: model.json segmentation.metal); move the plan onto scanned skin, or build "
               "the model from a scan that covers this region");
  if (flags & (kUndercut | kGrazing))
    return cat("lies where the model cannot represent the skin yet (", names, "): the ray from "
               "the head's axis crosses the skin twice (undercut: nostrils, under the nose and "
               "the chin, ears) or meets it edge-on (grazing), so its cylindrical image does not "
               "hold this skin; move the plan onto skin that faces the axis, or make a local "
               "chart that faces this skin (caps model chart MODEL --at THETA,Z) and plan on it "
               "at --at 0,0 (docs/mesher.md, \"Local charts\")");
  return cat("has no base under the skin (", names, "): neither bone nor an air cavity was found "
             "within the bone cap, and no measured base lies within the tissue reach around it; "
             "move the plan, or rebuild the model with a deeper --bone-cap, a longer "
             "--tissue-reach or --bone-method edge (finds thin bone)");
}

const char* bone_method_name(BoneMethod method) {
  return method == BoneMethod::Threshold ? "threshold" : "edge";
}

BoneMethod parse_bone_method(const std::string& name) {
  if (name == "threshold") return BoneMethod::Threshold;
  if (name == "edge") return BoneMethod::Edge;
  throw InvalidInput(cat("bone method '", name, "': expected edge or threshold"));
}

CylinderAxis fit_axis(const Segmentation& seg, const CylinderAxis& oriented) {
  const Mask& m = seg.skin;
  const auto& g = m.geom;
  const Eigen::Vector3d& d = oriented.direction;
  const Eigen::Vector3d e1 = oriented.front, e2 = d.cross(e1);
  // Area-weighted centre of the head's cross-sections square to the axis, in 2 mm bands along it.
  constexpr double kBand = 2.0;
  struct Band { double n = 0, x = 0, y = 0; };
  std::vector<Band> bands;
  for (int k = 0; k < g.dims[2]; ++k)
    for (int j = 0; j < g.dims[1]; ++j)
      for (int i = 0; i < g.dims[0]; ++i)
        if (m.at(i, j, k)) {
          const Eigen::Vector3d p = g.index_to_lps(Eigen::Vector3d(i, j, k)) - oriented.origin_lps;
          const auto b = static_cast<std::size_t>(std::max(0.0, (p.dot(d) + 1000.0) / kBand));
          if (b >= bands.size()) bands.resize(b + 1);
          bands[b].n += 1; bands[b].x += p.dot(e1); bands[b].y += p.dot(e2);
        }
  double max_n = 0;
  for (const auto& b : bands) max_n = std::max(max_n, b.n);
  if (max_n == 0) throw InvalidInput(cat(seg.working.source, ": cannot fit an axis: no head"));
  double w = 0, cx = 0, cy = 0;
  for (const auto& b : bands)
    if (b.n >= 0.3 * max_n) { w += b.n; cx += b.x; cy += b.y; }
  CylinderAxis axis = oriented;
  axis.origin_lps = oriented.origin_lps + (cx / w) * e1 + (cy / w) * e2;
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

void fill_layers(std::vector<float>& skin, std::vector<float>& fat, std::vector<float>& deep,
                 const std::vector<std::uint8_t>& layer_flags, const std::vector<float>& total,
                 const CylinderGrid& grid) {
  const std::size_t n = grid.size();
  std::vector<float> skin_fraction(n, 0.0f), fat_fraction(n, 0.0f);
  std::vector<std::uint8_t> skin_known(n, 0), fat_known(n, 0);
  for (std::size_t c = 0; c < n; ++c) {
    const double t = total[c];
    if (layer_flags[c] == 0 && t > 1e-3) {
      skin_fraction[c] = static_cast<float>(skin[c] / t);
      fat_fraction[c] = static_cast<float>(fat[c] / t);
      skin_known[c] = fat_known[c] = 1;
    } else if (layer_flags[c] == kLayerNoFat) {
      fat_known[c] = 1;  // seen: no fat
    }
  }
  tbb::parallel_invoke([&] { harmonic_fill(skin_fraction, skin_known, grid); },
                       [&] { harmonic_fill(fat_fraction, fat_known, grid); });
  for (std::size_t c = 0; c < n; ++c) {
    const double t = std::max(0.0f, total[c]);
    double s = skin[c], f = fat[c];
    if (layer_flags[c] != 0) {
      s = std::clamp<double>(skin_fraction[c], 0.0, 1.0) * t;
      f = std::clamp<double>(fat_fraction[c], 0.0, 1.0) * t;
    }
    if (s + f > t) {
      const double k = s + f > 0 ? t / (s + f) : 0.0;
      s *= k;
      f *= k;
    }
    skin[c] = static_cast<float>(s);
    fat[c] = static_cast<float>(f);
    deep[c] = static_cast<float>(std::max(0.0, t - s - f));
  }
}

namespace {

void check_map_options(const MapOptions& o) {
  if (o.n_theta < 8 || o.n_theta > 8192 || o.n_z < 4 || o.n_z > 8192)
    throw InvalidInput(cat("cylindrical grid ", o.n_theta, " x ", o.n_z,
                           " is out of range (theta 8..8192, z 4..8192)"));
  if (!(o.bone_cap_mm > 0 && o.bone_cap_mm <= 200))
    throw InvalidInput(cat("bone cap ", o.bone_cap_mm, " mm must be in (0, 200]"));
  if (!(o.bone.tissue_reach_mm >= 0 && o.bone.tissue_reach_mm <= 100))
    throw InvalidInput(cat("tissue reach ", o.bone.tissue_reach_mm, " mm must be in [0, 100] (how "
                           "far from a measured base a cell without bone takes an interpolated "
                           "one; 0: never)"));
  if (!(o.bone.floor_hu >= 50 && o.bone.floor_hu <= 1000))
    throw InvalidInput(cat("bone floor ", o.bone.floor_hu, " HU must be in [50, 1000] (a peak this "
                           "far above the soft tissue is bone; 150 by default)"));
  const LayerOptions& l = o.layers;
  if (!(l.fat_level_hu >= -500 && l.fat_level_hu <= 200))
    throw InvalidInput(cat("fat level ", l.fat_level_hu, " HU must be in [-500, 200] (halfway "
                           "between fat, about -100, and soft tissue, about +40)"));
  if (!(l.merge_gap_mm >= 0 && l.merge_gap_mm <= 20) || !(l.min_band_mm >= 0 && l.min_band_mm <= 20))
    throw InvalidInput(cat("fat band merge gap ", l.merge_gap_mm, " mm and minimum band ",
                           l.min_band_mm, " mm must be in [0, 20]"));
}

// The grid's z rows: by default the head's extent along the axis.
void set_z_rows(CylinderGrid& grid, const Volume& v, const Segmentation& seg,
                const CylinderAxis& axis, const MapOptions& o) {
  const auto& wg = seg.skin.geom;
  double zlo = std::numeric_limits<double>::max(), zhi = -zlo;
  for (int k = 0; k < wg.dims[2]; ++k)
    for (int j = 0; j < wg.dims[1]; ++j)
      for (int i = 0; i < wg.dims[0]; ++i)
        if (seg.skin.at(i, j, k)) {
          const double z =
              (wg.index_to_lps(Eigen::Vector3d(i, j, k)) - axis.origin_lps).dot(axis.direction);
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
}

// The head's largest radius near each row (within a working voxel's diagonal in z), so that
// every ray starts its walk just outside the head rather than at the grid's far corner.
std::vector<double> row_max_radii(const CylinderGrid& grid, const Segmentation& seg,
                                  const CylinderAxis& axis) {
  const auto& wg = seg.skin.geom;
  std::vector<double> row_r_max(static_cast<std::size_t>(grid.n_z), 0.0);
  const double reach = wg.spacing_mm.norm();
  for (int k = 0; k < wg.dims[2]; ++k)
    for (int j = 0; j < wg.dims[1]; ++j)
      for (int i = 0; i < wg.dims[0]; ++i) {
        if (!seg.skin.at(i, j, k)) continue;
        const Eigen::Vector3d q = wg.index_to_lps(Eigen::Vector3d(i, j, k)) - axis.origin_lps;
        const double z = q.dot(axis.direction);
        const double r = (q - z * axis.direction).norm() + reach;
        const int k0 =
            std::max(0, static_cast<int>(std::floor((z - reach - grid.z0_mm) / grid.dz_mm)));
        const int k1 = std::min(grid.n_z - 1,
                                static_cast<int>(std::ceil((z + reach - grid.z0_mm) / grid.dz_mm)));
        for (int kk = k0; kk <= k1; ++kk) row_r_max[kk] = std::max(row_r_max[kk], r);
      }
  return row_r_max;
}

// A bone mask as a volume of 0 and 1, whose 0.5 level is the bone's surface (MR).
Volume mask_as_volume(const Mask& mask) {
  Volume out;
  out.geom = mask.geom;
  out.data.assign(mask.data.begin(), mask.data.end());
  return out;
}

// A ray from the axis: centre + r d at radius r (mm).
struct Ray {
  Eigen::Vector3d centre, d;
  Eigen::Vector3d at(double r) const { return Eigen::Vector3d(centre + r * d); }
};

// Casts the ray of each cell of `maps.grid` (paper section 3) and stores what it meets: the
// skin's outermost crossing, the first bone under it and the thickness along the normal, with
// the cell's flags. Cells are independent; cast() may run in parallel for different cells.
class RayCaster {
  // Soft tissue's CT number where a ray has too few samples of its own (HU; muscle +20..+80).
  static constexpr double kNominalSoftHu = 40.0;

 public:
  RayCaster(const Volume& v, const Segmentation& seg, const MapOptions& o,
            const std::vector<double>& row_r_max, CylindricalMaps& maps)
      : v_(v),
        seg_(seg),
        o_(o),
        row_r_max_(row_r_max),
        maps_(maps),
        lowest_(*std::min_element(v.data.begin(), v.data.end())),
        intensity_(v, lowest_),
        skin_at_(seg.skin),
        bone_at_(seg.bone),
        bone_by_threshold_(std::isfinite(seg.bone_threshold)),
        bone_float_(mask_as_volume(seg.bone)),
        bone_mask_field_(bone_float_, 0.0f),
        bone_level_default_(bone_by_threshold_ ? static_cast<float>(seg.bone_threshold) : 0.5f),
        w_(seg.skin.geom.spacing_mm.maxCoeff()),
        coarse_(0.5 * seg.skin.geom.spacing_mm.minCoeff()),
        fine_(0.25 * v.geom.spacing_mm.minCoeff()),
        edge_span_(std::max(1.5, 1.5 * v.geom.spacing_mm.maxCoeff())),
        ramp_(v.geom.spacing_mm.maxCoeff()),
        is_ct_(v.modality == Modality::CT),
        skin_thr_(static_cast<float>(seg.skin_threshold)),
        measure_layers_(maps.has_layers()),
        layer_step_(0.5 * v.geom.spacing_mm.maxCoeff()),
        edge_method_(is_ct_ && bone_by_threshold_ && o.bone.method == BoneMethod::Edge),
        cavity_base_(is_ct_ && o.bone.cavity_base),
        lateral_mm_(v.geom.spacing_mm.maxCoeff()) {
    squared_distance_mm2(edge_method_ ? thin_bone_mask() : seg.bone, &nearest_bone_);
  }
  RayCaster(const RayCaster&) = delete;
  RayCaster& operator=(const RayCaster&) = delete;

  // `samples` is scratch space, one per thread.
  void cast(int j, int k, std::vector<double>& samples) const {
    const CylinderGrid& grid = maps_.grid;
    const CylinderAxis& axis = maps_.axis;
    const std::size_t c = grid.index(j, k);
    const double theta = deg_to_rad(grid.theta_deg(j));
    const Ray ray{axis.origin_lps + grid.z_mm(k) * axis.direction, axis.ray(theta)};
    double t0, t1;
    if (!clip_to_grid(seg_.skin.geom, ray.centre, ray.d, t0, t1)) {
      maps_.flags[c] = kNoSkin;
      return;
    }
    t1 = std::min(t1, std::max(t0, row_r_max_[k]));
    double r_first_exit = 0;
    const double r_entry = envelope_entry(ray, c, t0, t1, r_first_exit);
    if (!std::isfinite(r_entry)) {
      maps_.flags[c] = kNoSkin;
      return;
    }
    double r_s = skin_crossing(ray, r_entry);
    Base base;
    base.min_peak = bone_level_default_;
    if (edge_method_) {
      base = march_inward(ray, r_s, samples, true);
      // Bone that reaches the threshold starts from the threshold's crossing, as with the
      // threshold method, so the soft-tissue plateau (and the skin's edge) are sampled alike.
      if (std::isfinite(base.r_bone)) {
        const auto I = [&](double r) { return static_cast<double>(intensity_(ray.at(r))); };
        const double rb = crossing_inward(I, std::min(r_s, base.r_bone + 2 * w_),
                                          std::max(0.0, base.r_bone - 2 * w_), fine_,
                                          bone_level_default_);
        if (std::isfinite(rb)) base.r_bone = rb;
      }
    } else {
      base.r_bone = bone_crossing(ray, r_s);
      if (!std::isfinite(base.r_bone) && cavity_base_) base = march_inward(ray, r_s, samples, false);
    }
    double r_b = base.r_bone;
    const double bone_level = half_maximum_edges(ray, samples, r_s, r_b, base.min_peak);
    maps_.r_skin[c] = static_cast<float>(r_s);
    maps_.measured_skin[c] = 1;
    const Eigen::Vector3d p = ray.at(r_s);
    // The skin point sits on the edge of the acquired data: a cut face, not skin.
    if (near_data_edge(v_, p, 1.5)) maps_.flags[c] |= kTruncated;
    if (is_ct_ && over_globe(ray, r_s)) maps_.flags[c] |= kEye;  // confirmed by confirm_eyes()
    const bool on_cavity = !std::isfinite(r_b) && std::isfinite(base.r_cavity);
    if (!std::isfinite(r_b) && !on_cavity) {
      maps_.flags[c] |= kNoBone;
      return;
    }
    if (on_cavity) {
      r_b = base.r_cavity;
      maps_.flags[c] |= kBaseCavity;
    }
    // A re-entry below the base does not concern this cell: its column, skin to base, lies in
    // the tissue the ray meets first (the nasal wall over the nasal cavity's air, a lip or an
    // ear's rim over the air behind it). Only skin hidden above the base is an undercut.
    if ((maps_.flags[c] & kUndercut) && r_b >= r_first_exit - (w_ + coarse_))
      maps_.flags[c] &= static_cast<std::uint8_t>(~kUndercut);
    maps_.r_bone[c] = static_cast<float>(r_b);
    maps_.thickness[c] = static_cast<float>(r_s - r_b);
    maps_.measured_bone[c] = 1;
    Eigen::Vector3d inward = -ray.d;
    // Over a cavity the nearest bone lies beyond the air: the base is measured along the ray only.
    const double tn =
        on_cavity ? r_s - r_b : thickness_along_normal(p, r_s - r_b, bone_level, inward);
    maps_.thickness_normal[c] = static_cast<float>(tn);
    if (measure_layers_) {
      // One pointer captured: std::function keeps it without allocating.
      const struct { const Field& f; const Ray& ray; double r_s; const Eigen::Vector3d& p, &u; } q{
          intensity_, ray, r_s, p, inward};
      measure_layers(c, [x = &q](double s) { return x->f(x->ray.at(x->r_s - s)); }, r_s - r_b,
                     false);
      measure_layers(c, [x = &q](double s) { return x->f(Eigen::Vector3d(x->p + s * x->u)); }, tn,
                     true);
    }
  }

 private:
  // The globe under the lids (kEye): from past the skin's ramp, a run of soft tissue
  // kGlobeRunMm to kGlobeMaxRunMm deep (nothing below the fat level, no bone above +200 HU, no
  // air) that ends on a band of fat at least kOrbitFatMm thick (the orbit's fat behind it).
  bool over_globe(const Ray& ray, double r_s) const {
    // The search reaches past the deepest globe (27 mm) and the thickest lids (3 mm).
    constexpr double kStepMm = 0.5, kBoneHu = 200.0, kSearchMm = 40.0;
    const double fat_level = o_.layers.fat_level_hu;
    double first_fat = -1, fat_run = 0;
    for (double s = ramp_; s <= kSearchMm && r_s - s >= 0; s += kStepMm) {
      const double x = intensity_(ray.at(r_s - s));
      if (x > kBoneHu || x < skin_thr_) return false;
      if (x < fat_level) {
        if (fat_run == 0) first_fat = s;
        fat_run += kStepMm;
        if (fat_run >= kOrbitFatMm) return first_fat >= kGlobeRunMm && first_fat <= kGlobeMaxRunMm;
      } else {
        fat_run = 0;
      }
    }
    return false;
  }

  double bone_value(const Eigen::Vector3d& p) const {
    return bone_by_threshold_ ? intensity_(p) : bone_mask_field_(p);
  }
  // The intensity seen only through the mask's boundary layer (one working voxel outward), so
  // that an object lying just outside the head (a head holder on its pad) cannot be taken for
  // the skin.
  double gated_intensity(const Ray& ray, double r) const {
    return skin_at_(ray.at(r)) || skin_at_(ray.at(r - w_)) ? intensity_(ray.at(r)) : lowest_;
  }

  // 1. Walk the envelope mask inward from t1: the outermost entry (NaN if none), and any
  // re-entry (undercut, flagged in cell c). `r_first_exit`: where the ray first leaves the mask
  // below that entry (t0 if it does not within the bone cap).
  double envelope_entry(const Ray& ray, std::size_t c, double t0, double t1,
                        double& r_first_exit) const {
    double r_entry = std::numeric_limits<double>::quiet_NaN();
    // A re-entry counts as an undercut only after a real air gap (kMinGapMm): a ledge in the
    // mask between thick slices is not an ear.
    constexpr double kMinGapMm = kUndercutMinGapMm;
    bool inside = skin_at_(ray.at(t1));
    if (inside) maps_.flags[c] |= kTruncated;
    if (inside) r_entry = t1;
    int entries = inside ? 1 : 0;
    double r_left = t1;  // where the ray last left the mask
    // Below the outermost skin, only the bone cap's depth matters for undercuts.
    double r_stop = t0;
    r_first_exit = t0;
    bool exited = false;
    for (double r = t1 - coarse_; r >= r_stop; r -= coarse_) {
      const bool now = skin_at_(ray.at(r));
      if (now && !inside) {
        if (entries == 0) {
          r_entry = r + 0.5 * coarse_;
          entries = 1;
          r_stop = std::max(t0, r_entry - o_.bone_cap_mm);
        } else if (r_left - r >= kMinGapMm) {
          ++entries;
        }
      }
      if (!now && inside) {
        r_left = r;
        if (entries == 1 && !exited) r_first_exit = r + 0.5 * coarse_;
        exited = true;
      }
      inside = now;
    }
    if (entries == 0) return std::numeric_limits<double>::quiet_NaN();
    if (entries > 1) maps_.flags[c] |= kUndercut;
    return r_entry;
  }

  // 2. The skin refined on the full-resolution intensities near the mask's edge.
  double skin_crossing(const Ray& ray, double r_entry) const {
    const auto I_gated = [&](double r) { return gated_intensity(ray, r); };
    double r_s = crossing_inward(I_gated, r_entry + 2 * w_, std::max(0.0, r_entry - 2 * w_), fine_,
                                 skin_thr_);
    if (!std::isfinite(r_s)) r_s = r_entry;
    return r_s;
  }

  // 3. The first bone inward from the skin, within the cap (NaN if none).
  double bone_crossing(const Ray& ray, double r_s) const {
    double r_b = std::numeric_limits<double>::quiet_NaN();
    for (double r = r_s; r >= std::max(0.0, r_s - o_.bone_cap_mm); r -= coarse_)
      if (bone_at_(ray.at(r))) {
        r_b = r;
        break;
      }
    const auto B = [&](double r) { return bone_value(ray.at(r)); };
    if (std::isfinite(r_b)) {
      const double rb = crossing_inward(B, std::min(r_s, r_b + 2 * w_), std::max(0.0, r_b - 2 * w_),
                                        fine_, bone_level_default_);
      if (std::isfinite(rb)) r_b = rb;
    }
    return r_b;
  }

  // 3b. The edge method (bone_edge) and the cavity base: marches the full-resolution profile
  // inward from the skin, past its ramp, to the bone cap. With `find_bone`, the first sample at
  // least floor_hu above the ray's soft-tissue level (the median of the soft-tissue samples met so
  // far), confirmed laterally, is bone. A sample below the skin's tissue/air threshold past the
  // skin's ramp is a cavity's air (with cavity_base); its edge is placed at half maximum between
  // the soft tissue and the cavity's air. Whichever comes first ends the march.
  struct Base {
    double r_bone = std::numeric_limits<double>::quiet_NaN();
    double r_cavity = std::numeric_limits<double>::quiet_NaN();
    double min_peak = 0;  // the level that found r_bone
  };
  Base march_inward(const Ray& ray, double r_s, std::vector<double>& samples,
                    bool find_bone) const {
    // Physical bounds of the soft-tissue level (HU): from just above fat to muscle.
    constexpr double kSoftHu[2] = {0.0, 100.0};
    constexpr double kFatBelowHu = -30.0;  // samples below this are fat, not the reference
    constexpr double kTissueAboveHu = -200.0;  // fat and denser: tissue, not the skin's ramp
    // Air in a gap thinner than a voxel (a closed mouth, a nostril's slit) reads between fat and
    // air: a run of at least kPartialAirRunMm below kTissueAboveHu, after 2 mm of tissue, is a
    // cavity's air too (fat does not reach -200 HU).
    constexpr double kPartialAirRunMm = 1.0;
    double tissue_mm = 0, low_run_mm = 0, r_low = 0;
    const auto I = [&](double r) { return static_cast<double>(intensity_(ray.at(r))); };
    Base out;
    out.min_peak = bone_level_default_;
    samples.clear();
    auto soft_level = [&] {
      if (samples.size() < 3) return kNominalSoftHu;
      std::vector<double> xs = samples;
      return std::clamp(median(xs), kSoftHu[0], kSoftHu[1]);
    };
    // The cavity's edge: half maximum between the soft tissue and the air's lowest value.
    // The search starts at `from` (tissue) and runs inward past r_air.
    const auto cavity_at = [&](double r_air, double from) {
      const double soft = soft_level();
      double air = I(r_air);
      for (double t = 0; t <= 2.0 && r_air - t >= 0; t += fine_) air = std::min(air, I(r_air - t));
      const double level = 0.5 * (soft + std::max(air, -1024.0));
      const auto minus_I = [&](double q) { return -I(q); };
      const double rc = crossing_inward(minus_I, from, std::max(0.0, r_air - edge_span_),
                                        0.25 * fine_, -level);
      out.r_cavity = std::isfinite(rc) ? rc : r_air;
      return out;
    };
    const double r_end = std::max(0.0, r_s - o_.bone_cap_mm);
    for (double s = 0.5 * ramp_; r_s - s >= r_end; s += fine_) {
      const double r = r_s - s;
      const double x = I(r);
      if (find_bone && x >= kSoftHu[0] + o_.bone.floor_hu) {
        const double soft = soft_level();
        if (x >= soft + o_.bone.floor_hu && confirmed_laterally(ray, r, soft)) {
          out.r_bone = r;
          out.min_peak = soft + o_.bone.floor_hu;
          return out;
        }
      }
      // Air counts as a cavity only past the skin's ramp and after half a millimetre of tissue
      // (a ray oblique to the skin stretches the ramp beyond one voxel).
      if (cavity_base_ && s >= ramp_ && tissue_mm >= 0.5 && x < skin_thr_)
        return cavity_at(r, r + fine_);
      if (cavity_base_ && s >= ramp_ && tissue_mm >= 2.0 && x < kTissueAboveHu) {
        if (low_run_mm == 0) r_low = r;
        low_run_mm += fine_;
        // Its first sample below -200 HU already lies past the half maximum of a shallow dip:
        // the edge is searched from a voxel further out.
        if (low_run_mm >= kPartialAirRunMm - 1e-9) return cavity_at(r_low, r_low + w_);
      } else {
        low_run_mm = 0;
      }
      if (x >= kFatBelowHu && x < kSoftHu[1] + 50.0) samples.push_back(x);
      if (x >= kTissueAboveHu) tissue_mm += fine_;
    }
    return out;
  }

  // A bone candidate at r (the ray's soft-tissue level `soft`) is confirmed when, one voxel to
  // either side across the ray (along the axis and around it), the profile's peak within a
  // millimetre of the same depth averages at least half the floor above the soft tissue: a
  // plate or a cortex extends sideways, a noise voxel does not.
  bool confirmed_laterally(const Ray& ray, double r, double soft) const {
    const Eigen::Vector3d e1 = maps_.axis.direction;
    const Eigen::Vector3d e2 = ray.d.cross(e1).normalized();
    const Eigen::Vector3d p = ray.at(r);
    double sum = 0;
    for (const Eigen::Vector3d& e : {e1, e2})
      for (double sign : {-1.0, 1.0}) {
        const Eigen::Vector3d q = p + sign * lateral_mm_ * e;
        double peak = -std::numeric_limits<double>::max();
        for (double t = -1.0; t <= 1.0 + 1e-9; t += fine_)
          peak = std::max<double>(peak, intensity_(Eigen::Vector3d(q - t * ray.d)));
        sum += peak;
      }
    return 0.25 * sum >= soft + 0.5 * o_.bone.floor_hu;
  }

  // 4. Half-maximum edges: the threshold (or the edge method's peak) finds an edge, the level
  // halfway between the plateaus on either side locates it, independent of the threshold's
  // value. Moves r_s and r_b onto them (r_b when its peak reaches `min_peak`); returns the
  // bone's level.
  double half_maximum_edges(const Ray& ray, std::vector<double>& samples, double& r_s,
                            double& r_b, double min_peak) const {
    const auto I = [&](double r) { return intensity_(ray.at(r)); };
    const auto I_gated = [&](double r) { return gated_intensity(ray, r); };
    double air = I_gated(r_s + edge_span_);
    const double tissue = tissue_plateau(ray, samples, r_s, r_b, air);
    if (air < skin_thr_ && tissue > skin_thr_) {
      const double rs = crossing_inward(I_gated, r_s + edge_span_, std::max(0.0, r_s - edge_span_),
                                        fine_, 0.5 * (air + tissue));
      if (std::isfinite(rs)) r_s = rs;
    }
    double bone_level = bone_level_default_;
    if (std::isfinite(r_b) && bone_by_threshold_) {
      double peak = -std::numeric_limits<double>::max();
      for (double r = r_b; r >= std::max(0.0, r_b - 4.0); r -= fine_)
        peak = std::max<double>(peak, I(r));
      if (tissue < min_peak && peak >= min_peak) {
        const double rb =
            crossing_inward(I, std::min(r_s, r_b + edge_span_), std::max(0.0, r_b - edge_span_),
                            fine_, 0.5 * (tissue + peak));
        if (std::isfinite(rb)) {
          r_b = rb;
          bone_level = 0.5 * (tissue + peak);
        }
      }
    }
    return bone_level;
  }

  // The soft-tissue plateau, sampled between the two edges' ramps where at least 1 mm is left
  // free of both; thinner tissue on coarse voxels has no plateau, and CT then falls back on
  // soft tissue's physical value. CT plateaus (and `air`) are kept within their physical ranges.
  double tissue_plateau(const Ray& ray, std::vector<double>& samples, double r_s, double r_b,
                        double& air) const {
    // Physical ranges of CT plateaus (HU): air, and soft tissue from fat to muscle.
    constexpr double kCtAirHu[2] = {-1024.0, -850.0};
    constexpr double kCtTissueHu[2] = {-200.0, 150.0};
    const auto I = [&](double r) { return intensity_(ray.at(r)); };
    double tissue = std::numeric_limits<double>::quiet_NaN();
    if (std::isfinite(r_b) && (r_s - r_b) - ramp_ >= 1.0) {
      samples.clear();
      // About 16 samples: a median needs no more, and thick tissue would otherwise cost 100s.
      const double step = std::max(fine_, (r_s - r_b - ramp_) / 16.0);
      for (double r = r_b + 0.5 * ramp_; r <= r_s - 0.5 * ramp_; r += step) samples.push_back(I(r));
      if (samples.size() >= 3) tissue = median(samples);
    } else if (!std::isfinite(r_b)) {
      tissue = I(std::max(0.0, r_s - edge_span_));
    }
    if (is_ct_) {
      tissue = std::isfinite(tissue) ? std::clamp(tissue, kCtTissueHu[0], kCtTissueHu[1]) : 0.0;
      air = std::clamp(air, kCtAirHu[0], kCtAirHu[1]);
    } else if (!std::isfinite(tissue)) {
      tissue = I(std::max(0.0, r_s - edge_span_));
    }
    return tissue;
  }

  // 6. The tissue layers along one profile from the skin (depth 0) to the bone (depth length).
  template <typename Profile>
  void measure_layers(std::size_t c, const Profile& profile, double length, bool normal) const {
    const LayerSplit l = split_layers(profile, length, layer_step_, ramp_, o_.layers);
    (normal ? maps_.thickness_skin_normal : maps_.thickness_skin)[c] = static_cast<float>(l.skin_mm);
    (normal ? maps_.thickness_fat_normal : maps_.thickness_fat)[c] = static_cast<float>(l.fat_mm);
    (normal ? maps_.thickness_deep_normal : maps_.thickness_deep)[c] = static_cast<float>(l.deep_mm);
    (normal ? maps_.layer_flags_normal : maps_.layer_flags)[c] = l.flags;
  }

  // The bone the normal thickness looks for with the edge method: the working grid at or above
  // the nominal soft tissue plus the floor, inside the head, in the components that hold bone
  // of the threshold's mask (thin facial bone is attached to the skull; noise specks are not).
  Mask thin_bone_mask() const {
    const float level = static_cast<float>(kNominalSoftHu + o_.bone.floor_hu);
    Mask m;
    m.geom = seg_.working.geom;
    m.data.resize(seg_.working.data.size());
    for (std::size_t i = 0; i < m.data.size(); ++i)
      m.data[i] = (seg_.working.data[i] >= level && seg_.skin.data[i]) || seg_.bone.data[i];
    std::vector<std::int64_t> sizes;
    const auto labels = label_components(m, sizes);
    std::vector<char> holds_bone(sizes.size(), 0);
    for (std::size_t i = 0; i < labels.size(); ++i)
      if (seg_.bone.data[i]) holds_bone[labels[i]] = 1;
    for (std::size_t i = 0; i < labels.size(); ++i) m.data[i] = labels[i] > 0 && holds_bone[labels[i]];
    return m;
  }

  // 5. Thickness along the normal: distance from the skin point p to the nearest bone, found
  // through the exact feature transform on the working grid and refined on the bone's edge;
  // at most the radial thickness. `inward` receives the unit direction from p to that bone
  // (unchanged, the ray's, where the radial thickness is the shorter).
  double thickness_along_normal(const Eigen::Vector3d& p, double radial_mm, double bone_level,
                                Eigen::Vector3d& inward) const {
    const long cell = skin_at_.index(p);
    const std::int64_t q_idx = cell >= 0 ? nearest_bone_[static_cast<std::size_t>(cell)] : -1;
    double tn = radial_mm;
    if (q_idx >= 0) {
      const auto& bg = seg_.bone.geom;
      const int qi = static_cast<int>(q_idx % bg.dims[0]);
      const int qj = static_cast<int>((q_idx / bg.dims[0]) % bg.dims[1]);
      const int qk = static_cast<int>(q_idx / (std::int64_t(bg.dims[0]) * bg.dims[1]));
      const Eigen::Vector3d q = bg.index_to_lps(Eigen::Vector3d(qi, qj, qk));
      const double len = (q - p).norm();
      if (len > 1e-6) {
        const Eigen::Vector3d u = (q - p) / len;
        const auto Bs = [&](double s) { return bone_value(Eigen::Vector3d(p + (len - s) * u)); };
        // With the edge method the nearest bone may be thin: its edge is at half maximum between
        // the soft tissue and its own peak near q, not the ray's bone's level.
        double level = bone_level;
        if (edge_method_) {
          double peak = -std::numeric_limits<double>::max();
          for (double s = -w_; s <= 2 * w_; s += fine_) peak = std::max(peak, Bs(s));
          if (peak >= kNominalSoftHu + o_.bone.floor_hu) level = 0.5 * (kNominalSoftHu + peak);
        }
        // Parameterised so "inward" runs from the skin (s = len) to past the bone site. q is
        // the nearest bone voxel, so the edge lies within two working voxels of it.
        const double s = crossing_inward(Bs, std::min(len, 2 * w_), -w_, fine_, level);
        if (std::isfinite(s) && len - s < tn) {
          tn = len - s;
          inward = u;
        }
      }
    }
    return tn;
  }

  const Volume& v_;                       // not owned; outlives the caster
  const Segmentation& seg_;               // not owned
  const MapOptions& o_;                   // not owned
  const std::vector<double>& row_r_max_;  // not owned
  CylindricalMaps& maps_;                 // not owned; each cast() writes its own cell
  float lowest_;
  Field intensity_;
  MaskAt skin_at_, bone_at_;
  bool bone_by_threshold_;
  Volume bone_float_;      // bone given as a mask (MR): its surface is the 0.5 level
  Field bone_mask_field_;  // samples bone_float_
  float bone_level_default_;
  double w_;       // working voxel
  double coarse_;  // mask marching step
  double fine_;
  double edge_span_;
  double ramp_;  // width of an edge's partial-volume ramp
  bool is_ct_;
  float skin_thr_;
  bool measure_layers_;
  double layer_step_;  // profile sampling step of the layers: half the largest voxel spacing
  bool edge_method_;   // bone found by its edge on the profile (BoneMethod::Edge, CT)
  bool cavity_base_;   // a cavity's air under the skin is the base where no bone is found (CT)
  double lateral_mm_;  // lateral offset of the bone candidate's confirmation: one voxel
  std::vector<std::int64_t> nearest_bone_;
};

}  // namespace

namespace {

// Keeps the cells the ray caster flagged kEye only where they form a patch of at least
// kEyeMinAreaMm2 of skin (4-neighbours, periodic in theta), and widens those patches by
// kEyeMarginMm on the skin.
void confirm_eyes(CylindricalMaps& maps) {
  const CylinderGrid& g = maps.grid;
  const double dtheta = g.dtheta_deg() * kPi / 180.0;
  const auto area = [&](std::size_t c) { return std::max(0.0f, maps.r_skin[c]) * dtheta * g.dz_mm; };
  std::vector<char> seen(g.size(), 0), keep(g.size(), 0);
  std::vector<std::size_t> patch, stack;
  for (std::size_t c0 = 0; c0 < g.size(); ++c0) {
    if (!(maps.flags[c0] & kEye) || seen[c0]) continue;
    patch.clear();
    stack.assign(1, c0);
    seen[c0] = 1;
    double a = 0;
    while (!stack.empty()) {
      const std::size_t c = stack.back();
      stack.pop_back();
      patch.push_back(c);
      a += area(c);
      const int j = static_cast<int>(c % g.n_theta), k = static_cast<int>(c / g.n_theta);
      const int nb[4][2] = {{(j + 1) % g.n_theta, k}, {(j + g.n_theta - 1) % g.n_theta, k},
                            {j, k + 1}, {j, k - 1}};
      for (const auto& q : nb) {
        if (q[1] < 0 || q[1] >= g.n_z) continue;
        const std::size_t d = g.index(q[0], q[1]);
        if ((maps.flags[d] & kEye) && !seen[d]) {
          seen[d] = 1;
          stack.push_back(d);
        }
      }
    }
    for (std::size_t c : patch) {
      if (a >= kEyeMinAreaMm2) keep[c] = 1;
      else maps.flags[c] &= static_cast<std::uint8_t>(~kEye);
    }
  }
  for (int k = 0; k < g.n_z; ++k)
    for (int j = 0; j < g.n_theta; ++j) {
      if (!keep[g.index(j, k)]) continue;
      const double r = std::max(1.0f, maps.r_skin[g.index(j, k)]);
      const int dj =
          std::min(g.n_theta / 2, static_cast<int>(std::ceil(kEyeMarginMm / (r * dtheta))));
      const int dk = static_cast<int>(std::ceil(kEyeMarginMm / g.dz_mm));
      for (int b = std::max(0, k - dk); b <= std::min(g.n_z - 1, k + dk); ++b)
        for (int a = -dj; a <= dj; ++a) {
          const double x = a * r * dtheta, y = (b - k) * g.dz_mm;
          const std::size_t d = g.index(((j + a) % g.n_theta + g.n_theta) % g.n_theta, b);
          if (x * x + y * y <= kEyeMarginMm * kEyeMarginMm && maps.measured_skin[d])
            maps.flags[d] |= kEye;
        }
    }
}

// A ray down the nasal septum or the philtrum between two cavities' rays meets tissue all the
// way to the bone cap: a strip of no_bone at most kBridgeCells wide in theta between valid cells,
// at least one of them based on a cavity. Such a strip is based on the cavity as well (its
// thickness is then filled from its neighbours' like every cell without a measured base), so a
// plan across the midline of the nose or the lip is not refused for one column of cells.
void bridge_cavity_gaps(CylindricalMaps& maps) {
  constexpr int kBridgeCells = 3;
  const CylinderGrid& g = maps.grid;
  const auto at = [&](int j, int k) { return g.index(((j % g.n_theta) + g.n_theta) % g.n_theta, k); };
  for (int k = 0; k < g.n_z; ++k)
    for (int j = 0; j < g.n_theta; ++j) {
      if (maps.flags[at(j, k)] != kNoBone || maps.flags[at(j - 1, k)] == kNoBone) continue;
      int w = 1;
      while (w <= kBridgeCells && maps.flags[at(j + w, k)] == kNoBone) ++w;
      if (w > kBridgeCells) continue;
      const std::uint8_t left = maps.flags[at(j - 1, k)], right = maps.flags[at(j + w, k)];
      if (!flags_valid(left) || !flags_valid(right) || !((left | right) & kBaseCavity)) continue;
      for (int a = 0; a < w; ++a) maps.flags[at(j + a, k)] = kBaseCavity;
    }
}

// A cell with neither bone nor an air cavity within the cap (exactly kNoBone: skin measured,
// nothing else wrong) whose tissue goes on deeper is based on that tissue (kBaseTissue) when it
// lies at most `reach_mm` over the skin from a cell with a measured base (bone or cavity): its
// depth is then interpolated from the measured ones (the harmonic fill below, as for every cell
// without a measured base) and its base carries no support. Distances: Dijkstra over the grid's
// eight neighbours (r_skin dtheta around, dz along), through such cells only, so the reach does
// not cross the eye or a grazing strip.
void base_on_tissue(CylindricalMaps& maps, double reach_mm) {
  if (!(reach_mm > 0)) return;
  const CylinderGrid& g = maps.grid;
  const double dth = deg_to_rad(g.dtheta_deg());
  constexpr float kFar = std::numeric_limits<float>::infinity();
  std::vector<float> dist(g.size(), kFar);
  using Item = std::pair<float, std::size_t>;
  std::priority_queue<Item, std::vector<Item>, std::greater<>> queue;
  for (std::size_t i = 0; i < g.size(); ++i)
    if (maps.measured_bone[i] && flags_valid(maps.flags[i])) {
      dist[i] = 0;
      queue.push({0.0f, i});
    }
  while (!queue.empty()) {
    const auto [d, i] = queue.top();
    queue.pop();
    if (d > dist[i]) continue;
    const int j = static_cast<int>(i % g.n_theta), k = static_cast<int>(i / g.n_theta);
    const double around = maps.r_skin[i] * dth;
    for (int dk = -1; dk <= 1; ++dk)
      for (int dj = -1; dj <= 1; ++dj) {
        if ((dj == 0 && dk == 0) || k + dk < 0 || k + dk >= g.n_z) continue;
        const std::size_t n = g.index((j + dj + g.n_theta) % g.n_theta, k + dk);
        if (maps.flags[n] != kNoBone) continue;
        const float next = d + static_cast<float>(std::hypot(dj * around, dk * g.dz_mm));
        if (next < dist[n] && next <= reach_mm) {
          dist[n] = next;
          queue.push({next, n});
        }
      }
  }
  for (std::size_t i = 0; i < g.size(); ++i)
    if (maps.flags[i] == kNoBone && dist[i] <= reach_mm) maps.flags[i] = kBaseTissue;
}

// Metal (MapOptions::metal): a measured cell whose column, from its base (or the bone cap when
// none was found) to 2 mm above its skin, passes through a repaired slab is kTruncated and not
// measured; its skin and thickness are filled like every invalid cell's.
void mark_metal(CylindricalMaps& maps, const MetalRegion& metal, double bone_cap_mm) {
  const auto& g = maps.grid;
  maps.metal.assign(g.size(), 0);
  tbb::parallel_for(0, g.n_z, [&](int k) {
    for (int j = 0; j < g.n_theta; ++j) {
      const std::size_t c = g.index(j, k);
      if (!maps.measured_skin[c]) continue;
      const double theta = deg_to_rad(g.theta_deg(j)), z = g.z_mm(k);
      const double r_hi = maps.r_skin[c] + 2.0;
      const double r_lo = std::max(0.0, maps.measured_bone[c] ? maps.r_bone[c] - 1.0
                                                              : maps.r_skin[c] - bone_cap_mm);
      bool hit = false;
      for (double r = r_hi; r >= r_lo && !hit; r -= 0.5)
        hit = metal.in_slab(maps.axis.to_lps(theta, z, r));
      if (!hit) continue;
      maps.metal[c] = 1;
      maps.flags[c] |= kTruncated;
      maps.measured_skin[c] = 0;
      maps.measured_bone[c] = 0;
    }
  });
}

}  // namespace

CylindricalMaps cylindrical_maps(const Volume& v, const Segmentation& seg, const CylinderAxis& axis,
                                 const MapOptions& o, Reporter* reporter) {
  check_map_options(o);
  Progress progress(reporter, "casting cylindrical rays", 1.0);
  CylindricalMaps maps;
  maps.axis = axis;
  auto& grid = maps.grid;
  grid.n_theta = o.n_theta;
  grid.n_z = o.n_z;
  set_z_rows(grid, v, seg, axis, o);
  const std::vector<double> row_r_max = row_max_radii(grid, seg, axis);

  const std::size_t n = grid.size();
  maps.allocate();
  // Layers are told apart by fat's CT number; MR's contrasts are not calibrated (not measured).
  if (o.layers.measure && v.modality == Modality::CT) maps.allocate_layers();
  const RayCaster caster(v, seg, o, row_r_max, maps);
  tbb::parallel_for(0, grid.n_z, [&](int k) {
    std::vector<double> samples;
    for (int j = 0; j < grid.n_theta; ++j) caster.cast(j, k, samples);
  });
  progress.update(0.8);
  if (o.metal.found) mark_metal(maps, o.metal, o.bone_cap_mm);

  flag_grazing(maps, o.grazing_deg);
  confirm_eyes(maps);
  bridge_cavity_gaps(maps);
  if (v.modality == Modality::CT) base_on_tissue(maps, o.bone.tissue_reach_mm);
  std::size_t n_measured = 0;
  for (auto m : maps.measured_skin) n_measured += m;
  if (n_measured == 0)
    throw InvalidInput(
        cat(v.source, ": no ray from the axis met the skin; the head was not found"));
  harmonic_fill(maps.r_skin, maps.measured_skin, grid);
  harmonic_fill(maps.thickness, maps.measured_bone, grid);
  harmonic_fill(maps.thickness_normal, maps.measured_bone, grid);
  for (std::size_t i = 0; i < n; ++i) {
    maps.thickness[i] = std::max(0.0f, maps.thickness[i]);
    maps.r_bone[i] = maps.r_skin[i] - maps.thickness[i];
  }
  if (maps.has_layers()) {
    // Layers of cells whose thickness is not valid are filled like the thickness itself.
    for (std::size_t i = 0; i < n; ++i)
      if (!flags_valid(maps.flags[i]) || !maps.measured_bone[i]) {
        maps.layer_flags[i] |= kLayerNoThickness;
        maps.layer_flags_normal[i] |= kLayerNoThickness;
      }
    tbb::parallel_invoke(
        [&] {
          fill_layers(maps.thickness_skin, maps.thickness_fat, maps.thickness_deep,
                      maps.layer_flags, maps.thickness, grid);
        },
        [&] {
          fill_layers(maps.thickness_skin_normal, maps.thickness_fat_normal,
                      maps.thickness_deep_normal, maps.layer_flags_normal, maps.thickness_normal,
                      grid);
        });
  }
  progress.done();
  return maps;
}

}  // namespace caps
