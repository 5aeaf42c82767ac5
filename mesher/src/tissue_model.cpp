#include "caps/mesher/tissue_model.hpp"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>

#include "caps/core/error.hpp"
#include "caps/core/units.hpp"
#include "caps/volume/morphology.hpp"
#include "tissue_mesh_3.hpp"

namespace caps::mesher {

namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

// The 12-point rule of a tet's regular subdivision (its four corner tets, weight 1/8 each, and
// the central octahedron cut into eight tets from its centre, 1/16 each): barycentric weight of
// the own corner, of the others, and the point's weight.
struct SamplePoint {
  int corner;  // -1: the point's coordinates are (own, other, other, other) about `corner`
  double own, other, weight;
};
constexpr SamplePoint kCornerTet{0, 5.0 / 8, 1.0 / 8, 1.0 / 8};
constexpr SamplePoint kCutFace{0, 7.0 / 16, 3.0 / 16, 1.0 / 16};
constexpr SamplePoint kInnerFace{0, 1.0 / 16, 5.0 / 16, 1.0 / 16};

// The skin level set's depth inside (mm): deeper than the subcutaneous fat almost everywhere on
// the head; the cost of building the level set grows with it.
constexpr double kSkinDepthBandMm = 16.0;

}  // namespace

const char* tissue_layer_name(TissueLayer layer) {
  switch (layer) {
    case TissueLayer::Dermis:
      return "dermis";
    case TissueLayer::Fat:
      return "fat";
    case TissueLayer::Deep:
      return "deep";
  }
  return "?";
}

double tet_volume(const Eigen::MatrixX3d& X, const Eigen::Vector4i& t) {
  const Eigen::Vector3d x0 = X.row(t[0]).transpose();
  return (X.row(t[1]).transpose() - x0)
             .cross(X.row(t[2]).transpose() - x0)
             .dot(X.row(t[3]).transpose() - x0) /
         6.0;
}

std::vector<int> TissueModel::dominant_layer() const {
  std::vector<int> d(static_cast<std::size_t>(layer_fraction.rows()));
  for (Eigen::Index t = 0; t < layer_fraction.rows(); ++t) {
    Eigen::Index m = 0;
    layer_fraction.row(t).maxCoeff(&m);
    d[static_cast<std::size_t>(t)] = static_cast<int>(m);
  }
  return d;
}

std::size_t TissueModel::count_nodes(std::uint8_t flag) const {
  return static_cast<std::size_t>(std::count_if(
      node_flags.begin(), node_flags.end(), [&](std::uint8_t f) { return (f & flag) == flag; }));
}

TissueLevelSets tissue_level_sets(const Segmentation& seg, const TissueModelOptions& o) {
  const double voxel =
      o.level_set_voxel_mm > 0 ? o.level_set_voxel_mm : seg.skin.geom.spacing_mm.minCoeff();
  if (!(o.band_mm > 0) || !(o.depth_limit_mm > 0))
    throw InvalidInput(cat("tissue model: band ", o.band_mm, " mm and depth limit ",
                           o.depth_limit_mm, " mm must be positive"));
  TissueLevelSets ls;
  // The skin's band reaches kSkinDepthBandMm inside: the layers are found by depth below it
  // (deeper, build_tissue_model takes the depth from the voxels' distance transform).
  ls.skin = SignedDistanceField::from_mask(seg.skin, voxel, o.band_mm,
                                           std::min(kSkinDepthBandMm, o.depth_limit_mm + 2.0));
  if (seg.bone.count() == 0)
    throw InvalidInput(
        "tissue model: the segmentation has no bone; a tissue model needs the "
        "bone under the skin");
  ls.bone = SignedDistanceField::from_mask(seg.bone, voxel, o.band_mm, o.band_mm);
  return ls;
}

TissueModel build_tissue_model(const Segmentation& seg, const CylindricalMaps& maps,
                               const ModelStatistics& stats, const TissueLevelSets& ls,
                               const TissueModelOptions& o, Reporter* reporter) {
  const auto t_start = Clock::now();
  if (!ls.skin.is_valid() || !ls.bone.is_valid())
    throw InvalidInput("tissue model: the level sets are not built");
  if (!(o.face_size_mm > 0) || !(o.scalp_size_mm > 0) || !(o.cell_growth >= 0) ||
      !(o.facet_distance_fraction > 0))
    throw InvalidInput(cat("tissue model: sizes (face ", o.face_size_mm, ", scalp ",
                           o.scalp_size_mm, " mm, growth ", o.cell_growth, ", distance ",
                           o.facet_distance_fraction, ") must be positive"));
  const VolumeGeometry& g = seg.skin.geom;
  const Volume& w = seg.working;
  if (w.data.size() != g.n_voxels() || seg.bone.data.size() != g.n_voxels())
    throw InvalidInput("tissue model: the segmentation's masks and intensities differ in size");
  TissueModel m;
  m.options = o;
  m.label_voxel_mm = g.spacing_mm;
  m.level_set_voxel_mm = ls.skin.voxel_mm();
  m.source = w.source;

  // ---- the label image: soft tissue within the depth limit, in pieces reaching the skin ----
  const auto t_labels = Clock::now();
  Progress progress(reporter, "tissue model", 4.0);
  Mask outside;
  outside.geom = g;
  outside.data.resize(g.n_voxels());
  for (std::size_t v = 0; v < g.n_voxels(); ++v) outside.data[v] = seg.skin.data[v] ? 0 : 1;
  std::vector<std::int64_t> nearest;
  const std::vector<float> depth2 = squared_distance_mm2(outside, &nearest);
  const double limit2 = o.depth_limit_mm * o.depth_limit_mm;
  Mask tissue;
  tissue.geom = g;
  tissue.data.assign(g.n_voxels(), 0);
  // Soft tissue: inside the envelope, not bone, not air, within the depth limit, and not under
  // the bone: the straight path to its nearest point outside the skin crosses no bone (the
  // brain under the skull, the tissue behind a sinus's wall are out).
  const double step = 0.5 * g.spacing_mm.minCoeff();
  tbb::parallel_for(0, g.dims[2], [&](int k) {
    for (int j = 0; j < g.dims[1]; ++j)
      for (int i = 0; i < g.dims[0]; ++i) {
        const std::size_t v = g.linear(i, j, k);
        if (!(seg.skin.data[v] && !seg.bone.data[v] && w.data[v] > seg.skin_threshold &&
              depth2[v] <= limit2) ||
            nearest[v] < 0)
          continue;
        const std::int64_t n = nearest[v];
        const Eigen::Vector3d a(i, j, k);
        const Eigen::Vector3d b(
            static_cast<double>(n % g.dims[0]), static_cast<double>((n / g.dims[0]) % g.dims[1]),
            static_cast<double>(n / (static_cast<std::int64_t>(g.dims[0]) * g.dims[1])));
        const int steps = static_cast<int>(std::ceil(std::sqrt(depth2[v]) / step));
        bool under_bone = false;
        for (int s = 1; s < steps && !under_bone; ++s) {
          const Eigen::Vector3d q = a + (b - a) * (static_cast<double>(s) / steps);
          const int qi = static_cast<int>(std::lround(q[0])),
                    qj = static_cast<int>(std::lround(q[1])),
                    qk = static_cast<int>(std::lround(q[2]));
          under_bone = seg.bone.data[g.linear(qi, qj, qk)] != 0;
        }
        tissue.data[v] = under_bone ? 0 : 1;
      }
  });
  std::vector<std::int64_t> sizes;
  const std::vector<std::int32_t> comp = label_components(tissue, sizes);
  // A piece is kept if it reaches the skin (a voxel within 1.5 voxels of the envelope) and is
  // not tiny.
  const double reach2 = std::pow(1.5 * g.spacing_mm.maxCoeff(), 2);
  std::vector<std::uint8_t> reaches(sizes.size(), 0);
  for (std::size_t v = 0; v < g.n_voxels(); ++v)
    if (comp[v] > 0 && depth2[v] <= reach2) reaches[static_cast<std::size_t>(comp[v])] = 1;
  const double voxel_ml = g.spacing_mm.prod() * 1e-3;
  std::size_t dropped = 0;
  Eigen::Vector3i lo = g.dims, hi(-1, -1, -1);
  for (int k = 0; k < g.dims[2]; ++k)
    for (int j = 0; j < g.dims[1]; ++j)
      for (int i = 0; i < g.dims[0]; ++i) {
        const std::size_t v = g.linear(i, j, k);
        const std::int32_t c = comp[v];
        if (c <= 0) continue;
        if (!reaches[c] || sizes[c] * voxel_ml < o.min_component_ml) {
          tissue.data[v] = 0;
          ++dropped;
          continue;
        }
        lo = lo.cwiseMin(Eigen::Vector3i(i, j, k));
        hi = hi.cwiseMax(Eigen::Vector3i(i, j, k));
      }
  if (hi[0] < 0) throw InvalidInput(cat(w.source, ": no soft tissue under the skin to mesh"));
  constexpr int kPad = 2;  // unlabelled voxels around, so every boundary is the label's edge
  detail::LabelImage image;
  image.spacing_mm = g.spacing_mm;
  image.dims = hi - lo + Eigen::Vector3i::Constant(2 * kPad + 1);
  image.labels.assign(static_cast<std::size_t>(image.dims.prod()), 0);
  for (int k = lo[2]; k <= hi[2]; ++k)
    for (int j = lo[1]; j <= hi[1]; ++j)
      for (int i = lo[0]; i <= hi[0]; ++i)
        if (tissue.data[g.linear(i, j, k)]) {
          const int a = i - lo[0] + kPad, b = j - lo[1] + kPad, c = k - lo[2] + kPad;
          image.labels[(static_cast<std::size_t>(c) * image.dims[1] + b) * image.dims[0] + a] = 1;
        }
  const Eigen::Vector3d shift = (lo - Eigen::Vector3i::Constant(kPad)).cast<double>();
  // The image frame (mm from its voxel 0) to LPS.
  auto to_lps = [&](const Eigen::Vector3d& q) {
    return g.index_to_lps(q.cwiseQuotient(g.spacing_mm) + shift);
  };
  m.seconds_labels = seconds_since(t_labels);
  progress.update(1.0);

  // ---- sizes: fine on the face and near the skin, coarse on the scalp and deep ----
  const double blend = std::max(o.face_blend_deg, 1e-6);
  auto facet_size_lps = [&](const Eigen::Vector3d& p) {
    const double theta_deg = std::abs(maps.axis.to_cylindrical(p)[0]) * 180.0 / kPi;
    const double s = std::clamp((theta_deg - o.face_half_angle_deg) / blend, 0.0, 1.0);
    return o.face_size_mm + s * (o.scalp_size_mm - o.face_size_mm);
  };
  detail::Mesh3Criteria criteria;
  criteria.facet_size_mm = [&](const Eigen::Vector3d& q) { return facet_size_lps(to_lps(q)); };
  criteria.facet_distance_mm = [&](const Eigen::Vector3d& q) {
    return o.facet_distance_fraction * facet_size_lps(to_lps(q));
  };
  criteria.cell_size_mm = [&](const Eigen::Vector3d& q) {
    const Eigen::Vector3d p = to_lps(q);
    const double depth = std::max(0.0, -ls.skin(p));
    return 1.5 * facet_size_lps(p) + o.cell_growth * depth;
  };
  criteria.exude_seconds = o.exude_seconds;
  const auto t_mesh = Clock::now();
  const detail::Mesh3Output mesh = detail::mesh_label_image(image, criteria, reporter);
  m.seconds_mesh = seconds_since(t_mesh);
  progress.update(2.0);
  if (mesh.tets.rows() == 0) throw InvalidInput(cat(w.source, ": the tissue gave no tetrahedra"));

  // Nodes in LPS; a left-handed grid direction turns every tet over.
  m.nodes.resize(mesh.nodes.rows(), 3);
  for (Eigen::Index v = 0; v < mesh.nodes.rows(); ++v)
    m.nodes.row(v) = to_lps(mesh.nodes.row(v).transpose()).transpose();
  m.tets = mesh.tets;
  for (Eigen::Index t = 0; t < m.tets.rows(); ++t)
    if (tet_volume(m.nodes, m.tets.row(t).transpose()) < 0) std::swap(m.tets(t, 2), m.tets(t, 3));

  // ---- node flags on the boundary, from the level sets ----
  const double tol = 0.75 * g.spacing_mm.maxCoeff();
  std::vector<std::uint8_t> on_boundary(static_cast<std::size_t>(m.nodes.rows()), 0);
  for (Eigen::Index f = 0; f < mesh.boundary_faces.rows(); ++f)
    for (int c = 0; c < 3; ++c)
      on_boundary[static_cast<std::size_t>(mesh.boundary_faces(f, c))] = 1;
  m.node_flags.assign(on_boundary.size(), 0);
  tbb::parallel_for(std::size_t(0), on_boundary.size(), [&](std::size_t v) {
    if (!on_boundary[v]) return;
    const Eigen::Vector3d p = m.nodes.row(static_cast<Eigen::Index>(v)).transpose();
    std::uint8_t flag = 0;
    // The CT's field of view: within a voxel of the grid's border (or of unacquired voxels).
    if (near_data_edge(w, p, 1.0)) flag |= kTissueFieldOfView;
    const double s = std::abs(ls.skin(p)), b = std::abs(ls.bone(p));
    if (s < tol && (s <= b || b >= tol)) flag |= kTissueOnSkin;
    if (b < tol && (b < s || s >= tol)) flag |= kTissueOnBone;
    if (!flag) flag = kTissueOtherBoundary;
    m.node_flags[v] = flag;
  });
  progress.update(3.0);

  // ---- layer fractions: 12 points per tet, their depth against the measured layers ----
  const auto t_layers = Clock::now();
  double med_dermis = stats.skin_layer_median_mm, med_fat = stats.fat_median_mm;
  const bool have_medians = med_dermis > 0 || med_fat > 0;
  if (!have_medians) {
    med_dermis = 2.0;
    med_fat = 0.0;
    m.warnings.push_back(
        "the model has no measured tissue layers: every tet takes a 2 mm dermis over deep "
        "tissue, no fat");
  }
  const bool layers = maps.has_layers();
  const CylinderGrid& grid = maps.grid;
  // Dermis and dermis + fat depths (mm, along the normal) under a point; false: fallback.
  auto layer_depths = [&](const Eigen::Vector3d& p, double& dermis, double& fat_bottom) {
    if (layers) {
      const Eigen::Vector3d c = maps.axis.to_cylindrical(p);
      double jf = (c[0] * 180.0 / kPi - grid.theta0_deg) / grid.dtheta_deg();
      int j = static_cast<int>(std::lround(jf)) % grid.n_theta;
      if (j < 0) j += grid.n_theta;
      const int k = static_cast<int>(std::lround((c[1] - grid.z0_mm) / grid.dz_mm));
      if (k >= 0 && k < grid.n_z && maps.is_valid(j, k)) {
        const std::size_t i = grid.index(j, k);
        const double d = maps.thickness_skin_normal[i], f = maps.thickness_fat_normal[i];
        if (std::isfinite(d) && std::isfinite(f) && d >= 0 && f >= 0) {
          dermis = d;
          fat_bottom = d + f;
          return true;
        }
      }
    }
    dermis = med_dermis;
    fat_bottom = med_dermis + med_fat;
    return false;
  };
  // Depth below the skin (mm): the level set within its band, the voxels' exact distance
  // transform (nearest voxel) deeper.
  const double band_inside = ls.skin.interior_mm() - 2.0 * ls.skin.voxel_mm();
  auto depth_below_skin = [&](const Eigen::Vector3d& p) {
    const double phi = ls.skin(p);
    if (phi > -band_inside) return std::max(0.0, -phi);
    const Eigen::Vector3d ijk = g.lps_to_index(p);
    const int i = std::clamp(static_cast<int>(std::lround(ijk[0])), 0, g.dims[0] - 1);
    const int j = std::clamp(static_cast<int>(std::lround(ijk[1])), 0, g.dims[1] - 1);
    const int k = std::clamp(static_cast<int>(std::lround(ijk[2])), 0, g.dims[2] - 1);
    return std::max(band_inside, static_cast<double>(std::sqrt(depth2[g.linear(i, j, k)])));
  };
  const SamplePoint rules[3] = {kCornerTet, kCutFace, kInnerFace};
  const double rule_weight[3] = {1.0 / 8, 1.0 / 16, 1.0 / 16};
  m.layer_fraction.resize(m.tets.rows(), 3);
  std::vector<int> fallback(static_cast<std::size_t>(m.tets.rows()), 0);
  tbb::parallel_for(Eigen::Index(0), m.tets.rows(), [&](Eigen::Index t) {
    Eigen::Vector3d x[4];
    for (int c = 0; c < 4; ++c) x[c] = m.nodes.row(m.tets(t, c)).transpose();
    Eigen::Vector3d frac = Eigen::Vector3d::Zero();
    int fb = 0;
    for (int r = 0; r < 3; ++r)
      for (int corner = 0; corner < 4; ++corner) {
        Eigen::Vector3d p = Eigen::Vector3d::Zero();
        for (int c = 0; c < 4; ++c) p += (c == corner ? rules[r].own : rules[r].other) * x[c];
        const double depth = depth_below_skin(p);
        double dermis = 0, fat_bottom = 0;
        if (!layer_depths(p, dermis, fat_bottom)) ++fb;
        const int layer = depth < dermis ? 0 : (depth < fat_bottom ? 1 : 2);
        frac[layer] += rule_weight[r];
      }
    m.layer_fraction.row(t) = frac.cast<float>().transpose();
    fallback[static_cast<std::size_t>(t)] = fb;
  });
  std::size_t n_fallback = 0;
  for (int f : fallback) n_fallback += static_cast<std::size_t>(f);
  m.layer_fallback_fraction =
      static_cast<double>(n_fallback) / (12.0 * static_cast<double>(m.tets.rows()));
  if (have_medians && m.layer_fallback_fraction > 0.0)
    m.warnings.push_back(
        cat(std::lround(100.0 * m.layer_fallback_fraction),
            " % of the layer samples lie where the model has no measured "
            "thickness (or beyond its maps): they take the model's medians (dermis ",
            med_dermis, " mm, fat ", med_fat, " mm)"));
  double total = 0;
  for (Eigen::Index t = 0; t < m.tets.rows(); ++t) {
    const double v = tet_volume(m.nodes, m.tets.row(t).transpose());
    total += v;
    for (int l = 0; l < 3; ++l) m.layer_volume_ml[l] += 1e-3 * v * m.layer_fraction(t, l);
  }
  m.volume_ml = 1e-3 * total;
  m.seconds_layers = seconds_since(t_layers);
  progress.update(4.0);
  progress.done();
  if (dropped > 0)
    note(reporter, cat("tissue model: ", std::lround(dropped * voxel_ml),
                       " ml of soft tissue in "
                       "pieces that do not reach the skin (or smaller than ",
                       o.min_component_ml, " ml) left out"));
  m.method =
      cat("soft tissue (inside the skin envelope, not bone (", seg.bone_method,
          "), above the skin threshold ", seg.skin_threshold, ", within ", o.depth_limit_mm,
          " mm of the skin) as a label image on the working grid (", g.spacing_mm.transpose(),
          " mm); CGAL Mesh_3 (labelled image, linear tets, "
          "no optimisation); facets ",
          o.face_size_mm, " mm on the face, ", o.scalp_size_mm,
          " mm elsewhere; OpenVDB level sets (", m.level_set_voxel_mm, " mm voxels)");
  m.seconds_total = seconds_since(t_start);
  for (const auto& warning : m.warnings) warn(reporter, cat("tissue model: ", warning));
  return m;
}

}  // namespace caps::mesher
