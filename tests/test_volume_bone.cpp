// The base of the soft tissue: thin bone found by its edge (the thin-bone phantom, against the
// fixed threshold) and the air-cavity base where no bone lies under the skin (a hand-made CT).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "caps/core/units.hpp"
#include "caps/volume/model.hpp"
#include "caps/volume/phantom.hpp"
#include "phantom_crossing.hpp"

using namespace caps;

namespace {

// The thin-bone phantom at 1 mm voxels, from the vertex down to 60 mm below the centre, measured
// with the edge method (the default) and with the fixed 250 HU threshold.
struct ThinBoneModels {
  HeadPhantom ph{false, true};
  Volume ct;
  VolumeModel edge, threshold;
  ThinBoneModels() {
    PhantomOptions po;
    po.dims = {170, 230, 176};
    po.head_holder = false;
    po.thin_bone = true;
    ct = make_phantom(po);
    ModelOptions o;
    o.maps.n_theta = 256;
    o.maps.n_z = 128;
    o.maps.layers.measure = false;
    edge = build_volume_model(ct, o);
    o.maps.bone.method = BoneMethod::Threshold;
    threshold = build_volume_model(ct, o);
  }
};

const ThinBoneModels& thin_bone_models() {
  static const ThinBoneModels m;
  return m;
}

// The plate's peak in the phantom's closed form: tissue + contrast x t / blur (t < blur).
double plate_peak_hu(double t_mm) {
  return HeadPhantom::kTissueHu + (HeadPhantom::kThinBoneHu - HeadPhantom::kTissueHu) *
                                      std::min(1.0, t_mm / HeadPhantom::kThinBoneBlurMm);
}

}  // namespace

TEST(ThinBone, PhantomPlateIsBelowTheThresholdWhereThinnerThanAboutHalfAMillimetre) {
  const HeadPhantom ph(false, true);
  EXPECT_NEAR(ph.thin_bone_mm(deg_to_rad(-50.0), -50.0), 0.5, 1e-12);
  EXPECT_NEAR(ph.thin_bone_mm(deg_to_rad(-50.0), -10.0), 1.5, 1e-12);
  EXPECT_EQ(ph.thin_bone_mm(deg_to_rad(50.0), -30.0), 0.0);
  // Sampled on the voxels: the profile's largest value across the plate where it is 0.5 mm.
  const Volume& v = thin_bone_models().ct;
  const double th = deg_to_rad(-50.0), z = -48.0;
  const double rb = ph.bone_radius(th, z);
  double peak = -1e9;
  for (double r = rb - 3; r <= rb + 3; r += 0.05) {
    const Eigen::Vector3d p = ph.axis_point() + Eigen::Vector3d(0, 0, z) + r * HeadPhantom::ray_direction(th);
    peak = std::max<double>(peak, sample_trilinear(v, v.lps_to_index(p), -1000.0f));
  }
  // The phantom's voxels against the closed form of the plate's partial-volume peak (226.7 HU at
  // 0.5 mm): trilinear sampling between 1 mm voxels lowers it a little (219 HU). Below the
  // 250 HU bone threshold either way, which is why the threshold misses the plate there.
  EXPECT_NEAR(peak, plate_peak_hu(0.5), 12.0);
  EXPECT_LT(peak, 250.0);
}

// Over the plate (away from its edges), the fixed threshold misses the plate wherever it is
// thinner than 0.55 mm (its peak under 250 HU); the edge method finds it in 99 % of the cells,
// its half-maximum edge within 0.35 mm of (blur - t) / 2 outside the plate's outer face (where a
// half-maximum edge of a plate thinner than the blur lies: docs/volume.md).
TEST(ThinBone, EdgeMethodFindsThePlateThatTheThresholdMisses) {
  const auto& m = thin_bone_models();
  const auto& ge = m.edge.maps;
  const auto& gt = m.threshold.maps;
  const auto& g = ge.grid;
  int cells = 0, thin = 0, thin_missed = 0, found = 0;
  double se = 0, worst = 0;
  for (int k = 0; k < g.n_z; ++k)
    for (int j = 0; j < g.n_theta; ++j) {
      const double th_deg = g.theta_deg(j), z = g.z_mm(k);
      if (th_deg < -65 || th_deg > -35 || z < -45 || z > -15) continue;
      const double th = deg_to_rad(th_deg);
      const double t = m.ph.thin_bone_mm(th, z);
      ASSERT_GT(t, 0.0);
      const std::size_t c = g.index(j, k);
      ++cells;
      if (t < 0.55) {
        ++thin;
        thin_missed += !gt.measured_bone[c];  // no_bone, or based on tissue near the thick bone
      }
      if (ge.flags[c] != 0) continue;
      ++found;
      const double rb = caps_test::analytic_crossing(
          m.ph, ge.axis, th, z, [&](double a, double b) { return m.ph.bone_radius(a, b); },
          ge.r_skin[c] + 1.0);
      const double err = ge.r_bone[c] - rb;
      const double bias = 0.5 * std::max(0.0, HeadPhantom::kThinBoneBlurMm - t);
      EXPECT_NEAR(err, bias, 0.35) << "theta " << th_deg << " z " << z << " t " << t;
      se += err * err;
      worst = std::max(worst, std::abs(err - bias));
    }
  ASSERT_GT(cells, 300);
  ASSERT_GT(thin, cells / 5);
  const double rms = std::sqrt(se / std::max(1, found));
  std::printf("thin plate: %d cells, %d thinner than 0.55 mm of which the threshold misses %d; "
              "the edge method finds %d, depth error RMS %.3f mm, largest beyond the bias %.3f "
              "mm\n", cells, thin, thin_missed, found, rms, worst);
  EXPECT_GE(thin_missed, thin * 95 / 100);
  EXPECT_GE(found, cells * 99 / 100);
  EXPECT_LT(rms, 0.55);
}

TEST(ThinBone, EdgeMethodMatchesTheThresholdOnThickBone) {
  const auto& m = thin_bone_models();
  const auto& g = m.edge.maps.grid;
  double se = 0;
  int n = 0;
  for (int k = 0; k < g.n_z; ++k)
    for (int j = 0; j < g.n_theta; ++j) {
      const std::size_t c = g.index(j, k);
      if (m.edge.maps.flags[c] != 0 || m.threshold.maps.flags[c] != 0) continue;
      if (m.ph.thin_bone_mm(deg_to_rad(g.theta_deg(j)), g.z_mm(k)) > 0) continue;
      se += std::pow(m.edge.maps.r_bone[c] - m.threshold.maps.r_bone[c], 2);
      ++n;
    }
  ASSERT_GT(n, static_cast<int>(g.size() / 2));
  EXPECT_LT(std::sqrt(se / n), 0.05);
}

namespace {

// A hand-made CT of 1 mm voxels centred on the LPS z axis (`n` x `n` x `nz`), its value at each
// voxel centre hu(p, r, theta deg, in) with r the distance from the axis, theta as the cylindrical
// maps count it and in(R) the fraction of the voxel inside radius R (a linear ramp one voxel wide,
// as in the phantom).
template <class Hu>
Volume axial_ct(int n, int nz, const char* name, Hu&& hu) {
  Volume v;
  v.geom.dims = {n, n, nz};
  v.geom.spacing_mm = {1.0, 1.0, 1.0};
  v.geom.direction.setIdentity();
  v.geom.origin_lps = {-0.5 * (n - 1), -0.5 * (n - 1), -0.5 * (nz - 1)};
  v.modality = Modality::CT;
  v.source = name;
  v.format = "test";
  v.data.resize(v.geom.n_voxels());
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        const Eigen::Vector3d p = v.index_to_lps(Eigen::Vector3d(i, j, k));
        const double r = std::hypot(p.x(), p.y());
        const double th = std::atan2(p.x(), -p.y()) * 180.0 / 3.14159265358979323846;
        const auto in = [r](double R) { return std::clamp(0.5 + (R - r), 0.0, 1.0); };
        v.data[v.geom.linear(i, j, k)] = static_cast<float>(hu(p, th, in));
      }
  return v;
}

// The options of the hand-made CTs' models: the cylinder's axis on the LPS z axis, 1 deg around,
// `n_z` rows, no tissue layers, and no base on deeper tissue (base_on_tissue, tested on its own
// below, would base the no_bone cells these tests look at on the bone around them).
ModelOptions axial_options(int n_z) {
  ModelOptions o;
  o.maps.n_theta = 360;
  o.maps.n_z = n_z;
  o.maps.layers.measure = false;
  o.maps.bone.tissue_reach_mm = 0;
  o.axis = CylinderAxis{};
  o.axis->origin_lps = {0, 0, 0};
  return o;
}

// A hand-made CT: a soft-tissue cylinder (radius 80 mm, +40 HU) about the LPS z axis with a
// 4 mm skull (r 66..70, +1200 HU) and brain inside, except in front (|theta| < 25 deg,
// |z| < 15 mm) where there is no bone and the tissue ends on air at r = 68 mm (a "nasal
// cavity"). Edges are linear ramps one voxel wide, as in the phantom.
Volume cavity_ct() {
  return axial_ct(200, 70, "cavity", [](const Eigen::Vector3d& p, double th, auto in) {
    double hu = -1000.0 + in(80.0) * 1040.0;
    if (std::abs(th) < 25.0 && std::abs(p.z()) < 15.0)
      hu += in(68.0) * (-1000.0 - 40.0);
    else
      hu += in(70.0) * (1200.0 - 40.0) + in(66.0) * (35.0 - 1200.0);
    return hu;
  });
}

}  // namespace

TEST(CavityBase, NoBoneOverAnAirCavityIsBasedOnItsEdge) {
  const Volume v = cavity_ct();
  ModelOptions o = axial_options(64);
  const VolumeModel m = build_volume_model(v, o);
  const auto& g = m.maps.grid;
  int cavity = 0, inner = 0;
  for (int k = 0; k < g.n_z; ++k)
    for (int j = 0; j < g.n_theta; ++j) {
      const double th = g.theta_deg(j), z = g.z_mm(k);
      const std::size_t c = g.index(j, k);
      if (std::abs(th) < 20 && std::abs(z) < 10) {
        ++inner;
        EXPECT_EQ(m.maps.flags[c], kBaseCavity) << "theta " << th << " z " << z;
        EXPECT_TRUE(m.maps.is_valid(j, k));
        EXPECT_NEAR(m.maps.r_bone[c], 68.0, 0.1) << "theta " << th << " z " << z;
        EXPECT_NEAR(m.maps.thickness[c], 12.0, 0.2);
      } else if (std::abs(th) > 30 && std::abs(th) < 150 && std::abs(z) > 20 && std::abs(z) < 28) {
        EXPECT_EQ(m.maps.flags[c], 0) << "theta " << th << " z " << z;
        EXPECT_NEAR(m.maps.r_bone[c], 70.0, 0.1);
      }
      cavity += (m.maps.flags[c] & kBaseCavity) != 0;
    }
  ASSERT_GT(inner, 300);
  EXPECT_EQ(m.stats.base_cavity, static_cast<std::size_t>(cavity));
  EXPECT_EQ(describe_flags(kBaseCavity), "base_cavity");
  EXPECT_TRUE(flags_valid(kBaseCavity));
  EXPECT_FALSE(flags_valid(kBaseCavity | kNoBone));
  // Without the cavity base the same cells have no bone.
  o.maps.bone.cavity_base = false;
  const VolumeModel without = build_volume_model(v, o);
  EXPECT_EQ(without.stats.base_cavity, 0u);
  EXPECT_EQ(without.maps.flags[g.index(g.n_theta / 2, g.n_z / 2)], kNoBone);
}

// The cavity CT with soft tissue instead of air in its window (|theta| < 25 deg, |z| < 40 mm):
// neither bone nor a cavity within the cap. Cells at most tissue_reach_mm over the skin from the
// bone around are based on the tissue (kBaseTissue: valid, their depth interpolated, here the
// bone's 10 mm, within 0.3 mm where the window's edge blurs the bone beside it); the window's middle, farther, stays no_bone; with a reach of 0 all of
// it does.
TEST(TissueBase, NoBoneNearAMeasuredBaseIsBasedOnTheTissueAtTheInterpolatedDepth) {
  const Volume v = axial_ct(200, 100, "no bone", [](const Eigen::Vector3d& p, double th, auto in) {
    double hu = -1000.0 + in(80.0) * 1040.0;
    if (!(std::abs(th) < 25.0 && std::abs(p.z()) < 40.0))
      hu += in(70.0) * (1200.0 - 40.0) + in(66.0) * (35.0 - 1200.0);
    return hu;
  });
  ModelOptions o = axial_options(96);
  o.maps.bone.tissue_reach_mm = 15.0;
  const VolumeModel m = build_volume_model(v, o);
  const auto& g = m.maps.grid;
  const double around = 80.0 * deg_to_rad(1.0);  // mm per degree on the skin
  int based = 0, kept = 0;
  for (int k = 0; k < g.n_z; ++k)
    for (int j = 0; j < g.n_theta; ++j) {
      const double th = g.theta_deg(j), z = g.z_mm(k);
      if (!(std::abs(th) < 24.0 && std::abs(z) < 39.0)) continue;  // inside the window
      // the distance over the skin to the window's edge, where the bone is
      const double edge = std::min((25.0 - std::abs(th)) * around, 40.0 - std::abs(z));
      const std::size_t c = g.index(j, k);
      if (edge < 13.0) {
        ++based;
        EXPECT_EQ(m.maps.flags[c], kBaseTissue) << "theta " << th << " z " << z;
        EXPECT_TRUE(m.maps.is_valid(j, k));
        EXPECT_FALSE(m.maps.measured_bone[c]);
        EXPECT_NEAR(m.maps.thickness[c], 10.0, 0.35) << "theta " << th << " z " << z;
      } else if (edge > 17.0) {
        ++kept;
        EXPECT_EQ(m.maps.flags[c], kNoBone) << "theta " << th << " z " << z;
      }
    }
  ASSERT_GT(based, 500);
  ASSERT_GT(kept, 50);
  std::size_t tissue = 0;
  for (auto f : m.maps.flags) tissue += (f & kBaseTissue) != 0;
  EXPECT_EQ(m.stats.base_tissue, tissue);
  EXPECT_EQ(describe_flags(kBaseTissue), "base_tissue");
  EXPECT_TRUE(flags_valid(kBaseTissue));
  EXPECT_EQ(invalid_flags_advice(kBaseTissue), "");
  o.maps.bone.tissue_reach_mm = 0;
  const VolumeModel without = build_volume_model(v, o);
  EXPECT_EQ(without.stats.base_tissue, 0u);
  EXPECT_EQ(without.maps.flags[g.index(g.n_theta / 2 + 20, g.n_z / 2 + 30)], kNoBone);
  o.maps.bone.tissue_reach_mm = -1;
  EXPECT_THROW(build_volume_model(v, o), InvalidInput);
}

TEST(CavityBase, AirAtPartialVolumeIsACavityAndFatIsNot) {
  // The cavity CT with its "air" at -300 HU over 2 mm and then tissue again (a closed mouth's
  // gap, a nostril's slit: air thinner than a voxel reads between fat and air): a cavity, its
  // edge at half maximum between the tissue and the gap (r = 68 mm). At -150 HU (fat) the same
  // gap is tissue: no base.
  for (const double gap_hu : {-300.0, -150.0}) {
    const Volume v = axial_ct(200, 70, "gap", [&](const Eigen::Vector3d& p, double th, auto in) {
      double hu = -1000.0 + in(80.0) * 1040.0;
      if (std::abs(th) < 25.0 && std::abs(p.z()) < 15.0)
        hu += (in(68.0) - in(66.0)) * (gap_hu - 40.0);
      else
        hu += in(70.0) * (1200.0 - 40.0) + in(66.0) * (35.0 - 1200.0);
      return hu;
    });
    const VolumeModel m = build_volume_model(v, axial_options(64));
    const auto& g = m.maps.grid;
    int inner = 0;
    for (int k = 0; k < g.n_z; ++k)
      for (int j = 0; j < g.n_theta; ++j) {
        const double th = g.theta_deg(j), z = g.z_mm(k);
        if (std::abs(th) >= 20 || std::abs(z) >= 10) continue;
        ++inner;
        const std::size_t c = g.index(j, k);
        if (gap_hu < -200) {
          EXPECT_EQ(m.maps.flags[c], kBaseCavity) << "theta " << th << " z " << z;
          EXPECT_NEAR(m.maps.r_bone[c], 68.0, 0.2) << "theta " << th << " z " << z;
        } else {
          EXPECT_EQ(m.maps.flags[c], kNoBone) << "theta " << th << " z " << z;
        }
      }
    ASSERT_GT(inner, 300);
  }
}

TEST(CavityBase, ASeptumBetweenTwoCavitiesIsBasedOnThemToo) {
  // The cavity CT with a septum: at |theta| < 1 deg the tissue runs on past r = 68 mm with no air
  // and no bone within the cap (the nasal septum or the philtrum between two cavities). Its
  // cells (two or three columns of the 1 deg grid) are based on the cavity like their
  // neighbours, their depth filled from them; a strip wider than three cells is left no_bone.
  for (const double half_width : {1.0, 3.0}) {
    const Volume v = axial_ct(200, 70, "septum", [&](const Eigen::Vector3d& p, double th, auto in) {
      double hu = -1000.0 + in(80.0) * 1040.0;
      if (std::abs(th) < 25.0 && std::abs(p.z()) < 15.0) {
        if (std::abs(th) >= half_width) hu += in(68.0) * (-1000.0 - 40.0);
      } else {
        hu += in(70.0) * (1200.0 - 40.0) + in(66.0) * (35.0 - 1200.0);
      }
      return hu;
    });
    const VolumeModel m = build_volume_model(v, axial_options(64));
    const auto& g = m.maps.grid;
    int septum = 0;
    for (int k = 0; k < g.n_z; ++k)
      for (int j = 0; j < g.n_theta; ++j) {
        const double th = g.theta_deg(j), z = g.z_mm(k);
        if (std::abs(th) > half_width - 0.5 || std::abs(z) > 10) continue;
        ++septum;
        const std::size_t c = g.index(j, k);
        if (half_width < 2) {
          EXPECT_EQ(m.maps.flags[c], kBaseCavity) << "theta " << th << " z " << z;
          EXPECT_NEAR(m.maps.thickness[c], 12.0, 0.3) << "theta " << th << " z " << z;
        } else {
          EXPECT_EQ(m.maps.flags[c], kNoBone) << "theta " << th << " z " << z;
        }
      }
    EXPECT_GT(septum, 10) << half_width;
  }
}

TEST(CavityBase, AdviceSaysWhetherThePlaceIsNotOperableOrNotRepresented) {
  EXPECT_EQ(invalid_flags_advice(0), "");
  EXPECT_EQ(invalid_flags_advice(kBaseCavity), "");
  EXPECT_NE(invalid_flags_advice(kTruncated | kGrazing).find("not operable"), std::string::npos);
  EXPECT_NE(invalid_flags_advice(kNoSkin).find("not operable"), std::string::npos);
  EXPECT_NE(invalid_flags_advice(kUndercut).find("cannot represent"), std::string::npos);
  EXPECT_NE(invalid_flags_advice(kGrazing | kNoBone).find("cannot represent"), std::string::npos);
  EXPECT_NE(invalid_flags_advice(kNoBone).find("--bone-cap"), std::string::npos);
  EXPECT_EQ(parse_bone_method("edge"), BoneMethod::Edge);
  EXPECT_EQ(std::string(bone_method_name(BoneMethod::Threshold)), "threshold");
  EXPECT_THROW(parse_bone_method("otsu"), InvalidInput);
}

namespace {

// A hand-made CT for undercuts: a soft-tissue cylinder (radius 70 mm, +40 HU) about the LPS z
// axis on a 4 mm skull (r 56..60) with brain inside, and in front (|theta| < 20 deg) a shell of
// tissue 4 mm thick (r 76..80) held off the head by an air gap (r 70..76) for z in -12..8 mm and
// joined to it above (z 8..14): a lip or an ear's rim, whose gap is open to the outside air below
// and at the sides.
Volume overhang_ct() {
  const auto band = [](double x, double lo, double hi) {
    return std::clamp(0.5 + (x - lo), 0.0, 1.0) * std::clamp(0.5 + (hi - x), 0.0, 1.0);
  };
  return axial_ct(180, 50, "overhang", [&](const Eigen::Vector3d& p, double th, auto in) {
    const double front = band(th, -20.0, 20.0);
    // The shell (r 76..80, z -12..14) and its join to the head (r 70..76, z 8..14).
    double tissue = in(70.0);
    tissue = std::max(tissue, front * band(p.z(), -12.0, 14.0) * (in(80.0) - in(76.0)));
    tissue = std::max(tissue, front * band(p.z(), 8.0, 14.0) * (in(76.0) - in(70.0)));
    return -1000.0 + tissue * 1040.0 + in(60.0) * (1200.0 - 40.0) + in(56.0) * (35.0 - 1200.0);
  });
}

}  // namespace

TEST(Undercut, ReentryBelowTheBaseIsNotAnUndercut) {
  const Volume v = overhang_ct();
  ModelOptions o = axial_options(48);
  const VolumeModel m = build_volume_model(v, o);
  const auto& g = m.maps.grid;
  int shell = 0;
  for (int k = 0; k < g.n_z; ++k)
    for (int j = 0; j < g.n_theta; ++j) {
      const double th = g.theta_deg(j), z = g.z_mm(k);
      const std::size_t c = g.index(j, k);
      if (std::abs(th) < 15 && z > -9 && z < 5) {
        // The ray crosses the shell, the gap's air and the head: the shell's column ends on the
        // gap (a free base), and the head's skin behind it is below that base.
        ++shell;
        EXPECT_EQ(m.maps.flags[c], kBaseCavity) << "theta " << th << " z " << z;
        EXPECT_NEAR(m.maps.r_skin[c], 80.0, 0.2);
        EXPECT_NEAR(m.maps.r_bone[c], 76.0, 0.2) << "theta " << th << " z " << z;
      } else if (std::abs(th) > 30 && std::abs(z) < 18) {
        EXPECT_EQ(m.maps.flags[c], 0) << "theta " << th << " z " << z;
        EXPECT_NEAR(m.maps.r_bone[c], 60.0, 0.2);
      }
    }
  ASSERT_GT(shell, 400);
  // Without the cavity base the shell's rays reach the skull beyond the gap: the column would
  // span the air, so the re-entry is above the base and the cells stay undercut.
  o.maps.bone.cavity_base = false;
  const VolumeModel without = build_volume_model(v, o);
  const int j0 = g.n_theta / 2;  // theta 0
  int k0 = 0;
  while (g.z_mm(k0) < -2) ++k0;
  EXPECT_TRUE((without.maps.flags[g.index(j0, k0)] & kUndercut) != 0)
      << describe_flags(without.maps.flags[g.index(j0, k0)]);
}

namespace {

// A hand-made CT for the eye: the cylinder head of overhang_ct() without its shell (tissue to
// r 70 mm on a skull r 56..60), and in front (|theta| < 30 deg, |z| < 20 mm) an orbit: no skull,
// fat (-100 HU) from r 40 to r 68 under 2 mm of lid, holding a globe of water (+10 HU, radius
// 12 mm) whose front touches the lid at r 68; and at theta 90 deg a soft-tissue "muscle" (the
// same +10 HU, 20 mm deep) straight on the skull, with no fat behind it: not an eye.
Volume eye_ct() {
  const Eigen::Vector3d globe(0, -56.0, 0);  // r 56 in front (theta 0 is -y)
  return axial_ct(180, 60, "eye", [&](const Eigen::Vector3d& p, double th, auto in) {
    const bool orbit = std::abs(th) < 30 && std::abs(p.z()) < 20;
    const bool muscle = std::abs(th - 90) < 15 && std::abs(p.z()) < 20;
    double hu = -1000.0 + in(muscle ? 80.0 : 70.0) * (muscle ? 1010.0 : 1040.0);
    if (!orbit) return hu + in(60.0) * (1200.0 - 40.0) + in(56.0) * (35.0 - 1200.0);
    hu += (in(68.0) - in(40.0)) * (-100.0 - 40.0);
    const double g = std::clamp(0.5 + (12.0 - (p - globe).norm()), 0.0, 1.0);
    return (1 - g) * hu + g * 10.0;
  });
}

}  // namespace

TEST(Eye, TheGlobeUnderTheLidsIsNotOperable) {
  const Volume v = eye_ct();
  ModelOptions o = axial_options(60);
  o.maps.layers.measure = true;
  const VolumeModel m = build_volume_model(v, o);
  const auto& g = m.maps.grid;
  int eye = 0;
  for (int k = 0; k < g.n_z; ++k)
    for (int j = 0; j < g.n_theta; ++j) {
      const double th = g.theta_deg(j), z = g.z_mm(k);
      const std::size_t c = g.index(j, k);
      // Rays within 7 mm of the globe's centre line cross at least 15 mm of it.
      const double x = 70.0 * th * 3.14159265358979323846 / 180.0;
      if (std::hypot(x, z) < 7.0) {
        ++eye;
        EXPECT_TRUE(m.maps.flags[c] & kEye) << "theta " << th << " z " << z;
      }
      // Away from the orbit (its fat without the globe, the muscle, the rest): no eye.
      if (std::hypot(x, z) > 12.0 + kEyeMarginMm + 1.5) {
        EXPECT_FALSE(m.maps.flags[c] & kEye) << "theta " << th << " z " << z;
      }
    }
  ASSERT_GT(eye, 100);
  EXPECT_EQ(m.stats.eye, static_cast<std::size_t>(std::count_if(
                             m.maps.flags.begin(), m.maps.flags.end(),
                             [](std::uint8_t f) { return (f & kEye) != 0; })));
  EXPECT_FALSE(flags_valid(kEye));
  EXPECT_EQ(describe_flags(kEye), "eye");
  EXPECT_NE(invalid_flags_advice(kEye | kNoBone).find("not operable"), std::string::npos);
}
