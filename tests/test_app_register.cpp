// `caps model register` and `caps model fuse` on the phantom's CT model: a face patch cut from
// the model's own skin.ply and moved by a known pose is registered back (matrix, residual,
// distance map); a reshaped face is refused with exit code 2; a red marker painted on the scan
// lands in the fused model's colour where it was on the CT's skin. And a real scan of one person
// registered to the CT of another (the Lee Perry-Smith scan to Cranium) is refused.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <random>
#include <regex>
#include <unistd.h>

#include "caps/app/model.hpp"
#include "caps/app/register.hpp"
#include "caps/core/error.hpp"
#include "caps/core/units.hpp"
#include "caps/image/image_io.hpp"
#include "caps/surface/patient_model.hpp"
#include "caps/surface/register.hpp"
#include "caps/volume/mesh_io.hpp"
#include "cli_run.hpp"
#include "phantom_model.hpp"

namespace fs = std::filesystem;
using namespace caps;
using nlohmann::json;

namespace {

const fs::path& folder() { return caps_test::program_folder("caps_register"); }

// Registration and fusion read the model's skin and maps; no closure here needs the whole-face
// tissue model.
const std::string& model_dir() { return caps_test::program_phantom_model("caps_register", false); }

// model -> scan: 14 degrees about a skew axis, then (-30, 20, 35) mm.
Eigen::Matrix4d model_to_scan() {
  Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
  T.topLeftCorner<3, 3>() =
      Eigen::AngleAxisd(deg_to_rad(14.0), Eigen::Vector3d(-1, 0.5, 2).normalized()).toRotationMatrix();
  T.topRightCorner<3, 1>() = Eigen::Vector3d(-30, 20, 35);
  return T;
}

// The face of the model's skin.ply (the faces whose vertices lie within 60 degrees of the front
// and 70 mm of the nose's height), with a red disc of radius 8 mm around `marker` (LPS) and grey
// elsewhere, moved by model_to_scan() and with noise of 0.1 mm; `stretch` widens it left-right
// (another head). Written as PLY with vertex colours; returns the clean face (LPS mm).
TriMesh write_face_scan(const fs::path& path, const PatientModel& model, const Eigen::Vector3d& marker,
                        double stretch = 1.0) {
  const TriMesh skin = read_ply(fs::path(model_dir()) / "skin.ply");
  const CylindricalPoint nose = model.to_cylindrical(model.skin_point(0.0, -20.0));
  std::vector<char> keep(skin.n_vertices());
  for (Eigen::Index v = 0; v < skin.n_vertices(); ++v) {
    const CylindricalPoint c = model.to_cylindrical(skin.V.row(v).transpose());
    keep[v] = std::abs(c.theta_deg) <= 60 && std::abs(c.z_mm - nose.z_mm) <= 70 && c.r_mm > 30;
  }
  const TriMesh face = crop_mesh(skin, keep);
  Eigen::Matrix<std::uint8_t, Eigen::Dynamic, 3> colours(face.n_vertices(), 3);
  for (Eigen::Index v = 0; v < face.n_vertices(); ++v) {
    const bool red = (face.V.row(v).transpose() - marker).norm() <= 8.0;
    colours.row(v) << (red ? 230 : 150), (red ? 20 : 150), (red ? 20 : 150);
  }
  TriMesh scan = face;
  const Eigen::Vector3d centre = face.V.colwise().mean();
  scan.V.col(0) = (scan.V.col(0).array() - centre.x()) * stretch + centre.x();
  std::mt19937 rng(3);
  std::normal_distribution<double> noise(0.0, 0.1);
  for (Eigen::Index v = 0; v < scan.n_vertices(); ++v)
    for (int d = 0; d < 3; ++d) scan.V(v, d) += noise(rng);
  scan.V = transform_points(model_to_scan(), scan.V);
  write_ply(scan, path, &colours);
  return face;
}

}  // namespace

TEST(ModelRegister, FaceCutFromTheSkinIsRegisteredBackAndFusedWithItsColour) {
  const PatientModel model = PatientModel::load(model_dir());
  const Eigen::Vector3d marker = model.skin_point(25.0, 5.0);
  const fs::path scan = folder() / "face.ply";
  const TriMesh face = write_face_scan(scan, model, marker);
  ASSERT_GT(face.n_vertices(), 1000);

  app::RegisterRequest r;
  r.input = scan.string();
  r.to = model_dir();
  r.output = (folder() / "reg").string();
  r.scan_scale = 1.0;
  const app::RegisterResult result = app::run_register(r);
  const json j = json::parse(caps_test::slurp(folder() / "reg" / "registration.json"));
  EXPECT_TRUE(j.at("same_head").get<bool>()) << j.at("verdict");
  EXPECT_LE(j.at("residual").at("rms_mm").get<double>(), 0.5);
  EXPECT_GT(j.at("residual").at("overlap_fraction").get<double>(), 0.95);
  Eigen::Matrix4d T;
  for (int i = 0; i < 4; ++i)
    for (int k = 0; k < 4; ++k) T(i, k) = j.at("scan_to_model").at(i).at(k).get<double>();
  // The clean face moved to the scan's frame and back lands where it was.
  const Eigen::MatrixX3d back = transform_points(T, transform_points(model_to_scan(), face.V));
  EXPECT_LT((back - face.V).rowwise().norm().maxCoeff(), 0.5);
  EXPECT_NEAR(j.at("scale_mm_per_unit").get<double>(), 1.0, 1e-12);
  // The distance map: the registered scan with a float "distance" per vertex, and its picture.
  const std::string ply = caps_test::slurp(folder() / "reg" / "distance.ply");
  EXPECT_NE(ply.find("property float distance"), std::string::npos);
  EXPECT_EQ(read_ply(folder() / "reg" / "distance.ply").n_vertices(), face.n_vertices());
  const RgbImage picture = read_image(folder() / "reg" / "distance.png");
  EXPECT_EQ(picture.width, 1100);
  EXPECT_NE(app::summary(result).find("RMS"), std::string::npos);

  // Fuse: the red marker lands where it was on the CT's skin.
  app::FuseRequest f;
  f.input = scan.string();
  f.to = model_dir();
  f.registration = (folder() / "reg" / "registration.json").string();
  f.output = (folder() / "fused").string();
  app::run_fuse(f);
  const PatientModel fused = PatientModel::load(f.output);
  ASSERT_TRUE(fused.has_color());
  const auto& g = fused.grid();
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  int n_red = 0, n_grey = 0;
  for (int k = 0; k < g.n_z; ++k)
    for (int j2 = 0; j2 < g.n_theta; ++j2) {
      const Eigen::Vector3d c = fused.color_at(g.theta_deg(j2), g.z_mm(k));
      if (c[0] > 0.75 && c[1] < 0.25) {
        sum += fused.skin_point(g.theta_deg(j2), g.z_mm(k));
        ++n_red;
      } else if (std::abs(c[0] - 150.0 / 255) < 0.02 && std::abs(c[1] - 150.0 / 255) < 0.02) {
        ++n_grey;
      }
    }
  ASSERT_GT(n_red, 10);
  EXPECT_GT(n_grey, 20 * n_red);  // the rest of the face is the scan's grey
  EXPECT_LT((sum / n_red - marker).norm(), 1.5) << "marker at " << (sum / n_red).transpose()
                                                << ", painted at " << marker.transpose();
  // The depths are the CT's.
  EXPECT_NEAR(fused.thickness(25.0, 5.0), model.thickness(25.0, 5.0), 1e-6);
  EXPECT_NE(caps_test::slurp(fs::path(f.output) / "model.json").find("fused_scan"), std::string::npos);
}

TEST(ModelRegister, FaceOfAnotherHeadIsRefusedWithExitCode2) {
  const PatientModel model = PatientModel::load(model_dir());
  const fs::path scan = folder() / "other.ply";
  write_face_scan(scan, model, model.skin_point(25.0, 5.0), 1.15);
  const fs::path out = folder() / "other_reg";
  const auto run = caps_test::caps(cat("model register ", scan.string(), " --to ", model_dir(),
                                       " --scan-scale 1 -o ", out.string()));
  EXPECT_EQ(run.code, 2) << run.out;
  EXPECT_NE(run.out.find("another head"), std::string::npos) << run.out;
  EXPECT_NE(run.out.find("--accept-other-head"), std::string::npos) << run.out;
  EXPECT_FALSE(fs::exists(out));
  // Accepted on request: written, with the verdict as a warning.
  const auto accepted = caps_test::caps(cat("model register ", scan.string(), " --to ", model_dir(),
                                            " --scan-scale 1 --accept-other-head --json -o ", out.string()));
  EXPECT_EQ(accepted.code, 0) << accepted.out;
  const json j = json::parse(caps_test::slurp(out / "registration.json"));
  EXPECT_FALSE(j.at("same_head").get<bool>());
}

// Two real heads of two people: the Lee Perry-Smith scan ("Infinite, 3D Head Scan" by Lee
// Perry-Smith, CC BY 3.0, www.triplegangers.com; ../shared/data/scan/leeperrysmith) at about its
// real size (29 mm per unit: 7.95 units tall with neck and shoulders) and orientation (y up, face
// +z), docs/surface.md's command, against the skin of Cranium, the demo CT (Debian's
// invesalius-examples). Its residual says another head: exit code 2, nothing written, less than
// 70 % of the scan within 3 mm and a median distance over twice the 1 mm limit (27 % and 8.66 mm
// in two runs, as in docs/surface.md; at 28.93 mm per unit 8-40 % and 4.5-32 mm, varying from run
// to run). The model is built on a coarse grid without layers or the whole-face tissue model:
// registration uses only its skin.ply, the isosurface, which neither changes.
TEST(ModelRegister, LeePerrySmithScanAgainstCraniumIsRefusedByItsResidual) {
  const fs::path scan = fs::path(CAPS_SHARED_DATA) / "scan/leeperrysmith/LeePerrySmith.glb";
  const fs::path cranium = "/usr/share/doc/invesalius-examples/examples/Cranium.inv3";
  if (!fs::exists(scan)) GTEST_SKIP() << scan << " absent (the shared data)";
  if (!fs::exists(cranium)) GTEST_SKIP() << cranium << " not installed (invesalius-examples)";
  app::FromVolumeRequest fv;
  fv.input = cranium.string();
  fv.output = (folder() / "cranium").string();
  fv.n_theta = 128;
  fv.n_z = 64;
  fv.no_layers = true;
  fv.no_tissue = true;
  app::run_from_volume(fv);
  const fs::path out = folder() / "lps_reg";
  const auto run = caps_test::caps(cat("model register ", scan.string(), " --to ", fv.output,
                                       " --scan-scale 29 --up +y --front +z -o ", out.string()));
  EXPECT_EQ(run.code, 2) << run.out;
  EXPECT_NE(run.out.find("another head"), std::string::npos) << run.out;
  EXPECT_FALSE(fs::exists(out));
  std::smatch m;
  ASSERT_TRUE(std::regex_search(run.out, m, std::regex(R"((\d+) % of it within 3 mm)"))) << run.out;
  EXPECT_LT(std::stod(m[1]), 70.0) << run.out;
  ASSERT_TRUE(std::regex_search(run.out, m, std::regex(R"(median distance ([0-9.]+) mm)"))) << run.out;
  EXPECT_GT(std::stod(m[1]), 2.0) << run.out;
  // Let free from the centimetre guess, the scale shrinks the scan about 3 times onto a part of
  // Cranium's skin (a head 27 mm tall), where the residual alone passed (73 % within 3 mm,
  // median 0.85 mm): the scale's move refuses it.
  const auto free_scale = caps_test::caps(cat("model register ", scan.string(), " --to ",
                                              fv.output, " --estimate-scale -o ", out.string()));
  EXPECT_EQ(free_scale.code, 2) << free_scale.out;
  EXPECT_NE(free_scale.out.find("scale estimate moved from 10 to"), std::string::npos)
      << free_scale.out;
  EXPECT_FALSE(fs::exists(out));
}
