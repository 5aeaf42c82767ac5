#include "caps/surface/register.hpp"

#include <CGAL/AABB_traits.h>
#include <CGAL/AABB_tree.h>
#include <CGAL/AABB_triangle_primitive.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <open3d/geometry/KDTreeSearchParam.h>
#include <open3d/geometry/PointCloud.h>
#include <open3d/pipelines/registration/CorrespondenceChecker.h>
#include <open3d/pipelines/registration/Feature.h>
#include <open3d/pipelines/registration/Registration.h>
#include <open3d/pipelines/registration/RobustKernel.h>
#include <open3d/pipelines/registration/TransformationEstimation.h>
#include <open3d/utility/Logging.h>
#include <open3d/utility/Random.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <functional>
#include <mutex>
#include <optional>

#include "caps/core/error.hpp"
#include "caps/core/units.hpp"

namespace caps {
namespace {

namespace reg = open3d::pipelines::registration;
using open3d::geometry::KDTreeSearchParamHybrid;
using open3d::geometry::PointCloud;

// Area-weighted vertex normals of a mesh (its faces' orientation).
Eigen::MatrixX3d vertex_normals_of(const TriMesh& m) {
  Eigen::MatrixX3d N = Eigen::MatrixX3d::Zero(m.n_vertices(), 3);
  for (Eigen::Index f = 0; f < m.n_faces(); ++f) {
    const Eigen::Vector3d a = m.V.row(m.F(f, 0)), b = m.V.row(m.F(f, 1)), c = m.V.row(m.F(f, 2));
    const Eigen::Vector3d n = (b - a).cross(c - a);  // twice the area, outward
    for (int q = 0; q < 3; ++q) N.row(m.F(f, q)) += n.transpose();
  }
  for (Eigen::Index v = 0; v < N.rows(); ++v) {
    const double len = N.row(v).norm();
    if (len > 0) N.row(v) /= len;
  }
  return N;
}

// The vertices used by at least one face, with their normals, as an Open3D cloud.
PointCloud cloud_of(const TriMesh& m, double scale, bool orient_outward) {
  const Eigen::MatrixX3d N = vertex_normals_of(m);
  std::vector<char> used(m.n_vertices(), 0);
  for (Eigen::Index f = 0; f < m.n_faces(); ++f)
    for (int q = 0; q < 3; ++q) used[m.F(f, q)] = 1;
  PointCloud pc;
  for (Eigen::Index v = 0; v < m.n_vertices(); ++v) {
    if (!used[v] || N.row(v).squaredNorm() == 0) continue;
    pc.points_.push_back(scale * m.V.row(v).transpose());
    pc.normals_.push_back(N.row(v).transpose());
  }
  if (orient_outward && !pc.points_.empty()) {
    // A scan's faces may point into the head: the normals should point away from its centre
    // (for a face-only patch, the centre lies behind the face).
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    for (const auto& p : pc.points_) c += p;
    c /= static_cast<double>(pc.points_.size());
    double s = 0;
    for (std::size_t i = 0; i < pc.points_.size(); ++i) s += pc.normals_[i].dot(pc.points_[i] - c);
    if (s < 0)
      for (auto& n : pc.normals_) n = -n;
  }
  return pc;
}

// x to 2 decimals, for messages.
double r2(double x) { return std::round(x * 100.0) / 100.0; }

double diagonal(const Eigen::MatrixX3d& V) {
  return (V.colwise().maxCoeff() - V.colwise().minCoeff()).norm();
}

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  const std::size_t k = std::min(v.size() - 1, static_cast<std::size_t>(std::floor(q * (v.size() - 1) + 0.5)));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

void check_options(const RegistrationOptions& o) {
  if (o.mm_per_unit && !(*o.mm_per_unit > 0 && std::isfinite(*o.mm_per_unit)))
    throw InvalidParameter(cat("{scan_scale} ", *o.mm_per_unit, ": give millimetres per scan unit (> 0)"));
  if (!(o.voxel_mm >= 0.5 && o.voxel_mm <= 20))
    throw InvalidParameter(cat("{voxel} ", o.voxel_mm, " mm must be in [0.5, 20]"));
  if (!(o.icp_final_mm > 0 && o.icp_final_mm <= 20))
    throw InvalidParameter(cat("{icp_distance} ", o.icp_final_mm, " mm must be in (0, 20]"));
  if (!(o.overlap_mm > 0) || !(o.max_rms_mm > 0) || !(o.max_median_mm > 0))
    throw InvalidParameter(cat("registration limits: {overlap_distance} ", o.overlap_mm, " mm, {max_rms} ",
                           o.max_rms_mm, " mm and {max_median} ", o.max_median_mm,
                           " mm must be positive"));
  if (!(o.min_overlap >= 0 && o.min_overlap <= 1))
    throw InvalidParameter(cat("{min_overlap} ", o.min_overlap, " must be in [0, 1]"));
  if (!(o.max_scale_change >= 1) || !std::isfinite(o.max_scale_change))
    throw InvalidParameter(cat("{max_scale_change} ", o.max_scale_change,
                               " must be a finite factor of at least 1"));
  if (o.orientation && !(std::abs(o.orientation->determinant() - 1) < 1e-6))
    throw InvalidInput("registration: the orientation prior must be a rotation");
  if (!(o.max_orientation_deg > 0 && o.max_orientation_deg <= 180))
    throw InvalidParameter(cat("{max_orientation} ", o.max_orientation_deg, " deg must be in (0, 180]"));
  if (o.ransac_iterations < 1000 || o.ransac_iterations > 10000000)
    throw InvalidInput(cat("RANSAC iterations ", o.ransac_iterations, " must be in [1000, 1e7]"));
}

// Rejects RANSAC hypotheses whose rotation is further than a limit from a prior rotation.
class OrientationChecker : public reg::CorrespondenceChecker {
 public:
  OrientationChecker(const Eigen::Matrix3d& prior, double max_deg)
      : reg::CorrespondenceChecker(true), prior_(prior), min_cos_(std::cos(max_deg * kPi / 180.0)) {}
  bool Check(const PointCloud&, const PointCloud&, const reg::CorrespondenceSet&,
             const Eigen::Matrix4d& T) const override {
    // The angle of R prior^T from its trace: cos(angle) = (tr - 1) / 2.
    const Eigen::Matrix3d d = T.topLeftCorner<3, 3>() * prior_.transpose();
    return (d.trace() - 1.0) / 2.0 >= min_cos_;
  }

 private:
  Eigen::Matrix3d prior_;
  double min_cos_;
};

}  // namespace

TriMesh crop_mesh(const TriMesh& mesh, const std::vector<char>& keep) {
  if (keep.size() != static_cast<std::size_t>(mesh.n_vertices()))
    throw InvalidInput(cat("crop_mesh: ", keep.size(), " flags for ", mesh.n_vertices(), " vertices"));
  std::vector<int> index(keep.size(), -1);
  std::vector<Eigen::Index> faces;
  int n = 0;
  for (Eigen::Index f = 0; f < mesh.n_faces(); ++f) {
    if (!keep[mesh.F(f, 0)] || !keep[mesh.F(f, 1)] || !keep[mesh.F(f, 2)]) continue;
    faces.push_back(f);
    for (int q = 0; q < 3; ++q)
      if (index[mesh.F(f, q)] < 0) index[mesh.F(f, q)] = n++;
  }
  TriMesh out;
  out.V.resize(n, 3);
  for (std::size_t v = 0; v < index.size(); ++v)
    if (index[v] >= 0) out.V.row(index[v]) = mesh.V.row(static_cast<Eigen::Index>(v));
  out.F.resize(static_cast<Eigen::Index>(faces.size()), 3);
  for (std::size_t i = 0; i < faces.size(); ++i)
    for (int q = 0; q < 3; ++q) out.F(static_cast<Eigen::Index>(i), q) = index[mesh.F(faces[i], q)];
  return out;
}

Eigen::MatrixX3d transform_points(const Eigen::Matrix4d& T, const Eigen::MatrixX3d& points) {
  Eigen::MatrixX3d out = points * T.topLeftCorner<3, 3>().transpose();
  out.rowwise() += T.topRightCorner<3, 1>().transpose();
  return out;
}

Eigen::VectorXd signed_distance_to_mesh(const Eigen::MatrixX3d& points, const TriMesh& mesh) {
  using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
  using Triangle = Kernel::Triangle_3;
  using Iterator = std::vector<Triangle>::const_iterator;
  using Tree = CGAL::AABB_tree<CGAL::AABB_traits<Kernel, CGAL::AABB_triangle_primitive<Kernel, Iterator>>>;
  std::vector<Triangle> tris;
  std::vector<Eigen::Vector3d> normal;
  tris.reserve(mesh.n_faces());
  for (Eigen::Index f = 0; f < mesh.n_faces(); ++f) {
    const Eigen::Vector3d a = mesh.V.row(mesh.F(f, 0)), b = mesh.V.row(mesh.F(f, 1)),
                          c = mesh.V.row(mesh.F(f, 2));
    const Eigen::Vector3d n = (b - a).cross(c - a);
    if (!(n.norm() > 0)) continue;
    tris.emplace_back(Kernel::Point_3(a[0], a[1], a[2]), Kernel::Point_3(b[0], b[1], b[2]),
                      Kernel::Point_3(c[0], c[1], c[2]));
    normal.push_back(n.normalized());
  }
  if (tris.empty()) throw InvalidInput("distance to a mesh: the mesh has no face with an area");
  Tree tree(tris.cbegin(), tris.cend());
  tree.accelerate_distance_queries();
  Eigen::VectorXd d(points.rows());
  for (Eigen::Index i = 0; i < points.rows(); ++i) {
    const Kernel::Point_3 p(points(i, 0), points(i, 1), points(i, 2));
    const auto [q, id] = tree.closest_point_and_primitive(p);
    const Eigen::Vector3d diff(p.x() - q.x(), p.y() - q.y(), p.z() - q.z());
    const double s = diff.dot(normal[static_cast<std::size_t>(id - tris.cbegin())]);
    d[i] = s < 0 ? -diff.norm() : diff.norm();
  }
  return d;
}

ResidualStatistics residual_statistics(const Eigen::VectorXd& distance_mm, double overlap_mm) {
  ResidualStatistics r;
  r.vertices = static_cast<std::size_t>(distance_mm.size());
  if (r.vertices == 0) return r;
  std::vector<double> a(r.vertices);
  double se = 0, se_all = 0, sum = 0;
  for (std::size_t i = 0; i < r.vertices; ++i) {
    const double d = distance_mm[static_cast<Eigen::Index>(i)];
    a[i] = std::abs(d);
    se_all += d * d;
    if (a[i] <= overlap_mm) {
      ++r.overlapping;
      se += d * d;
      sum += d;
    }
  }
  r.overlap_fraction = double(r.overlapping) / double(r.vertices);
  r.rms_mm = r.overlapping ? std::sqrt(se / double(r.overlapping)) : 0.0;
  r.mean_signed_mm = r.overlapping ? sum / double(r.overlapping) : 0.0;
  r.rms_all_mm = std::sqrt(se_all / double(r.vertices));
  r.median_mm = percentile(a, 0.5);
  r.p90_mm = percentile(a, 0.9);
  r.p95_mm = percentile(a, 0.95);
  r.p99_mm = percentile(a, 0.99);
  r.max_mm = *std::max_element(a.begin(), a.end());
  return r;
}

ScanRegistration register_scan(const TriMesh& scan, const TriMesh& skin,
                               const RegistrationOptions& o, Reporter* reporter) {
  const auto t0 = std::chrono::steady_clock::now();
  check_options(o);
  if (scan.n_faces() == 0 || skin.n_faces() == 0)
    throw InvalidInput("registration: the scan and the skin must be triangle meshes with faces");
  if (!scan.V.allFinite() || !skin.V.allFinite())
    throw InvalidInput("registration: a vertex has a non-finite coordinate");
  {
    // Open3D's logger writes to stdout; caps reports through the Reporter only.
    static std::once_flag quiet;
    std::call_once(quiet, [] { open3d::utility::SetVerbosityLevel(open3d::utility::VerbosityLevel::Error); });
  }
  open3d::utility::random::Seed(o.seed);
  ScanRegistration out;
  Progress progress(reporter, "registering the scan", 1.0);

  // 1. Units.
  if (o.mm_per_unit) {
    out.scale = *o.mm_per_unit;
    out.scale_source = "given";
  } else {
    const double ratio = diagonal(skin.V) / std::max(diagonal(scan.V), 1e-300);
    const std::pair<double, const char*> units[] = {{1.0, "mm"}, {10.0, "cm"}, {1000.0, "m"}};
    double best = 1e300;
    for (const auto& [s, name] : units) {
      const double miss = std::abs(std::log(s / ratio));
      if (miss < best) {
        best = miss;
        out.scale = s;
        out.scale_source = cat("size (", name, ")");
      }
    }
  }
  const double v = o.voxel_mm;
  const PointCloud scan_full = cloud_of(scan, out.scale, true);
  const PointCloud skin_full = cloud_of(skin, 1.0, false);
  if (scan_full.points_.size() < 3 || skin_full.points_.size() < 3)
    throw InvalidInput("registration: the scan or the skin has fewer than 3 usable vertices");

  // 2. Coarse: FPFH on voxel samples, RANSAC.
  const auto scan_coarse = scan_full.VoxelDownSample(v);
  const auto skin_coarse = skin_full.VoxelDownSample(v);
  for (auto* pc : {scan_coarse.get(), skin_coarse.get()})
    for (auto& n : pc->normals_) n.normalize();
  const KDTreeSearchParamHybrid feature_param(5 * v, 100);
  const auto scan_fpfh = reg::ComputeFPFHFeature(*scan_coarse, feature_param);
  const auto skin_fpfh = reg::ComputeFPFHFeature(*skin_coarse, feature_param);
  progress.update(0.2);
  const reg::CorrespondenceCheckerBasedOnEdgeLength edge_check(0.9);
  const reg::CorrespondenceCheckerBasedOnDistance distance_check(1.5 * v);
  std::vector<std::reference_wrapper<const reg::CorrespondenceChecker>> checks{edge_check, distance_check};
  std::optional<OrientationChecker> orientation_check;
  if (o.orientation) {
    orientation_check.emplace(*o.orientation, o.max_orientation_deg);
    checks.emplace_back(*orientation_check);
  }
  const auto coarse = reg::RegistrationRANSACBasedOnFeatureMatching(
      *scan_coarse, *skin_coarse, *scan_fpfh, *skin_fpfh, true, 1.5 * v,
      reg::TransformationEstimationPointToPoint(false), 3, checks,
      reg::RANSACConvergenceCriteria(o.ransac_iterations, 0.9999));
  if (coarse.correspondence_set_.empty())
    throw InvalidInput(cat("registration: no alignment of the scan brings any of its ", scan_coarse->points_.size(),
                           " samples within ", 1.5 * v, " mm of the skin; check the scan's units "
                           "(--scan-scale) or the voxel size"));
  out.coarse_fitness = coarse.fitness_;
  progress.update(0.5);

  // 3. Fine: ICP from coarse to fine correspondence distances on ~1 mm samples.
  const double fine = std::min(1.0, v / 2);
  const auto scan_fine = scan_full.VoxelDownSample(fine);
  const auto skin_fine = skin_full.VoxelDownSample(fine);
  for (auto& n : skin_fine->normals_) n.normalize();
  Eigen::Matrix4d T = coarse.transformation_;
  if (o.estimate_scale) {
    for (const double d : {2.0 * v, v, 0.5 * v}) {
      const auto r = reg::RegistrationICP(*scan_fine, *skin_fine, d, T,
                                          reg::TransformationEstimationPointToPoint(true),
                                          reg::ICPConvergenceCriteria(1e-7, 1e-7, 50));
      T = r.transformation_;
    }
  }
  reg::RegistrationResult last;
  const double stages[] = {2.0 * v, v, 0.5 * v + 0.5 * o.icp_final_mm, o.icp_final_mm};
  for (const double d : stages) {
    // Tukey's biweight: correspondences beyond d get no weight (Zhou et al. 2018 use it so).
    const reg::TransformationEstimationPointToPlane estimation(std::make_shared<reg::TukeyLoss>(d));
    last = reg::RegistrationICP(*scan_fine, *skin_fine, std::max(d, o.icp_final_mm), T, estimation,
                                reg::ICPConvergenceCriteria(1e-7, 1e-7, 50));
    T = last.transformation_;
  }
  out.icp_fitness = last.fitness_;
  progress.update(0.8);

  // The scale in T: the scaled ICP multiplies it into the rotation part.
  const double s_icp = std::cbrt(T.topLeftCorner<3, 3>().determinant());
  out.scan_to_model = T;
  out.scan_to_model.topLeftCorner<3, 3>() *= out.scale;
  out.scale *= s_icp;
  if (o.estimate_scale) out.scale_source = "estimated";

  // 4. Residual on every scan vertex.
  std::vector<char> used(scan.n_vertices(), 0);
  for (Eigen::Index f = 0; f < scan.n_faces(); ++f)
    for (int q = 0; q < 3; ++q) used[scan.F(f, q)] = 1;
  out.distance_mm = signed_distance_to_mesh(transform_points(out.scan_to_model, scan.V), skin);
  Eigen::VectorXd measured(out.distance_mm.size());
  Eigen::Index n = 0;
  for (Eigen::Index i = 0; i < out.distance_mm.size(); ++i)
    if (used[i]) measured[n++] = out.distance_mm[i];
  out.residual = residual_statistics(measured.head(n), o.overlap_mm);
  const auto& r = out.residual;
  out.same_head = r.rms_mm <= o.max_rms_mm && r.median_mm <= o.max_median_mm &&
                  r.overlap_fraction >= o.min_overlap;
  // A scale estimate that moved far from its start fits the scan onto a part of the skin at an
  // absurd size (Lee Perry-Smith's head, in cm by its size, shrunk 3 times onto Cranium's skin
  // passed every residual test): refused whatever the residual says.
  const double scale_change = std::max(s_icp, 1.0 / s_icp);
  if (o.estimate_scale && !(scale_change <= o.max_scale_change)) {
    out.same_head = false;
    out.verdict = cat("the scale estimate moved from ", r2(out.scale / s_icp), " to ",
                      r2(out.scale), " mm per scan unit (", r2(scale_change),
                      " times; at most ", o.max_scale_change, " expected): the scan fits the "
                      "skin only at a size no head has, probably a scan of another head or "
                      "units far off; give --scan-scale near the truth");
  } else if (out.same_head)
    out.verdict = cat("the scan fits the skin: ", std::lround(100 * r.overlap_fraction),
                      " % of it within ", o.overlap_mm, " mm, RMS ", r2(r.rms_mm),
                      " mm there, median distance ", r2(r.median_mm), " mm");
  else
    out.verdict = cat("the scan does not fit this skin: ", std::lround(100 * r.overlap_fraction),
                      " % of it within ", o.overlap_mm, " mm (at least ",
                      std::lround(100 * o.min_overlap), " % expected), RMS ", r2(r.rms_mm),
                      " mm there (at most ", o.max_rms_mm, " mm expected), median distance ",
                      r2(r.median_mm), " mm (at most ", o.max_median_mm,
                      " mm expected): probably a scan of another head");
  out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  progress.done();
  return out;
}

}  // namespace caps
