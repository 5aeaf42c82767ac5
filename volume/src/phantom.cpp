#include "caps/volume/phantom.hpp"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>

#include "caps/core/error.hpp"
#include "caps/core/units.hpp"

namespace caps {
namespace {

constexpr double kSemiLR = 75.0;    // head half-width, left-right
constexpr double kSemiAP = 95.0;    // head half-depth, anterior-posterior
constexpr double kTopMm = 105.0;    // vertex height above z = 0
constexpr double kBottomMm = 160.0; // the ellipsoid's lower semi-axis (cut by the field of view)

double gauss(double x) { return std::exp(-x * x); }

// Wrapped angular difference in (-pi, pi].
double dtheta(double a, double b) {
  double d = std::fmod(a - b, 2.0 * kPi);
  if (d > kPi) d -= 2.0 * kPi;
  if (d <= -kPi) d += 2.0 * kPi;
  return d;
}

double clamp01(double x) { return x < 0 ? 0 : (x > 1 ? 1 : x); }

// A point of the scaled head in the head's own lengths (scale 1) about its axis point a: the
// point, the voxel's size, the offsets from a, and the cylindrical radius and angle.
struct HeadPoint {
  Eigen::Vector3d p, voxel_mm;
  double x, y, z, r, theta;
  HeadPoint(const Eigen::Vector3d& a, double scale, const Eigen::Vector3d& p_scaled,
            const Eigen::Vector3d& voxel_scaled)
      : p(a + (p_scaled - a) / scale), voxel_mm(voxel_scaled / scale), x(p[0] - a[0]),
        y(p[1] - a[1]), z(p[2] - a[2]), r(std::hypot(x, y)), theta(std::atan2(x, -y)) {}
};

}  // namespace

Eigen::Vector3d HeadPhantom::ray_direction(double theta) {
  return {std::sin(theta), -std::cos(theta), 0.0};
}

double HeadPhantom::head_radius(double theta, double z) const {
  const double s = std::sin(theta) / kSemiLR, c = std::cos(theta) / kSemiAP;
  const double ellipse = 1.0 / std::sqrt(s * s + c * c);
  const double semi = z > 0 ? kTopMm : kBottomMm;
  const double u = z / semi;
  return std::abs(u) >= 1.0 ? 0.0 : ellipse * std::sqrt(1.0 - u * u);
}

double HeadPhantom::face_relief(double theta, double z) const {
  if (!face_) return 0.0;
  const double t = dtheta(theta, 0.0);
  // A midline feature: height (mm, negative for a dip), half-width in theta (rad) and z (mm).
  // A feature more than 6.4 of its half-widths away in z adds less than 1e-16 mm (exp(-41)
  // times its height): it is left out without evaluating its theta profile, which is most of
  // the phantom's cost (the face's 25 exponentials for every voxel).
  constexpr double kNegligible = 41.0;
  auto mid = [&](double h, double wt, double z0, double wz) {
    const double u = (z - z0) / wz;
    return u * u > kNegligible ? 0.0 : h * gauss(t / wt) * gauss(u);
  };
  // A pair of features at +-theta0 (rad).
  auto pair = [&](double h, double t0, double wt, double z0, double wz) {
    const double u = (z - z0) / wz;
    return u * u > kNegligible ? 0.0 : h * (gauss((t - t0) / wt) + gauss((t + t0) / wt)) * gauss(u);
  };
  constexpr double deg = kPi / 180.0;
  return mid(5.0, 0.30, 28.0, 6.0)      // glabella (brow)
         + mid(-3.0, 0.25, 12.0, 5.0)   // nasion
         + mid(16.0, 0.16, -12.0, 9.0)  // nose
         + mid(-4.0, 0.20, -27.0, 4.0)  // subnasale
         + mid(4.0, 0.30, -36.0, 5.0)   // upper lip
         + mid(3.5, 0.30, -48.0, 5.0)   // lower lip
         + mid(-2.5, 0.30, -58.0, 4.0)  // labiomental fold
         + mid(6.0, 0.30, -70.0, 8.0)   // chin
         + pair(-5.0, 20.0 * deg, 0.12, 5.0, 5.0)   // eyes
         + pair(7.0, 65.0 * deg, 0.14, -5.0, 12.0)  // cheeks
         + pair(14.0, 100.0 * deg, 0.10, 0.0, 14.0);  // ears
}

double HeadPhantom::skin_radius(double theta, double z) const {
  const double head = head_radius(theta, z);
  if (head <= 0) return 0.0;
  if (face_) {
    const double marker =
        8.0 * gauss(dtheta(theta, kMarkerTheta) / 0.12) * gauss((z - kMarkerZ) / 9.0);
    return head + face_relief(theta, z) + marker;
  }
  const double nose = 18.0 * gauss(dtheta(theta, 0.0) / 0.2) * gauss((z - kNoseZ) / 18.0);
  const double marker =
      8.0 * gauss(dtheta(theta, kMarkerTheta) / 0.12) * gauss((z - kMarkerZ) / 9.0);
  return head + nose + marker;
}

double HeadPhantom::thickness(double theta, double z) const {
  if (layered_) return dermis_depth(theta, z) + fat_depth(theta, z) + deep_depth(theta, z);
  const double s = std::sin(0.5 * theta);
  return 4.0 + 3.0 * s * s + 1.5 * std::cos(z / 25.0);
}

double HeadPhantom::dermis_depth(double theta, double z) const {
  return 1.8 + 0.4 * std::sin(theta + z / 40.0);
}

double HeadPhantom::fat_depth(double theta, double z) const {
  return 3.0 + 2.0 * std::sin(z / 30.0 - theta);
}

double HeadPhantom::deep_depth(double theta, double z) const {
  return 3.4 + 1.6 * std::cos(z / 25.0 + 2.0 * theta);
}

double HeadPhantom::fat_top_radius(double theta, double z) const {
  return head_radius(theta, z) - dermis_depth(theta, z);
}

double HeadPhantom::fat_bottom_radius(double theta, double z) const {
  return fat_top_radius(theta, z) - fat_depth(theta, z);
}

double HeadPhantom::thin_bone_mm(double theta, double z) const {
  if (!thin_bone_) return 0.0;
  const double th = dtheta(theta, 0.0);
  if (th < kThinThetaMin || th > kThinThetaMax || z < kThinZMin || z > kThinZMax) return 0.0;
  const double u = (z - kThinZMin) / (kThinZMax - kThinZMin);
  return 0.5 + u * u * u;
}

double HeadPhantom::bone_radius(double theta, double z) const {
  return head_radius(theta, z) - thickness(theta, z);
}

double HeadPhantom::hu_at(const Eigen::Vector3d& p_scaled, const Eigen::Vector3d& voxel_scaled,
                          bool head_holder) const {
  const Eigen::Vector3d a = axis_point();
  // The head at scale 1: the point and the voxel in its lengths.
  const HeadPoint h(a, scale_, p_scaled, voxel_scaled);
  const Eigen::Vector3d& p = h.p;
  const Eigen::Vector3d& voxel_mm = h.voxel_mm;
  const double x = h.x, y = h.y, z = h.z, r = h.r, theta = h.theta;

  // Fraction of a voxel inside the surface r = R(theta, z): a linear ramp across the interface,
  // as wide as the voxel is along the surface normal. Distances come from the level set
  // g = R - r divided by |grad g|, evaluated by central differences.
  //
  // Far from the surface the ramp is 0 or 1 whatever its gradient: the width is at most
  // max(min_width, |voxel|) (n is a unit vector), so for |g| beyond kFar times that bound the
  // fraction saturates unless the gradient's norm exceeds 2 kFar (a surface within 3.6 degrees
  // of parallel to the radius, which the head has only at its vertex, where |g| is small). Most
  // voxels (air, brain) are far from every surface, and the four radii of the gradient are then
  // not evaluated: the phantoms are the same to the bit, at a third of the cost.
  constexpr double kFar = 8.0;
  const double voxel_diagonal = voxel_mm.norm();
  auto fraction = [&](auto&& R, double min_width = 0.0) {
    const double g = R(theta, z) - r;
    if (std::abs(g) > kFar * std::max(min_width, voxel_diagonal)) return g > 0 ? 1.0 : 0.0;
    const double h = 1e-3;
    const double rr = std::max(r, 1e-6);
    const double gt = (R(theta + h, z) - R(theta - h, z)) / (2 * h) / rr;
    const double gz = (R(theta, z + h) - R(theta, z - h)) / (2 * h);
    // Gradient of g in (radial, tangential, axial) components: (-1, gt, gz).
    const double norm = std::sqrt(1.0 + gt * gt + gz * gz);
    const Eigen::Vector3d radial(x / rr, y / rr, 0.0);
    const Eigen::Vector3d tangential(-y / rr, x / rr, 0.0);  // direction of increasing theta
    const Eigen::Vector3d n = (radial - tangential * gt - Eigen::Vector3d(0, 0, gz)) / norm;
    double width = std::max(min_width, std::abs(n[0]) * voxel_mm[0] +
                                           std::abs(n[1]) * voxel_mm[1] +
                                           std::abs(n[2]) * voxel_mm[2]);
    // On the axis above the vertex (r = 0 where R = 0) the level set has no direction: n is 0
    // and the ramp would be 0/0, a NaN voxel (a 64 x 64 x 60 grid of 4 mm has a voxel centre
    // there); the voxel's mean size stands in.
    if (!(width > 0)) width = voxel_mm.mean();
    return clamp01(0.5 + (g / norm) / width);
  };

  const double f_skin = fraction([&](double t, double zz) { return skin_radius(t, zz); });
  // The layered phantom: dermis under the skin, fat from its top to its bottom, muscle below;
  // partial volumes superpose (each interface's ramp adds its step in HU).
  const double surface_hu = layered_ ? kDermisHu : kTissueHu;
  const double deep_hu = layered_ ? kMuscleHu : kTissueHu;
  double hu = kAirHu + f_skin * (surface_hu - kAirHu);
  if (f_skin > 0) {
    if (layered_) {
      hu += fraction([&](double t, double zz) { return fat_top_radius(t, zz); }) *
            (kFatHu - kDermisHu);
      hu += fraction([&](double t, double zz) { return fat_bottom_radius(t, zz); }) *
            (kMuscleHu - kFatHu);
    }
    const double f_inner =
        fraction([&](double t, double zz) { return bone_radius(t, zz) - kSkullMm; });
    if (const double plate = thin_bone_mm(theta, z); plate > 0) {
      // The thin plate over soft tissue, both its faces blurred by the scanner (partial volume).
      const double f_out = fraction([&](double t, double zz) { return bone_radius(t, zz); },
                                    kThinBoneBlurMm);
      const double f_in = fraction(
          [&](double t, double zz) { return bone_radius(t, zz) - thin_bone_mm(t, zz); },
          kThinBoneBlurMm);
      hu += (f_out - f_in) * (kThinBoneHu - deep_hu) + f_inner * (kBrainHu - deep_hu);
    } else {
      const double f_bone = fraction([&](double t, double zz) { return bone_radius(t, zz); });
      hu += f_bone * (kBoneHu - deep_hu) + f_inner * (kBrainHu - kBoneHu);
    }
    // An enclosed air cavity (a "sinus") behind the forehead, inside the skull.
    const Eigen::Vector3d c = a + Eigen::Vector3d(0.0, -45.0, 35.0);
    const double d = (p - c).norm() - 9.0;
    const double f_cavity = clamp01(0.5 - d / voxel_mm.mean());
    hu += f_cavity * (kAirHu - kBrainHu) * f_inner;
  }
  return head_holder ? holder_over(p_scaled, voxel_scaled, hu) : hu;
}

double HeadPhantom::holder_over(const Eigen::Vector3d& p_scaled, const Eigen::Vector3d& voxel_scaled,
                                double hu) const {
  const HeadPoint h(axis_point(), scale_, p_scaled, voxel_scaled);
  const double x = h.x, y = h.y, z = h.z;
  // A 5 mm plastic arc behind the head about a vertical line 6.5 mm anterior of the axis: its
  // inner face (radius 103 mm) stays 1.5 mm (a foam pad) from the back of the head, and a thin
  // strap (4 mm tall, 6 mm wide) bridges that gap at z = -40: it touches only thinly.
  const double hx = x, hy = y + 6.5;
  const double rh = std::hypot(hx, hy);
  const double back = std::abs(dtheta(std::atan2(hx, -hy), kPi));
  const double w = h.voxel_mm.mean();
  if (back < 0.9 && z > -100 && z < 20) {
    const double f = clamp01(0.5 + (rh - 103.0) / w) * clamp01(0.5 + (108.0 - rh) / w);
    hu = std::max(hu, kAirHu + f * (kHolderHu - kAirHu));
  }
  const double lateral = std::abs(x);  // distance from the mid-sagittal plane at the back
  if (y > 0 && rh < 104.0 && h.r > head_radius(h.theta, z) - 1.0) {
    const double f =
        clamp01(0.5 + (2.0 - std::abs(z + 40.0)) / w) * clamp01(0.5 + (3.0 - lateral) / w);
    hu = std::max(hu, kAirHu + f * (kHolderHu - kAirHu));
  }
  return hu;
}

Volume make_phantom(const PhantomOptions& options) {
  if (options.dims.minCoeff() < 8 || options.dims.cast<double>().maxCoeff() > 2048)
    throw InvalidInput(cat("phantom: size (", options.dims.transpose(),
                           ") voxels must be between 8 and 2048 per axis"));
  if (!(options.spacing_mm.minCoeff() >= 0.1) || options.spacing_mm.maxCoeff() > 10.0)
    throw InvalidInput(cat("phantom: spacing (", options.spacing_mm.transpose(),
                           ") mm must be between 0.1 and 10 mm"));
  if (!(std::abs(options.pitch_deg) <= 45) || !(std::abs(options.yaw_deg) <= 45) ||
      !(std::abs(options.roll_deg) <= 45))
    throw InvalidInput(cat("phantom: pitch ", options.pitch_deg, ", yaw ", options.yaw_deg,
                           " and roll ", options.roll_deg, " deg must be between -45 and 45"));
  if (options.metal && !(options.metal_z_mm >= -90 && options.metal_z_mm <= 60))
    throw InvalidInput(cat("phantom: the metal's height ", options.metal_z_mm,
                           " mm must be between -90 and 60"));
  Volume v;
  v.geom.dims = options.dims;
  v.geom.spacing_mm = options.spacing_mm;
  v.geom.direction.setIdentity();
  // Centre the grid on the head (between the vertex and the neck cut), so the head is inside.
  const Eigen::Vector3d extent = (options.dims.cast<double>() - Eigen::Vector3d::Ones())
                                     .cwiseProduct(options.spacing_mm);
  v.geom.origin_lps = -0.5 * extent;
  if (!(options.scale >= 0.7 && options.scale <= 1.3))
    throw InvalidInput(cat("phantom: scale ", options.scale, " must be between 0.7 and 1.3"));
  // the top slice is 10 mm (times the scale) above the vertex
  v.geom.origin_lps[2] = 115.0 * options.scale - extent[2];
  v.modality = Modality::CT;
  v.source = "phantom";
  v.format = "phantom";
  v.data.resize(v.geom.n_voxels());
  const HeadPhantom head(options.layered, options.thin_bone, options.face, options.scale);
  // The posed head at p is the upright head at pose^T (p - a) + a. Leaning left: the vertex
  // (+S) towards +L about +P; forward: the vertex towards anterior (-P) about +L; to the left:
  // the face (-P) towards +L about +S.
  const double kDeg = 3.14159265358979323846 / 180.0;
  const Eigen::Matrix3d pose =
      (Eigen::AngleAxisd(options.yaw_deg * kDeg, Eigen::Vector3d::UnitZ()) *
       Eigen::AngleAxisd(options.pitch_deg * kDeg, Eigen::Vector3d::UnitX()) *
       Eigen::AngleAxisd(options.roll_deg * kDeg, Eigen::Vector3d::UnitY()))
          .toRotationMatrix();
  const bool posed = options.pitch_deg != 0 || options.yaw_deg != 0 || options.roll_deg != 0;
  const Eigen::Vector3d a = head.axis_point();
  // metal: the block of dental metal, posed and scaled with the head, and its streaks in the
  // scanner's axial slices (the caricature of HeadPhantom::kStreak*; docs/volume.md, "Metal").
  const double s = options.scale;
  const Eigen::Vector3d metal_scanner = a + s * (pose * (head.metal_centre(options.metal_z_mm) - a));
  const double* half = HeadPhantom::kMetalHalfMm;
  const double metal_half_z = s * (std::abs(pose(2, 0)) * half[0] + std::abs(pose(2, 1)) * half[1] +
                                   std::abs(pose(2, 2)) * half[2]);
  auto with_metal = [&](const Eigen::Vector3d& p, double hu) {
    // The block, in the upright head at scale 1: (left, anterior, superior) from its centre.
    const Eigen::Vector3d q = posed ? Eigen::Vector3d(pose.transpose() * (p - a) + a) : p;
    const Eigen::Vector3d u = a + (q - a) / s - head.metal_centre(options.metal_z_mm);
    const Eigen::Vector3d local(u[0], -u[1], u[2]);
    double f_metal = 1.0;
    for (int axis = 0; axis < 3; ++axis)
      f_metal *= clamp01(0.5 + (half[axis] - std::abs(local[axis])) /
                                   (options.spacing_mm[axis] / s));
    hu += f_metal * (HeadPhantom::kMetalHu - hu);
    // The streaks: only in the slices through the metal, as strong as the part of the slice the
    // metal fills.
    const double dz = options.spacing_mm[2];
    const double overlap = std::min(p[2] + 0.5 * dz, metal_scanner[2] + metal_half_z) -
                           std::max(p[2] - 0.5 * dz, metal_scanner[2] - metal_half_z);
    if (overlap > 0) {
      const double f_z = std::min(1.0, overlap / std::min(dz, 2.0 * metal_half_z));
      const double dx = p[0] - metal_scanner[0], dy = p[1] - metal_scanner[1];
      const double rho = std::hypot(dx, dy), phi = std::atan2(dy, dx);
      const double width = 1.2 + 0.01 * rho;
      double lines = 0;
      for (int line = 0; line < HeadPhantom::kStreakLines; ++line) {
        const double phi_line = 7.0 * kDeg + line * kPi / HeadPhantom::kStreakLines;
        const double across = rho * std::sin(phi - phi_line) / width;
        lines += (line % 2 == 0 ? 1.0 : -1.0) * std::exp(-across * across);
      }
      hu += f_z * lines * HeadPhantom::kStreakHu * HeadPhantom::kStreakDecayMm /
            (HeadPhantom::kStreakDecayMm + rho);
    }
    return std::clamp(hu, HeadPhantom::kStoredMinHu, HeadPhantom::kStoredMaxHu);
  };
  const auto& d = v.geom.dims;
  tbb::parallel_for(0, d[2], [&](int k) {
    for (int j = 0; j < d[1]; ++j)
      for (int i = 0; i < d[0]; ++i) {
        const Eigen::Vector3d p = v.index_to_lps(Eigen::Vector3d(i, j, k));
        // Whole Hounsfield units, as a CT stores them (the rounding is far below the noise of
        // any measurement here: 0.5 HU of a 1040 HU skin edge is 0.0005 voxel).
        // Upright, the head and its holder in one evaluation.
        float hu = static_cast<float>(std::round(head.hu_at(
            posed ? Eigen::Vector3d(pose.transpose() * (p - a) + a) : p, options.spacing_mm,
            options.head_holder && !posed)));
        // Posed, the holder stays in the scanner's frame: where the posed head leaves air, the
        // holder where the upright head would leave air too (the holder alone).
        constexpr float kAir = static_cast<float>(HeadPhantom::kAirHu);
        if (options.head_holder && posed && hu == kAir) {
          const double upright = head.hu_at(p, options.spacing_mm, false);
          if (std::round(upright) == kAir)
            hu = static_cast<float>(std::round(head.holder_over(p, options.spacing_mm, upright)));
        }
        if (options.metal) hu = static_cast<float>(std::round(with_metal(p, hu)));
        v.data[v.geom.linear(i, j, k)] = hu;
      }
  });
  v.notes.push_back(options.layered ? "analytic layered head phantom (caps phantom --layered)"
                                     : "analytic head phantom (caps phantom)");
  if (options.thin_bone)
    v.notes.push_back("with a thin bone plate (0.5 .. 1.5 mm) under the right cheek");
  if (options.face) v.notes.push_back("with a face of analytic landmarks (caps phantom --face)");
  if (options.metal)
    v.notes.push_back(cat("with a dental metal block in the upper jaw and its streak artefacts "
                          "(caps phantom --metal), values clipped to ", HeadPhantom::kStoredMinHu,
                          " .. ", HeadPhantom::kStoredMaxHu, " HU"));
  if (options.scale != 1.0) v.notes.push_back(cat("head scaled by ", options.scale));
  if (posed)
    v.notes.push_back(cat("head leaning left ", options.roll_deg, " deg, tilted forward ",
                          options.pitch_deg, " deg and turned left ", options.yaw_deg, " deg"));
  return v;
}

}  // namespace caps
