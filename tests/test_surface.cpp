// The surface module: the patient-model API (sampling, frames, seam and poles), picking against a
// brute-force reference and analytic shapes, and scan import (the phantom's skin reproduces the
// volume path; the Lee Perry-Smith scan comes out upright, facing theta = 0).
#include <gtest/gtest.h>

#include "synthetic_model.hpp"

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>

#include <sys/stat.h>
#include <unistd.h>

#include "caps/core/error.hpp"
#include "caps/core/units.hpp"
#include "caps/surface/patient_model.hpp"
#include "caps/surface/picking.hpp"
#include "caps/surface/range_mesh.hpp"
#include "caps/surface/scan_io.hpp"
#include "caps/surface/scan_model.hpp"
#include "caps/volume/isosurface.hpp"
#include "caps/volume/model.hpp"
#include "caps/volume/phantom.hpp"

namespace fs = std::filesystem;
using namespace caps;

namespace {

// Maps of an analytic surface r = R(theta [rad], z) about the LPS z axis through `origin`.
template <typename Radius>
CylindricalMaps analytic_maps(Radius&& R, int n_theta, int n_z, double z0, double dz,
                              Eigen::Vector3d origin = {0, 0, 0}) {
  CylindricalMaps m = caps_test::synthetic_maps(
      caps_test::grid(n_theta, n_z, z0, dz),
      [&](double theta_deg, double z) { return R(deg_to_rad(theta_deg), z); },
      [](double, double) { return 5.0; });
  m.axis.origin_lps = origin;
  return m;
}

// A sphere of radius 90 mm about the origin, sampled as a range image (poles excluded).
CylindricalMaps sphere_maps(int n_theta = 512, int n_z = 256) {
  const double a = 85.0;
  return analytic_maps([](double, double z) { return std::sqrt(90.0 * 90.0 - z * z); }, n_theta,
                       n_z, -a, 2 * a / (n_z - 1));
}

}  // namespace

TEST(PatientModel, BilinearSamplingIsExactOnSamplesAndPeriodicAcrossTheSeam) {
  auto maps = analytic_maps([](double th, double z) { return 80 + 5 * std::cos(th) + 0.1 * z; },
                            64, 16, -30, 4);
  const PatientModel model(maps);
  const auto& g = model.grid();
  EXPECT_NEAR(model.r_skin(g.theta_deg(5), g.z_mm(3)), maps.r_skin[g.index(5, 3)], 1e-5);
  // Across the seam (between the last column and the first) the value is the mean of both.
  const double last = g.theta_deg(g.n_theta - 1), half = last + 0.5 * g.dtheta_deg();
  const double expect = 0.5 * (maps.r_skin[g.index(g.n_theta - 1, 2)] + maps.r_skin[g.index(0, 2)]);
  EXPECT_NEAR(model.r_skin(half, g.z_mm(2)), expect, 1e-5);
  EXPECT_NEAR(model.r_skin(half - 360.0, g.z_mm(2)), expect, 1e-5);
  EXPECT_NEAR(model.r_skin(179.99, 0), model.r_skin(-180.01, 0), 1e-3);
  // z outside the grid is clamped to the end rows and reported by has_z().
  EXPECT_FALSE(model.has_z(g.z0_mm - 1));
  EXPECT_NEAR(model.r_skin(0, g.z0_mm - 50), model.r_skin(0, g.z0_mm), 1e-9);
  EXPECT_NEAR(model.thickness(10, 0), 5.0, 1e-6);
  EXPECT_NEAR(model.r_bone(10, 0), model.r_skin(10, 0) - 5.0, 1e-5);
}

TEST(PatientModel, FrameConversionsRoundTripAndFollowTheConvention) {
  const PatientModel model(sphere_maps(64, 32));
  // theta = 0 is anterior (LPS -y), +90 the patient's left (LPS +x).
  EXPECT_TRUE(model.to_lps(0, 0, 10).isApprox(Eigen::Vector3d(0, -10, 0), 1e-12));
  EXPECT_TRUE(model.to_lps(90, 5, 10).isApprox(Eigen::Vector3d(10, 0, 5), 1e-12));
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> th(-180, 180), z(-80, 80), r(1, 120);
  for (int i = 0; i < 100; ++i) {
    const CylindricalPoint c{th(rng), z(rng), r(rng)};
    const CylindricalPoint back = model.to_cylindrical(model.to_lps(c));
    EXPECT_NEAR(back.theta_deg, c.theta_deg, 1e-9);
    EXPECT_NEAR(back.z_mm, c.z_mm, 1e-9);
    EXPECT_NEAR(back.r_mm, c.r_mm, 1e-9);
  }
}

TEST(PatientModel, SkinNormalOfSphereAndCylinderIsRadial) {
  const PatientModel sphere(sphere_maps());
  for (double th : {-179.9, -90.0, 0.0, 37.0, 179.9})
    for (double z : {-60.0, 0.0, 45.0}) {
      const Eigen::Vector3d p = sphere.skin_point(th, z);
      EXPECT_NEAR(p.norm(), 90.0, 0.02);
      EXPECT_GT(sphere.skin_normal(th, z).dot(p.normalized()), 0.9999) << th << " " << z;
    }
  const PatientModel cyl(analytic_maps([](double, double) { return 70.0; }, 128, 16, 0, 5));
  const Eigen::Vector3d n = cyl.skin_normal(90, 30);
  EXPECT_TRUE(n.isApprox(Eigen::Vector3d(1, 0, 0), 1e-9));
}

TEST(RangeMesh, OneQuadPerFourSamplesClosedAtTheSeamAndPoles) {
  const auto maps = sphere_maps(32, 8);
  const TriMesh open = range_mesh(maps, RangeSurface::Skin, {false});
  EXPECT_EQ(open.n_vertices(), 32 * 8);
  EXPECT_EQ(open.n_faces(), 2 * 32 * 7);
  const TriMesh closed = range_mesh(maps);
  EXPECT_TRUE(is_closed_manifold(closed));
  EXPECT_GT(mesh_volume(closed), 0.0);  // outward normals
  EXPECT_EQ(range_mesh_cell(maps.grid, 2 * (3 * 32 + 5) + 1), Eigen::Vector2i(5, 3));
  EXPECT_EQ(range_mesh_cell(maps.grid, open.n_faces()), Eigen::Vector2i(-1, -1));
}

TEST(Picking, AgreesWithBruteForceOnRandomRays) {
  auto maps = analytic_maps(
      [](double th, double z) { return 80 + 8 * std::cos(3 * th) * std::cos(z / 20) + 10 * std::exp(-th * th * 20); },
      128, 64, -90, 180.0 / 63);
  const TriMesh mesh = range_mesh(maps);
  const MeshRayCaster caster(mesh);
  std::mt19937 rng(7);
  std::normal_distribution<double> n(0, 1);
  int hits = 0;
  for (int i = 0; i < 300; ++i) {
    Eigen::Vector3d o(n(rng), n(rng), n(rng));
    o = o.normalized() * 300;
    const Eigen::Vector3d target(20 * n(rng), 20 * n(rng), 60 * n(rng));
    const Ray ray{o, target - o};
    const auto fast = caster.first_hit(ray);
    const auto slow = first_hit_brute_force(mesh, ray);
    ASSERT_EQ(fast.has_value(), slow.has_value()) << i;
    if (!fast) continue;
    ++hits;
    EXPECT_NEAR(fast->t, slow->t, 1e-9) << i;
    EXPECT_LT((fast->point - slow->point).norm(), 1e-6);
  }
  EXPECT_GT(hits, 150);
}

TEST(Picking, TrianglesWithoutAreaAreNotHit) {
  // A unit square in z = 0 split into faces 0 and 1, and face 2 collapsed onto the segment
  // (0.2, 0.5, 1) - (0.8, 0.5, 1) above it (as a closed wound's fill is).
  TriMesh m;
  m.V.resize(6, 3);
  m.V << 0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0, 0.2, 0.5, 1, 0.8, 0.5, 1;
  m.F.resize(3, 3);
  m.F << 0, 1, 2, 0, 2, 3, 4, 5, 5;
  const MeshRayCaster caster(m);
  const Ray down{{0.7, 0.5, 5}, {0, 0, -1}};  // through the segment, then face 0
  const auto h = caster.first_hit(down);
  ASSERT_TRUE(h);
  EXPECT_EQ(h->face, 0);
  EXPECT_NEAR(h->t, 5.0, 1e-12);
  ASSERT_EQ(caster.all_hits(down).size(), 1u);
  EXPECT_EQ(first_hit_brute_force(m, down)->face, 0);
  // faces keep their indices in the mesh when one is left out
  const auto right = caster.first_hit({{0.9, 0.2, 5}, {0, 0, -1}});
  ASSERT_TRUE(right);
  EXPECT_EQ(right->face, 0);
  EXPECT_EQ(caster.first_hit({{0.1, 0.8, 5}, {0, 0, -1}})->face, 1);
  // a mesh of only such triangles is never hit
  TriMesh flat = m;
  flat.F = m.F.bottomRows(1);
  EXPECT_FALSE(MeshRayCaster(flat).first_hit(down));
}

TEST(Picking, SphereAndCylinderMatchAnalyticIntersections) {
  const PatientModel sphere(sphere_maps());
  const SkinPicker picker(sphere);
  std::mt19937 rng(11);
  std::normal_distribution<double> n(0, 1);
  for (int i = 0; i < 200; ++i) {
    Eigen::Vector3d o(n(rng), n(rng), 0.3 * n(rng));
    o = o.normalized() * 400;
    Eigen::Vector3d d = -o.normalized() + 0.1 * Eigen::Vector3d(n(rng), n(rng), n(rng));
    d.normalize();
    // |o + t d| = 90: t = -o.d - sqrt((o.d)^2 - |o|^2 + 90^2).
    const double b = o.dot(d), disc = b * b - o.squaredNorm() + 90.0 * 90.0;
    const SkinHit h = picker.pick({o, d});
    if (disc <= 0) continue;
    const double t = -b - std::sqrt(disc);
    const Eigen::Vector3d p = o + t * d;
    if (std::abs(p[2]) > 80) continue;  // beyond the sampled rows
    ASSERT_TRUE(h.hit) << i;
    // The polyhedron lies inside the sphere by at most the chord sag of a cell (~0.03 mm).
    EXPECT_NEAR(h.distance_mm, t, 0.1) << i;
    EXPECT_NEAR(h.z_mm, p[2], 0.1);
    const double th = rad_to_deg(std::atan2(p[0], -p[1]));
    EXPECT_NEAR(std::remainder(h.theta_deg - th, 360.0), 0.0, 0.1);
    EXPECT_FALSE(h.on_pole_cap);
  }
  // A ray that passes beside the sphere misses.
  EXPECT_FALSE(picker.pick({{0, -400, 0}, {1, 0, 0}}).hit);
  EXPECT_FALSE(picker.pick({{200, -400, 0}, {0, 1, 0}}).hit);
  // A cylinder r = 70 mm: horizontal rays toward the axis meet it at r = 70 (on a sample column
  // exactly; between columns within the chord sag 70 (1 - cos(dtheta / 2)) ~ 0.005 mm).
  const PatientModel cyl(analytic_maps([](double, double) { return 70.0; }, 256, 32, -50, 100.0 / 31));
  const SkinPicker cp(cyl);
  for (double th : {0.0, 33.3, 90.0, -150.0, 179.5}) {
    const Eigen::Vector3d dir = cyl.axis().ray(deg_to_rad(th));
    const SkinHit h = cp.pick({Eigen::Vector3d(0, 0, 12.5) + 300 * dir, -dir});
    ASSERT_TRUE(h.hit);
    EXPECT_NEAR(h.distance_mm, 230.0, 0.01);
    EXPECT_NEAR(h.z_mm, 12.5, 1e-6);
    EXPECT_NEAR(std::remainder(h.theta_deg - th, 360.0), 0.0, 1e-6);
  }
  // From above along the axis: the pole cap closes the top row.
  const SkinHit top = cp.pick({{0.5, 0.5, 300}, {0, 0, -1}});
  ASSERT_TRUE(top.hit);
  EXPECT_TRUE(top.on_pole_cap);
  EXPECT_NEAR(top.lps[2], 50.0, 1e-6);
}

TEST(Picking, CameraRayThroughTheImageCentreHitsTheFace) {
  const PatientModel sphere(sphere_maps());
  const SkinPicker picker(sphere);
  // at (0, -600, 0) looking at the origin: the face
  const Camera cam = Camera::look_at({0, -600, 0}, {0, 0, 0}, {0, 0, 1}, 30, 640, 480);
  const SkinHit h = picker.pick(cam.ray(cam.width_px / 2.0, cam.height_px / 2.0));
  ASSERT_TRUE(h.hit);
  EXPECT_NEAR(h.theta_deg, 0.0, 1e-6);
  EXPECT_NEAR(h.distance_mm, 510.0, 0.01);
  // A pixel above the centre picks a higher point; one to the right the patient's left (+theta).
  EXPECT_GT(picker.pick(cam.ray(320, 200)).z_mm, 1.0);
  EXPECT_GT(picker.pick(cam.ray(360, 240)).theta_deg, 1.0);
}

TEST(Picking, NearestPlanPointAndOcclusion) {
  const PatientModel sphere(sphere_maps());
  const SkinPicker picker(sphere);
  Eigen::MatrixX3d pts(3, 3);
  pts << 1.0, -90.0, 0.0,   // on the face, 1 mm off the ray
      0.0, 90.0, 0.0,       // on the back: hidden behind the skin
      0.0, -90.0, 30.0;     // far from the ray
  const Ray ray{{0, -400, 0}, {0, 1, 0}};
  const PointPick p = picker.pick_point(pts, ray, 3.0);
  EXPECT_EQ(p.index, 0);
  EXPECT_NEAR(p.distance_to_ray_mm, 1.0, 1e-9);
  Eigen::MatrixX3d back(1, 3);
  back << 0.0, 90.0, 0.0;
  EXPECT_EQ(picker.pick_point(back, ray, 3.0).index, -1);
  EXPECT_EQ(pick_nearest_point(back, ray, 3.0).index, 0);  // without the occlusion test
}

TEST(ScanImport, FrameMappingIsAProperRotation) {
  const Eigen::Matrix3d R = scan_to_lps_rotation(parse_axis_name("+y", "--up"),
                                                 parse_axis_name("+z", "--front"));
  EXPECT_NEAR(R.determinant(), 1.0, 1e-12);
  EXPECT_TRUE((R * Eigen::Vector3d(0, 0, 1)).isApprox(Eigen::Vector3d(0, -1, 0)));  // face: anterior
  EXPECT_TRUE((R * Eigen::Vector3d(0, 1, 0)).isApprox(Eigen::Vector3d(0, 0, 1)));   // up: superior
  EXPECT_TRUE((R * Eigen::Vector3d(1, 0, 0)).isApprox(Eigen::Vector3d(1, 0, 0)));   // +x: left
  EXPECT_THROW(scan_to_lps_rotation(Eigen::Vector3d(0, 1, 0), Eigen::Vector3d(0, 1, 0)), InvalidInput);
  EXPECT_THROW(parse_axis_name("up", "--up"), InvalidInput);
  EXPECT_TRUE(parse_axis_name("1,0,-1", "--front").isApprox(Eigen::Vector3d(1, 0, -1).normalized()));
}

// The phantom's skin surface (the volume model's skin.ply) run through the scan path, with the
// volume model's axis and grid, reproduces the volume path's r_skin.
TEST(ScanModel, PhantomSkinMeshReproducesVolumeRSkin) {
  const Volume ct = make_phantom();
  const VolumeModel vm = build_volume_model(ct);
  ScanMesh scan;
  scan.mesh = vm.skin;  // LPS mm
  scan.source = "phantom skin.ply";
  scan.format = "PLY";
  ScanModelOptions o;
  o.thickness_mm = 6;
  o.up = {0, 0, 1};       // LPS superior
  o.front = {0, -1, 0};   // LPS anterior: the rotation is the identity
  o.mm_per_unit = 1.0;
  o.axis = vm.maps.axis;
  o.grid = vm.maps.grid;
  o.maps.n_theta = vm.maps.grid.n_theta;
  o.maps.n_z = vm.maps.grid.n_z;
  const ScanModel sm = build_scan_model(scan, o);
  EXPECT_TRUE(sm.rotation.isIdentity(1e-12));
  double sum = 0;
  std::size_t n = 0;
  for (std::size_t c = 0; c < sm.maps.grid.size(); ++c) {
    if (vm.maps.flags[c] & (kNoSkin | kUndercut | kGrazing | kTruncated)) continue;
    if (sm.maps.flags[c] & (kNoSkin | kUndercut | kGrazing | kTruncated)) continue;
    const double d = sm.maps.r_skin[c] - vm.maps.r_skin[c];
    sum += d * d;
    ++n;
  }
  ASSERT_GT(n, sm.maps.grid.size() / 2);
  const double rms = std::sqrt(sum / n);
  std::cout << "r_skin RMS scan vs volume path: " << rms << " mm over " << n << " cells\n";
  EXPECT_LT(rms, 0.2);
  // The constant thickness and its bone.
  EXPECT_NEAR(sm.stats.thickness_median_mm, 6.0, 1e-6);
  EXPECT_NEAR(sm.maps.r_bone[1000], sm.maps.r_skin[1000] - 6.0f, 1e-4);
  // The nose (the phantom's face) is found at theta = 0.
  EXPECT_NEAR(sm.stats.face_theta_deg, 0.0, 3.0);
}

TEST(ScanModel, WritesAFormatOneModelThatLoadsBack) {
  // A closed, textured 'head': the sphere's range mesh with a per-vertex colour ramp.
  ScanMesh scan;
  scan.mesh = range_mesh(sphere_maps(96, 48));
  scan.source = "sphere";
  scan.format = "PLY";
  scan.vertex_colors.resize(scan.mesh.n_vertices(), 3);
  for (Eigen::Index i = 0; i < scan.mesh.n_vertices(); ++i)
    scan.vertex_colors.row(i) << (scan.mesh.V(i, 0) > 0 ? 200 : 50), 100, 100;  // left red
  ScanModelOptions o;
  o.thickness_mm = 5;
  o.up = {0, 0, 1};
  o.front = {0, -1, 0};
  o.maps.n_theta = 128;
  o.maps.n_z = 64;
  const ScanModel sm = build_scan_model(scan, o);
  const fs::path dir = fs::temp_directory_path() / "caps_test_surface_model";
  fs::remove_all(dir);
  write_scan_model(sm, dir, false);
  EXPECT_THROW(write_scan_model(sm, dir, false), InvalidInput);
  const PatientModel model = PatientModel::load(dir);
  EXPECT_EQ(model.source_kind(), "scan");
  EXPECT_EQ(model.thickness_kind(), "constant");
  ASSERT_TRUE(model.has_color());
  EXPECT_GT(model.color_at(90, 0)[0], 0.7);   // the patient's left is red
  EXPECT_LT(model.color_at(-90, 0)[0], 0.3);
  EXPECT_NEAR(model.r_skin(0, 0), 90.0, 0.1);
  EXPECT_NEAR(model.thickness(45, 10), 5.0, 1e-5);
  EXPECT_TRUE(fs::exists(dir / "color.png"));
  fs::remove_all(dir);
}

TEST(ScanModel, BadScansAreRefusedWithAReason) {
  ScanMesh s;
  s.source = "bad";
  s.format = "PLY";
  s.mesh = range_mesh(sphere_maps(32, 16));
  ScanModelOptions o;
  o.thickness_mm = 5;
  o.up = {0, 0, 1};
  o.front = {0, -1, 0};
  auto message = [&](const ScanMesh& m, const ScanModelOptions& opt) {
    try {
      build_scan_model(m, opt);
    } catch (const InvalidInput& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  ScanMesh inside_out = s;
  inside_out.mesh.F.col(1).swap(inside_out.mesh.F.col(2));
  EXPECT_NE(message(inside_out, o).find("inside-out"), std::string::npos);
  ScanMesh nan = s;
  nan.mesh.V(3, 1) = std::nan("");
  EXPECT_NE(message(nan, o).find("non-finite"), std::string::npos);
  ScanMesh none = s;
  none.mesh.F.resize(0, 3);
  EXPECT_NE(message(none, o).find("no faces"), std::string::npos);
  ScanMesh fin = s;  // a fin: a third face on an existing edge
  fin.mesh.F.conservativeResize(fin.mesh.F.rows() + 1, 3);
  fin.mesh.F.bottomRows(1) << fin.mesh.F(0, 0), fin.mesh.F(0, 1), fin.mesh.n_vertices() - 1;
  EXPECT_NE(message(fin, o).find("non-manifold"), std::string::npos);
  ScanModelOptions metres = o;
  metres.mm_per_unit = 1000.0;
  EXPECT_NE(message(s, metres).find("--head-height-mm"), std::string::npos);
  ScanModelOptions tiny = o;
  tiny.mm_per_unit = 0.01;
  EXPECT_NE(message(s, tiny).find("--scale"), std::string::npos);
  ScanModelOptions thick = o;
  thick.thickness_mm = 0;
  EXPECT_NE(message(s, thick).find("--thickness"), std::string::npos);
}

TEST(ScanModel, LeePerrySmithIsUprightAndFacesThetaZero) {
  const fs::path dir = fs::path(CAPS_SHARED_DATA) / "scan" / "leeperrysmith";
  if (!fs::exists(dir / "LeePerrySmith.glb")) GTEST_SKIP() << "no shared scan data";
  ScanReadOptions ro;
  ro.texture = dir / "Map-COL.jpg";
  ro.flip_v = true;
  const ScanMesh scan = read_scan_mesh(dir / "LeePerrySmith.glb", ro);
  EXPECT_EQ(scan.texture.width, 1024);
  ScanModelOptions o;
  o.thickness_mm = 6;
  o.head_height_mm = 230;
  o.maps.n_theta = 256;
  o.maps.n_z = 128;
  const ScanModel sm = build_scan_model(scan, o);
  EXPECT_NEAR(sm.height_mm, 230, 1e-6);
  EXPECT_NEAR(sm.stats.face_theta_deg, 0.0, 6.0);  // the nose, at the front
  // The nose is above the neck cut and below the top of the head.
  const auto& g = sm.maps.grid;
  EXPECT_GT(sm.stats.face_z_mm, g.z0_mm + 0.4 * (g.n_z - 1) * g.dz_mm);
  // Skin colour at the forehead is skin-toned (red > blue), background where no skin is grey.
  const PatientModel model(sm.maps, sm.color);
  const Eigen::Vector3d forehead = model.color_at(0, sm.stats.face_z_mm + 50);
  EXPECT_GT(forehead[0], forehead[2] + 0.05);
  // Glb without a texture and without --texture: the model is built without colour.
  EXPECT_THROW(read_scan_mesh(dir / "missing.glb"), IoError);
  ScanReadOptions bad;
  bad.texture = dir / "no-such-texture.jpg";
  EXPECT_THROW(read_scan_mesh(dir / "LeePerrySmith.glb", bad), IoError);
}

// A .gltf's external buffer is read from the file it names beside it; a name that is a folder
// (fuzz_gltf: tinygltf's own reader sized the buffer from tellg()'s -1, an allocation of 2^63
// bytes) or a FIFO (its reader would wait for a writer) is refused with the file named.
TEST(ScanIo, AGltfsExternalBufferIsReadOnlyFromAFile) {
  const fs::path dir = fs::temp_directory_path() / ("caps_gltf_uri_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  // One triangle: (0,0,0), (0.01,0,0), (0,0.02,0) m.
  const float xyz[9] = {0, 0, 0, 0.01f, 0, 0, 0, 0.02f, 0};
  std::ofstream(dir / "tri.bin", std::ios::binary)
      .write(reinterpret_cast<const char*>(xyz), sizeof xyz);
  auto gltf = [&](const std::string& uri) {
    const fs::path p = dir / "scan.gltf";
    std::ofstream(p) << "{\"asset\": {\"version\": \"2.0\"}, \"scene\": 0, \"scenes\": [{\"nodes\": [0]}],"
                        " \"nodes\": [{\"mesh\": 0}], \"meshes\": [{\"primitives\": [{\"attributes\": "
                        "{\"POSITION\": 0}}]}], \"accessors\": [{\"bufferView\": 0, \"componentType\": 5126, "
                        "\"count\": 3, \"type\": \"VEC3\"}], \"bufferViews\": [{\"buffer\": 0, "
                        "\"byteLength\": 36}], \"buffers\": [{\"byteLength\": 36, \"uri\": \""
                     << uri << "\"}]}";
    return p;
  };
  const ScanMesh scan = read_scan_mesh(gltf("tri.bin"));
  ASSERT_EQ(scan.mesh.n_vertices(), 3);
  EXPECT_NEAR((scan.mesh.V.row(2) * scan.mm_per_unit).norm(), 20.0, 1e-4);  // mm
  fs::create_directories(dir / "data");
  ASSERT_EQ(::mkfifo((dir / "pipe").c_str(), 0600), 0);
  for (const std::string uri : {"data", "pipe", "missing.bin"}) {
    try {
      (void)read_scan_mesh(gltf(uri));
      ADD_FAILURE() << uri << " was read";
    } catch (const IoError& e) {
      EXPECT_NE(std::string(e.what()).find(uri), std::string::npos) << e.what();
    }
  }
  fs::remove_all(dir);
}

