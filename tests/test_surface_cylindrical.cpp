// Cyberware-style cylindrical range images: export and import round trip, image layouts, and
// bad inputs.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>

#include "caps/core/error.hpp"
#include "caps/surface/cylindrical_scan.hpp"
#include "caps/surface/scan_model.hpp"
#include "caps/volume/model.hpp"
#include "caps/volume/phantom.hpp"

namespace fs = std::filesystem;
using namespace caps;

namespace {

fs::path temp_dir(const std::string& name) {
  const fs::path d = fs::temp_directory_path() / ("caps_cyl_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

void write_grey16(const fs::path& p, int w, int h, const std::vector<std::uint16_t>& v) {
  write_grey16_png(p, GreyImage{w, h, v});
}

const VolumeModel& phantom_model() {
  static const VolumeModel m = [] {
    PhantomOptions po;
    po.dims = {128, 128, 120};
    po.spacing_mm = {2, 2, 2};
    ModelOptions o;
    o.maps.n_theta = 128;
    o.maps.n_z = 64;
    return build_volume_model(make_phantom(po), o);
  }();
  return m;
}

}  // namespace

TEST(CylindricalScan, ExportImportRoundTripKeepsTheSkin) {
  const auto& vm = phantom_model();
  const PatientModel model(vm.maps);
  const fs::path dir = temp_dir("roundtrip");
  const fs::path sidecar = write_cylindrical_scan(model, dir, 0.01);
  const CylindricalScanSpec spec = read_cylindrical_sidecar(sidecar);
  const ScanMesh scan = cylindrical_scan_mesh(spec);
  EXPECT_EQ(scan.format, "cylindrical range image");
  // The same cylinder: the file's height 0 is the top row; theta 0 is the first column.
  const auto& g = vm.maps.grid;
  ScanModelOptions o;
  o.thickness_mm = 6;
  o.mm_per_unit = 1;
  o.maps.n_theta = g.n_theta;
  o.maps.n_z = g.n_z;
  CylinderAxis axis;
  axis.origin_lps = {0, 0, 0};
  o.axis = axis;
  o.grid = g;  // the sidecar's top_z_mm keeps z in the model's frame
  const ScanModel sm = build_scan_model(scan, o);
  double se = 0;
  int n = 0;
  for (int k = 1; k + 1 < g.n_z; ++k)
    for (int j = 0; j < g.n_theta; ++j) {
      const std::size_t c = g.index(j, k);
      if (!vm.maps.measured_skin[c] || vm.maps.flags[c] || sm.maps.flags[c]) continue;
      se += std::pow(sm.maps.r_skin[c] - vm.maps.r_skin[c], 2);
      ++n;
    }
  ASSERT_GT(n, g.size() / 2);
  // The rays pass through the samples, so only the 0.01 mm quantisation remains.
  EXPECT_LT(std::sqrt(se / n), 0.01);
  EXPECT_NEAR(sm.maps.r_skin[g.index(g.n_theta / 4, g.n_z / 2)],
              vm.maps.r_skin[g.index(g.n_theta / 4, g.n_z / 2)], 0.01);
  fs::remove_all(dir);
}

TEST(CylindricalScan, LayoutsDescribeTheSameSurface) {
  // A 32 (theta) x 16 (z) image of r = 70 + j mm, stored four ways.
  const int nt = 32, nz = 16;
  auto value = [&](int t, int h) { return static_cast<std::uint16_t>(700 + 10 * t + h); };
  const fs::path dir = temp_dir("layouts");
  std::vector<std::uint16_t> cols(nt * nz), rows(nt * nz), flipped(nt * nz);
  for (int h = 0; h < nz; ++h)
    for (int t = 0; t < nt; ++t) {
      cols[h * nt + t] = value(t, h);                        // theta across, top first
      rows[t * nz + h] = value(t, h);                        // theta down, top first
      flipped[(nz - 1 - h) * nt + (nt - 1 - t)] = value(t, h);  // reversed theta, bottom first
    }
  write_grey16(dir / "cols.png", nt, nz, cols);
  write_grey16(dir / "rows.png", nz, nt, rows);
  write_grey16(dir / "flipped.png", nt, nz, flipped);
  CylindricalScanSpec a;
  a.r_scale_mm = 0.1;
  a.z_scale_mm = 2;
  a.range = dir / "cols.png";
  CylindricalScanSpec b = a;
  b.range = dir / "rows.png";
  b.theta_along_rows = true;
  CylindricalScanSpec c = a;
  c.range = dir / "flipped.png";
  c.theta_reverse = true;
  c.top_first = false;
  const ScanMesh ma = cylindrical_scan_mesh(a), mb = cylindrical_scan_mesh(b), mc = cylindrical_scan_mesh(c);
  ASSERT_EQ(ma.mesh.n_vertices(), nt * nz);
  EXPECT_EQ(ma.mesh.n_faces(), 2 * nt * (nz - 1));  // closed in theta: 360 degrees
  // The same vertex set (sorted by position).
  auto sorted = [](const Eigen::MatrixX3d& V) {
    std::vector<std::array<double, 3>> v;
    for (Eigen::Index i = 0; i < V.rows(); ++i) v.push_back({V(i, 0), V(i, 1), V(i, 2)});
    std::sort(v.begin(), v.end());
    return v;
  };
  const auto sa = sorted(ma.mesh.V), sb = sorted(mb.mesh.V), sc = sorted(mc.mesh.V);
  for (std::size_t i = 0; i < sa.size(); ++i)
    for (int d = 0; d < 3; ++d) {
      EXPECT_NEAR(sa[i][d], sb[i][d], 1e-9);
      EXPECT_NEAR(sa[i][d], sc[i][d], 1e-9);
    }
  // theta = 0 (first column) looks along +z, theta = 90 degrees (column 8) along +x.
  EXPECT_NEAR(ma.mesh.V(0, 2), 70.0, 1e-9);
  EXPECT_NEAR(ma.mesh.V(0, 0), 0.0, 1e-9);
  EXPECT_NEAR(ma.mesh.V(8, 0), 78.0, 1e-9);
  // Faces point away from the axis.
  for (Eigen::Index f = 0; f < ma.mesh.n_faces(); ++f) {
    const Eigen::Vector3d p0 = ma.mesh.V.row(ma.mesh.F(f, 0)), p1 = ma.mesh.V.row(ma.mesh.F(f, 1)),
                          p2 = ma.mesh.V.row(ma.mesh.F(f, 2));
    const Eigen::Vector3d n = (p1 - p0).cross(p2 - p0);
    const Eigen::Vector3d centre = (p0 + p1 + p2) / 3.0;
    ASSERT_GT(n.dot(Eigen::Vector3d(centre.x(), 0, centre.z())), 0) << "face " << f;
  }
  fs::remove_all(dir);
}

TEST(CylindricalScan, BadInputsAreRefused) {
  const fs::path dir = temp_dir("bad");
  write_grey16(dir / "r.png", 8, 4, std::vector<std::uint16_t>(32, 800));
  CylindricalScanSpec s;
  s.range = dir / "r.png";
  s.r_scale_mm = 0.1;
  s.z_scale_mm = 1;
  EXPECT_NO_THROW(cylindrical_scan_mesh(s));
  CylindricalScanSpec bad = s;
  bad.r_scale_mm = 0;
  EXPECT_THROW(cylindrical_scan_mesh(bad), InvalidInput);
  bad = s;
  bad.z_scale_mm = -1;
  EXPECT_THROW(cylindrical_scan_mesh(bad), InvalidInput);
  bad = s;
  bad.theta_span_deg = 400;
  EXPECT_THROW(cylindrical_scan_mesh(bad), InvalidInput);
  // Every sample void.
  write_grey16(dir / "void.png", 8, 4, std::vector<std::uint16_t>(32, 0));
  bad = s;
  bad.range = dir / "void.png";
  EXPECT_THROW(cylindrical_scan_mesh(bad), InvalidInput);
  // A colour image of another size.
  write_grey16(dir / "other.png", 4, 4, std::vector<std::uint16_t>(16, 1));
  bad = s;
  bad.color = dir / "other.png";
  try {
    cylindrical_scan_mesh(bad);
    FAIL();
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("layout"), std::string::npos);
  }
  // A colour PNG given as the range image; a truncated PNG; a missing file.
  write_png(dir / "rgb.png", RgbImage{4, 4, std::vector<std::uint8_t>(48, 100)});
  bad = s;
  bad.range = dir / "rgb.png";
  EXPECT_THROW(cylindrical_scan_mesh(bad), InvalidInput);
  {
    std::ifstream in(dir / "r.png", std::ios::binary);
    std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    std::ofstream(dir / "cut.png", std::ios::binary) << bytes.substr(0, bytes.size() / 2);
  }
  bad = s;
  bad.range = dir / "cut.png";
  EXPECT_THROW(cylindrical_scan_mesh(bad), IoError);
  bad.range = dir / "missing.png";
  EXPECT_THROW(cylindrical_scan_mesh(bad), IoError);
  // Sidecars: missing field, wrong type, bad layout name.
  std::ofstream(dir / "a.json") << R"({"r_scale_mm": 0.1, "z_scale_mm": 1})";
  EXPECT_THROW(read_cylindrical_sidecar(dir / "a.json"), InvalidInput);
  std::ofstream(dir / "b.json") << R"({"range": "r.png", "r_scale_mm": "x", "z_scale_mm": 1})";
  EXPECT_THROW(read_cylindrical_sidecar(dir / "b.json"), InvalidInput);
  std::ofstream(dir / "c.json") << R"({"range": "r.png", "r_scale_mm": 0.1, "z_scale_mm": 1, "theta_axis": "diagonal"})";
  EXPECT_THROW(read_cylindrical_sidecar(dir / "c.json"), InvalidInput);
  std::ofstream(dir / "d.json") << R"({"range": "r.png", "r_scale_mm": 0.1, "z_scale_mm": 1})";
  EXPECT_EQ(read_cylindrical_sidecar(dir / "d.json").range, dir / "r.png");
  // void_value: a whole number a 16-bit image holds, not a huge or fractional number (which would
  // be cast to unsigned out of range: the fuzzer's find).
  for (const char* v : {"4.4e78", "-1", "65536", "0.5"}) {
    std::ofstream(dir / "e.json") << R"({"range": "r.png", "r_scale_mm": 0.1, "z_scale_mm": 1, "void_value": )"
                                  << v << "}";
    EXPECT_THROW(read_cylindrical_sidecar(dir / "e.json"), InvalidInput) << v;
  }
  std::ofstream(dir / "f.json") << R"({"range": "r.png", "r_scale_mm": 0.1, "z_scale_mm": 1, "void_value": 65535})";
  EXPECT_EQ(read_cylindrical_sidecar(dir / "f.json").void_value, 65535u);
  fs::remove_all(dir);
}

TEST(CylindricalScan, UniformCylinderHasSkinInEveryColumn) {
  // A cylinder of radius 150 mm at 1024 columns x 64 lines: every ray from the axis meets it,
  // also the rays that pass exactly through a vertical edge of the reconstruction (at 1024 grid
  // columns every ray does; theta -25.66 deg used to find no face).
  const int nt = 1024, nz = 64;
  const fs::path dir = temp_dir("uniform");
  write_grey16(dir / "r.png", nt, nz, std::vector<std::uint16_t>(std::size_t(nt) * nz, 1500));
  CylindricalScanSpec s;
  s.range = dir / "r.png";
  s.r_scale_mm = 0.1;
  s.z_scale_mm = 2;
  const ScanMesh scan = cylindrical_scan_mesh(s);
  for (const int n_theta : {512, 1024}) {
    ScanModelOptions o;
    o.thickness_mm = 6;
    o.mm_per_unit = 1;
    o.maps.n_theta = n_theta;
    o.maps.n_z = 32;
    const ScanModel sm = build_scan_model(scan, o);
    const auto& g = sm.maps.grid;
    int missing = 0;
    double worst = 0;
    for (int k = 1; k + 1 < g.n_z; ++k)
      for (int j = 0; j < g.n_theta; ++j) {
        const std::size_t c = g.index(j, k);
        if (sm.maps.flags[c] & kNoSkin) {
          if (missing++ == 0) ADD_FAILURE() << "no skin at theta " << g.theta_deg(j) << " deg, z " << g.z_mm(k);
          continue;
        }
        worst = std::max(worst, std::abs(sm.maps.r_skin[c] - 150.0));
      }
    EXPECT_EQ(missing, 0) << n_theta << " columns";
    // Chords of 1024 sides: 150 (1 - cos(pi / 1024)) = 0.0007 mm inside the circle at most.
    EXPECT_LT(worst, 0.01) << n_theta << " columns";
  }
  fs::remove_all(dir);
}
