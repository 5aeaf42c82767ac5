// The whole-face tissue model (mesher/tissue_model.hpp): on the analytic layered phantom, the
// tets fill the shell between skin and bone, the nodes' flags lie on the right surfaces, the
// layer fractions integrate to the known layer volumes and the level sets measure the known
// distances; the files round-trip and damaged ones are refused; on Cranium (the demo's CT) the
// model holds the nose, lips and eyelids, keeps out of the air and builds in time.
#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "caps/core/error.hpp"
#include "caps/core/units.hpp"
#include "caps/mesher/tissue_model.hpp"
#include "caps/surface/feature_lines.hpp"
#include "caps/surface/landmarks.hpp"
#include "caps/surface/patient_model.hpp"
#include "caps/volume/model.hpp"
#include "caps/volume/phantom.hpp"
#include "caps/volume/read_volume.hpp"

using namespace caps;
using namespace caps::mesher;
namespace fs = std::filesystem;

namespace {

// The layered phantom at the working voxel of a head CT (1.5 mm), without the head holder.
struct PhantomTissue {
  HeadPhantom head{true};
  Volume v;
  Segmentation seg;
  CylindricalMaps maps;
  ModelStatistics stats;
  TissueLevelSets ls;
  TissueModel m;
  double seconds = 0;
};

// Ray-to-normal cosine of a surface r = R(theta, z) of the phantom (as the phantom's own
// partial-volume ramp computes its normal).
template <class F>
double cos_normal(F&& R, double theta, double z) {
  const double h = 1e-3, r = R(theta, z);
  const double gt = (R(theta + h, z) - R(theta - h, z)) / (2 * h) / r;
  const double gz = (R(theta, z + h) - R(theta, z - h)) / (2 * h);
  return 1.0 / std::sqrt(1.0 + gt * gt + gz * gz);
}

const PhantomTissue& phantom_tissue() {
  static const PhantomTissue p = [] {
    PhantomTissue t;
    PhantomOptions po;
    po.dims = {124, 156, 150};
    po.spacing_mm = {1.5, 1.5, 1.5};
    po.head_holder = false;
    po.layered = true;
    t.v = make_phantom(po);
    t.seg = segment_head(t.v);
    // Maps on the phantom's own axis with its analytic layers along the normal, so the
    // fractions are checked against the layers they were given.
    CylindricalMaps& maps = t.maps;
    maps.axis.origin_lps = t.head.axis_point();
    maps.grid.n_theta = 360;
    maps.grid.n_z = 240;
    maps.grid.z0_mm = -120;
    maps.grid.dz_mm = 1.0;
    maps.allocate();
    maps.allocate_layers();
    const HeadPhantom& h = t.head;
    auto head_r = [&](double th, double z) { return h.head_radius(th, z); };
    for (int k = 0; k < maps.grid.n_z; ++k)
      for (int j = 0; j < maps.grid.n_theta; ++j) {
        const double th = deg_to_rad(maps.grid.theta_deg(j)), z = maps.grid.z_mm(k);
        const std::size_t i = maps.grid.index(j, k);
        if (h.head_radius(th, z) <= 0) {
          maps.flags[i] = kNoSkin;
          continue;
        }
        const double c = cos_normal(head_r, th, z);
        maps.thickness_skin_normal[i] = static_cast<float>(h.dermis_depth(th, z) * c);
        maps.thickness_fat_normal[i] = static_cast<float>(h.fat_depth(th, z) * c);
        maps.thickness_deep_normal[i] = static_cast<float>(h.deep_depth(th, z) * c);
        maps.layer_flags_normal[i] = 0;
      }
    t.stats.skin_layer_median_mm = 1.8;
    t.stats.fat_median_mm = 3.0;
    TissueModelOptions o;
    o.face_size_mm = 2.5;
    o.scalp_size_mm = 4.0;
    const auto t0 = std::chrono::steady_clock::now();
    t.ls = tissue_level_sets(t.seg, o);
    t.m = build_tissue_model(t.seg, t.maps, t.stats, t.ls, o);
    t.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return t;
  }();
  return p;
}

// Phantom cylindrical coordinates (theta rad, z mm, r mm) of an LPS point.
Eigen::Vector3d cyl(const HeadPhantom& h, const Eigen::Vector3d& p) {
  const Eigen::Vector3d q = p - h.axis_point();
  return {std::atan2(q[0], -q[1]), q[2], std::hypot(q[0], q[1])};
}

// Integral over theta in [t0, t1] (rad) and z in [z0, z1] of (R_out^2 - R_in^2) / 2 (mm^3): the
// volume between two star-shaped surfaces r = R(theta, z), by the midpoint rule.
template <class Fo, class Fi>
double shell_volume(Fo&& R_out, Fi&& R_in, double t0, double t1, double z0, double z1) {
  const int nt = 1440, nz = 400;
  const double dt = (t1 - t0) / nt, dz = (z1 - z0) / nz;
  double s = 0;
  for (int a = 0; a < nt; ++a)
    for (int b = 0; b < nz; ++b) {
      const double th = t0 + (a + 0.5) * dt, z = z0 + (b + 0.5) * dz;
      const double ro = R_out(th, z), ri = R_in(th, z);
      if (ro > ri) s += 0.5 * (ro * ro - ri * ri) * dt * dz;
    }
  return s;
}

// Where the phantom's CT crosses `level` (HU) on its ramp from `outside_hu` to `inside_hu` across
// the surface r = R(theta, z): the ramp is as wide as the voxel along the surface's normal
// (HeadPhantom::hu_at), so a threshold off the ramp's middle shifts the surface it finds by a
// known amount. The segmentation's skin (-400 HU) and bone (250 HU) are these surfaces.
template <class F>
double threshold_radius(F&& R, double th, double z, double outside_hu, double inside_hu,
                        double level, double voxel_mm) {
  const double h = 1e-3, r = R(th, z);
  const double gt = (R(th + h, z) - R(th - h, z)) / (2 * h) / r;
  const double gz = (R(th, z + h) - R(th, z - h)) / (2 * h);
  const double norm = std::sqrt(1.0 + gt * gt + gz * gz);
  const Eigen::Vector3d radial = HeadPhantom::ray_direction(th);
  const Eigen::Vector3d tangential(std::cos(th), std::sin(th), 0.0);
  const Eigen::Vector3d n = (radial - tangential * gt - Eigen::Vector3d(0, 0, gz)) / norm;
  const double width = voxel_mm * n.cwiseAbs().sum();
  const double f = (level - outside_hu) / (inside_hu - outside_hu);
  return r - (f - 0.5) * width * norm;
}

fs::path temp_dir(const std::string& name) {
  const fs::path d = fs::temp_directory_path() / (name + "_" + std::to_string(::getpid()));
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

}  // namespace

TEST(TissueModel, PhantomEveryTetPositiveAndFractionsSumToOne) {
  const auto& t = phantom_tissue();
  const TissueModel& m = t.m;
  ASSERT_GT(m.n_tets(), 1000);
  std::printf(
      "phantom tissue model: %lld nodes, %lld tets, %.1f ml, %.1f s (labels %.1f, mesh "
      "%.1f, layers %.1f s)\n",
      static_cast<long long>(m.n_nodes()), static_cast<long long>(m.n_tets()), m.volume_ml,
      t.seconds, m.seconds_labels, m.seconds_mesh, m.seconds_layers);
  for (Eigen::Index c = 0; c < m.n_tets(); ++c) {
    ASSERT_GT(tet_volume(m.nodes, m.tets.row(c).transpose()), 0.0) << "tet " << c;
    ASSERT_NEAR(m.layer_fraction.row(c).sum(), 1.0, 1e-6);
  }
  ASSERT_EQ(m.node_flags.size(), static_cast<std::size_t>(m.n_nodes()));
}

TEST(TissueModel, PhantomFillsTheShellBetweenSkinAndBone) {
  const auto& t = phantom_tissue();
  const HeadPhantom& h = t.head;
  // Tets whose centroid lies in z in [-50, 50] mm, against the analytic shell there (nose and
  // marker included): bone_radius < r < skin_radius.
  double vol = 0;
  for (Eigen::Index c = 0; c < t.m.n_tets(); ++c) {
    Eigen::Vector3d x = Eigen::Vector3d::Zero();
    for (int q = 0; q < 4; ++q) x += 0.25 * t.m.nodes.row(t.m.tets(c, q)).transpose();
    const double z = cyl(h, x)[1];
    if (z >= -50 && z <= 50) vol += tet_volume(t.m.nodes, t.m.tets.row(c).transpose());
  }
  // The surfaces the segmentation finds: the skin at -400 HU on the air-dermis ramp, the bone at
  // 250 HU on the deep tissue-bone ramp (0.48-0.8 mm outside the bone at 1.5 mm voxels).
  const double voxel = t.v.geom.spacing_mm[0];
  auto Rs = [&](double th, double z) { return h.skin_radius(th, z); };
  auto Rb = [&](double th, double z) { return h.bone_radius(th, z); };
  const double exact = shell_volume(
      [&](double th, double z) {
        return threshold_radius(Rs, th, z, HeadPhantom::kAirHu, HeadPhantom::kDermisHu,
                                t.seg.skin_threshold, voxel);
      },
      [&](double th, double z) {
        return threshold_radius(Rb, th, z, HeadPhantom::kMuscleHu, HeadPhantom::kBoneHu,
                                t.seg.bone_threshold, voxel);
      },
      -kPi, kPi, -50, 50);
  std::printf("shell z in [-50, 50]: tets %.1f ml, analytic %.1f ml (%+.2f %%)\n", vol * 1e-3,
              exact * 1e-3, 100 * (vol / exact - 1));
  EXPECT_NEAR(vol / exact, 1.0, 0.05);
}

TEST(TissueModel, PhantomNodeFlagsLieOnSkinAndBone) {
  const auto& t = phantom_tissue();
  const HeadPhantom& h = t.head;
  std::vector<double> skin_err, bone_err;
  std::size_t fov = 0;
  for (Eigen::Index v = 0; v < t.m.n_nodes(); ++v) {
    const std::uint8_t f = t.m.node_flags[static_cast<std::size_t>(v)];
    const Eigen::Vector3d c = cyl(h, t.m.nodes.row(v).transpose());
    if (f & kTissueFieldOfView) {
      ++fov;
      // The field of view ends at the lowest slice.
      EXPECT_LT(c[1], t.v.geom.origin_lps[2] + 2.0 * t.v.geom.spacing_mm[2] + 1e-9);
    }
    if (c[1] < -60 || c[1] > 60) continue;
    if (f & kTissueOnSkin) skin_err.push_back(std::abs(c[2] - h.skin_radius(c[0], c[1])));
    if (f & kTissueOnBone)
      bone_err.push_back(
          std::abs(c[2] - threshold_radius([&](double a, double b) { return h.bone_radius(a, b); },
                                           c[0], c[1], HeadPhantom::kMuscleHu, HeadPhantom::kBoneHu,
                                           t.seg.bone_threshold, t.v.geom.spacing_mm[0])));
  }
  ASSERT_GT(skin_err.size(), 500u);
  ASSERT_GT(bone_err.size(), 500u);
  EXPECT_GT(fov, 20u);  // the neck is cut by the lowest slice
  auto p95 = [](std::vector<double> e) {
    std::sort(e.begin(), e.end());
    return e[e.size() * 95 / 100];
  };
  std::printf("radial distance of flagged nodes, 95th percentile: skin %.2f mm, bone %.2f mm\n",
              p95(skin_err), p95(bone_err));
  // Within a voxel (1.5 mm) of the analytic surfaces, most within half of one.
  EXPECT_LT(p95(skin_err), 0.75);
  EXPECT_LT(p95(bone_err), 0.75);
  EXPECT_LT(*std::max_element(skin_err.begin(), skin_err.end()), 1.5);
  EXPECT_LT(*std::max_element(bone_err.begin(), bone_err.end()), 1.5);
}

TEST(TissueModel, PhantomLayerFractionsIntegrateToTheLayers) {
  const auto& t = phantom_tissue();
  const HeadPhantom& h = t.head;
  // Away from the nose (|theta| < 45 deg) and the marker (z > 30): the layers lie under the
  // plain head's radius there.
  const double t0 = deg_to_rad(45), t1 = deg_to_rad(315), z0 = -50, z1 = 25;
  double layer[3] = {0, 0, 0};
  for (Eigen::Index c = 0; c < t.m.n_tets(); ++c) {
    Eigen::Vector3d x = Eigen::Vector3d::Zero();
    for (int q = 0; q < 4; ++q) x += 0.25 * t.m.nodes.row(t.m.tets(c, q)).transpose();
    const Eigen::Vector3d cy = cyl(h, x);
    double th = cy[0] < 0 ? cy[0] + 2 * kPi : cy[0];
    if (th < t0 || th > t1 || cy[1] < z0 || cy[1] > z1) continue;
    const double v = tet_volume(t.m.nodes, t.m.tets.row(c).transpose());
    for (int l = 0; l < 3; ++l) layer[l] += v * t.m.layer_fraction(c, l);
  }
  auto R = [&](double th, double z) { return h.head_radius(th, z); };
  auto Ft = [&](double th, double z) { return h.fat_top_radius(th, z); };
  auto Fb = [&](double th, double z) { return h.fat_bottom_radius(th, z); };
  auto B = [&](double th, double z) {
    return threshold_radius([&](double a, double b) { return h.bone_radius(a, b); }, th, z,
                            HeadPhantom::kMuscleHu, HeadPhantom::kBoneHu, t.seg.bone_threshold,
                            t.v.geom.spacing_mm[0]);
  };
  const double exact[3] = {shell_volume(R, Ft, t0, t1, z0, z1),
                           shell_volume(Ft, Fb, t0, t1, z0, z1),
                           shell_volume(Fb, B, t0, t1, z0, z1)};
  const char* names[3] = {"dermis", "fat", "deep"};
  for (int l = 0; l < 3; ++l)
    std::printf("%s: tets %.2f ml, analytic %.2f ml (%+.1f %%)\n", names[l], layer[l] * 1e-3,
                exact[l] * 1e-3, 100 * (layer[l] / exact[l] - 1));
  // The dermis (1.4-2.2 mm) is about a voxel: its volume within 15 %, the fat's and the deep
  // tissue's (3-5 mm) within 10 %.
  EXPECT_NEAR(layer[0] / exact[0], 1.0, 0.15);
  EXPECT_NEAR(layer[1] / exact[1], 1.0, 0.10);
  EXPECT_NEAR(layer[2] / exact[2], 1.0, 0.10);
}

TEST(TissueModel, PhantomLevelSetsMeasureTheDistance) {
  const auto& t = phantom_tissue();
  const HeadPhantom& h = t.head;
  const double voxel = t.v.geom.spacing_mm[0];
  // The surfaces the segmentation's masks hold (the thresholds' crossings of the CT's ramps).
  auto Rs = [&](double th, double z) {
    return threshold_radius([&](double a, double b) { return h.skin_radius(a, b); }, th, z,
                            HeadPhantom::kAirHu, HeadPhantom::kDermisHu, t.seg.skin_threshold,
                            voxel);
  };
  auto Rb = [&](double th, double z) {
    return threshold_radius([&](double a, double b) { return h.bone_radius(a, b); }, th, z,
                            HeadPhantom::kMuscleHu, HeadPhantom::kBoneHu, t.seg.bone_threshold,
                            voxel);
  };
  double worst_skin = 0, worst_bone = 0, worst_closest = 0;
  for (int a = 0; a < 36; ++a)
    for (double z : {-40.0, -10.0, 20.0}) {
      const double th = deg_to_rad(10.0 * a - 180.0 + 5.0);
      for (double off : {-3.0, -1.0, 1.0, 3.0}) {
        // Points `off` mm from the skin along the ray: the signed distance is off * cos(alpha).
        const double cs = cos_normal(Rs, th, z);
        const Eigen::Vector3d ps = h.axis_point() +
                                   (Rs(th, z) + off) * HeadPhantom::ray_direction(th) +
                                   Eigen::Vector3d(0, 0, z);
        worst_skin = std::max(worst_skin, std::abs(t.ls.skin(ps) - off * cs));
        const Eigen::Vector3d q = t.ls.skin.closest_point(ps);
        const Eigen::Vector3d cq = cyl(h, q);
        worst_closest = std::max(worst_closest, std::abs(cq[2] - Rs(cq[0], cq[1])));
        const double cb = cos_normal(Rb, th, z);
        const Eigen::Vector3d pb = h.axis_point() +
                                   (Rb(th, z) + off) * HeadPhantom::ray_direction(th) +
                                   Eigen::Vector3d(0, 0, z);
        worst_bone = std::max(worst_bone, std::abs(t.ls.bone(pb) - off * cb));
      }
    }
  std::printf("level sets vs analytic, worst: skin %.2f mm, bone %.2f mm, closest point %.2f mm\n",
              worst_skin, worst_bone, worst_closest);
  // The level sets come from binary masks on 1.5 mm voxels: within half a voxel.
  EXPECT_LT(worst_skin, 0.5 * voxel);
  EXPECT_LT(worst_bone, 0.5 * voxel);
  EXPECT_LT(worst_closest, 0.5 * voxel);
  // The normal points out of the head.
  const Eigen::Vector3d p = h.axis_point() + Rs(0.7, 0.0) * HeadPhantom::ray_direction(0.7);
  EXPECT_GT(t.ls.skin.normal(p).dot(HeadPhantom::ray_direction(0.7)), 0.95);
}

TEST(TissueModel, FilesRoundTrip) {
  const auto& t = phantom_tissue();
  const fs::path dir = temp_dir("caps_tissue_io");
  write_tissue_model(dir, t.m, t.ls);
  for (const char* f : {tissue_file::kMesh, tissue_file::kJson, tissue_file::kSkinLevelSet,
                        tissue_file::kBoneLevelSet})
    EXPECT_TRUE(fs::exists(dir / f)) << f;
  const TissueModel r = read_tissue_model(dir);
  ASSERT_EQ(r.n_nodes(), t.m.n_nodes());
  ASSERT_EQ(r.n_tets(), t.m.n_tets());
  EXPECT_EQ((r.nodes - t.m.nodes).cwiseAbs().maxCoeff(), 0.0);
  EXPECT_TRUE(r.tets == t.m.tets);
  EXPECT_LT((r.layer_fraction - t.m.layer_fraction).cwiseAbs().maxCoeff(), 1e-5f);
  EXPECT_EQ(r.node_flags, t.m.node_flags);
  EXPECT_NEAR(r.volume_ml, t.m.volume_ml, 1e-9 * t.m.volume_ml);
  EXPECT_EQ(r.method, t.m.method);
  const SignedDistanceField bone = read_bone_level_set(dir);
  const SignedDistanceField skin = read_skin_level_set(dir);
  EXPECT_DOUBLE_EQ(bone.voxel_mm(), t.ls.bone.voxel_mm());
  EXPECT_DOUBLE_EQ(skin.interior_mm(), t.ls.skin.interior_mm());
  for (int i = 0; i < 50; ++i) {
    const Eigen::Vector3d p = t.m.nodes.row((i * 7919) % t.m.n_nodes()).transpose();
    EXPECT_FLOAT_EQ(static_cast<float>(bone(p)), static_cast<float>(t.ls.bone(p)));
    EXPECT_FLOAT_EQ(static_cast<float>(skin(p)), static_cast<float>(t.ls.skin(p)));
  }
  fs::remove_all(dir);
}

TEST(TissueModel, RefusesAMissingOrDamagedModel) {
  const auto& t = phantom_tissue();
  const fs::path dir = temp_dir("caps_tissue_bad");
  try {
    read_tissue_model(dir);
    FAIL() << "a directory without tissue.vtu was read";
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("run `caps model tissue MODEL`"), std::string::npos);
  }
  EXPECT_THROW(read_bone_level_set(dir), InvalidInput);
  write_tissue_model(dir, t.m, t.ls);
  std::string text;
  {
    std::ifstream in(dir / tissue_file::kMesh);
    std::stringstream ss;
    ss << in.rdbuf();
    text = ss.str();
  }
  auto refuse = [&](const std::string& damaged, const char* what) {
    {
      std::ofstream out(dir / tissue_file::kMesh, std::ios::trunc);
      out << damaged;
    }
    EXPECT_THROW(read_tissue_model(dir), InvalidInput) << what;
  };
  refuse(text.substr(0, text.size() / 2), "truncated");
  refuse("<VTKFile type=\"UnstructuredGrid\"></VTKFile>", "another VTU");
  std::string huge = text;
  huge.replace(huge.find("NumberOfPoints=\""), 16, "NumberOfPoints=\"9999999999");
  refuse(huge, "a count larger than the file");
  std::string wedge = text;
  const std::size_t types = wedge.find("Name=\"types\"");
  wedge.replace(wedge.find("10", wedge.find('>', types)), 2, "13");
  refuse(wedge, "a wedge");
  std::string flipped = text;  // swap two corners of the first tet: negative volume
  {
    const std::size_t c = flipped.find('>', flipped.find("Name=\"connectivity\"")) + 2;
    const std::size_t e = flipped.find('\n', c);
    std::istringstream ids(flipped.substr(c, e - c));
    long long a, b, cc, d;
    ids >> a >> b >> cc >> d;
    flipped.replace(c, e - c,
                    std::to_string(a) + " " + std::to_string(b) + " " + std::to_string(d) + " " +
                        std::to_string(cc));
  }
  refuse(flipped, "an inverted tet");
  {
    std::ofstream out(dir / tissue_file::kBoneLevelSet, std::ios::trunc);
    out << "not a vdb";
  }
  EXPECT_THROW(read_bone_level_set(dir), InvalidInput);
  fs::remove_all(dir);
}

// The demo patient (Debian's invesalius-examples): the model holds the nose, the lips and the
// eyelids' corners, stays out of the air, and builds in time.
TEST(TissueModel, CraniumHoldsTheFaceAndNoAir) {
  const fs::path cranium = "/usr/share/doc/invesalius-examples/examples/Cranium.inv3";
  if (!fs::exists(cranium)) GTEST_SKIP() << "Cranium.inv3 (invesalius-examples) is not installed";
  const Volume v = read_volume(cranium);
  const VolumeModel vm = build_volume_model(v);
  const fs::path dir =
      fs::temp_directory_path() / ("caps_tissue_cranium_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  write_model(vm, dir, false);
  const Landmarks lm = find_landmarks(PatientModel::load(dir));
  const auto t0 = std::chrono::steady_clock::now();
  const TissueLevelSets ls = tissue_level_sets(vm.segmentation);
  const TissueModel m = build_tissue_model(vm.segmentation, vm.maps, vm.stats, ls);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf("Cranium tissue model: %lld nodes, %lld tets, %.0f ml, %.1f s (mesh %.1f s)\n",
              static_cast<long long>(m.n_nodes()), static_cast<long long>(m.n_tets()), m.volume_ml,
              seconds, m.seconds_mesh);
  EXPECT_LT(seconds, 120.0);  // the benchmark measures it; this only catches a runaway
  for (Eigen::Index c = 0; c < m.n_tets(); ++c)
    ASSERT_GT(tet_volume(m.nodes, m.tets.row(c).transpose()), 0.0);
  // The face's features: tets within 3 mm of each landmark (on the skin), skin nodes within
  // 1.5 mm: the nose's tip and its junction with the lip, and the eyes' corners as the lateral
  // ends of the lower eyelid margins (Cranium's exocanthions are withdrawn: found 43 mm apart,
  // within the eyes; docs/landmarks.md).
  const FeatureLines features = find_feature_lines(PatientModel::load(dir), lm);
  std::vector<std::pair<std::string, Eigen::Vector3d>> points;
  for (const char* name : {"pronasale", "subnasale", "exocanthion_left", "exocanthion_right"}) {
    const Landmark* l = lm.find(name);
    ASSERT_NE(l, nullptr);
    if (l->found) points.emplace_back(name, l->lps);
  }
  for (const char* name : {"lower_eyelid_margin_left", "lower_eyelid_margin_right"}) {
    const FeatureLine* f = features.find(name);
    ASSERT_NE(f, nullptr);
    if (f->found && !f->lps.empty()) points.emplace_back(std::string(name) + "'s lateral end", f->lps.back());
  }
  int checked = 0;
  for (const auto& [name, at] : points) {
    ++checked;
    double tet_d = 1e9, skin_d = 1e9;
    for (Eigen::Index c = 0; c < m.n_tets(); ++c) {
      Eigen::Vector3d x = Eigen::Vector3d::Zero();
      for (int q = 0; q < 4; ++q) x += 0.25 * m.nodes.row(m.tets(c, q)).transpose();
      tet_d = std::min(tet_d, (x - at).norm());
    }
    for (Eigen::Index n = 0; n < m.n_nodes(); ++n)
      if (m.node_flags[static_cast<std::size_t>(n)] & kTissueOnSkin)
        skin_d = std::min(skin_d, (m.nodes.row(n).transpose() - at).norm());
    std::printf("%s: nearest tet centroid %.2f mm, nearest skin node %.2f mm\n", name.c_str(),
                tet_d, skin_d);
    EXPECT_LT(tet_d, 3.0) << name;
    EXPECT_LT(skin_d, 1.5) << name;
  }
  EXPECT_GE(checked, 4);
  // No tet in an air cavity: no centroid in air with air 1.5 mm around it on all six sides (a
  // tet across a cavity's wall or a 1-2 voxel slit, such as between the lips, may have its
  // centroid on the air side; one inside the cavity would not), and the tets' volume on the air
  // side of the skin threshold is a sliver of the whole.
  const Volume& w = vm.segmentation.working;
  auto hu = [&](const Eigen::Vector3d& x) {
    return static_cast<double>(sample_trilinear(w, w.lps_to_index(x), -1000.0f));
  };
  const double air = vm.segmentation.skin_threshold;
  std::size_t centroid_in_air = 0, in_cavity = 0;
  double air_volume = 0;
  for (Eigen::Index c = 0; c < m.n_tets(); ++c) {
    Eigen::Vector3d x = Eigen::Vector3d::Zero();
    for (int q = 0; q < 4; ++q) x += 0.25 * m.nodes.row(m.tets(c, q)).transpose();
    if (hu(x) >= air) continue;
    ++centroid_in_air;
    air_volume += tet_volume(m.nodes, m.tets.row(c).transpose());
    bool all_air = true;
    for (int a = 0; a < 3 && all_air; ++a)
      for (double s : {-1.5, 1.5}) {
        Eigen::Vector3d y = x;
        y[a] += s;
        all_air = all_air && hu(y) < air;
      }
    if (all_air) ++in_cavity;
  }
  std::printf("tets with the centroid in air: %zu (%.2f ml of %.0f), inside a cavity: %zu\n",
              centroid_in_air, air_volume * 1e-3, m.volume_ml, in_cavity);
  // Measured: 2 of 160,916 (slivers between the nasal cavity's turbinates): at most 1 in 10,000.
  EXPECT_LE(in_cavity, static_cast<std::size_t>(m.n_tets() / 10000));
  EXPECT_LT(air_volume * 1e-3, 0.01 * m.volume_ml);
  // Every boundary class is there: skin, bone, the CT's ends, the cavities.
  EXPECT_GT(m.count_nodes(kTissueOnSkin), 1000u);
  EXPECT_GT(m.count_nodes(kTissueOnBone), 1000u);
  EXPECT_GT(m.count_nodes(kTissueFieldOfView), 100u);
  EXPECT_GT(m.count_nodes(kTissueOtherBoundary), 100u);
  fs::remove_all(dir);
}
