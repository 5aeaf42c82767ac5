// `caps model tissue` and the tissue model `caps model from-volume` makes (app/model.hpp): the
// files land in the model directory, a second build needs --force, a model without them is
// refused with what to run, and one whose CT is gone says so.
#include <gtest/gtest.h>

#include <filesystem>
#include <nlohmann/json.hpp>

#include "caps/app/model.hpp"
#include "caps/core/error.hpp"
#include "caps/mesher/tissue_model.hpp"
#include "phantom_model.hpp"

using namespace caps;
namespace fs = std::filesystem;

TEST(AppTissue, FromVolumeBuildsItAndModelTissueRebuildsIt) {
  const fs::path folder = caps_test::program_folder("caps_app_tissue");
  const std::string model = (folder / "model").string();
  caps_test::make_phantom_model(folder, model);
  for (const char* f : {mesher::tissue_file::kMesh, mesher::tissue_file::kJson,
                        mesher::tissue_file::kSkinLevelSet, mesher::tissue_file::kBoneLevelSet})
    EXPECT_TRUE(fs::exists(fs::path(model) / f)) << f;
  const mesher::TissueModel first = mesher::read_tissue_model(model);
  EXPECT_GT(first.n_tets(), 1000);
  // The phantom's soft tissue (a 4-12 mm shell around a 150 x 190 mm head, neck cut): hundreds
  // of ml, not the brain's litre.
  EXPECT_GT(first.volume_ml, 200.0);
  EXPECT_LT(first.volume_ml, 1200.0);

  app::TissueRequest r;
  r.model = model;
  r.face_size = 3.0;
  EXPECT_THROW(app::run_model_tissue(r), InvalidInput);  // it has one already
  r.force = true;
  const app::TissueResult out = app::run_model_tissue(r);
  const nlohmann::json j = nlohmann::json::parse(out.tissue_json);
  EXPECT_EQ(j.at("sizes_mm").at("face_facet").get<double>(), 3.0);
  EXPECT_EQ(j.at("counts").at("tets").get<long long>(), mesher::read_tissue_model(model).n_tets());
  EXPECT_NE(app::summary(out).find("tets"), std::string::npos);
  // The same CT, segmented again with the recorded thresholds: the same tissue, within the
  // meshes' difference.
  EXPECT_NEAR(mesher::read_tissue_model(model).volume_ml, first.volume_ml, 0.05 * first.volume_ml);
  const nlohmann::json as_json = nlohmann::json::parse(app::to_json(out));
  EXPECT_TRUE(as_json.contains("counts"));
}

TEST(AppTissue, AModelWithoutItIsRefusedWithWhatToRun) {
  const fs::path folder = caps_test::program_folder("caps_app_tissue");
  app::PhantomRequest ph;
  ph.output = (folder / "ct2.nii.gz").string();
  ph.voxels = "96,96,90";
  ph.spacing = "2.5,2.5,2.5";
  app::run_phantom(ph);
  app::FromVolumeRequest fv;
  fv.input = ph.output;
  fv.output = (folder / "no_tissue").string();
  fv.n_theta = 128;
  fv.n_z = 64;
  fv.no_tissue = true;
  app::run_from_volume(fv);
  EXPECT_FALSE(fs::exists(folder / "no_tissue" / mesher::tissue_file::kMesh));
  try {
    mesher::read_tissue_model(fv.output);
    FAIL() << "a model without a tissue model was read";
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("run `caps model tissue MODEL`"), std::string::npos);
  }
  EXPECT_THROW(mesher::read_bone_level_set(fv.output), InvalidInput);
  // Its CT gone: caps model tissue says where it looked.
  fs::remove(ph.output);
  app::TissueRequest r;
  r.model = fv.output;
  try {
    app::run_model_tissue(r);
    FAIL() << "built without the CT";
  } catch (const IoError& e) {
    EXPECT_NE(std::string(e.what()).find("ct2.nii.gz"), std::string::npos);
  }
}
