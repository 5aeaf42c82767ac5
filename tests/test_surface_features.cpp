// Feature lines on the skin (surface/feature_lines.hpp): the finder on a range image whose creases
// and ridges are known in closed form (the face phantom's skin plus a palpebral fissure, brow
// ridges, a stomion crease ending at the mouth's corners and alar creases), on the demo patient
// Cranium where its model is there (the lines where anatomy puts them beside the landmarks), and
// feature_displacements() on analytic displacement fields.

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "caps/surface/feature_lines.hpp"
#include "caps/surface/landmarks.hpp"
#include "caps/volume/model.hpp"
#include "caps/volume/model_dir.hpp"
#include "caps/volume/phantom.hpp"

using namespace caps;
namespace fs = std::filesystem;

namespace {

constexpr double kPi = 3.14159265358979323846;

double gauss(double x) { return std::exp(-x * x); }

// A band from a to b (deg) with ends 1 deg wide: 1 inside, 0 outside.
double band(double t, double a, double b) {
  auto step = [](double x) { return 0.5 * (1 + std::tanh(x)); };
  return step((t - a) / 1.0) * step((b - t) / 1.0);
}

// The crease and ridge placement of the synthetic face (deg, mm).
constexpr double kFissureZ = 3.0, kBrowZ = 22.0, kStomionZ = -42.0;
constexpr double kEyeFrom = 8.0, kEyeTo = 30.0;  // theta of the fissure's ends, each side
constexpr double kBrowFrom = 6.0, kBrowTo = 34.0;
constexpr double kMouthTo = 16.0;                   // theta of the mouth's corners
constexpr double kAlaTheta = 12.0;                  // theta of the alar creases
constexpr double kAlaFrom = -25.0, kAlaTo = -12.0;  // their z extent

// The face phantom's skin (theta deg, z mm) with the creases and ridges added.
double synthetic_r(const HeadPhantom& head, double t, double z) {
  double r = head.skin_radius(t * kPi / 180.0, z);
  const double a = std::abs(t);
  r += -1.5 * band(a, kEyeFrom, kEyeTo) * gauss((z - kFissureZ) / 1.0);  // fissure
  r += 2.0 * band(a, kBrowFrom, kBrowTo) * gauss((z - kBrowZ) / 3.0);    // brow ridges
  // The stomion crease: shallow enough that the subnasale (the sharpest concave turn of the
  // midline profile below the nose) stays at the nose's base.
  r += -0.6 * band(a, -kMouthTo, kMouthTo) * gauss((z - kStomionZ) / 1.2);
  // Alar creases: 1 mm deep, 1.2 mm wide across theta (at about 100 mm: 0.7 deg).
  r += -1.0 * band(z, kAlaFrom, kAlaTo) * gauss((a - kAlaTheta) / 0.7);
  return r;
}

SkinRangeView synthetic_view(const HeadPhantom& head) {
  SkinRangeView v;
  v.r_mm = [&head](double t, double z) { return synthetic_r(head, t, z); };
  v.measured = [](double, double z) { return z >= -100 && z <= 100; };
  v.z_min_mm = -100;
  v.z_max_mm = 100;
  v.dtheta_deg = 0.5;
  v.dz_mm = 0.5;
  v.r_typical_mm = 90;
  return v;
}

// The lateral distance (mm) of (theta, z) from the midsagittal plane of the synthetic face.
double lateral(const HeadPhantom& head, double t, double z) {
  return synthetic_r(head, t, z) * std::sin(t * kPi / 180.0);
}

}  // namespace

TEST(FeatureLines, SyntheticCreasesAreFoundWhereTheyAre) {
  const HeadPhantom head(false, false, true);
  const SkinRangeView view = synthetic_view(head);
  const Landmarks lm = find_landmarks(view);
  ASSERT_TRUE(lm.find("subnasale")->found);
  EXPECT_GT(lm.find("subnasale")->z_mm, -30.0);  // not the stomion crease
  ASSERT_TRUE(lm.find("exocanthion_left")->found);
  const FeatureLines lines = find_feature_lines(view, lm);
  ASSERT_EQ(lines.items.size(), feature_line_names().size());
  for (const char* sfx : {"_left", "_right"}) {
    const double side = std::string(sfx) == "_left" ? 1 : -1;
    const FeatureLine* up = lines.find(std::string("upper_eyelid_margin") + sfx);
    const FeatureLine* lo = lines.find(std::string("lower_eyelid_margin") + sfx);
    const FeatureLine* brow = lines.find(std::string("eyebrow") + sfx);
    ASSERT_TRUE(up && up->found) << (up ? up->note : "");
    ASSERT_TRUE(lo && lo->found) << (lo ? lo->note : "");
    ASSERT_TRUE(brow && brow->found) << (brow ? brow->note : "");
    // Along the fissure (not at its tapered ends): the margins straddle it within 1.5 mm.
    int inside = 0;
    for (std::size_t i = 0; i < up->theta_z.size(); ++i) {
      const double t = side * up->theta_z[i][0];
      if (t < kEyeFrom + 2 || t > kEyeTo - 2) continue;
      ++inside;
      EXPECT_GT(up->theta_z[i][1], kFissureZ) << sfx << " at theta " << t;
      EXPECT_LT(up->theta_z[i][1], kFissureZ + 1.5) << sfx << " at theta " << t;
      EXPECT_LT(lo->theta_z[i][1], kFissureZ) << sfx << " at theta " << t;
      EXPECT_GT(lo->theta_z[i][1], kFissureZ - 1.5) << sfx << " at theta " << t;
    }
    EXPECT_GE(inside, 15) << sfx;
    // The points run from medial to lateral.
    EXPECT_LT(std::abs(up->theta_z.front()[0]), std::abs(up->theta_z.back()[0]));
    // The brow on its ridge (its crest within 1 mm where the ridge is at full height).
    int on_ridge = 0;
    for (const auto& tz : brow->theta_z) {
      const double t = side * tz[0];
      if (t < kBrowFrom + 2 || t > kBrowTo - 2) continue;
      ++on_ridge;
      EXPECT_NEAR(tz[1], kBrowZ, 1.0) << sfx << " at theta " << t;
    }
    EXPECT_GE(on_ridge, 20) << sfx;
    // The mouth's corner at the crease's end (within 2 mm) and on it (within 1 mm).
    const FeatureLine* ch = lines.find(std::string("oral_commissure") + sfx);
    ASSERT_TRUE(ch && ch->found) << (ch ? ch->note : "");
    ASSERT_EQ(ch->theta_z.size(), 1u);
    EXPECT_NEAR(ch->theta_z[0][1], kStomionZ, 1.0);
    EXPECT_NEAR(std::abs(lateral(head, ch->theta_z[0][0], ch->theta_z[0][1])),
                std::abs(lateral(head, kMouthTo, kStomionZ)), 2.0);
    // The alar rim on the alar crease (within 1 mm laterally) where it is at full depth.
    const FeatureLine* al = lines.find(std::string("alar_rim") + sfx);
    ASSERT_TRUE(al && al->found) << (al ? al->note : "");
    int on_crease = 0;
    for (const auto& tz : al->theta_z) {
      if (tz[1] < kAlaFrom + 2 || tz[1] > kAlaTo - 2) continue;
      ++on_crease;
      EXPECT_NEAR(lateral(head, tz[0], tz[1]), side * std::abs(lateral(head, kAlaTheta, tz[1])),
                  1.0)
          << sfx << " at z " << tz[1];
    }
    EXPECT_GE(on_crease, 5) << sfx;
  }
  // The lip borders: on the phantom's lips (their crests at z -36 and -48), between the corners.
  const FeatureLine* ul = lines.find("upper_lip_vermilion");
  const FeatureLine* ll = lines.find("lower_lip_vermilion");
  ASSERT_TRUE(ul && ul->found) << (ul ? ul->note : "");
  ASSERT_TRUE(ll && ll->found) << (ll ? ll->note : "");
  const auto& um = ul->theta_z[ul->theta_z.size() / 2];
  const auto& lmid = ll->theta_z[ll->theta_z.size() / 2];
  EXPECT_NEAR(um[0], 0.0, 2.0);
  EXPECT_NEAR(um[1], -36.0, 1.5);
  EXPECT_NEAR(lmid[1], -48.0, 1.5);
  EXPECT_LT(ul->theta_z.front()[0], 0);  // from the patient's right to the left
  EXPECT_GT(ul->theta_z.back()[0], 0);
  // The hairline is never found on a range image of the skin, and says why.
  EXPECT_FALSE(lines.find("hairline")->found);
  EXPECT_NE(lines.find("hairline")->note.find("not visible in the CT"), std::string::npos);
}

TEST(FeatureLines, AFaceWithoutTheCreasesHasNoEyelidsOrLipsInventedAtRandom) {
  // The scan cut above the mouth: the lips and the commissures are outside the field of view.
  const HeadPhantom head(false, false, true);
  SkinRangeView view = synthetic_view(head);
  view.measured = [](double, double z) { return z >= -32 && z <= 100; };
  view.z_min_mm = -32;
  const Landmarks lm = find_landmarks(view);
  ASSERT_TRUE(lm.find("subnasale")->found);
  const FeatureLines lines = find_feature_lines(view, lm);
  for (const char* n : {"upper_lip_vermilion", "lower_lip_vermilion", "oral_commissure_left",
                        "oral_commissure_right"}) {
    const FeatureLine* l = lines.find(n);
    ASSERT_TRUE(l);
    EXPECT_FALSE(l->found) << n;
    EXPECT_NE(l->note.find("outside the field of view"), std::string::npos) << n << ": " << l->note;
  }
  EXPECT_TRUE(lines.find("upper_eyelid_margin_left")->found);
}

TEST(FeatureLines, JsonRoundTrip) {
  FeatureLines lines;
  FeatureLine a;
  a.name = "eyebrow_left";
  a.found = true;
  a.side = "left";
  a.along = "medial-lateral";
  a.confidence = 0.5;
  a.theta_z = {{10, 20}, {12, 21}};
  a.lps = {{1, 2, 3}, {4, 5, 6}};
  lines.items.push_back(a);
  const FeatureLines back = feature_lines_from_json(feature_lines_to_json(lines), "m/model.json");
  ASSERT_EQ(back.items.size(), feature_line_names().size());
  const FeatureLine* b = back.find("eyebrow_left");
  ASSERT_TRUE(b && b->found);
  EXPECT_EQ(b->lps.size(), 2u);
  EXPECT_DOUBLE_EQ(b->lps[1][2], 6.0);
  EXPECT_FALSE(back.find("hairline")->found);
  EXPECT_THROW(feature_lines_from_json("{\"items\": 3}", "m/model.json"), InvalidInput);
  EXPECT_THROW(feature_lines_from_json("[", "m/model.json"), InvalidInput);
}

namespace {

// A horizontal line of points 1 mm apart along the frame's left, from x0 to x1 (mm).
FeatureLine straight(const std::string& name, const std::string& side, const std::string& along,
                     double x0, double x1) {
  FeatureLine l;
  l.name = name;
  l.found = true;
  l.side = side;
  l.along = along;
  const int n = static_cast<int>(std::abs(x1 - x0)) + 1;
  for (int i = 0; i < n; ++i) {
    const double x = x0 + (x1 - x0) * i / (n - 1);
    l.theta_z.emplace_back(0, 0);
    l.lps.emplace_back(x, -90, 40);  // LPS: x is the patient's left
  }
  return l;
}

}  // namespace

TEST(FeatureDisplacements, AUniformDownwardShiftIsTwoMillimetresDownEverywhere) {
  FeatureLines lines;
  lines.items.push_back(straight("lower_eyelid_margin_left", "left", "medial-lateral", 15, 45));
  const AnatomicalFrame frame;  // LPS: front -P, left +L, up +S
  const auto d = feature_displacements(
      lines, [](const Eigen::Vector3d&) { return Eigen::Vector3d(0, 0, -2.0); }, frame);
  ASSERT_EQ(d.size(), 1u);
  EXPECT_TRUE(d[0].has_value);
  EXPECT_NEAR(d[0].max_mm, 2.0, 1e-12);
  EXPECT_NEAR(d[0].mean_mm, 2.0, 1e-12);
  EXPECT_EQ(d[0].direction, "down");
  EXPECT_NE(d[0].sentence.find("the left lower eyelid margin is pulled 2.0 mm down"),
            std::string::npos)
      << d[0].sentence;
  // 2 mm down passes the lower lid's 1 mm (scleral show), with its source.
  EXPECT_NE(d[0].warning.find("scleral show"), std::string::npos) << d[0].warning;
  EXPECT_NE(d[0].warning.find("Dutton"), std::string::npos) << d[0].warning;
  // Half a millimetre does not.
  const auto small = feature_displacements(
      lines, [](const Eigen::Vector3d&) { return Eigen::Vector3d(0, 0, -0.5); }, frame);
  EXPECT_TRUE(small[0].warning.empty()) << small[0].warning;
  // The JSON form for result.json.
  const auto j = nlohmann::json::parse(feature_displacements_to_json(d));
  ASSERT_EQ(j.size(), 1u);
  EXPECT_EQ(j[0]["name"], "lower_eyelid_margin_left");
  EXPECT_NEAR(j[0]["max_mm"].get<double>(), 2.0, 1e-9);
  EXPECT_NEAR(j[0]["direction_lps"][2].get<double>(), -2.0, 1e-9);
  EXPECT_EQ(j[0]["direction"], "down");
  EXPECT_EQ(j[0]["where"], "whole length");  // a uniform field: no third stands out
  EXPECT_TRUE(j[0].contains("warning"));
}

TEST(FeatureDisplacements, AFieldGrowingAlongTheLineIsLargestAtItsEndInItsWords) {
  FeatureLines lines;
  // A lip border from the patient's right (x = -25) to the left (x = +25), and a right brow
  // from medial (x = -10) to lateral (x = -50).
  lines.items.push_back(straight("upper_lip_vermilion", "midline", "right-left", -25, 25));
  lines.items.push_back(straight("eyebrow_right", "right", "medial-lateral", -10, -50));
  const AnatomicalFrame frame;
  // Growing towards the patient's right (-x), pointing up; on the brow up and to the right
  // (laterally for a right brow).
  const auto d = feature_displacements(
      lines,
      [](const Eigen::Vector3d& p) {
        const double g = std::max(0.0, (30.0 - p[0]) / 20.0);
        return Eigen::Vector3d(-0.8 * g, 0, g);
      },
      frame);
  ASSERT_EQ(d.size(), 2u);
  EXPECT_EQ(d[0].where, "right third") << d[0].sentence;
  EXPECT_NEAR(d[0].max_mm, std::hypot(0.8, 1.0) * 55.0 / 20.0, 1e-9);
  EXPECT_LT(d[0].mean_mm, d[0].max_mm);
  EXPECT_EQ(d[0].direction, "up and to the patient's right") << d[0].sentence;
  EXPECT_EQ(d[1].where, "lateral third") << d[1].sentence;
  EXPECT_EQ(d[1].direction, "up and laterally") << d[1].sentence;
  EXPECT_NE(d[1].sentence.find("the right brow is pulled"), std::string::npos) << d[1].sentence;
  EXPECT_NE(d[1].warning.find("brow"), std::string::npos);
  // The summary names the feature displaced most (the brow: 4 mm up and laterally at x = -50).
  EXPECT_EQ(feature_displacements_summary(d).rfind(d[1].sentence, 0), 0u)
      << feature_displacements_summary(d);
  EXPECT_NE(feature_displacements_summary(d).find("feature warning"), std::string::npos);
  EXPECT_EQ(feature_displacements_summary({}), "");
}

TEST(FeatureDisplacements, NoneWhereTheFieldHasNoValue) {
  FeatureLines lines;
  lines.items.push_back(straight("alar_rim_left", "left", "inferior-superior", 10, 20));
  lines.items.push_back(straight("upper_eyelid_margin_left", "left", "medial-lateral", 15, 45));
  FeatureLine gone;
  gone.name = "oral_commissure_left";
  gone.note = "outside the field of view";
  lines.items.push_back(gone);
  // A field only where x > 30: the alar rim has none; the eyelid only its lateral half.
  const auto d = feature_displacements(
      lines,
      [](const Eigen::Vector3d& p) -> std::optional<Eigen::Vector3d> {
        if (p[0] <= 30) return std::nullopt;
        return Eigen::Vector3d(0, 0, 1.0);
      },
      AnatomicalFrame{});
  ASSERT_EQ(d.size(), 3u);
  EXPECT_FALSE(d[0].has_value);
  EXPECT_NE(d[0].sentence.find("no displacement"), std::string::npos) << d[0].sentence;
  EXPECT_TRUE(d[1].has_value);
  EXPECT_EQ(d[1].n_with_value, 15);
  EXPECT_NEAR(d[1].mean_mm, 1.0, 1e-12);
  EXPECT_EQ(d[1].direction, "up");
  EXPECT_FALSE(d[2].found);
  EXPECT_NE(d[2].sentence.find("not found"), std::string::npos);
  const auto j = nlohmann::json::parse(feature_displacements_to_json(d));
  EXPECT_TRUE(j[0]["max_mm"].is_null());
}

TEST(FeatureLines, OnCraniumTheLinesLieWhereAnatomyPutsThem) {
  // The demo patient's model (scripts/demo.sh writes out/cranium), where it is there.
  std::string root = CAPS_SHARED_DATA;
  const std::string tail = "/../shared/data";
  if (root.size() > tail.size() && root.compare(root.size() - tail.size(), tail.size(), tail) == 0)
    root = root.substr(0, root.size() - tail.size());
  const fs::path dir = fs::path(root) / "out" / "cranium";
  if (!fs::exists(dir / "model.json")) GTEST_SKIP() << dir << " is not there (scripts/demo.sh)";
  const PatientModel model = PatientModel::load(dir);
  const Landmarks lm = find_landmarks(model);
  const FeatureLines lines = find_feature_lines(model, lm);
  auto mean_z = [](const FeatureLine& l) {
    double s = 0;
    for (const auto& tz : l.theta_z) s += tz[1];
    return s / l.theta_z.size();
  };
  const double zn = lm.find("nasion")->z_mm, zsn = lm.find("subnasale")->z_mm;
  for (const char* sfx : {"_left", "_right"}) {
    const FeatureLine& up = *lines.find(std::string("upper_eyelid_margin") + sfx);
    const FeatureLine& lo = *lines.find(std::string("lower_eyelid_margin") + sfx);
    const FeatureLine& brow = *lines.find(std::string("eyebrow") + sfx);
    const FeatureLine& al = *lines.find(std::string("alar_rim") + sfx);
    ASSERT_TRUE(up.found && lo.found && brow.found && al.found) << sfx;
    const Landmark& ex = *lm.find(std::string("exocanthion") + sfx);
    // The eyelids at about the exocanthion's height (it lay on the lower lid on Cranium), or,
    // with the exocanthions withdrawn (Cranium's, 43 mm apart, since 6 December), about 10 mm
    // below the nasion, where the detector then looks (docs/landmarks.md); below the nasion;
    // the upper above the lower.
    EXPECT_NEAR(mean_z(lo), ex.found ? ex.z_mm : zn - 10.0, 6.0) << sfx;
    EXPECT_GT(mean_z(up), mean_z(lo)) << sfx;
    EXPECT_LT(mean_z(up), zn) << sfx;
    // The brows above the eyelids by 10..35 mm (the brow's height above the lid fissure).
    EXPECT_GT(mean_z(brow) - mean_z(up), 10.0) << sfx;
    EXPECT_LT(mean_z(brow) - mean_z(up), 35.0) << sfx;
    // The alar rims between the subnasale's and the nasion's heights.
    EXPECT_GT(mean_z(al), zsn) << sfx;
    EXPECT_LT(mean_z(al), zn) << sfx;
  }
  // The scan ends at the upper lip: the lips are outside its field of view, and say so.
  const FeatureLine& lip = *lines.find("lower_lip_vermilion");
  EXPECT_FALSE(lip.found);
  EXPECT_NE(lip.note.find("field of view"), std::string::npos) << lip.note;
}

TEST(FeatureLines, OnTheFacePhantomsCtTheLinesLieOnItsAnalyticFeatures) {
  // The face phantom (caps phantom --face) in 1.5 mm voxels and its model on a 512 x 256 grid, as
  // tests/test_surface_landmarks.cpp builds it. Its face has no eyelid crease, no brow ridges
  // beside the glabella and no alar crease: its eyes are 5 mm dips (z 5, theta +-20 deg), its lips
  // two bumps (z -36 and -48, 0.3 rad wide) with a saddle between them. The lines found must lie
  // on those: the fissure in the eye's dip, the stomion in the saddle, the lip borders on the
  // lips' crests, the corners where the saddle fades out.
  PhantomOptions o;
  o.dims = {160, 160, 150};
  o.spacing_mm = {1.5, 1.5, 1.5};
  o.face = true;
  o.head_holder = false;
  const Volume ct = make_phantom(o);
  ModelOptions mo;
  mo.maps.n_theta = 512;
  mo.maps.n_z = 256;
  const PatientModel model(build_volume_model(ct, mo).maps);
  const Landmarks lm = find_landmarks(model);
  const FeatureLines lines = find_feature_lines(model, lm);
  const double z0 = -model.axis().origin_lps[2];  // the phantom's z = 0 in the model's z
  auto mean_z = [&](const FeatureLine& l) {
    double s = 0;
    for (const auto& tz : l.theta_z) s += tz[1];
    return s / l.theta_z.size() - z0;
  };
  for (const char* sfx : {"_left", "_right"}) {
    const FeatureLine& up = *lines.find(std::string("upper_eyelid_margin") + sfx);
    const FeatureLine& lo = *lines.find(std::string("lower_eyelid_margin") + sfx);
    ASSERT_TRUE(up.found && lo.found) << sfx << ": " << up.note;
    EXPECT_NEAR(0.5 * (mean_z(up) + mean_z(lo)), 5.0, 2.0) << sfx;
  }
  const FeatureLine& ul = *lines.find("upper_lip_vermilion");
  const FeatureLine& ll = *lines.find("lower_lip_vermilion");
  ASSERT_TRUE(ul.found) << ul.note;
  ASSERT_TRUE(ll.found) << ll.note;
  EXPECT_NEAR(ul.theta_z[ul.theta_z.size() / 2][1] - z0, -36.0, 2.0);
  EXPECT_NEAR(ll.theta_z[ll.theta_z.size() / 2][1] - z0, -48.0, 2.0);
  const FeatureLine& ch = *lines.find("oral_commissure_left");
  ASSERT_TRUE(ch.found) << ch.note;
  EXPECT_NEAR(ch.theta_z[0][1] - z0, -42.0, 2.0);
  // It has no brow ridges beside the glabella and no alar creases: none are invented.
  for (const char* n : {"eyebrow_left", "eyebrow_right", "alar_rim_left", "alar_rim_right"})
    EXPECT_FALSE(lines.find(n)->found) << n << ": " << lines.find(n)->note;
}

TEST(FeatureLines, ModelJsonKeepsThemWhenTheLandmarksAreWrittenAgain) {
  std::string root = CAPS_SHARED_DATA;
  const std::string tail = "/../shared/data";
  if (root.size() > tail.size() && root.compare(root.size() - tail.size(), tail.size(), tail) == 0)
    root = root.substr(0, root.size() - tail.size());
  const fs::path src = fs::path(root) / "out" / "cranium";
  if (!fs::exists(src / "model.json")) GTEST_SKIP() << src << " is not there (scripts/demo.sh)";
  const fs::path dir = fs::temp_directory_path() / "caps_test_features_model";
  fs::remove_all(dir);
  fs::copy(src, dir, fs::copy_options::recursive);
  const PatientModel model = PatientModel::load(dir);
  const Landmarks lm = find_landmarks(model);
  const FeatureLines lines = find_feature_lines(model, lm);
  write_model_features(dir, feature_lines_to_json(lines));
  // Rewriting the landmarks (caps model landmarks) keeps the features, and they read back.
  write_model_landmarks(dir, landmarks_to_json(lm));
  const ModelInfo info = read_model_info(dir);
  ASSERT_FALSE(info.features_json.empty());
  const FeatureLines back =
      feature_lines_from_json(info.features_json, (dir / "model.json").string());
  const FeatureLine* a = lines.find("upper_eyelid_margin_left");
  const FeatureLine* b = back.find("upper_eyelid_margin_left");
  ASSERT_TRUE(a && b && a->found && b->found);
  ASSERT_EQ(a->lps.size(), b->lps.size());
  EXPECT_LT((a->lps.back() - b->lps.back()).norm(), 1e-3);
  EXPECT_THROW(write_model_features(dir, "[1, 2]"), InvalidInput);
  fs::remove_all(dir);
}

TEST(FeatureDisplacements, AFieldFromSamplesIsExactAtThemAndAbsentFarFromThem) {
  // Samples of u = (0, 0, -0.1 x) on a 1 mm grid in the plane y = -90 (x 0..20, z 30..50).
  std::vector<Eigen::Vector3d> p, u;
  for (int i = 0; i <= 20; ++i)
    for (int k = 0; k <= 20; ++k) {
      p.emplace_back(i, -90, 30 + k);
      u.emplace_back(0, 0, -0.1 * i);
    }
  Eigen::MatrixX3d P(p.size(), 3), U(u.size(), 3);
  for (std::size_t i = 0; i < p.size(); ++i) {
    P.row(i) = p[i].transpose();
    U.row(i) = u[i].transpose();
  }
  const DisplacementAt at = displacement_from_samples(P, U, 1.5);
  ASSERT_TRUE(at(Eigen::Vector3d(7, -90, 40)));
  EXPECT_NEAR((*at(Eigen::Vector3d(7, -90, 40)))[2], -0.7, 1e-12);
  // Between samples: a weighted mean of the neighbours, symmetric about a column's midpoint.
  EXPECT_NEAR((*at(Eigen::Vector3d(7.5, -90, 40)))[2], -0.75, 1e-12);
  EXPECT_FALSE(at(Eigen::Vector3d(30, -90, 40)));  // beyond the samples: nothing
  // A lower eyelid along x 5..15 at z 40: 1.0 mm down at its lateral end.
  FeatureLines lines;
  FeatureLine l;
  l.name = "lower_eyelid_margin_left";
  l.found = true;
  l.side = "left";
  l.along = "medial-lateral";
  for (int x = 5; x <= 15; ++x) {
    l.theta_z.emplace_back(0, 0);
    l.lps.emplace_back(x, -90, 40);
  }
  lines.items.push_back(l);
  const auto d = feature_displacements(lines, at, AnatomicalFrame{});
  EXPECT_NEAR(d[0].max_mm, 1.5, 1e-12);
  EXPECT_NEAR(d[0].mean_mm, 1.0, 1e-12);
  EXPECT_EQ(d[0].where, "lateral third");
  EXPECT_NE(d[0].sentence.find("pulled 1.5 mm down at its lateral third"), std::string::npos)
      << d[0].sentence;
  EXPECT_THROW(displacement_from_samples(P, U.topRows(3), 1.0), InvalidInput);
}

// A field carried on across a seam: samples along the line y = 0 (every 0.1 mm, the value 1 in
// x) blended into a far field of 3 in x over 2 mm: 1 on the seam, 2 halfway, the far field's 3
// from 2 mm on; where the far field has nothing, the blend goes to zero and then nothing.
TEST(FeatureLines, AFieldIsCarriedOnAcrossASeamWithoutAnEdge) {
  const int n = 201;
  Eigen::MatrixX3d P(n, 3), U = Eigen::MatrixX3d::Zero(n, 3);
  for (int i = 0; i < n; ++i) {
    P.row(i) = Eigen::RowVector3d(-10 + 0.1 * i, 0, 0);
    U(i, 0) = 1;
  }
  const DisplacementAt far = [](const Eigen::Vector3d& x) -> std::optional<Eigen::Vector3d> {
    if (x.y() > 5) return std::nullopt;
    return Eigen::Vector3d(3, 0, 0);
  };
  const DisplacementAt at = blend_across_seam(far, P, U, 2.0);
  EXPECT_NEAR(at(Eigen::Vector3d(0.3, 0, 0))->x(), 1.0, 1e-12);
  EXPECT_NEAR(at(Eigen::Vector3d(0, 1, 0))->x(), 2.0, 1e-12);
  EXPECT_NEAR(at(Eigen::Vector3d(0, 0.5, 0))->x(), 1.5, 1e-12);
  EXPECT_NEAR(at(Eigen::Vector3d(0, 0, -1.5))->x(), 2.5, 1e-12);
  EXPECT_NEAR(at(Eigen::Vector3d(0, 2.5, 0))->x(), 3.0, 1e-12);
  EXPECT_NEAR(at(Eigen::Vector3d(30, 0, 0))->x(), 3.0, 1e-12);  // past the seam's end
  // Where the far field has none, a seam with nothing beyond it: the samples fade to zero.
  const DisplacementAt alone = blend_across_seam(
      [](const Eigen::Vector3d&) { return std::optional<Eigen::Vector3d>(); }, P, U, 2.0);
  EXPECT_NEAR(alone(Eigen::Vector3d(0, 1.5, 0))->x(), 0.25, 1e-12);
  EXPECT_FALSE(alone(Eigen::Vector3d(0, 2.5, 0)));
  EXPECT_THROW(blend_across_seam(far, P, U.topRows(3), 1.0), InvalidInput);
  EXPECT_THROW(blend_across_seam(far, P, U, 0.0), InvalidInput);
  EXPECT_THROW(blend_across_seam(nullptr, P, U, 1.0), InvalidInput);
}
