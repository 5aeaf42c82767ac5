// The tissue layers (skin, fat, deep) measured in CT: on hand-made profiles with known interfaces,
// and on the layered analytic phantom, against its closed-form interfaces along the model's rays.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>

#include "caps/core/units.hpp"
#include "caps/volume/model.hpp"
#include "caps/volume/model_dir.hpp"
#include "caps/volume/phantom.hpp"
#include "layered_phantom_model.hpp"
#include "phantom_crossing.hpp"

namespace fs = std::filesystem;
using namespace caps;

namespace {

// A partial-volume profile (each interface a linear ramp `w` wide, as the phantom's voxels):
// air above depth 0, then the given layers (HU, thickness mm), then bone.
struct Layer { double hu, mm; };
double profile(double s, const std::vector<Layer>& layers, double w) {
  auto step = [&](double x) { return std::clamp(0.5 + x / w, 0.0, 1.0); };  // 0 above, 1 below
  double hu = -1000.0 + step(s) * (layers[0].hu + 1000.0);
  double depth = 0.0;
  for (std::size_t i = 0; i < layers.size(); ++i) {
    depth += layers[i].mm;
    const double next = i + 1 < layers.size() ? layers[i + 1].hu : 1200.0;
    hu += step(s - depth) * (next - layers[i].hu);
  }
  return hu;
}

}  // namespace

TEST(Layers, SplitFindsKnownInterfacesOfAPartialVolumeProfile) {
  const LayerOptions o;
  for (double w : {0.5, 0.75, 1.0}) {
    const std::vector<Layer> layers{{55, 1.8}, {-100, 3.2}, {45, 4.0}};
    const auto hu = [&](double s) { return profile(s, layers, w); };
    const LayerSplit l = split_layers(hu, 9.0, 0.5 * w, w, o);
    EXPECT_EQ(l.flags, 0) << "w " << w;
    // The level -30 HU is not exactly halfway between the plateaus: on a ramp w wide the top
    // crossing lies (halfway - level) / contrast * w = 7.5 / 155 w deeper than the interface,
    // the bottom one 2.5 / 145 w shallower.
    const double top = 1.8 + 7.5 / 155 * w, bottom = 5.0 - 2.5 / 145 * w;
    EXPECT_NEAR(l.skin_mm, top, 0.005 * w) << "w " << w;
    EXPECT_NEAR(l.fat_mm, bottom - top, 0.005 * w) << "w " << w;
    EXPECT_NEAR(l.deep_mm, 9.0 - bottom, 0.005 * w) << "w " << w;
    EXPECT_NEAR(l.skin_mm + l.fat_mm + l.deep_mm, 9.0, 1e-9);
  }
}

TEST(Layers, ThinFatAndSeveralBandsAreFlagged) {
  const LayerOptions o;
  const double w = 1.0;
  // Fat thinner than half a voxel does not reach the halfway level: none is seen.
  const std::vector<Layer> thin{{55, 2.0}, {-100, 0.3}, {45, 4.0}};
  LayerSplit l = split_layers([&](double s) { return profile(s, thin, w); }, 6.3, 0.5, w, o);
  EXPECT_EQ(l.flags, kLayerNoFat);
  EXPECT_DOUBLE_EQ(l.skin_mm, 6.3);
  EXPECT_EQ(l.fat_mm, 0.0);
  // Two fat bands 3 mm apart stay two bands; 1 mm apart (a septum) they are one.
  const std::vector<Layer> two{{55, 1.5}, {-100, 2.0}, {45, 3.0}, {-100, 2.0}, {45, 2.0}};
  l = split_layers([&](double s) { return profile(s, two, w); }, 10.5, 0.5, w, o);
  EXPECT_EQ(l.flags, kLayerSeveralBands);
  EXPECT_NEAR(l.skin_mm, 1.5, 0.05);
  EXPECT_NEAR(l.fat_mm, 7.0, 0.07);  // the first band's top to the last band's bottom (see above)
  const std::vector<Layer> septum{{55, 1.5}, {-100, 2.0}, {45, 1.0}, {-100, 2.0}, {45, 2.0}};
  l = split_layers([&](double s) { return profile(s, septum, w); }, 8.5, 0.5, w, o);
  EXPECT_EQ(l.flags, 0);
  EXPECT_NEAR(l.fat_mm, 5.0, 0.07);
  EXPECT_EQ(describe_layer_flags(kLayerNoFat | kLayerNoContrast), "no_fat|no_contrast");
}

TEST(Layers, LayeredPhantomDepthsRecoveredWithinAFifthOfAMillimetre) {
  const auto& lm = caps_test::layered_model();
  const auto& maps = lm.model.maps;
  const auto& g = maps.grid;
  ASSERT_TRUE(maps.has_layers());
  const HeadPhantom& ph = lm.ph;
  double se[3] = {0, 0, 0};
  int n = 0, valid = 0;
  for (int k = 0; k < g.n_z; ++k)
    for (int j = 0; j < g.n_theta; ++j) {
      const std::size_t c = g.index(j, k);
      if (maps.flags[c] != 0) continue;
      ++valid;
      if (maps.layer_flags[c] != 0) continue;
      const double th = deg_to_rad(g.theta_deg(j)), z = g.z_mm(k);
      auto at = [&](auto R, double from) {
        return caps_test::analytic_crossing(ph, maps.axis, th, z, R, from);
      };
      const double rs = at([&](double t, double zz) { return ph.skin_radius(t, zz); }, 160.0);
      const double rt = at([&](double t, double zz) { return ph.fat_top_radius(t, zz); }, rs);
      const double rf = at([&](double t, double zz) { return ph.fat_bottom_radius(t, zz); }, rt);
      const double rb = at([&](double t, double zz) { return ph.bone_radius(t, zz); }, rf);
      ASSERT_TRUE(std::isfinite(rb)) << "theta " << g.theta_deg(j) << " z " << z;
      se[0] += std::pow(maps.thickness_skin[c] - (rs - rt), 2);
      se[1] += std::pow(maps.thickness_fat[c] - (rt - rf), 2);
      se[2] += std::pow(maps.thickness_deep[c] - (rf - rb), 2);
      ++n;
      if (std::getenv("CAPS_DEBUG_CELLS") && std::abs(maps.thickness_skin[c] - (rs - rt)) > 0.4)
        std::printf("theta %.1f z %.1f skin %.2f (%.2f) fat %.2f (%.2f) deep %.2f (%.2f)\n",
                    g.theta_deg(j), z, maps.thickness_skin[c], rs - rt, maps.thickness_fat[c],
                    rt - rf, maps.thickness_deep[c], rf - rb);
      if (std::getenv("CAPS_DEBUG_CELLS") && std::abs(maps.thickness_skin[c] - (rs - rt)) > 0.4) {
        for (double d = -1.5; d < rs - rb + 1; d += 0.25)
          std::printf(" %.0f", sample_trilinear(lm.ct, lm.ct.lps_to_index(maps.axis.to_lps(th, z, maps.r_skin[c] - d)), -1000));
        std::printf("\n r_skin %.3f exp %.3f\n", maps.r_skin[c], rs);
      }
    }
  ASSERT_GT(valid, static_cast<int>(g.size() / 2));
  // The phantom's fat (>= 1 mm) is seen nearly everywhere; near the vertex the thinnest dermis
  // (1.4 mm) meets the rays obliquely and is not resolved (kLayerThinSkin).
  EXPECT_GT(n, valid * 3 / 4);
  const double rms[3] = {std::sqrt(se[0] / n), std::sqrt(se[1] / n), std::sqrt(se[2] / n)};
  std::printf("layered phantom 0.75 mm: RMS skin %.3f, fat %.3f, deep %.3f mm over %d cells\n",
              rms[0], rms[1], rms[2], n);
  for (double r : rms) EXPECT_LE(r, 0.2);
}

TEST(Layers, LayersSumToTheThicknessEverywhere) {
  const auto& maps = caps_test::layered_model().model.maps;
  for (std::size_t c = 0; c < maps.grid.size(); ++c) {
    ASSERT_NEAR(maps.thickness_skin[c] + maps.thickness_fat[c] + maps.thickness_deep[c],
                maps.thickness[c], 1e-3);
    ASSERT_NEAR(maps.thickness_skin_normal[c] + maps.thickness_fat_normal[c] +
                    maps.thickness_deep_normal[c],
                maps.thickness_normal[c], 1e-3);
    ASSERT_GE(maps.thickness_fat[c], 0.0f);
    ASSERT_GE(maps.thickness_deep_normal[c], 0.0f);
  }
}

TEST(Layers, NormalLayersMatchWhereTheHeadIsLocallyFlat) {
  // At theta = +-90, z = 30 the nearest bone is close to the radius: the layers along the normal
  // match the phantom's radial depths within the radial bar plus the small obliquity.
  const auto& lm = caps_test::layered_model();
  const auto& maps = lm.model.maps;
  const auto& g = maps.grid;
  for (double th : {-90.0, 90.0}) {
    const int j = static_cast<int>(std::lround((th - g.theta0_deg) / g.dtheta_deg()));
    const int k = static_cast<int>(std::lround((30.0 - g.z0_mm) / g.dz_mm));
    const std::size_t c = g.index(j, k);
    const double t = deg_to_rad(g.theta_deg(j)), z = g.z_mm(k);
    ASSERT_EQ(maps.layer_flags_normal[c], 0);
    EXPECT_NEAR(maps.thickness_skin_normal[c], lm.ph.dermis_depth(t, z), 0.3) << th;
    EXPECT_NEAR(maps.thickness_fat_normal[c], lm.ph.fat_depth(t, z), 0.3) << th;
    EXPECT_NEAR(maps.thickness_deep_normal[c], lm.ph.deep_depth(t, z), 0.3) << th;
  }
}

TEST(Layers, ModelDirectoryHoldsTheLayersAndReadsThemBack) {
  const auto& lm = caps_test::layered_model();
  const fs::path dir = fs::temp_directory_path() / ("caps_layers_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  write_model(lm.model, dir, false);
  const ModelInfo info = read_model_info(dir);
  EXPECT_TRUE(info.has_layers);
  EXPECT_GT(info.stats.layer_cells, 0u);
  EXPECT_NEAR(info.stats.fat_median_mm, lm.model.stats.fat_median_mm, 1e-9);
  const CylindricalMaps back = read_model_maps(dir, info);
  const auto& m = lm.model.maps;
  EXPECT_EQ(back.thickness_skin, m.thickness_skin);
  EXPECT_EQ(back.thickness_fat_normal, m.thickness_fat_normal);
  EXPECT_EQ(back.thickness_deep, m.thickness_deep);
  EXPECT_EQ(back.layer_flags, m.layer_flags);
  EXPECT_EQ(back.layer_flags_normal, m.layer_flags_normal);
  for (const char* f : {model_file::kThicknessSkin, model_file::kThicknessFat,
                        model_file::kThicknessDeep, model_file::kThicknessSkinNormal,
                        model_file::kThicknessFatNormal, model_file::kThicknessDeepNormal,
                        model_file::kLayerValidity, model_file::kLayerValidityNormal,
                        model_file::kLayerSkinPng, model_file::kLayerFatPng,
                        model_file::kLayerDeepPng})
    EXPECT_TRUE(fs::exists(dir / f)) << f;
  const std::string json = read_model_json(dir);
  EXPECT_NE(json.find("\"fat_level_hu\": -30.0"), std::string::npos);
  fs::remove_all(dir);
}

TEST(Layers, MrHasNoLayersAndModelJsonSaysWhy) {
  PhantomOptions po;
  po.dims = {64, 80, 96};
  po.spacing_mm = {3, 3, 3};
  po.head_holder = false;
  po.layered = true;
  Volume v = make_phantom(po);
  v.modality = Modality::MR;
  ModelOptions o;
  o.maps.n_theta = 64;
  o.maps.n_z = 32;
  const VolumeModel m = build_volume_model(v, o);
  EXPECT_FALSE(m.maps.has_layers());
  const fs::path dir = fs::temp_directory_path() / ("caps_layers_mr_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  write_model(m, dir, false);
  EXPECT_FALSE(read_model_info(dir).has_layers);
  EXPECT_FALSE(fs::exists(dir / model_file::kThicknessFat));
  const std::string json = read_model_json(dir);
  EXPECT_NE(json.find("\"measured\": false"), std::string::npos);
  EXPECT_NE(json.find("MR: fat is told apart by its CT number"), std::string::npos);
  fs::remove_all(dir);
}
