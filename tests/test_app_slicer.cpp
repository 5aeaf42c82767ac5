// `caps model export-slicer` (app/slicer.hpp, docs/slicer.md): the segmentation's labels against
// the analytic layered phantom, the verb in the one list, and refusals that write nothing. The
// files are read back by independent readers in tests/slicer/ (VTK, nibabel, jsonschema).
#include <gtest/gtest.h>
#include <teem/nrrd.h>

#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "caps/app/simulation.hpp"
#include "caps/app/slicer.hpp"
#include "caps/app/verbs.hpp"
#include "caps/core/error.hpp"
#include "caps/volume/phantom.hpp"
#include "caps/volume/read_volume.hpp"
#include "phantom_model.hpp"

using namespace caps;
namespace fs = std::filesystem;

namespace {

// The layered phantom at 0.75 mm voxels, the head from 15 mm above its centre to the vertex (as
// tests/layered_phantom_model.hpp, where the volume module's layer depths are checked to 0.3 mm),
// and its model, made once.
const std::string& layered_model() {
  static const std::string dir = [] {
    const fs::path folder = caps_test::program_folder("caps_app_slicer");
    app::PhantomRequest ph;
    ph.output = (folder / "ct.nii.gz").string();
    ph.voxels = "216,280,120";
    ph.spacing = "0.75,0.75,0.75";
    ph.no_holder = true;
    ph.layered = true;
    app::run_phantom(ph);
    app::FromVolumeRequest fv;
    fv.input = ph.output;
    fv.output = (folder / "model").string();
    fv.n_theta = 256;
    fv.n_z = 128;
    fv.no_tissue = true;
    app::run_from_volume(fv);
    return fv.output;
  }();
  return dir;
}

}  // namespace

// Each voxel's label against the phantom's analytic layer at the voxel's centre, where the centre
// lies at least 0.3 mm from every interface (the model measures the layers along rays, to a
// fraction of a voxel). Known answer: the phantom's dermis / fat / deep radii (phantom.hpp).
TEST(AppSlicer, SegmentationLabelsTheLayeredPhantomsTissue) {
  const fs::path folder = caps_test::program_folder("caps_app_slicer");
  app::ExportSlicerRequest r;
  r.model = layered_model();
  r.output = (folder / "export").string();
  const app::ExportSlicerResult out = app::run_export_slicer(r);
  EXPECT_EQ(out.volume_file, "ct.nrrd");
  for (const std::string& w : out.warnings)  // a skull cap has no face to find landmarks on
    EXPECT_NE(w.find("no landmark"), std::string::npos) << w;
  const Volume labels = read_volume(folder / "export" / "tissue.seg.nrrd");
  const Volume ct = read_volume(folder / "export" / "ct.nrrd");
  const Volume source = read_volume(folder / "ct.nii.gz");
  // caps reads back the grid it wrote, which is the source's, to the float's precision
  ASSERT_EQ(labels.geom.dims, source.geom.dims);
  EXPECT_LT((labels.geom.origin_lps - source.geom.origin_lps).norm(), 1e-9);
  EXPECT_LT((labels.geom.direction - source.geom.direction).norm(), 1e-9);
  EXPECT_LT((ct.geom.spacing_mm - source.geom.spacing_mm).norm(), 1e-9);
  for (std::size_t i = 0; i < ct.data.size(); i += 97) ASSERT_EQ(ct.data[i], source.data[i]);

  const HeadPhantom ph(/*layered=*/true);
  const double pi = std::acos(-1.0);
  int agree[5] = {0}, total[5] = {0}, confusion[5][5] = {{0}};
  const auto& g = labels.geom;
  for (int k = 0; k < g.dims[2]; ++k)
    for (int j = 0; j < g.dims[1]; ++j)
      for (int i = 0; i < g.dims[0]; ++i) {
        const Eigen::Vector3d p = g.index_to_lps(Eigen::Vector3d(i, j, k));
        const Eigen::Vector3d v = p - ph.axis_point();
        const double theta = std::atan2(v.x(), -v.y()), z = v.z(), r = std::hypot(v.x(), v.y());
        // away from the marker (left, z 50), the vertex and the volume's lower edge (z 15)
        if (std::abs(theta - pi / 2) < 0.5 || z > 60 || z < 22) continue;
        const double rs = ph.skin_radius(theta, z), ft = ph.fat_top_radius(theta, z),
                     fb = ph.fat_bottom_radius(theta, z), rb = ph.bone_radius(theta, z);
        if (std::abs(rs - ph.head_radius(theta, z)) > 0.01) continue;  // on a bump
        int truth = 0;
        double margin = 0;
        if (r < rs && r > ft)
          truth = 1, margin = std::min(rs - r, r - ft);
        else if (r < ft && r > fb)
          truth = 2, margin = std::min(ft - r, r - fb);
        else if (r < fb && r > rb)
          truth = 3, margin = std::min(fb - r, r - rb);
        else
          continue;
        if (margin < 0.3) continue;
        ++total[truth];
        if (labels.at(i, j, k) == truth) ++agree[truth];
        ++confusion[truth][static_cast<int>(labels.at(i, j, k))];
      }
  for (int c = 1; c <= 3; ++c) {
    ASSERT_GT(total[c], 1000) << "class " << c;
    const std::string row =
        cat("class ", c, " labelled 0: ", confusion[c][0], ", 1: ", confusion[c][1],
            ", 2: ", confusion[c][2], ", 3: ", confusion[c][3], ", 4: ", confusion[c][4]);
    // The layers' depths are measured to about 0.3 mm (tests/test_volume_layers.cpp); a few
    // per cent are left unlabelled (in cells the model does not hold as valid).
    EXPECT_GT(static_cast<double>(agree[c]) / total[c], 0.9) << row;
    // and no tissue is taken for another
    const int wrong = total[c] - agree[c] - confusion[c][0];
    EXPECT_LT(static_cast<double>(wrong) / total[c], 0.005) << row;
  }
}

// teem's nrrdLoad (ITK's NrrdImageIO, through which 3D Slicer reads .nrrd and .seg.nrrd, embeds
// NrrdIO, a subset of teem) parses the export's header: LPS space, the grid, and every segment's
// key/value fields.
TEST(AppSlicer, TeemReadsTheSegmentationsFieldsAsSlicersReaderWould) {
  const fs::path folder = caps_test::program_folder("caps_app_slicer");
  app::ExportSlicerRequest r;
  r.model = layered_model();
  r.output = (folder / "export_teem").string();
  app::run_export_slicer(r);
  const Volume source = read_volume(folder / "ct.nii.gz");
  Nrrd* n = nrrdNew();
  ASSERT_EQ(nrrdLoad(n, (folder / "export_teem" / "tissue.seg.nrrd").c_str(), nullptr), 0);
  EXPECT_EQ(n->space, nrrdSpaceLeftPosteriorSuperior);
  EXPECT_EQ(n->type, nrrdTypeUChar);
  ASSERT_EQ(n->dim, 3u);
  for (int a = 0; a < 3; ++a) {
    EXPECT_EQ(static_cast<int>(n->axis[a].size), source.geom.dims[a]);
    for (int c = 0; c < 3; ++c)
      EXPECT_NEAR(n->axis[a].spaceDirection[c],
                  source.geom.direction(c, a) * source.geom.spacing_mm[a], 1e-12);
    EXPECT_NEAR(n->spaceOrigin[a], source.geom.origin_lps[a], 1e-12);
  }
  auto value = [&](const std::string& key) {
    char* v = nrrdKeyValueGet(n, key.c_str());
    const std::string s = v ? v : "<absent>";
    free(v);
    return s;
  };
  EXPECT_EQ(value("Segmentation_MasterRepresentation"), "Binary labelmap");
  const char* names[] = {"skin (dermis)", "subcutaneous fat", "deep tissue", "bone"};
  for (int i = 0; i < 4; ++i) {
    const std::string k = cat("Segment", i, "_");
    EXPECT_EQ(value(k + "Name"), names[i]);
    EXPECT_EQ(value(k + "LabelValue"), std::to_string(i + 1));
    EXPECT_EQ(value(k + "Layer"), "0");
    EXPECT_NE(value(k + "Extent"), "<absent>");
  }
  EXPECT_EQ(value("Segment4_ID"), "<absent>");
  nrrdNuke(n);
}

TEST(AppSlicer, IsOneVerbOfTheList) {
  const app::VerbEntry& v = app::find_verb("model export-slicer");
  EXPECT_EQ(v.key, "model_export_slicer");
  const nlohmann::json d = nlohmann::json::parse(v.defaults_json());
  for (const char* k : {"model", "output", "plan", "result", "force"})
    EXPECT_TRUE(d.contains(k)) << k;
}

// A finite-element result that is not on the model's skin (a box) is refused before anything is
// written; so is a request whose output is its model.
TEST(AppSlicer, RefusesAResultOfAnotherModelAndWritesNothing) {
  const fs::path folder = caps_test::program_folder("caps_app_slicer");
  app::BoxRequest b;
  b.output = (folder / "box").string();
  app::run_box(b);
  app::SolveRequest s;
  s.mesh = b.output;
  s.output = (folder / "box_result").string();
  app::run_solve(s);
  for (const auto& f : fs::directory_iterator(b.output))  // a folder as caps simulate writes it
    if (!fs::exists(fs::path(s.output) / f.path().filename()))
      fs::copy_file(f.path(), fs::path(s.output) / f.path().filename());
  app::ExportSlicerRequest r;
  r.model = layered_model();
  r.result = s.output;
  r.output = (folder / "refused").string();
  try {
    app::run_export_slicer(r);
    FAIL() << "a box's result was taken for a simulation on the model";
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("does not lie on the skin"), std::string::npos)
        << e.what();
  }
  EXPECT_FALSE(fs::exists(r.output));
  r.result.clear();
  r.output = r.model;
  r.force = true;
  EXPECT_THROW(app::run_export_slicer(r), InvalidInput);
  EXPECT_TRUE(fs::exists(fs::path(r.model) / "model.json"));
}
