// Isosurface extraction, Taubin smoothing, decimation, mesh statistics and PLY IO (volume module).
#include "caps/core/error.hpp"
#include "caps/core/units.hpp"
#include "caps/volume/isosurface.hpp"
#include "caps/volume/mesh_io.hpp"

#include <gtest/gtest.h>
#include <tbb/global_control.h>
#include <unistd.h>
#include <Eigen/Geometry>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <random>
#include <string>
#include <vector>

namespace fs = std::filesystem;
using caps::kPi;

namespace {

// A volume of `n` voxels per axis with the given geometry, filled with f(LPS position).
caps::Volume sample(const caps::VolumeGeometry& geom,
                    const std::function<float(const Eigen::Vector3d&)>& f) {
  caps::Volume v;
  v.geom = geom;
  v.source = "test";
  v.data.resize(geom.n_voxels());
  for (int k = 0; k < geom.dims[2]; ++k)
    for (int j = 0; j < geom.dims[1]; ++j)
      for (int i = 0; i < geom.dims[0]; ++i)
        v.at(i, j, k) = f(geom.index_to_lps(Eigen::Vector3d(i, j, k)));
  return v;
}

// Sphere SDF (positive inside) of radius r around c on an axis-aligned grid of spacing h that
// covers the sphere with a margin.
caps::Volume sphere_volume(double r, double h, const Eigen::Vector3d& c = Eigen::Vector3d::Zero()) {
  caps::VolumeGeometry g;
  const int n = int(std::ceil(2 * (r + 3 * h) / h)) + 1;
  g.dims = {n, n, n};
  g.spacing_mm = {h, h, h};
  g.origin_lps = c - Eigen::Vector3d::Constant(0.5 * (n - 1) * h);
  return sample(g, [&](const Eigen::Vector3d& p) { return float(r - (p - c).norm()); });
}

double max_radial_error(const caps::TriMesh& m, double r, const Eigen::Vector3d& c) {
  double e = 0;
  for (Eigen::Index v = 0; v < m.n_vertices(); ++v)
    e = std::max(e, std::abs((m.V.row(v).transpose() - c).norm() - r));
  return e;
}

double rms_radial_error(const caps::TriMesh& m, double r) {
  return std::sqrt((m.V.rowwise().norm().array() - r).square().mean());
}

fs::path temp_dir() {
  const fs::path d = fs::temp_directory_path() / ("caps_test_iso_" + std::to_string(::getpid()));
  fs::create_directories(d);
  return d;
}

void write_text(const fs::path& p, const std::string& s) {
  std::ofstream(p, std::ios::binary) << s;
}

}  // namespace

TEST(Isosurface, SphereAreaAndVolumeConvergeWithVoxelSize) {
  const double r = 10.0;
  const double area_exact = 4 * kPi * r * r, vol_exact = 4.0 / 3.0 * kPi * r * r * r;
  double prev_area_err = 1e9, prev_vol_err = 1e9;
  for (double h : {2.0, 1.0, 0.5, 0.25}) {
    const caps::TriMesh m = caps::extract_isosurface(sphere_volume(r, h), 0.0f);
    ASSERT_GT(m.n_faces(), 0);
    EXPECT_TRUE(caps::is_closed_manifold(m)) << "h = " << h;
    const double area_err = std::abs(caps::mesh_area(m) - area_exact) / area_exact;
    const double vol = caps::mesh_volume(m);
    const double vol_err = std::abs(vol - vol_exact) / vol_exact;
    EXPECT_GT(vol, 0.0) << "normals must point outwards";
    EXPECT_LT(area_err, prev_area_err) << "h = " << h;
    EXPECT_LT(vol_err, prev_vol_err) << "h = " << h;
    EXPECT_LT(max_radial_error(m, r, Eigen::Vector3d::Zero()), 0.1 * h) << "h = " << h;
    prev_area_err = area_err;
    prev_vol_err = vol_err;
  }
  EXPECT_LT(prev_area_err, 0.01);
  EXPECT_LT(prev_vol_err, 0.01);
}

TEST(Isosurface, LeftHandedDirectionAndOriginGivePositionsInLps) {
  const double r = 8.0;
  const Eigen::Vector3d c(31.0, -12.5, 140.0);
  caps::VolumeGeometry g;
  g.dims = {50, 46, 30};
  g.spacing_mm = {0.45, 0.5, 0.7};
  // A rotation composed with a mirror: det = -1.
  const Eigen::Matrix3d R =
      Eigen::AngleAxisd(0.4, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  g.direction = R * Eigen::Vector3d(1, -1, 1).asDiagonal();
  ASSERT_LT(g.direction.determinant(), 0);
  // Put the sphere centre at the middle of the grid.
  const Eigen::Vector3d mid = 0.5 * (g.dims.cast<double>() - Eigen::Vector3d::Ones());
  g.origin_lps = c - g.direction * g.spacing_mm.cwiseProduct(mid);
  const caps::Volume v =
      sample(g, [&](const Eigen::Vector3d& p) { return float(r - (p - c).norm()); });

  const caps::TriMesh m = caps::extract_isosurface(v, 0.0f);
  EXPECT_TRUE(caps::is_closed_manifold(m));
  const double vol_exact = 4.0 / 3.0 * kPi * r * r * r;
  EXPECT_NEAR(caps::mesh_volume(m), vol_exact, 0.02 * vol_exact) << "outward in LPS";
  EXPECT_LT(max_radial_error(m, r, c), 0.1 * 0.7);

  // The same grid with the mirror removed gives the same surface, so the same positive volume.
  caps::VolumeGeometry g2 = g;
  g2.direction = R;
  g2.origin_lps = c - g2.direction * g2.spacing_mm.cwiseProduct(mid);
  const caps::TriMesh m2 = caps::extract_isosurface(
      sample(g2, [&](const Eigen::Vector3d& p) { return float(r - (p - c).norm()); }), 0.0f);
  EXPECT_NEAR(caps::mesh_volume(m2), caps::mesh_volume(m), 1e-6 * vol_exact);
}

TEST(Isosurface, EveryCaseAndRandomFieldsGiveClosedManifolds) {
  // Each of the 256 cube configurations in the middle of an otherwise outside 4x4x4 grid.
  caps::Volume v;
  v.geom.dims = {4, 4, 4};
  for (int cs = 0; cs < 256; ++cs) {
    v.data.assign(64, -1.0f);
    for (int c = 0; c < 8; ++c)
      v.at(1 + (c & 1), 1 + ((c >> 1) & 1), 1 + (c >> 2)) = ((cs >> c) & 1) ? 1.0f : -1.0f;
    const caps::TriMesh m = caps::extract_isosurface(v, 0.0f);
    if (cs == 0) {
      EXPECT_EQ(m.n_faces(), 0);
      continue;
    }
    EXPECT_TRUE(caps::is_closed_manifold(m)) << "case " << cs;
    EXPECT_GT(caps::mesh_volume(m), 0.0) << "case " << cs;
  }
  // White noise exercises every pair of neighbouring configurations, ambiguous faces included.
  std::mt19937 rng(7);
  for (float density : {0.3f, 0.5f, 0.7f}) {
    std::uniform_real_distribution<float> U(0.0f, 1.0f);
    const int n = 40;
    v.geom.dims = {n, n, n};
    v.data.resize(n * n * n);
    for (int k = 0; k < n; ++k)
      for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) {
          const bool border = i == 0 || j == 0 || k == 0 || i == n - 1 || j == n - 1 || k == n - 1;
          v.at(i, j, k) = border ? -1.0f : U(rng) - (1.0f - density);
        }
    const caps::TriMesh m = caps::extract_isosurface(v, 0.0f);
    EXPECT_TRUE(caps::is_closed_manifold(m)) << "density " << density;
    EXPECT_GT(caps::mesh_volume(m), 0.0);
  }
}

TEST(Isosurface, OpenWhereTheSurfaceLeavesTheVolume) {
  caps::Volume v = sphere_volume(10.0, 1.0);
  for (int j = 0; j < v.geom.dims[1]; ++j)
    for (int i = 0; i < v.geom.dims[0]; ++i) v.at(i, j, 0) = 1.0f;  // inside on the bottom slice
  EXPECT_FALSE(caps::is_closed_manifold(caps::extract_isosurface(v, 0.0f)));
  EXPECT_EQ(caps::extract_isosurface(v, 1e6f).n_faces(), 0);
  EXPECT_THROW(caps::extract_isosurface(v, std::nanf("")), caps::InvalidInput);
}

TEST(Isosurface, ResultIndependentOfThreadCount) {
  const caps::Volume v = sphere_volume(20.0, 0.5, Eigen::Vector3d(1, 2, 3));
  const caps::TriMesh par = caps::extract_isosurface(v, 0.3f);
  caps::TriMesh seq;
  {
    tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
    seq = caps::extract_isosurface(v, 0.3f);
  }
  ASSERT_EQ(par.n_vertices(), seq.n_vertices());
  ASSERT_EQ(par.n_faces(), seq.n_faces());
  EXPECT_TRUE(par.V == seq.V);
  EXPECT_TRUE(par.F == seq.F);

  caps::TriMesh a = par, b = par;
  caps::smooth_taubin(a, 5);
  {
    tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
    caps::smooth_taubin(b, 5);
  }
  EXPECT_TRUE(a.V == b.V);
}

TEST(Taubin, KeepsSphereVolumeAndRemovesNoise) {
  const double r = 10.0;
  const caps::TriMesh clean = caps::extract_isosurface(sphere_volume(r, 0.5), 0.0f);
  const double vol0 = caps::mesh_volume(clean);

  caps::TriMesh smooth = clean;
  caps::smooth_taubin(smooth, 10);
  EXPECT_NEAR(caps::mesh_volume(smooth), vol0, 0.01 * vol0);
  EXPECT_TRUE(smooth.F == clean.F);

  caps::TriMesh noisy = clean;
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> U(-0.15, 0.15);
  for (Eigen::Index v = 0; v < noisy.n_vertices(); ++v) {
    const Eigen::Vector3d p = noisy.V.row(v);
    noisy.V.row(v) = (p.normalized() * (p.norm() + U(rng))).transpose();
  }
  const double before = max_radial_error(noisy, r, Eigen::Vector3d::Zero());
  const double rms_before = rms_radial_error(noisy, r);
  caps::smooth_taubin(noisy, 10);
  // Uniform weights damp the noise (rms falls ~2.5x) but a few vertices of near-degenerate
  // marching-cubes triangles keep part of theirs, so the maximum falls less.
  EXPECT_LT(max_radial_error(noisy, r, Eigen::Vector3d::Zero()), 0.9 * before);
  EXPECT_LT(rms_radial_error(noisy, r), 0.5 * rms_before);
  EXPECT_NEAR(caps::mesh_volume(noisy), vol0, 0.01 * vol0);

  EXPECT_THROW(caps::smooth_taubin(noisy, 10, 0.5, -0.4), caps::InvalidInput);
}

TEST(Decimate, KeepsClosedManifoldAndArea) {
  const caps::TriMesh m = caps::extract_isosurface(sphere_volume(10.0, 0.5), 0.0f);
  const caps::TriMesh d = caps::decimate(m, 0.2);
  EXPECT_NEAR(double(d.n_faces()), 0.2 * m.n_faces(), 0.02 * m.n_faces());
  EXPECT_TRUE(caps::is_closed_manifold(d));
  EXPECT_NEAR(caps::mesh_area(d), caps::mesh_area(m), 0.03 * caps::mesh_area(m));
  EXPECT_NEAR(caps::mesh_volume(d), caps::mesh_volume(m), 0.03 * caps::mesh_volume(m));
  EXPECT_THROW(caps::decimate(m, 0.0), caps::InvalidInput);
}

TEST(MeshStatistics, UnitCube) {
  caps::TriMesh cube;
  cube.V.resize(8, 3);
  for (int c = 0; c < 8; ++c) cube.V.row(c) << (c & 1), (c >> 1) & 1, c >> 2;
  cube.F.resize(12, 3);
  cube.F << 0, 2, 1, 1, 2, 3, 4, 5, 6, 5, 7, 6, 0, 1, 4, 1, 5, 4, 2, 6, 3, 3, 6, 7, 0, 4, 2, 2, 4,
      6, 1, 3, 5, 3, 7, 5;
  EXPECT_TRUE(caps::is_closed_manifold(cube));
  EXPECT_NEAR(caps::mesh_area(cube), 6.0, 1e-12);
  EXPECT_NEAR(caps::mesh_volume(cube), 1.0, 1e-12);
  caps::TriMesh open = cube;
  open.F.conservativeResize(11, 3);
  EXPECT_FALSE(caps::is_closed_manifold(open));
  caps::TriMesh flipped = cube;
  std::swap(flipped.F(0, 1), flipped.F(0, 2));
  EXPECT_FALSE(caps::is_closed_manifold(flipped));
}

TEST(Ply, BinaryRoundTripWithAndWithoutColours) {
  const fs::path dir = temp_dir();
  const caps::TriMesh m = caps::extract_isosurface(sphere_volume(5.0, 0.5, {100, -50, 20}), 0.0f);
  caps::write_ply(m, dir / "sphere.ply");
  const caps::TriMesh back = caps::read_ply(dir / "sphere.ply");
  ASSERT_EQ(back.n_vertices(), m.n_vertices());
  EXPECT_TRUE(back.F == m.F);
  EXPECT_LT((back.V - m.V).cwiseAbs().maxCoeff(), 1e-4);  // float storage
  std::ifstream in(dir / "sphere.ply", std::ios::binary);
  std::string header(300, '\0');
  in.read(header.data(), 300);
  EXPECT_NE(header.find("comment caps: units mm, frame LPS"), std::string::npos);
  EXPECT_NE(header.find("format binary_little_endian 1.0"), std::string::npos);

  Eigen::Matrix<std::uint8_t, Eigen::Dynamic, 3> rgb(m.n_vertices(), 3);
  rgb.setConstant(200);
  caps::write_ply(m, dir / "rgb.ply", &rgb);
  const caps::TriMesh back_rgb = caps::read_ply(dir / "rgb.ply");
  EXPECT_TRUE(back_rgb.F == m.F);
  EXPECT_LT((back_rgb.V - back.V).cwiseAbs().maxCoeff(), 1e-12);
  fs::remove_all(dir);
}

TEST(Ply, ReadsAsciiQuadsAndBigEndian) {
  const fs::path dir = temp_dir();
  write_text(dir / "cube.ply",
             "ply\r\nformat ascii 1.0\r\ncomment a unit cube of quads\r\nelement vertex 8\r\n"
             "property double x\r\nproperty double y\r\nproperty double z\r\nproperty uchar red\r\n"
             "element face 6\r\nproperty list uchar int vertex_indices\r\nend_header\r\n"
             "0 0 0 1\n1 0 0 1\n0 1 0 1\n1 1 0 1\n0 0 1 1\n1 0 1 1\n0 1 1 1\n1 1 1 1\n"
             "4 0 2 3 1\n4 4 5 7 6\n4 0 1 5 4\n4 2 6 7 3\n4 0 4 6 2\n4 1 3 7 5\n");
  const caps::TriMesh cube = caps::read_ply(dir / "cube.ply");
  EXPECT_EQ(cube.n_faces(), 12);
  EXPECT_TRUE(caps::is_closed_manifold(cube));
  EXPECT_NEAR(caps::mesh_volume(cube), 1.0, 1e-12);

  // One triangle, big-endian, with double coordinates and a uint vertex list.
  std::string be =
      "ply\nformat binary_big_endian 1.0\nelement vertex 3\nproperty double x\n"
      "property double y\nproperty double z\nelement face 1\n"
      "property list uchar uint vertex_indices\nend_header\n";
  auto put_be = [&](auto v) {
    char b[sizeof(v)];
    std::memcpy(b, &v, sizeof(v));
    for (int q = int(sizeof(v)) - 1; q >= 0; --q) be.push_back(b[q]);
  };
  const double xyz[9] = {0, 0, 0, 2, 0, 0, 0, 3, 0};
  for (double x : xyz) put_be(x);
  be.push_back(3);
  for (std::uint32_t i : {0u, 1u, 2u}) put_be(i);
  write_text(dir / "be.ply", be);
  const caps::TriMesh tri = caps::read_ply(dir / "be.ply");
  ASSERT_EQ(tri.n_faces(), 1);
  EXPECT_NEAR(caps::mesh_area(tri), 3.0, 1e-12);
  fs::remove_all(dir);
}

TEST(Ply, ReadsColoursAndTextureCoordinatesInEveryEncoding) {
  const fs::path dir = temp_dir();
  // Two triangles sharing an edge; per vertex: float x y z, uchar red green blue, float s t
  // (the scanner names), plus a property the reader must skip.
  const float xyz[4][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};
  const std::uint8_t rgb[4][3] = {{255, 0, 0}, {0, 255, 0}, {0, 0, 255}, {10, 20, 30}};
  const float st[4][2] = {{0, 0}, {1, 0}, {1, 1}, {0, 0.5f}};
  const std::string header =
      "element vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
      "property uchar red\nproperty uchar green\nproperty uchar blue\nproperty float s\n"
      "property float t\nproperty short quality\nelement face 2\n"
      "property list uchar int vertex_indices\nend_header\n";
  auto binary = [&](bool big) {
    std::string b = std::string("ply\nformat ") +
                    (big ? "binary_big_endian" : "binary_little_endian") + " 1.0\n" + header;
    auto put = [&](auto v) {
      char bytes[sizeof(v)];
      std::memcpy(bytes, &v, sizeof(v));
      if (big) std::reverse(bytes, bytes + sizeof(v));  // the test machine is little-endian
      b.append(bytes, sizeof(v));
    };
    for (int v = 0; v < 4; ++v) {
      for (float x : xyz[v]) put(x);
      for (std::uint8_t c : rgb[v]) put(c);
      for (float x : st[v]) put(x);
      put(std::int16_t(-7));
    }
    for (const auto& f : {std::array<std::int32_t, 3>{0, 1, 2}, std::array<std::int32_t, 3>{0, 2, 3}}) {
      put(std::uint8_t(3));
      for (std::int32_t i : f) put(i);
    }
    return b;
  };
  std::string ascii = "ply\nformat ascii 1.0\n" + header;
  for (int v = 0; v < 4; ++v)
    ascii += caps::cat(xyz[v][0], " ", xyz[v][1], " ", xyz[v][2], " ", int(rgb[v][0]), " ",
                       int(rgb[v][1]), " ", int(rgb[v][2]), " ", st[v][0], " ", st[v][1], " -7\n");
  ascii += "3 0 1 2\n3 0 2 3\n";
  write_text(dir / "be.ply", binary(true));
  write_text(dir / "le.ply", binary(false));
  write_text(dir / "ascii.ply", ascii);
  for (const char* name : {"be.ply", "le.ply", "ascii.ply"}) {
    SCOPED_TRACE(name);
    const caps::PlyMesh ply = caps::read_ply_with_attributes(dir / name);
    ASSERT_EQ(ply.mesh.n_vertices(), 4);
    ASSERT_EQ(ply.mesh.n_faces(), 2);
    EXPECT_NEAR(caps::mesh_area(ply.mesh), 1.0, 1e-12);
    ASSERT_EQ(ply.colors.rows(), 4);
    ASSERT_EQ(ply.uv.rows(), 4);
    for (int v = 0; v < 4; ++v)
      for (int c = 0; c < 3; ++c) {
        EXPECT_EQ(ply.mesh.V(v, c), xyz[v][c]);
        EXPECT_EQ(ply.colors(v, c), rgb[v][c]);
        if (c < 2) EXPECT_EQ(ply.uv(v, c), st[v][c]);
      }
  }
  // Without colour or texture properties the attributes are empty; float colours in [0, 1]
  // are scaled to bytes.
  write_text(dir / "plain.ply",
             "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
             "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
             "end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
  const caps::PlyMesh plain = caps::read_ply_with_attributes(dir / "plain.ply");
  EXPECT_EQ(plain.colors.rows(), 0);
  EXPECT_EQ(plain.uv.rows(), 0);
  write_text(dir / "unit.ply",
             "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
             "property float z\nproperty float r\nproperty float g\nproperty float b\n"
             "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
             "0 0 0 1 0.5 0\n1 0 0 0 0 0\n0 1 0 2 -1 0\n3 0 1 2\n");
  const caps::PlyMesh unit = caps::read_ply_with_attributes(dir / "unit.ply");
  ASSERT_EQ(unit.colors.rows(), 3);
  EXPECT_EQ(unit.colors(0, 0), 255);
  EXPECT_EQ(unit.colors(0, 1), 127);  // 127.5 truncated
  EXPECT_EQ(unit.colors(2, 0), 255);  // clamped
  EXPECT_EQ(unit.colors(2, 1), 0);
  fs::remove_all(dir);
}

TEST(Ply, BadFilesThrowTheRightErrorNamingTheFile) {
  const fs::path dir = temp_dir();
  const std::string head =
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
      "property float z\n";
  auto expect_error = [&](const std::string& file, const std::string& text, auto error_type) {
    write_text(dir / file, text);
    try {
      caps::read_ply(dir / file);
      ADD_FAILURE() << file << " was accepted";
    } catch (const decltype(error_type)& e) {
      EXPECT_NE(std::string(e.what()).find(file), std::string::npos) << e.what();
    } catch (const std::exception& e) {
      ADD_FAILURE() << file << ": wrong error type: " << e.what();
    }
  };
  expect_error("no_faces.ply",
               head +
                   "element face 0\nproperty list uchar int vertex_indices\n"
                   "end_header\n0 0 0\n1 0 0\n0 1 0\n",
               caps::InvalidInput(""));
  expect_error("points.ply", head + "end_header\n0 0 0\n1 0 0\n0 1 0\n", caps::InvalidInput(""));
  expect_error("nan.ply",
               head +
                   "element face 1\nproperty list uchar int vertex_indices\n"
                   "end_header\n0 0 0\nnan 0 0\n0 1 0\n3 0 1 2\n",
               caps::InvalidInput(""));
  expect_error("bad_index.ply",
               head +
                   "element face 1\nproperty list uchar int vertex_indices\n"
                   "end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n",
               caps::InvalidInput(""));
  expect_error("not_ply.ply", "solid stl\n", caps::InvalidInput(""));
  // An element of another name claiming far more items than bytes follow (it was read item by
  // item until the data ran out) and one without properties claiming 4e17 items (fuzz_ply: it
  // looped for ever over nothing; it holds no data, so the mesh around it reads).
  expect_error("lying_other.ply",
               head + "element extra 433333333333333330\nproperty uchar flag\n"
                      "element face 1\nproperty list uchar int vertex_indices\n"
                      "end_header\n0 0 0\n1 0 0\n0 1 0\n1\n3 0 1 2\n",
               caps::IoError(""));
  write_text(dir / "empty_element.ply",
             head + "element nothing 433333333333333330\nelement face 1\n"
                    "property list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n"
                    "3 0 1 2\n");
  EXPECT_EQ(caps::read_ply(dir / "empty_element.ply").n_faces(), 1);

  // A binary file cut in the middle of the face list.
  const caps::TriMesh m = caps::extract_isosurface(sphere_volume(4.0, 1.0), 0.0f);
  caps::write_ply(m, dir / "full.ply");
  std::ifstream in(dir / "full.ply", std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  expect_error("truncated.ply", bytes.substr(0, bytes.size() - 20), caps::IoError(""));
  expect_error("truncated_header.ply", bytes.substr(0, 40), caps::IoError(""));
  EXPECT_THROW(caps::read_ply(dir / "missing.ply"), caps::IoError);
  fs::remove_all(dir);
}
