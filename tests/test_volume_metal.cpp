// Metal in a CT (volume/metal.hpp; docs/volume.md, "Metal"): the face phantom with a dental metal
// block in the upper jaw and its streak artefacts (caps phantom --metal) gives the skin, the
// thickness and the landmarks of the same phantom without metal, outside the cells marked for it;
// the metal is found where it was put, its cells are marked, and heads without metal are left
// alone.

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <unistd.h>

#include <nlohmann/json.hpp>

#include "caps/surface/landmarks.hpp"
#include "caps/surface/patient_model.hpp"
#include "caps/volume/metal.hpp"
#include "caps/volume/model.hpp"
#include "caps/volume/phantom.hpp"

using namespace caps;

namespace {

// The face phantom in 1.5 mm voxels without the head holder, with or without the metal, and its
// model on a 512 x 256 grid (what the landmark tests use); made once each.
PhantomOptions face_options(bool metal, double metal_z_mm = HeadPhantom::kMetalZ) {
  PhantomOptions o;
  o.metal_z_mm = metal_z_mm;
  o.dims = {160, 160, 150};
  o.spacing_mm = {1.5, 1.5, 1.5};
  o.face = true;
  o.head_holder = false;
  o.metal = metal;
  return o;
}

ModelOptions model_options() {
  ModelOptions mo;
  mo.maps.n_theta = 512;
  mo.maps.n_z = 256;
  mo.smoothing_iterations = 0;
  return mo;
}

// The two phantoms at the teeth' height, made once each.
const Volume& face_ct(bool metal) {
  static std::unique_ptr<Volume> made[2];
  auto& v = made[metal ? 1 : 0];
  if (!v) v = std::make_unique<Volume>(make_phantom(face_options(metal)));
  return *v;
}

// What building it warned about is in `reporter` (model.json's warnings).
const VolumeModel& face_model(bool metal, Reporter** reporter = nullptr) {
  static Reporter reporters[2];
  static std::unique_ptr<VolumeModel> made[2];
  auto& m = made[metal ? 1 : 0];
  Reporter* r = &reporters[metal ? 1 : 0];
  if (!m)
    m = std::make_unique<VolumeModel>(
        build_volume_model(face_ct(metal), model_options(), r));
  if (reporter) *reporter = r;
  return *m;
}

// The cells compared: valid in both models and not marked for metal.
bool compared(const VolumeModel& with, const VolumeModel& without, std::size_t c) {
  return flags_valid(with.maps.flags[c]) && flags_valid(without.maps.flags[c]) &&
         (with.maps.metal.empty() || !with.maps.metal[c]);
}

}  // namespace

// The phantom's metal is there, clipped as a CT without its extended scale stores it, and its
// streaks cross the skin: in the slice through it the air in front of the face is raised above
// the skin threshold and soft tissue is dropped below it.
TEST(MetalPhantom, StreaksCrossTheSkinInTheSlicesThroughTheMetal) {
  const Volume& ct = face_ct(true);
  const Volume& clean = face_ct(false);
  const HeadPhantom head(false, false, true);
  const Eigen::Vector3d m = head.metal_centre();
  const Eigen::Vector3d ijk = ct.lps_to_index(m).array().round();
  EXPECT_EQ(ct.at(ijk[0], ijk[1], ijk[2]), HeadPhantom::kStoredMaxHu);
  int raised_air = 0, dropped_tissue = 0;
  for (std::size_t i = 0; i < ct.data.size(); ++i) {
    const double lps_z = ct.index_to_lps(Eigen::Vector3d(0, 0, i / (160 * 160)))[2];
    if (std::abs(lps_z - m[2]) > 1.0) continue;
    raised_air += clean.data[i] < -900 && ct.data[i] > -400;
    dropped_tissue += clean.data[i] > -100 && clean.data[i] < 100 && ct.data[i] < -400;
  }
  EXPECT_GT(raised_air, 500);
  EXPECT_GT(dropped_tissue, 100);
  // Slices 6 mm away from the metal are untouched.
  for (std::size_t i = 0; i < ct.data.size(); ++i) {
    const double lps_z = ct.index_to_lps(Eigen::Vector3d(0, 0, i / (160 * 160)))[2];
    if (std::abs(lps_z - m[2]) > 6.0) ASSERT_EQ(ct.data[i], clean.data[i]) << i;
  }
}

TEST(Metal, FoundWhereItWasPutAndItsCellsMarked) {
  const VolumeModel& vm = face_model(true);
  const HeadPhantom head(false, false, true);
  ASSERT_TRUE(vm.metal.checked);
  ASSERT_TRUE(vm.metal.found);
  // The crown, and pieces of the bright streaks next to it that reach the clip too.
  EXPECT_GE(vm.metal.components, 1);
  EXPECT_LT((vm.metal.centre_lps - head.metal_centre()).norm(), 1.5);
  // The block is 4 mm tall about S -40 mm: the repaired slabs hold it and at most 4 mm more on
  // either side.
  EXPECT_LE(vm.metal.z_min_mm, head.metal_centre()[2] - HeadPhantom::kMetalHalfMm[2]);
  EXPECT_GE(vm.metal.z_max_mm, head.metal_centre()[2] + HeadPhantom::kMetalHalfMm[2]);
  EXPECT_GT(vm.metal.z_min_mm, head.metal_centre()[2] - 6.0);
  EXPECT_LT(vm.metal.z_max_mm, head.metal_centre()[2] + 6.0);
  // Every cell whose skin lies in the slices through the metal is marked kTruncated and filled;
  // none farther than 1 mm from the repaired slabs is (the model's axis is vertical).
  const auto& maps = vm.maps;
  const auto& g = maps.grid;
  ASSERT_EQ(maps.metal.size(), g.size());
  const double z_axis = maps.axis.origin_lps[2];
  std::size_t marked = 0;
  for (int k = 0; k < g.n_z; ++k)
    for (int j = 0; j < g.n_theta; ++j) {
      const std::size_t c = g.index(j, k);
      const double s = z_axis + g.z_mm(k);
      if (maps.metal[c]) {
        ++marked;
        EXPECT_TRUE(maps.flags[c] & kTruncated);
        EXPECT_FALSE(maps.measured_skin[c]);
        EXPECT_GT(s, vm.metal.z_min_mm - 1.0);
        EXPECT_LT(s, vm.metal.z_max_mm + 1.0);
      } else if (s > vm.metal.z_min_mm + 0.5 && s < vm.metal.z_max_mm - 0.5) {
        EXPECT_FALSE(maps.measured_skin[c]) << "cell " << j << "," << k << " not marked";
      }
    }
  EXPECT_GT(marked, static_cast<std::size_t>(g.n_theta));
  EXPECT_EQ(metal_cells(maps).count, marked);
}

// Outside the marked cells the skin, the thickness and the validity are those of the phantom
// without metal.
TEST(Metal, SkinAndThicknessAsWithoutMetal) {
  const VolumeModel& with = face_model(true);
  const VolumeModel& without = face_model(false);
  ASSERT_EQ(with.maps.grid.size(), without.maps.grid.size());
  double sum2 = 0, worst = 0, sum2_t = 0, worst_t = 0;
  std::size_t n = 0, flags_differ = 0;
  for (std::size_t c = 0; c < with.maps.grid.size(); ++c) {
    if (!with.maps.metal.empty() && with.maps.metal[c]) continue;
    flags_differ += with.maps.flags[c] != without.maps.flags[c];
    if (!compared(with, without, c)) continue;
    const double d = with.maps.r_skin[c] - without.maps.r_skin[c];
    const double t = with.maps.thickness[c] - without.maps.thickness[c];
    sum2 += d * d;
    sum2_t += t * t;
    worst = std::max(worst, std::abs(d));
    worst_t = std::max(worst_t, std::abs(t));
    ++n;
  }
  ASSERT_GT(n, with.maps.grid.size() / 2);
  EXPECT_LT(std::sqrt(sum2 / n), 0.1);
  EXPECT_LT(worst, 1.0);
  EXPECT_LT(std::sqrt(sum2_t / n), 0.1);
  EXPECT_LT(worst_t, 1.0);
  EXPECT_LT(flags_differ, with.maps.grid.size() / 1000) << "cells whose validity changed";
  // The skin surface has no spikes: its extent is that of the phantom without metal.
  ASSERT_GT(with.skin.n_vertices(), 0);
  const Eigen::RowVector3d lo_a = with.skin.V.colwise().minCoeff(),
                           hi_a = with.skin.V.colwise().maxCoeff(),
                           lo_b = without.skin.V.colwise().minCoeff(),
                           hi_b = without.skin.V.colwise().maxCoeff();
  EXPECT_LT((lo_a - lo_b).cwiseAbs().maxCoeff(), 1.0);
  EXPECT_LT((hi_a - hi_b).cwiseAbs().maxCoeff(), 1.0);
}

namespace {

// Each landmark of the model without metal is, in the model with metal, found within 1 mm of
// it where its cell is not marked, and absent where it is: never displaced. The names of those
// found and of those absent.
std::pair<std::vector<std::string>, std::vector<std::string>> compare_landmarks(
    const PatientModel& with, const PatientModel& without) {
  const Landmarks a = find_landmarks(with), b = find_landmarks(without);
  std::vector<std::string> same, absent;
  for (const Landmark& lb : b.items) {
    EXPECT_TRUE(lb.found) << lb.name << ": " << lb.note;
    if (!lb.found) continue;
    const Landmark* la = a.find(lb.name);
    if (!la) {
      ADD_FAILURE() << lb.name;
      continue;
    }
    const bool marked = (with.flags_at(lb.theta_deg, lb.z_mm) & kTruncated) != 0;
    if (marked) {
      EXPECT_FALSE(la->found) << lb.name << " found in the metal's band, "
                              << (la->lps - lb.lps).norm() << " mm from where it is";
      absent.push_back(lb.name);
      continue;
    }
    EXPECT_TRUE(la->found) << lb.name << " absent away from the metal: " << la->note;
    if (!la->found) continue;
    EXPECT_LT((la->lps - lb.lps).norm(), 1.0) << lb.name;
    EXPECT_LT(std::abs(la->thickness_mm - lb.thickness_mm), 1.0) << lb.name;
    same.push_back(lb.name);
  }
  return {same, absent};
}

}  // namespace

TEST(Metal, LandmarksAsWithoutMetalOrAbsent) {
  const PatientModel with(face_model(true).maps), without(face_model(false).maps);
  const auto [same, absent] = compare_landmarks(with, without);
  EXPECT_EQ(same.size(), 11u);  // none lies in the band at the teeth
  EXPECT_TRUE(absent.empty());
}

// Metal at the chin (a plate on the mandible, its band over the pogonion): the pogonion is
// absent, not moved to the band's edge, and the others are where they were.
TEST(Metal, ALandmarkInTheBandIsAbsentNotDisplaced) {
  const PatientModel without(face_model(false).maps);
  const Landmark* pogonion = find_landmarks(without).find("pogonion");
  ASSERT_TRUE(pogonion && pogonion->found);
  const VolumeModel chin =
      build_volume_model(make_phantom(face_options(true, pogonion->z_mm)), model_options());
  ASSERT_TRUE(chin.metal.found);
  const auto [same, absent] = compare_landmarks(PatientModel(chin.maps), without);
  EXPECT_EQ(absent, std::vector<std::string>{"pogonion"});
  EXPECT_EQ(same.size(), 10u);
}


// Whoever segments (caps model tissue segments the CT again) gets masks without the metal and its
// streaks: the skin and bone masks of the phantom with metal differ from those without it only
// in the repaired slices, by a few voxels there, and the bone holds no metal.
TEST(Metal, SegmentationHoldsNeitherTheMetalNorItsStreaks) {
  const Segmentation with = segment_head(face_ct(true)), without = segment_head(face_ct(false));
  ASSERT_TRUE(with.metal.found);
  EXPECT_FALSE(without.metal.found);
  ASSERT_EQ(with.skin.geom.dims, without.skin.geom.dims);
  std::size_t skin_differ = 0, bone_differ = 0, outside = 0;
  for (std::size_t i = 0; i < with.skin.data.size(); ++i) {
    const bool ds = with.skin.data[i] != without.skin.data[i];
    const bool db = with.bone.data[i] != without.bone.data[i];
    skin_differ += ds;
    bone_differ += db;
    if (ds || db) {
      const auto& g = with.skin.geom;
      const int k = static_cast<int>(i / (static_cast<std::size_t>(g.dims[0]) * g.dims[1]));
      const double s = g.index_to_lps(Eigen::Vector3d(0, 0, k))[2];
      outside += s < with.metal.z_min_mm - 1.5 || s > with.metal.z_max_mm + 1.5;
    }
  }
  EXPECT_EQ(outside, 0u);
  EXPECT_LT(skin_differ, without.skin.count() / 1000) << "of " << without.skin.count();
  EXPECT_LT(bone_differ, without.bone.count() / 100) << "of " << without.bone.count();
  const Eigen::Vector3d m = with.bone.geom.lps_to_index(HeadPhantom(false, false, true).metal_centre());
  const Eigen::Vector3i n = m.array().round().cast<int>();
  EXPECT_EQ(with.bone.at(n[0], n[1], n[2]), without.bone.at(n[0], n[1], n[2]));
}

// Heads without metal: nothing found, nothing marked, the model unchanged (the plain phantom,
// the layered one with its thin bone plate, whose bone is far below the threshold).
TEST(Metal, NoMetalNoDetection) {
  Reporter* reporter = nullptr;
  const VolumeModel& without = face_model(false, &reporter);
  for (const auto& w : reporter->warnings()) EXPECT_EQ(w.find("metal"), std::string::npos) << w;
  EXPECT_TRUE(without.metal.checked);
  EXPECT_FALSE(without.metal.found);
  EXPECT_TRUE(without.maps.metal.empty());
  PhantomOptions o;
  o.dims = {96, 96, 90};
  o.spacing_mm = {2.5, 2.5, 2.5};
  o.layered = true;
  o.thin_bone = true;
  const MetalRegion none = detect_metal(make_phantom(o));
  EXPECT_TRUE(none.checked);
  EXPECT_FALSE(none.found);
  // An MR is not examined, whatever its values.
  Volume mr = face_ct(true);
  mr.modality = Modality::MR;
  EXPECT_FALSE(detect_metal(mr).checked);
}

// model.json says where the metal was found and which cells were marked.
TEST(Metal, ModelJsonSaysWhere) {
  Reporter* reporter = nullptr;
  const VolumeModel& vm = face_model(true, &reporter);
  const auto dir = std::filesystem::temp_directory_path() / ("caps_metal_" + std::to_string(::getpid()));
  write_model(vm, dir, true, reporter);
  std::ifstream in(dir / "model.json");
  const auto j = nlohmann::json::parse(in);
  const auto& m = j.at("segmentation").at("metal");
  EXPECT_TRUE(m.at("found").get<bool>());
  EXPECT_EQ(m.at("cells").at("count").get<std::size_t>(), metal_cells(vm.maps).count);
  EXPECT_EQ(m.at("cells").at("flag"), "truncated");
  EXPECT_NEAR(m.at("centre_lps_mm")[2].get<double>(), HeadPhantom(false, false, true).metal_centre()[2], 1.0);
  bool warned = false;
  for (const auto& w : j.at("warnings")) warned = warned || w.get<std::string>().find("metal") != std::string::npos;
  EXPECT_TRUE(warned);
  // The summary (caps model from-volume, caps model info) says it too.
  const std::string summary = model_summary(dir);
  EXPECT_NE(summary.find("metal      found"), std::string::npos) << summary;
  std::filesystem::remove_all(dir);
  // And without metal: none found.
  write_model(face_model(false), dir, true);
  const std::string clean = model_summary(dir);
  EXPECT_NE(clean.find("metal      none"), std::string::npos) << clean;
  std::filesystem::remove_all(dir);
}
