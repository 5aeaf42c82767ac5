// Tests for the volume readers and the NIfTI writer: synthetic files written by the test (NIfTI,
// NRRD, MetaImage, DICOM) with known geometry, the real shared data sets, and a catalogue of bad
// inputs that must fail with the right exception type and a message naming the file.

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <Eigen/Geometry>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <functional>
#include <fstream>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "caps/core/error.hpp"
#include "caps/core/units.hpp"
#include "caps/volume/phantom.hpp"
#include "caps/volume/read_volume.hpp"

namespace fs = std::filesystem;
using caps::Modality;
using caps::ReadOptions;
using caps::Volume;

namespace {

const fs::path kData = CAPS_SHARED_DATA;
const fs::path kCranium = "/usr/share/doc/invesalius-examples/examples/Cranium.inv3";
const fs::path kCh2 = "/usr/share/mricron/templates/ch2.nii.gz";

/// A fresh temporary folder, removed with its contents at the end of the test.
class TempDir {
 public:
  TempDir() {
    std::random_device rd;
    path_ = fs::temp_directory_path() / ("caps_test_volume_io_" + std::to_string(rd()));
    fs::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(path_, ec);
  }
  fs::path operator/(const std::string& name) const { return path_ / name; }
  const fs::path& path() const { return path_; }

 private:
  fs::path path_;
};

void write_bytes(const fs::path& p, const std::string& bytes) {
  std::ofstream out(p, std::ios::binary);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

template <typename T>
std::string raw_bytes(const std::vector<T>& v, bool big_endian = false) {
  std::string s(v.size() * sizeof(T), '\0');
  for (std::size_t n = 0; n < v.size(); ++n) {
    char b[sizeof(T)];
    std::memcpy(b, &v[n], sizeof(T));
    if (big_endian) std::reverse(b, b + sizeof(T));
    std::memcpy(&s[n * sizeof(T)], b, sizeof(T));
  }
  return s;
}

std::string read_bytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

// Deflate "stored" blocks: a valid, uncompressed deflate stream (RFC 1951, section 3.2.4).
std::string deflate_stored(const std::string& data) {
  std::string out;
  std::size_t pos = 0;
  do {
    const std::size_t len = std::min<std::size_t>(data.size() - pos, 65535);
    const bool last = pos + len == data.size();
    out += static_cast<char>(last ? 1 : 0);
    out += static_cast<char>(len & 0xff);
    out += static_cast<char>(len >> 8);
    out += static_cast<char>(~len & 0xff);
    out += static_cast<char>((~len >> 8) & 0xff);
    out += data.substr(pos, len);
    pos += len;
  } while (pos < data.size());
  return out;
}

void put_le32(std::string& s, std::uint32_t v) {
  for (int b = 0; b < 4; ++b) s += static_cast<char>((v >> (8 * b)) & 0xff);
}

std::string gzip_stored(const std::string& data) {
  std::uint32_t crc = 0xffffffffu;
  for (unsigned char c : data) {
    crc ^= c;
    for (int b = 0; b < 8; ++b) crc = (crc >> 1) ^ (0xedb88320u & (0u - (crc & 1u)));
  }
  std::string out("\x1f\x8b\x08\x00\x00\x00\x00\x00\x00\x03", 10);
  out += deflate_stored(data);
  put_le32(out, ~crc);
  put_le32(out, static_cast<std::uint32_t>(data.size()));
  return out;
}

std::string zlib_stored(const std::string& data) {
  std::uint32_t a = 1, b = 0;
  for (unsigned char c : data) {
    a = (a + c) % 65521;
    b = (b + a) % 65521;
  }
  std::string out("\x78\x01", 2);
  out += deflate_stored(data);
  const std::uint32_t adler = (b << 16) | a;
  for (int s = 3; s >= 0; --s) out += static_cast<char>((adler >> (8 * s)) & 0xff);
  return out;
}

/// Runs f, expects exception E whose message mentions `name`.
template <typename E, typename F>
void expect_error(F&& f, const std::string& name, const std::string& also = "") {
  try {
    f();
    ADD_FAILURE() << "no exception for " << name;
  } catch (const E& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find(name), std::string::npos) << what;
    if (!also.empty()) {
      EXPECT_NE(what.find(also), std::string::npos) << what;
    }
  } catch (const std::exception& e) {
    ADD_FAILURE() << "wrong exception type for " << name << ": " << e.what();
  }
}

float value_fn(int i, int j, int k) { return static_cast<float>(i * 1.5 - j * 2.0 + k * 10.0 + 0.25); }

// ---------------------------------------------------------------------------------------------
// Minimal DICOM writer (explicit VR little endian) for synthetic CT slices.

void put_u16(std::string& s, std::uint16_t v) {
  s += static_cast<char>(v & 0xff);
  s += static_cast<char>(v >> 8);
}

void element(std::string& s, std::uint16_t g, std::uint16_t e, const char* vr, std::string value) {
  if (value.size() % 2) value += std::strcmp(vr, "UI") == 0 ? '\0' : ' ';
  put_u16(s, g);
  put_u16(s, e);
  s += vr;
  if (std::strcmp(vr, "OW") == 0 || std::strcmp(vr, "OB") == 0) {
    put_u16(s, 0);
    put_le32(s, static_cast<std::uint32_t>(value.size()));
  } else {
    put_u16(s, static_cast<std::uint16_t>(value.size()));
  }
  s += value;
}

std::string us(std::uint16_t v) {
  std::string s;
  put_u16(s, v);
  return s;
}

std::string ds3(const Eigen::Vector3d& p) {
  char buf[128];
  std::snprintf(buf, sizeof buf, "%.6f\\%.6f\\%.6f", p.x(), p.y(), p.z());
  return buf;
}

struct SliceSpec {
  Eigen::Vector3d ipp;
  Eigen::Vector3d row{1, 0, 0}, col{0, 1, 0};
  int rows = 6, cols = 8;
  double row_spacing = 0.5, col_spacing = 0.75;  // PixelSpacing = (row, col)
  double slope = 1.0, intercept = -1024.0;
  std::string series_uid = "1.2.3.4.5.1";
  std::string patient_name = "Doe^Jane", patient_id = "P001", study_uid = "1.2.3.4.5";
  int instance = 1;
  int frames = 1;             // NumberOfFrames written when above 1
  bool rle = false;           // RLE Lossless (encapsulated) instead of native pixel data
  std::string syntax;         // with `fragment`: this encapsulated transfer syntax ...
  std::string fragment;       // ... and this one fragment per frame instead of the pixels
  bool geometry = true;       // ImagePositionPatient / ImageOrientationPatient / PixelSpacing
  std::string group_0018;     // elements of group 0018 (tag order), e.g. SpacingBetweenSlices
  std::string before_pixels;  // elements between group 0028 and PixelData, e.g. functional groups
};

/// DICOM RLE (PS3.5 Annex G) of one 16-bit frame: two segments (high bytes, then low bytes),
/// each a PackBits stream of literal runs split so that its length is even.
std::string rle_frame(const std::vector<std::int16_t>& px) {
  std::vector<std::string> segments(2);
  for (int b = 0; b < 2; ++b) {
    std::string bytes;
    for (auto v : px) bytes += static_cast<char>((static_cast<std::uint16_t>(v) >> (8 * (1 - b))) & 0xff);
    std::size_t runs = (bytes.size() + 127) / 128;
    if ((bytes.size() + runs) % 2) ++runs;
    std::string& seg = segments[b];
    for (std::size_t r = 0, at = 0; r < runs; ++r) {
      const std::size_t len = (bytes.size() - at) / (runs - r);
      seg += static_cast<char>(len - 1);
      seg += bytes.substr(at, len);
      at += len;
    }
  }
  std::string out;
  put_le32(out, 2);
  put_le32(out, 64);
  put_le32(out, static_cast<std::uint32_t>(64 + segments[0].size()));
  out += std::string(64 - out.size(), '\0');
  return out + segments[0] + segments[1];
}

/// Writes one CT image of s.frames frames; stored(x, y, k) gives the stored int16 value at
/// column x, row y of frame k.
template <typename F>
void write_dicom_image(const fs::path& p, const SliceSpec& s, F stored) {
  const std::string sop_class = "1.2.840.10008.5.1.4.1.1.2";
  const std::string sop_inst = s.series_uid + ".9." + std::to_string(s.instance);
  std::string meta;
  element(meta, 0x0002, 0x0001, "OB", std::string("\0\1", 2));
  element(meta, 0x0002, 0x0002, "UI", sop_class);
  element(meta, 0x0002, 0x0003, "UI", sop_inst);
  const bool encapsulated = s.rle || !s.fragment.empty();
  element(meta, 0x0002, 0x0010, "UI",
          s.rle ? "1.2.840.10008.1.2.5" : (encapsulated ? s.syntax : "1.2.840.10008.1.2.1"));
  std::string out(128, '\0');
  out += "DICM";
  std::string len;
  put_le32(len, static_cast<std::uint32_t>(meta.size()));
  element(out, 0x0002, 0x0000, "UL", len);
  out += meta;
  char buf[256];
  element(out, 0x0008, 0x0016, "UI", sop_class);
  element(out, 0x0008, 0x0018, "UI", sop_inst);
  element(out, 0x0008, 0x0060, "CS", "CT");
  element(out, 0x0008, 0x103e, "LO", "synthetic");
  element(out, 0x0010, 0x0010, "PN", s.patient_name);
  element(out, 0x0010, 0x0020, "LO", s.patient_id);
  out += s.group_0018;
  element(out, 0x0020, 0x000d, "UI", s.study_uid);
  element(out, 0x0020, 0x000e, "UI", s.series_uid);
  element(out, 0x0020, 0x0013, "IS", std::to_string(s.instance));
  if (s.geometry) {
    element(out, 0x0020, 0x0032, "DS", ds3(s.ipp));
    std::snprintf(buf, sizeof buf, "%.6f\\%.6f\\%.6f\\%.6f\\%.6f\\%.6f", s.row.x(), s.row.y(),
                  s.row.z(), s.col.x(), s.col.y(), s.col.z());
    element(out, 0x0020, 0x0037, "DS", buf);
  }
  element(out, 0x0028, 0x0002, "US", us(1));
  element(out, 0x0028, 0x0004, "CS", "MONOCHROME2");
  if (s.frames > 1) element(out, 0x0028, 0x0008, "IS", std::to_string(s.frames));
  element(out, 0x0028, 0x0010, "US", us(static_cast<std::uint16_t>(s.rows)));
  element(out, 0x0028, 0x0011, "US", us(static_cast<std::uint16_t>(s.cols)));
  if (s.geometry) {
    std::snprintf(buf, sizeof buf, "%.6f\\%.6f", s.row_spacing, s.col_spacing);
    element(out, 0x0028, 0x0030, "DS", buf);
  }
  element(out, 0x0028, 0x0100, "US", us(16));
  element(out, 0x0028, 0x0101, "US", us(16));
  element(out, 0x0028, 0x0102, "US", us(15));
  element(out, 0x0028, 0x0103, "US", us(1));
  std::snprintf(buf, sizeof buf, "%g", s.intercept);
  element(out, 0x0028, 0x1052, "DS", buf);
  std::snprintf(buf, sizeof buf, "%g", s.slope);
  element(out, 0x0028, 0x1053, "DS", buf);
  out += s.before_pixels;
  std::vector<std::vector<std::int16_t>> frames(s.frames);
  for (int k = 0; k < s.frames; ++k)
    for (int y = 0; y < s.rows; ++y)
      for (int x = 0; x < s.cols; ++x)
        frames[k].push_back(static_cast<std::int16_t>(stored(x, y, k)));
  if (!encapsulated) {
    std::vector<std::int16_t> px;
    for (const auto& f : frames) px.insert(px.end(), f.begin(), f.end());
    element(out, 0x7fe0, 0x0010, "OW", raw_bytes(px));
  } else {
    // Encapsulated: undefined length, an empty offset table, one fragment per frame.
    out += std::string("\xe0\x7f\x10\x00OB\0\0", 8);
    put_le32(out, 0xffffffffu);
    const auto item = [&](const std::string& body) {
      put_u16(out, 0xfffe);
      put_u16(out, 0xe000);
      put_le32(out, static_cast<std::uint32_t>(body.size()));
      out += body;
    };
    item("");
    for (const auto& f : frames) item(s.fragment.empty() ? rle_frame(f) : s.fragment);
    put_u16(out, 0xfffe);
    put_u16(out, 0xe0dd);
    put_le32(out, 0);
  }
  write_bytes(p, out);
}

/// Writes one CT slice; stored(x, y) gives the stored int16 value at column x, row y.
template <typename F>
void write_dicom_slice(const fs::path& p, const SliceSpec& s, F stored) {
  write_dicom_image(p, s, [&](int x, int y, int) { return stored(x, y); });
}

/// A uniform axial series of n slices 2 mm apart; stored value = 100 * slice + 10 * y + x.
void write_uniform_series(const fs::path& dir, int n, const std::string& uid = "1.2.3.4.5.1",
                          const std::function<void(int, SliceSpec&)>& change = nullptr) {
  fs::create_directories(dir);
  for (int k = 0; k < n; ++k) {
    SliceSpec s;
    if (change) change(k, s);
    s.ipp = Eigen::Vector3d(-10, -20, 30 + 2.0 * k);
    if (s.series_uid == SliceSpec{}.series_uid) s.series_uid = uid;
    s.instance = k + 1;
    char name[32];
    std::snprintf(name, sizeof name, "IM%03d.dcm", k);
    write_dicom_slice(dir / name, s, [k](int x, int y) { return 100 * k + 10 * y + x; });
  }
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// NIfTI

TEST(VolumeIo, NiftiRoundTripKeepsObliqueGeometryAndValues) {
  TempDir tmp;
  Volume v;
  v.source = "synthetic";
  v.format = "phantom";
  v.geom.dims = Eigen::Vector3i(7, 5, 4);
  v.geom.spacing_mm = Eigen::Vector3d(0.8, 1.1, 2.5);
  v.geom.origin_lps = Eigen::Vector3d(12.5, -30.25, 40.0);
  v.geom.direction =
      (Eigen::AngleAxisd(0.4, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix() *
       Eigen::Vector3d(1, 1, -1).asDiagonal())  // an improper (left-handed) frame too
          .eval();
  v.data.resize(v.geom.n_voxels());
  for (int k = 0; k < 4; ++k)
    for (int j = 0; j < 5; ++j)
      for (int i = 0; i < 7; ++i) v.at(i, j, k) = value_fn(i, j, k);

  for (const char* name : {"rt.nii", "rt.nii.gz"}) {
    caps::write_nifti(v, tmp / name);
    const Volume r = caps::read_volume(tmp / name);
    EXPECT_EQ(r.format, "NIfTI-1");
    EXPECT_EQ(r.geom.dims, v.geom.dims);
    EXPECT_LT((r.geom.spacing_mm - v.geom.spacing_mm).cwiseAbs().maxCoeff(), 1e-5) << name;
    EXPECT_LT((r.geom.origin_lps - v.geom.origin_lps).cwiseAbs().maxCoeff(), 1e-5) << name;
    EXPECT_LT((r.geom.direction - v.geom.direction).cwiseAbs().maxCoeff(), 1e-5) << name;
    ASSERT_EQ(r.data.size(), v.data.size());
    for (std::size_t n = 0; n < v.data.size(); ++n) ASSERT_FLOAT_EQ(r.data[n], v.data[n]);
    // A voxel lands at the same LPS point.
    const Eigen::Vector3d ijk(3, 2, 1);
    EXPECT_LT((r.index_to_lps(ijk) - v.index_to_lps(ijk)).norm(), 1e-4);
  }
  EXPECT_FALSE(fs::exists(tmp / "rt.nii.gz.tmp"));
}

/// A NIfTI-1 header (348 bytes) for a float32 image of `dims` (3 to 5 of them) with 1 mm axes
/// along RAS from the origin (sform code 1); `pair` writes the magic of a .hdr/.img pair.
std::string nifti1_header(const std::vector<int>& dims, int intent = 0, bool pair = false) {
  std::string h(348, '\0');
  auto i16 = [&](int at, int v) {
    const std::int16_t x = static_cast<std::int16_t>(v);
    std::memcpy(&h[at], &x, 2);
  };
  auto f32 = [&](int at, float v) { std::memcpy(&h[at], &v, 4); };
  const std::int32_t size = 348;
  std::memcpy(&h[0], &size, 4);
  i16(40, static_cast<int>(dims.size()));
  for (std::size_t d = 0; d < dims.size(); ++d) i16(42 + 2 * static_cast<int>(d), dims[d]);
  i16(68, intent);
  i16(70, 16);  // DT_FLOAT32
  i16(72, 32);
  for (int d = 0; d < 8; ++d) f32(76 + 4 * d, 1.0f);
  f32(108, pair ? 0.0f : 352.0f);
  h[123] = 2;   // xyzt_units: mm
  i16(254, 1);  // sform_code
  f32(280, 1.0f);
  f32(296 + 4, 1.0f);
  f32(312 + 8, 1.0f);
  f32(280 + 12, -3.0f);  // origin (-3, 4, 5) RAS
  f32(296 + 12, 4.0f);
  f32(312 + 12, 5.0f);
  std::memcpy(&h[344], pair ? "ni1\0" : "n+1\0", 4);
  return h;
}

std::string nifti1_file(const std::vector<int>& dims, const std::vector<float>& values,
                        int intent = 0) {
  return nifti1_header(dims, intent) + std::string(4, '\0') + raw_bytes(values);
}

TEST(VolumeIo, Nifti4dReadsTheVolumeAskedForAndSaysWhich) {
  TempDir tmp;
  const int nx = 4, ny = 3, nz = 2, nt = 5;
  std::vector<float> values;
  for (int t = 0; t < nt; ++t)
    for (int n = 0; n < nx * ny * nz; ++n) values.push_back(1000.0f * t + n);
  write_bytes(tmp / "fmri.nii", nifti1_file({nx, ny, nz, nt}, values));
  const Volume first = caps::read_volume(tmp / "fmri.nii");
  EXPECT_EQ(first.geom.dims, Eigen::Vector3i(nx, ny, nz));
  EXPECT_FLOAT_EQ(first.at(3, 2, 1), 23.0f);
  bool said = false;
  for (const auto& n : first.notes) said |= n.find("5 volumes") != std::string::npos &&
                                            n.find("read volume 0") != std::string::npos;
  EXPECT_TRUE(said);
  ReadOptions o;
  o.volume_index = 3;
  const Volume fourth = caps::read_volume(tmp / "fmri.nii", o);
  EXPECT_FLOAT_EQ(fourth.at(0, 0, 0), 3000.0f);
  EXPECT_FLOAT_EQ(fourth.at(3, 2, 1), 3023.0f);
  o.volume_index = 5;
  expect_error<caps::InvalidInput>([&] { caps::read_volume(tmp / "fmri.nii", o); }, "fmri.nii",
                                   "5 volume(s)");
}

TEST(VolumeIo, NiftiIntentsThatAreNotImagesAreRefused) {
  TempDir tmp;
  // A vector field (1007) and a CIFTI dense connectivity matrix (3001, as nibabel's
  // row_major.dconn.nii, which was read as a 1x1x1 volume).
  write_bytes(tmp / "vec.nii", nifti1_file({2, 2, 2, 1, 3}, std::vector<float>(24, 1.0f), 1007));
  write_bytes(tmp / "conn.nii", nifti1_file({1, 1, 1, 1, 4, 4}, std::vector<float>(16, 0.5f), 3001));
  expect_error<caps::InvalidInput>([&] { caps::read_volume(tmp / "vec.nii"); }, "vec.nii",
                                   "intent 1007");
  expect_error<caps::InvalidInput>([&] { caps::read_volume(tmp / "conn.nii"); }, "conn.nii",
                                   "intent 3001");
  // A statistic (t-test, 3) is an image of one value per voxel.
  write_bytes(tmp / "t.nii", nifti1_file({2, 2, 2}, std::vector<float>(8, 2.0f), 3));
  EXPECT_FLOAT_EQ(caps::read_volume(tmp / "t.nii").at(1, 1, 1), 2.0f);
}

TEST(VolumeIo, NiftiNanReachingTheEdgeIsOutsideTheFieldAndEnclosedNanIsRefused) {
  TempDir tmp;
  const int n = 6;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  std::vector<float> values(n * n * n);
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) values[(k * n + j) * n + i] = 100.0f + i + 10.0f * j + k;
  // No data in the plane i = 0 and in a channel from it to the centre (i = 1..3 at j = k = 3):
  // all joined to the edge.
  std::vector<float> edge = values;
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j) edge[(k * n + j) * n] = nan;
  for (int i = 1; i <= 3; ++i) edge[(3 * n + 3) * n + i] = nan;
  write_bytes(tmp / "edge.nii", nifti1_file({n, n, n}, edge));
  const Volume v = caps::read_volume(tmp / "edge.nii");
  ASSERT_EQ(v.acquired.size(), v.data.size());
  EXPECT_EQ(v.acquired[v.geom.linear(0, 2, 2)], 0);
  EXPECT_EQ(v.acquired[v.geom.linear(3, 3, 3)], 0);
  EXPECT_EQ(v.acquired[v.geom.linear(4, 3, 3)], 1);
  EXPECT_FLOAT_EQ(v.at(0, 2, 2), 101.0f);  // the smallest finite value: (1, 0, 0)
  EXPECT_FLOAT_EQ(v.at(4, 3, 3), 100.0f + 4 + 30 + 3);
  // One NaN voxel enclosed by data: damage inside the image.
  std::vector<float> inner = values;
  inner[(3 * n + 3) * n + 3] = nan;
  write_bytes(tmp / "inner.nii", nifti1_file({n, n, n}, inner));
  expect_error<caps::InvalidInput>([&] { caps::read_volume(tmp / "inner.nii"); }, "inner.nii",
                                   "enclosed by data, first at (3, 3, 3)");
}

TEST(VolumeIo, NiftiPairReadsLikeTheSingleFile) {
  TempDir tmp;
  std::vector<float> values(24);
  for (std::size_t n = 0; n < values.size(); ++n) values[n] = static_cast<float>(n) * 0.5f;
  write_bytes(tmp / "one.nii", nifti1_file({4, 3, 2}, values));
  write_bytes(tmp / "two.hdr", nifti1_header({4, 3, 2}, 0, true));
  write_bytes(tmp / "two.img", raw_bytes(values));
  const Volume one = caps::read_volume(tmp / "one.nii");
  for (const char* name : {"two.hdr", "two.img"}) {
    const Volume two = caps::read_volume(tmp / name);
    EXPECT_EQ(two.geom.dims, one.geom.dims) << name;
    EXPECT_LT((two.geom.origin_lps - Eigen::Vector3d(3, -4, 5)).norm(), 1e-9) << name;
    EXPECT_EQ(two.data, one.data) << name;
  }
  // A header whose image file is missing names it.
  write_bytes(tmp / "lone.hdr", nifti1_header({4, 3, 2}, 0, true));
  expect_error<caps::IoError>([&] { caps::read_volume(tmp / "lone.hdr"); }, "lone.img");
}

TEST(VolumeIo, NiftiWriteRejectsWrongExtension) {
  TempDir tmp;
  Volume v;
  v.geom.dims = Eigen::Vector3i(1, 1, 1);
  v.data = {1.0f};
  expect_error<caps::InvalidInput>([&] { caps::write_nifti(v, tmp / "out.img"); }, "out.img");
}

TEST(VolumeIo, ACtStoredUnsignedIsRecognisedAndAnMrIsNot) {
  // The phantom CT (HU) stored as HU + 1024 in a NIfTI (no modality field): a CT. The same head
  // with MR-like intensities on the same scale (air 0, fat bright, bone dark, the brain and CSF
  // spread between): not a CT. Real MRs: Ch2TemplateIsMrSizedAndInMniSpace below.
  caps::PhantomOptions po;
  po.dims = {64, 64, 60};
  po.spacing_mm = {4, 4, 4};
  const Volume ct = caps::make_phantom(po);
  const fs::path f = fs::temp_directory_path() / "caps_test_modality.nii.gz";
  const auto read_back = [&](const Volume& v) {
    caps::write_nifti(v, f);
    return caps::read_volume(f);
  };
  EXPECT_EQ(read_back(ct).modality, Modality::CT);  // signed HU, as before
  Volume stored = ct;
  for (float& x : stored.data) x = std::round(std::max(x, -1024.0f) + 1024.0f);
  const Volume back = read_back(stored);
  EXPECT_EQ(back.modality, Modality::CT) << back.notes.back();
  // An MR on the same scale: the soft tissue spread over 300..1300, fat at 1500, bone at 150.
  Volume mr = ct;
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> spread(300.0f, 1300.0f);
  for (float& x : mr.data)
    x = x < -500 ? 0.0f : x < -50 ? 1500.0f : x > 300 ? 150.0f : std::round(spread(rng));
  const Volume mr_back = read_back(mr);
  EXPECT_NE(mr_back.modality, Modality::CT) << mr_back.notes.back();
  // Fractional values are no stored CT either.
  Volume fractional = stored;
  for (float& x : fractional.data) x += 0.25f;
  EXPECT_NE(read_back(fractional).modality, Modality::CT);
  fs::remove(f);
}

TEST(VolumeIo, Ch2TemplateIsMrSizedAndInMniSpace) {
  if (!fs::exists(kCh2)) GTEST_SKIP() << "mricron-data not installed";
  const Volume v = caps::read_volume(kCh2);
  EXPECT_EQ(v.geom.dims, Eigen::Vector3i(181, 217, 181));
  EXPECT_LT((v.geom.spacing_mm - Eigen::Vector3d(1, 1, 1)).norm(), 1e-6);
  EXPECT_NE(v.modality, Modality::CT);  // an MR template: not mistaken for CT
  // sform is RAS with i towards +x(RAS) = right -> LPS -x.
  EXPECT_NEAR(v.geom.direction(0, 0), -1.0, 1e-6);
  EXPECT_NEAR(v.geom.direction(1, 1), -1.0, 1e-6);
  EXPECT_NEAR(v.geom.direction(2, 2), 1.0, 1e-6);
  EXPECT_LT((v.geom.origin_lps - Eigen::Vector3d(90, 126, -72)).cwiseAbs().maxCoeff(), 2.0);
  float hi = 0;
  for (float x : v.data) hi = std::max(hi, x);
  EXPECT_GT(hi, 100.0f);
}

// ---------------------------------------------------------------------------------------------
// NRRD

TEST(VolumeIo, NrrdDetachedRawWithLpsDirections) {
  TempDir tmp;
  std::vector<std::int16_t> vals;
  for (int k = 0; k < 3; ++k)
    for (int j = 0; j < 4; ++j)
      for (int i = 0; i < 5; ++i) vals.push_back(static_cast<std::int16_t>(100 * k + 10 * j + i));
  write_bytes(tmp / "img.raw", raw_bytes(vals));
  write_bytes(tmp / "img.nhdr",
              "NRRD0004\ntype: short\ndimension: 3\nsizes: 5 4 3\nspace: left-posterior-superior\n"
              "space directions: (0,1.5,0) (-2,0,0) (0,0,3)\nspace origin: (1,2,3)\n"
              "endian: little\nencoding: raw\ndata file: img.raw\n");
  const Volume v = caps::read_volume(tmp / "img.nhdr");
  EXPECT_EQ(v.format, "NRRD");
  EXPECT_EQ(v.geom.dims, Eigen::Vector3i(5, 4, 3));
  EXPECT_LT((v.geom.spacing_mm - Eigen::Vector3d(1.5, 2, 3)).norm(), 1e-9);
  EXPECT_LT((v.geom.direction.col(0) - Eigen::Vector3d(0, 1, 0)).norm(), 1e-9);
  EXPECT_LT((v.geom.direction.col(1) - Eigen::Vector3d(-1, 0, 0)).norm(), 1e-9);
  EXPECT_LT((v.geom.origin_lps - Eigen::Vector3d(1, 2, 3)).norm(), 1e-9);
  EXPECT_FLOAT_EQ(v.at(4, 3, 2), 234.0f);
  EXPECT_FLOAT_EQ(v.at(1, 2, 0), 21.0f);
  EXPECT_LT((v.index_to_lps({1, 1, 1}) - Eigen::Vector3d(-1, 3.5, 6)).norm(), 1e-9);
}

TEST(VolumeIo, NrrdRasSpaceIsFlippedToLps) {
  TempDir tmp;
  std::vector<float> vals(2 * 3 * 4);
  for (std::size_t n = 0; n < vals.size(); ++n) vals[n] = static_cast<float>(n) * 0.5f;
  write_bytes(tmp / "ras.nrrd",
              "NRRD0004\ntype: float\ndimension: 3\nsizes: 2 3 4\n"
              "space: right-anterior-superior\nspace directions: (1,0,0) (0,2,0) (0,0,3)\n"
              "space origin: (10,20,30)\nendian: little\nencoding: raw\n\n" +
                  raw_bytes(vals));
  const Volume v = caps::read_volume(tmp / "ras.nrrd");
  EXPECT_LT((v.geom.direction - Eigen::Matrix3d(Eigen::Vector3d(-1, -1, 1).asDiagonal())).norm(),
            1e-12);
  EXPECT_LT((v.geom.spacing_mm - Eigen::Vector3d(1, 2, 3)).norm(), 1e-12);
  EXPECT_LT((v.geom.origin_lps - Eigen::Vector3d(-10, -20, 30)).norm(), 1e-12);
  EXPECT_FLOAT_EQ(v.at(1, 2, 3), static_cast<float>(1 + 2 * 2 + 3 * 6) * 0.5f);
}

TEST(VolumeIo, NrrdGzipEncoding) {
  TempDir tmp;
  std::vector<std::uint16_t> vals(6 * 5 * 4);
  for (std::size_t n = 0; n < vals.size(); ++n) vals[n] = static_cast<std::uint16_t>(n * 7);
  write_bytes(tmp / "gz.nrrd",
              "NRRD0004\ntype: ushort\ndimension: 3\nsizes: 6 5 4\nspacings: 0.5 0.6 0.7\n"
              "endian: little\nencoding: gzip\n\n" +
                  gzip_stored(raw_bytes(vals)));
  const Volume v = caps::read_volume(tmp / "gz.nrrd");
  EXPECT_EQ(v.geom.dims, Eigen::Vector3i(6, 5, 4));
  EXPECT_LT((v.geom.spacing_mm - Eigen::Vector3d(0.5, 0.6, 0.7)).norm(), 1e-12);
  EXPECT_FLOAT_EQ(v.at(5, 4, 3), static_cast<float>(119 * 7));
  EXPECT_FALSE(v.notes.empty());  // "no space directions" is recorded
}

// A field line too long for teem is refused before teem reads it, also when a ":=" late in the
// line (after NUL bytes, as fuzz_nrrd wrote it) makes it look like a key:=value line, which
// teem keeps whole; a real long key:=value line is read.
TEST(VolumeIo, NrrdLongFieldLineIsRefusedEvenWithAKeyValueMarkLaterInIt) {
  TempDir tmp;
  std::string sizes = "sizes: 2 2 2";
  for (int i = 0; i < 400; ++i) sizes += " 35";  // 1200 characters: teem overflowed
  sizes += std::string(4, '\0') + " k:=v";
  const std::string tail = "\nendian: little\nencoding: raw\n\n" + std::string(16, '\0');
  write_bytes(tmp / "long.nrrd", "NRRD0004\ntype: short\ndimension: 3\n" + sizes + tail);
  try {
    caps::read_volume(tmp / "long.nrrd");
    FAIL() << "expected InvalidInput";
  } catch (const caps::InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("header line 4"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("characters long"), std::string::npos) << e.what();
  }
  const std::string note = "note:=" + std::string(2000, 'x');
  write_bytes(tmp / "note.nrrd",
              "NRRD0004\ntype: short\ndimension: 3\nsizes: 2 2 2\n" + note + tail);
  EXPECT_EQ(caps::read_volume(tmp / "note.nrrd").geom.dims, Eigen::Vector3i(2, 2, 2));
}

// Without the NRRD magic teem would pick another of its formats by the content (a table of
// numbers is its plain-text image format, whose reader leaks on the files it refuses): caps
// refuses the file before teem reads it, the same answer for a table and for noise.
TEST(VolumeIo, NrrdWithoutTheMagicIsRefusedBeforeTeemReadsIt) {
  TempDir tmp;
  for (const std::string& body : {std::string("1 2 3\n4 5 6\n"),
                                   std::string("00typeeendiann: 3\n\xd2\xd2\x01") +
                                       std::string(1, '\0') + "V>",
                                   std::string("NRRD\ntype: short\n"),
                                   std::string("NRRD0003og003og\ni:=x\n"), std::string()}) {
    write_bytes(tmp / "a.nrrd", body);
    try {
      caps::read_volume(tmp / "a.nrrd");
      FAIL() << "expected InvalidInput for '" << body << "'";
    } catch (const caps::InvalidInput& e) {
      EXPECT_NE(std::string(e.what()).find("not a NRRD file"), std::string::npos) << e.what();
    }
  }
}

// teem leaves a data file it cannot read open: a header whose data file is a folder (here its
// own, named by an empty name cut short by a NUL byte, or by ".") or is truncated cost a file
// descriptor on every read. Both are refused before teem opens the data; reading them many
// times leaves nothing open.
TEST(VolumeIo, NrrdDataFileThatIsAFolderIsRefusedWithoutLeakingADescriptor) {
  TempDir tmp;
  const std::string head = "NRRD0004\ntype: short\ndimension: 3\nsizes: 2 2 2\nendian: little\n"
                           "encoding: raw\ndata file: ";
  write_bytes(tmp / "nul.nhdr", head + std::string(3, '\0') + "data.raw\n\n");
  write_bytes(tmp / "dot.nhdr", head + ".\n\n");
  write_bytes(tmp / "data.raw", std::string(16, '\0'));
  const auto open_descriptors = [] {
    return std::distance(fs::directory_iterator("/proc/self/fd"), fs::directory_iterator());
  };
  const auto before = open_descriptors();
  for (const char* name : {"nul.nhdr", "dot.nhdr"})
    for (int i = 0; i < 20; ++i) {
      try {
        caps::read_volume(tmp / name);
        FAIL() << "expected InvalidInput for " << name;
      } catch (const caps::InvalidInput& e) {
        EXPECT_NE(std::string(e.what()).find("data file 1"), std::string::npos) << e.what();
      }
    }
  // The same for a truncated data file (10 of the 16 bytes): teem left it open as well.
  write_bytes(tmp / "short.nhdr", head + "short.raw\n\n");
  write_bytes(tmp / "short.raw", std::string(10, '\0'));
  for (int i = 0; i < 20; ++i) {
    try {
      caps::read_volume(tmp / "short.nhdr");
      FAIL() << "expected IoError for short.nhdr";
    } catch (const caps::IoError& e) {
      EXPECT_NE(std::string(e.what()).find("truncated"), std::string::npos) << e.what();
    }
  }
  EXPECT_EQ(open_descriptors(), before);
}

TEST(VolumeIo, HeadsqQuarterNhdr) {
  const fs::path p = kData / "ct/vtk-headsq/quarter.nhdr";
  if (!fs::exists(p)) GTEST_SKIP() << p;
  const Volume v = caps::read_volume(p);
  EXPECT_EQ(v.geom.dims, Eigen::Vector3i(64, 64, 93));
  EXPECT_LT((v.geom.spacing_mm - Eigen::Vector3d(3.2, 3.2, 1.5)).norm(), 1e-9);
  // Stored HU + 1024 without a modality field: recognised from its intensities (air at 0, the
  // soft tissue's peak at 1024, bone beyond), and said so.
  EXPECT_EQ(v.modality, Modality::CT);
  bool said = false;
  for (const std::string& n : v.notes) said |= n.find("HU + 1024") != std::string::npos;
  EXPECT_TRUE(said);
  float lo = 1e9f, hi = -1e9f;
  for (float x : v.data) lo = std::min(lo, x), hi = std::max(hi, x);
  EXPECT_GE(lo, 0.0f);
  EXPECT_GT(hi, 1000.0f);
  EXPECT_LT(v.at(0, 0, 46), 50.0f);       // air in the corner
  EXPECT_GT(v.at(32, 32, 46), 50.0f);     // tissue in the middle
  EXPECT_GE(v.notes.size(), 2u);
}

// ---------------------------------------------------------------------------------------------
// MetaImage

TEST(VolumeIo, MhaLocalCompressedWithTransformMatrix) {
  TempDir tmp;
  std::vector<std::int16_t> vals;
  for (int k = 0; k < 3; ++k)
    for (int j = 0; j < 4; ++j)
      for (int i = 0; i < 5; ++i) vals.push_back(static_cast<std::int16_t>(-1000 + 100 * k + 10 * j + i));
  const std::string z = zlib_stored(raw_bytes(vals));
  // Axis i points to +y (LPS), axis j to -x, axis k to +z: ITK writes direction columns as
  // consecutive triples.
  write_bytes(tmp / "c.mha", "ObjectType = Image\nNDims = 3\nBinaryData = True\n"
                             "BinaryDataByteOrderMSB = False\nCompressedData = True\n"
                             "CompressedDataSize = " + std::to_string(z.size()) +
                             "\nTransformMatrix = 0 1 0 -1 0 0 0 0 1\nOffset = -5 6.5 7\n"
                             "CenterOfRotation = 0 0 0\nAnatomicalOrientation = RAI\n"
                             "ElementSpacing = 0.5 0.25 2\nDimSize = 5 4 3\n"
                             "ElementType = MET_SHORT\nElementDataFile = LOCAL\n" + z);
  const Volume v = caps::read_volume(tmp / "c.mha");
  EXPECT_EQ(v.format, "MetaImage");
  EXPECT_LT((v.geom.direction.col(0) - Eigen::Vector3d(0, 1, 0)).norm(), 1e-12);
  EXPECT_LT((v.geom.direction.col(1) - Eigen::Vector3d(-1, 0, 0)).norm(), 1e-12);
  EXPECT_LT((v.geom.origin_lps - Eigen::Vector3d(-5, 6.5, 7)).norm(), 1e-12);
  EXPECT_LT((v.geom.spacing_mm - Eigen::Vector3d(0.5, 0.25, 2)).norm(), 1e-12);
  EXPECT_FLOAT_EQ(v.at(4, 3, 2), -1000.0f + 234.0f);
  EXPECT_LT((v.index_to_lps({2, 0, 0}) - Eigen::Vector3d(-5, 7.5, 7)).norm(), 1e-12);
}

TEST(VolumeIo, MhdDetachedBigEndianFloat) {
  TempDir tmp;
  std::vector<float> vals(3 * 2 * 2);
  for (std::size_t n = 0; n < vals.size(); ++n) vals[n] = 0.5f + static_cast<float>(n);
  write_bytes(tmp / "d.raw", raw_bytes(vals, true));
  write_bytes(tmp / "d.mhd", "ObjectType = Image\nNDims = 3\nDimSize = 3 2 2\n"
                             "ElementType = MET_FLOAT\nElementSpacing = 1 1 4\n"
                             "Origin = 1 2 3\nBinaryDataByteOrderMSB = True\n"
                             "Modality = MET_MOD_CT\nElementDataFile = d.raw\n");
  const Volume v = caps::read_volume(tmp / "d.mhd");
  EXPECT_EQ(v.modality, Modality::CT);
  EXPECT_FLOAT_EQ(v.at(2, 1, 1), 11.5f);
  EXPECT_LT((v.geom.origin_lps - Eigen::Vector3d(1, 2, 3)).norm(), 1e-12);
  EXPECT_TRUE(v.geom.direction.isIdentity());
}

// ---------------------------------------------------------------------------------------------
// InVesalius

TEST(VolumeIo, CraniumInv3IsHuAndFacesAnterior) {
  if (!fs::exists(kCranium)) GTEST_SKIP() << "invesalius-examples not installed";
  const Volume v = caps::read_volume(kCranium);
  EXPECT_EQ(v.format, "InVesalius");
  EXPECT_EQ(v.modality, Modality::CT);
  EXPECT_EQ(v.geom.dims, Eigen::Vector3i(256, 256, 108));
  EXPECT_NEAR(v.geom.spacing_mm[0], 0.957, 1e-3);
  EXPECT_NEAR(v.geom.spacing_mm[2], 1.5, 1e-9);
  float lo = 1e9f, hi = -1e9f;
  for (float x : v.data) lo = std::min(lo, x), hi = std::max(hi, x);
  EXPECT_EQ(lo, -1024.0f);
  EXPECT_GT(hi, 1500.0f);  // bone / teeth in HU
  // The most anterior skin voxel (smallest LPS y) is the nose: low on the head and near the
  // left-right middle; the head's top (largest z with skin) is far above it.
  const auto& d = v.geom.dims;
  Eigen::Vector3d anterior(0, 1e9, 0), top(0, 0, -1e9), centre = Eigen::Vector3d::Zero();
  std::size_t n_skin = 0;
  for (int k = 0; k < d[2]; ++k)
    for (int j = 1; j < d[1]; ++j)  // row 0 holds the table edge
      for (int i = 0; i < d[0]; ++i)
        if (v.at(i, j, k) > -400.0f) {
          const Eigen::Vector3d p = v.index_to_lps(Eigen::Vector3d(i, j, k));
          if (p.y() < anterior.y()) anterior = p;
          if (p.z() > top.z()) top = p;
          centre += p;
          ++n_skin;
        }
  centre /= static_cast<double>(n_skin);
  EXPECT_LT(anterior.y(), centre.y() - 80.0);                 // the face is far forward
  EXPECT_NEAR(anterior.x(), centre.x(), 25.0);                // ... and on the midline
  EXPECT_LT(anterior.z(), centre.z());                        // nose below the head's centre
  EXPECT_GT(top.z(), centre.z() + 50.0);                      // vertex at high z
  // Brain tissue near the centre of the head is soft tissue in HU.
  const Eigen::Vector3d c = v.lps_to_index(centre + Eigen::Vector3d(0, 0, 20));
  const float brain = v.at(static_cast<int>(c.x()), static_cast<int>(c.y()), static_cast<int>(c.z()));
  EXPECT_GT(brain, -100.0f);
  EXPECT_LT(brain, 100.0f);
}

// ---------------------------------------------------------------------------------------------
// DICOM

TEST(VolumeIo, DicomSlicesOfTwoPatientsAreNeverReadAsOneVolume) {
  TempDir tmp;
  // One series whose slices 16 on are another patient's (PatientID and PatientName differ).
  write_uniform_series(tmp / "mixed", 24, "1.2.3.4.5.1", [](int k, SliceSpec& s) {
    if (k >= 16) {
      s.patient_name = "Roe^Richard";
      s.patient_id = "P002";
    }
  });
  try {
    caps::read_volume(tmp / "mixed");
    ADD_FAILURE() << "a series of two patients was read";
  } catch (const caps::InvalidInput& e) {
    const std::string m = e.what();
    for (const std::string w : {"two patients", "Doe^Jane", "P001", "Roe^Richard", "P002"})
      EXPECT_NE(m.find(w), std::string::npos) << w << ": " << m;
  }
  // The same with only the PatientID differing, or the study.
  write_uniform_series(tmp / "id", 8, "1.2.3.4.5.1",
                       [](int k, SliceSpec& s) { if (k == 5) s.patient_id = "P003"; });
  EXPECT_THROW(caps::read_volume(tmp / "id"), caps::InvalidInput);
  write_uniform_series(tmp / "study", 8, "1.2.3.4.5.1",
                       [](int k, SliceSpec& s) { if (k == 7) s.study_uid = "1.2.3.4.6"; });
  EXPECT_THROW(caps::read_volume(tmp / "study"), caps::InvalidInput);
  // A folder of two patients' series (each whole): refused naming both, unless a series is
  // chosen with --series (ReadOptions::series_uid).
  write_uniform_series(tmp / "two", 8, "1.2.3.4.5.1");
  write_uniform_series(tmp / "two" / "b", 6, "1.2.3.4.5.2", [](int, SliceSpec& s) {
    s.patient_name = "Roe^Richard";
    s.patient_id = "P002";
  });
  for (const auto& e : fs::directory_iterator(tmp / "two" / "b"))
    fs::rename(e.path(), tmp / "two" / ("b_" + e.path().filename().string()));
  fs::remove(tmp / "two" / "b");
  try {
    caps::read_volume(tmp / "two");
    ADD_FAILURE() << "a folder of two patients was read";
  } catch (const caps::InvalidInput& e) {
    const std::string m = e.what();
    for (const std::string w : {"more than one patient", "Doe^Jane", "Roe^Richard", "--series"})
      EXPECT_NE(m.find(w), std::string::npos) << w << ": " << m;
  }
  ReadOptions o;
  o.series_uid = "1.2.3.4.5.2";
  const Volume b = caps::read_volume(tmp / "two", o);
  EXPECT_EQ(b.geom.dims.z(), 6);
  // One patient throughout is read as before.
  write_uniform_series(tmp / "one", 8);
  EXPECT_EQ(caps::read_volume(tmp / "one").geom.dims.z(), 8);
}

TEST(VolumeIo, DicomUniformSeriesAppliesRescale) {
  TempDir tmp;
  write_uniform_series(tmp / "ct", 5);
  const Volume v = caps::read_volume(tmp / "ct");
  EXPECT_EQ(v.format, "DICOM");
  EXPECT_EQ(v.modality, Modality::CT);
  EXPECT_EQ(v.geom.dims, Eigen::Vector3i(8, 6, 5));
  EXPECT_LT((v.geom.spacing_mm - Eigen::Vector3d(0.75, 0.5, 2.0)).norm(), 1e-6);
  EXPECT_LT((v.geom.origin_lps - Eigen::Vector3d(-10, -20, 30)).norm(), 1e-6);
  EXPECT_TRUE(v.geom.direction.isIdentity(1e-9));
  EXPECT_FLOAT_EQ(v.at(3, 2, 4), 400 + 20 + 3 - 1024.0f);
  // One file of the series reads the whole series.
  const Volume one = caps::read_volume(tmp / "ct/IM002.dcm");
  EXPECT_EQ(one.geom.dims, v.geom.dims);
}

TEST(VolumeIo, DicomRleSeriesDecodesToTheSameValues) {
  TempDir tmp;
  write_uniform_series(tmp / "native", 3);
  fs::create_directories(tmp / "rle");
  for (int k = 0; k < 3; ++k) {
    SliceSpec s;
    s.ipp = Eigen::Vector3d(-10, -20, 30 + 2.0 * k);
    s.instance = k + 1;
    s.rle = true;
    // Negative values too: the two RLE segments carry the high and the low bytes.
    write_dicom_slice(tmp / ("rle/IM" + std::to_string(k) + ".dcm"), s,
                      [k](int x, int y) { return 100 * k + 10 * y + x - 60 * (x % 3); });
  }
  const Volume v = caps::read_volume(tmp / "rle");
  EXPECT_EQ(v.geom.dims, Eigen::Vector3i(8, 6, 3));
  for (int k = 0; k < 3; ++k)
    for (int y = 0; y < 6; ++y)
      for (int x = 0; x < 8; ++x)
        ASSERT_FLOAT_EQ(v.at(x, y, k), 100 * k + 10 * y + x - 60 * (x % 3) - 1024.0f);
}

TEST(VolumeIo, DicomCompressedFramesDisagreeingWithTheHeaderAreRefused) {
  // Found by fuzz_dicom: GDCM's JPEG codec dereferences a null pointer on a frame whose
  // precision (18 bits) exceeds BitsAllocated (16). Each frame's own header is checked first.
  TempDir tmp;
  auto sof3 = [](int precision, int rows, int cols) {
    std::string f("\xff\xd8\xff\xc3\x00\x0b", 6);
    f += static_cast<char>(precision);
    f += static_cast<char>(rows >> 8);
    f += static_cast<char>(rows & 0xff);
    f += static_cast<char>(cols >> 8);
    f += static_cast<char>(cols & 0xff);
    f += std::string("\x01\x01\x11\x00\xff\xd9", 6);
    return f;
  };
  for (const char* d : {"deep", "size", "rle3", "mpeg"}) fs::create_directories(tmp / d);
  SliceSpec s;
  s.syntax = "1.2.840.10008.1.2.4.70";
  s.fragment = sof3(18, 6, 8);
  write_dicom_slice(tmp / "deep" / "deep.dcm", s, [](int, int) { return 0; });
  expect_error<caps::IoError>([&] { caps::read_volume(tmp / "deep" / "deep.dcm"); }, "deep.dcm",
                              "precision of 18 bits");
  s.fragment = sof3(16, 7, 8);
  write_dicom_slice(tmp / "size" / "size.dcm", s, [](int, int) { return 0; });
  expect_error<caps::IoError>([&] { caps::read_volume(tmp / "size" / "size.dcm"); }, "size.dcm",
                              "8x7 pixels");
  // A frame whose header agrees but which holds no scan: GDCM's JPEG codec asserts on what
  // libjpeg reports (found by fuzz_dicom); decoded in a child process, it is a damaged file.
  fs::create_directories(tmp / "noscan");
  s.fragment = sof3(16, 6, 8);
  write_dicom_slice(tmp / "noscan" / "noscan.dcm", s, [](int, int) { return 0; });
  expect_error<caps::IoError>([&] { caps::read_volume(tmp / "noscan" / "noscan.dcm"); },
                              "noscan.dcm", "could not be decoded");
  // An RLE frame with three segments for 16-bit pixels.
  s.syntax = "1.2.840.10008.1.2.5";
  s.fragment = std::string("\x03\0\0\0\x40\0\0\0", 8) + std::string(60, '\0');
  write_dicom_slice(tmp / "rle3" / "rle3.dcm", s, [](int, int) { return 0; });
  expect_error<caps::IoError>([&] { caps::read_volume(tmp / "rle3" / "rle3.dcm"); }, "rle3.dcm",
                              "3 segments");
  // A compression caps does not read (MPEG-2) is named, with what to do.
  s.syntax = "1.2.840.10008.1.2.4.100";
  write_dicom_slice(tmp / "mpeg" / "mpeg.dcm", s, [](int, int) { return 0; });
  expect_error<caps::InvalidInput>([&] { caps::read_volume(tmp / "mpeg" / "mpeg.dcm"); }, "mpeg.dcm",
                                   "gdcmconv --raw");
}

/// One slice in Explicit VR Big Endian (1.2.840.10008.1.2.2), as pydicom's MR_small_expb.dcm and
/// rtdose_expb_1frame.dcm: 8 x 6 pixels of `bits` (16 signed or 32 unsigned) in an OW element,
/// stored(x, y) at column x, row y, rescale 1/0.
template <typename F>
void write_big_endian_slice(const fs::path& p, int bits, F stored) {
  auto be16 = [](std::string& s, std::uint16_t v) {
    s += static_cast<char>(v >> 8);
    s += static_cast<char>(v & 0xff);
  };
  auto be32 = [](std::string& s, std::uint32_t v) {
    for (int b = 3; b >= 0; --b) s += static_cast<char>((v >> (8 * b)) & 0xff);
  };
  auto elem = [&](std::string& s, std::uint16_t g, std::uint16_t e, const char* vr,
                  std::string value) {
    if (value.size() % 2) value += std::strcmp(vr, "UI") == 0 ? '\0' : ' ';
    be16(s, g);
    be16(s, e);
    s += vr;
    if (std::strcmp(vr, "OW") == 0) {
      be16(s, 0);
      be32(s, static_cast<std::uint32_t>(value.size()));
    } else {
      be16(s, static_cast<std::uint16_t>(value.size()));
    }
    s += value;
  };
  auto us_be = [&](std::uint16_t v) {
    std::string s;
    be16(s, v);
    return s;
  };
  std::string meta;
  element(meta, 0x0002, 0x0001, "OB", std::string("\0\1", 2));
  element(meta, 0x0002, 0x0002, "UI", "1.2.840.10008.5.1.4.1.1.4");
  element(meta, 0x0002, 0x0003, "UI", "1.2.3.4.9.1");
  element(meta, 0x0002, 0x0010, "UI", "1.2.840.10008.1.2.2");
  std::string out(128, '\0');
  out += "DICM";
  std::string len;
  put_le32(len, static_cast<std::uint32_t>(meta.size()));
  element(out, 0x0002, 0x0000, "UL", len);
  out += meta;
  elem(out, 0x0008, 0x0016, "UI", "1.2.840.10008.5.1.4.1.1.4");
  elem(out, 0x0008, 0x0018, "UI", "1.2.3.4.9.1");
  elem(out, 0x0008, 0x0060, "CS", "MR");
  elem(out, 0x0020, 0x000d, "UI", "1.2.3.4");
  elem(out, 0x0020, 0x000e, "UI", "1.2.3.4.7");
  elem(out, 0x0020, 0x0032, "DS", "-10\\-20\\30");
  elem(out, 0x0020, 0x0037, "DS", "1\\0\\0\\0\\1\\0");
  elem(out, 0x0028, 0x0002, "US", us_be(1));
  elem(out, 0x0028, 0x0004, "CS", "MONOCHROME2");
  elem(out, 0x0028, 0x0010, "US", us_be(6));
  elem(out, 0x0028, 0x0011, "US", us_be(8));
  elem(out, 0x0028, 0x0030, "DS", "0.5\\0.75");
  elem(out, 0x0028, 0x0100, "US", us_be(static_cast<std::uint16_t>(bits)));
  elem(out, 0x0028, 0x0101, "US", us_be(static_cast<std::uint16_t>(bits)));
  elem(out, 0x0028, 0x0102, "US", us_be(static_cast<std::uint16_t>(bits - 1)));
  elem(out, 0x0028, 0x0103, "US", us_be(bits == 16 ? 1 : 0));
  std::string px;
  for (int y = 0; y < 6; ++y)
    for (int x = 0; x < 8; ++x) {
      if (bits == 16) be16(px, static_cast<std::uint16_t>(static_cast<std::int16_t>(stored(x, y))));
      else be32(px, static_cast<std::uint32_t>(stored(x, y)));
    }
  elem(out, 0x7fe0, 0x0010, "OW", px);
  write_bytes(p, out);
}

TEST(VolumeIo, DicomBigEndianPixelsAreSwappedOnce) {
  // GDCM swaps an OW value into host order as it reads; caps swapped each pixel again (pydicom's
  // MR_small_expb.dcm read as -32767..32518 instead of 127..2145).
  TempDir tmp;
  fs::create_directories(tmp / "s16");
  fs::create_directories(tmp / "u32");
  auto v16 = [](int x, int y) { return 300 * x - 700 * y + 129; };  // both signs, both bytes
  auto v32 = [](int x, int y) { return 795000 + 65537 * x + 259 * y; };
  write_big_endian_slice(tmp / "s16" / "be.dcm", 16, v16);
  write_big_endian_slice(tmp / "u32" / "be.dcm", 32, v32);
  const Volume a = caps::read_volume(tmp / "s16" / "be.dcm");
  const Volume b = caps::read_volume(tmp / "u32" / "be.dcm");
  EXPECT_EQ(a.geom.dims, Eigen::Vector3i(8, 6, 1));
  for (int y = 0; y < 6; ++y)
    for (int x = 0; x < 8; ++x) {
      ASSERT_FLOAT_EQ(a.at(x, y, 0), static_cast<float>(v16(x, y))) << x << "," << y;
      ASSERT_FLOAT_EQ(b.at(x, y, 0), static_cast<float>(v32(x, y))) << x << "," << y;
    }
}

TEST(VolumeIo, DicomRtDoseFramesArePlacedByTheirGridFrameOffsets) {
  TempDir tmp;
  SliceSpec s;
  s.ipp = Eigen::Vector3d(5, 6, 7);
  s.frames = 3;
  element(s.before_pixels, 0x3004, 0x000c, "DS", "0\\-2.5\\-5");
  write_dicom_image(tmp / "dose.dcm", s, [](int x, int y, int k) { return 1000 * k + 10 * y + x; });
  const Volume v = caps::read_volume(tmp / "dose.dcm");
  EXPECT_EQ(v.geom.dims, Eigen::Vector3i(8, 6, 3));
  EXPECT_LT((v.geom.spacing_mm - Eigen::Vector3d(0.75, 0.5, 2.5)).norm(), 1e-9);
  EXPECT_LT((v.geom.origin_lps - Eigen::Vector3d(5, 6, 7)).norm(), 1e-9);
  EXPECT_NEAR(v.geom.direction(2, 2), -1.0, 1e-12);  // offsets run towards -z
  EXPECT_FLOAT_EQ(v.at(7, 5, 2), 2000 + 57 - 1024.0f);
}

TEST(VolumeIo, DicomNamedFileReadsItsSeriesBesideADamagedFileOfAnother) {
  // As pydicom's test folder: CT_small.dcm beside MR_truncated.dcm (another series) was refused
  // for the damaged neighbour.
  TempDir tmp;
  write_uniform_series(tmp / "mixed", 3);
  SliceSpec other;
  other.ipp = Eigen::Vector3d(0, 0, 0);
  other.series_uid = "1.2.3.4.5.9";
  write_dicom_slice(tmp / "mixed" / "Z_other.dcm", other, [](int, int) { return 1; });
  const std::string whole = read_bytes(tmp / "mixed" / "Z_other.dcm");
  write_bytes(tmp / "mixed" / "Z_other.dcm", whole.substr(0, whole.find("1.2.3.4.5.9") + 4));
  // A copy of the named slice under another name (another encoding of it, as pydicom's
  // MR_small*.dcm family) and a slice of the series in another orientation.
  fs::copy_file(tmp / "mixed" / "IM001.dcm", tmp / "mixed" / "IM001_copy.dcm");
  SliceSpec loc;
  loc.ipp = Eigen::Vector3d(0, 0, 31);
  loc.row = Eigen::Vector3d(0, 1, 0);
  loc.col = Eigen::Vector3d(0, 0, -1);
  loc.instance = 9;
  write_dicom_slice(tmp / "mixed" / "LOC.dcm", loc, [](int, int) { return 5; });

  const Volume v = caps::read_volume(tmp / "mixed" / "IM001.dcm");
  EXPECT_EQ(v.geom.dims, Eigen::Vector3i(8, 6, 3));
  EXPECT_FLOAT_EQ(v.at(3, 2, 2), 200 + 20 + 3 - 1024.0f);
  std::string notes;
  for (const auto& n : v.notes) notes += n + "\n";
  EXPECT_NE(notes.find("Z_other.dcm"), std::string::npos) << notes;
  EXPECT_NE(notes.find("IM001_copy.dcm"), std::string::npos) << notes;
  // The localizer named reads its own orientation group, not the larger axial one.
  const Volume l = caps::read_volume(tmp / "mixed" / "LOC.dcm");
  EXPECT_EQ(l.geom.dims[2], 1);
  EXPECT_FLOAT_EQ(l.at(0, 0, 0), 5 - 1024.0f);
  // The folder itself is still refused for the damaged file, and for the copies.
  expect_error<caps::IoError>([&] { caps::read_volume(tmp / "mixed"); }, "Z_other.dcm");
  fs::remove(tmp / "mixed" / "Z_other.dcm");
  expect_error<caps::InvalidInput>([&] { caps::read_volume(tmp / "mixed"); }, "IM001",
                                   "same position");
}

TEST(VolumeIo, DicomRescaleSlopeOfZeroIsRefused) {
  // Found by fuzz_dicom: GDCM asserts (aborting the process) on a slope of 0.
  TempDir tmp;
  SliceSpec s;
  s.slope = 0.0;
  write_dicom_slice(tmp / "zero.dcm", s, [](int, int) { return 1; });
  expect_error<caps::InvalidInput>([&] { caps::read_volume(tmp / "zero.dcm"); }, "zero.dcm",
                                   "RescaleSlope");
}

/// A sequence element of undefined length holding `items` (each of undefined length).
std::string sequence(std::uint16_t g, std::uint16_t e, const std::vector<std::string>& items) {
  std::string out;
  put_u16(out, g);
  put_u16(out, e);
  out += std::string("SQ\0\0", 4);
  put_le32(out, 0xffffffffu);
  for (const auto& body : items) {
    put_u16(out, 0xfffe);
    put_u16(out, 0xe000);
    put_le32(out, 0xffffffffu);
    out += body;
    put_u16(out, 0xfffe);
    put_u16(out, 0xe00d);
    put_le32(out, 0);
  }
  put_u16(out, 0xfffe);
  put_u16(out, 0xe0dd);
  put_le32(out, 0);
  return out;
}

TEST(VolumeIo, DicomClassicMultiFrameTakesItsStepFromSpacingBetweenSlices) {
  TempDir tmp;
  SliceSpec s;
  s.ipp = Eigen::Vector3d(5, 6, 7);
  s.frames = 4;
  element(s.group_0018, 0x0018, 0x0088, "DS", "2.5");
  write_dicom_image(tmp / "mf.dcm", s, [](int x, int y, int k) { return 1000 * k + 10 * y + x; });
  const Volume v = caps::read_volume(tmp / "mf.dcm");
  EXPECT_EQ(v.geom.dims, Eigen::Vector3i(8, 6, 4));
  EXPECT_LT((v.geom.spacing_mm - Eigen::Vector3d(0.75, 0.5, 2.5)).norm(), 1e-9);
  EXPECT_LT((v.geom.origin_lps - Eigen::Vector3d(5, 6, 7)).norm(), 1e-9);
  EXPECT_TRUE(v.geom.direction.isIdentity(1e-9));
  EXPECT_FLOAT_EQ(v.at(7, 5, 3), 3000 + 57 - 1024.0f);

  // Without any step the frames cannot be placed.
  SliceSpec bare = s;
  bare.group_0018.clear();
  write_dicom_image(tmp / "nostep.dcm", bare, [](int, int, int) { return 0; });
  expect_error<caps::InvalidInput>([&] { caps::read_volume(tmp / "nostep.dcm"); },
                                   "nostep.dcm", "spacing between frames");
}

TEST(VolumeIo, DicomEnhancedMultiFrameIsPlacedFromItsFunctionalGroups) {
  // Shared groups: PixelSpacing and the orientation; per frame: the position, descending in z
  // by 3 mm (the volume's third axis then points to -z), RLE compressed.
  TempDir tmp;
  auto enhanced = [](const std::vector<double>& zs) {
    std::string measures, orientation;
    element(measures, 0x0028, 0x0030, "DS", "0.5\\0.75");
    element(orientation, 0x0020, 0x0037, "DS", "1\\0\\0\\0\\1\\0");
    std::vector<std::string> per_frame;
    for (double z : zs) {
      std::string position;
      element(position, 0x0020, 0x0032, "DS", ds3(Eigen::Vector3d(-10, -20, z)));
      per_frame.push_back(sequence(0x0020, 0x9113, {position}));
    }
    SliceSpec s;
    s.geometry = false;
    s.frames = static_cast<int>(zs.size());
    s.rle = true;
    s.before_pixels = sequence(0x5200, 0x9229, {sequence(0x0020, 0x9116, {orientation}) +
                                                sequence(0x0028, 0x9110, {measures})}) +
                      sequence(0x5200, 0x9230, per_frame);
    return s;
  };
  write_dicom_image(tmp / "enh.dcm", enhanced({30, 27, 24}),
                    [](int x, int y, int k) { return 1000 * k + 10 * y + x; });
  const Volume v = caps::read_volume(tmp / "enh.dcm");
  EXPECT_EQ(v.geom.dims, Eigen::Vector3i(8, 6, 3));
  EXPECT_LT((v.geom.spacing_mm - Eigen::Vector3d(0.75, 0.5, 3.0)).norm(), 1e-9);
  EXPECT_LT((v.geom.origin_lps - Eigen::Vector3d(-10, -20, 30)).norm(), 1e-9);
  EXPECT_NEAR(v.geom.direction(2, 2), -1.0, 1e-12);
  EXPECT_FLOAT_EQ(v.at(2, 1, 2), 2000 + 12 - 1024.0f);

  // Uneven frames are refused, naming the frame.
  write_dicom_image(tmp / "uneven.dcm", enhanced({30, 27, 20}), [](int, int, int) { return 0; });
  expect_error<caps::InvalidInput>([&] { caps::read_volume(tmp / "uneven.dcm"); }, "uneven.dcm",
                                   "frame 3");
}

TEST(VolumeIo, DicomTiltedUnevenSeriesIsResampledExactlyForLinearFields) {
  // A sheared stack (gantry tilt 20 deg about the row axis) with gaps 2, 2, 3, 3 mm along the
  // normal. The stored values are an affine function of the LPS position, which bilinear +
  // linear interpolation reproduces exactly, so every output voxel can be checked.
  TempDir tmp;
  fs::create_directories(tmp / "tilt");
  const double tilt = caps::deg_to_rad(20.0);
  const Eigen::Vector3d row(1, 0, 0), col(0, std::cos(tilt), -std::sin(tilt));
  const Eigen::Vector3d normal = row.cross(col);
  auto field = [](const Eigen::Vector3d& p) { return 2.0 * p.x() - 3.0 * p.y() + 5.0 * p.z(); };
  const double positions[] = {0, 2, 4, 7, 10};
  const int rows = 20, cols = 10;
  for (int k = 0; k < 5; ++k) {
    SliceSpec s;
    s.rows = rows;
    s.cols = cols;
    s.row = row;
    s.col = col;
    s.intercept = 0;
    s.slope = 0.5;
    s.instance = k + 1;
    // Slices move along z (the table), not along the normal.
    s.ipp = Eigen::Vector3d(-5, -8, 0) + Eigen::Vector3d(0, 0, positions[k] / normal.z());
    write_dicom_slice(tmp / ("tilt/s" + std::to_string(k) + ".dcm"), s, [&](int x, int y) {
      const Eigen::Vector3d p = s.ipp + x * s.col_spacing * row + y * s.row_spacing * col;
      return static_cast<int>(std::lround(field(p) / s.slope));
    });
  }
  const Volume v = caps::read_volume(tmp / "tilt");
  EXPECT_NEAR(v.geom.spacing_mm[2], 2.0, 1e-6);
  EXPECT_EQ(v.geom.dims[2], 6);  // 0..10 mm every 2 mm
  EXPECT_LT((v.geom.direction.col(2) - normal).norm(), 1e-6);
  EXPECT_GT(v.geom.dims[1], rows);  // grown to keep every slice's field of view
  ASSERT_FALSE(v.notes.empty());
  bool noted = false;
  for (const auto& n : v.notes) noted |= n.find("gantry tilt 20.0 deg") != std::string::npos;
  EXPECT_TRUE(noted);
  const auto& d = v.geom.dims;
  int checked = 0;
  for (int k = 0; k < d[2]; ++k)
    for (int j = 0; j < d[1]; ++j)
      for (int i = 0; i < d[0]; ++i) {
        const Eigen::Vector3d p = v.index_to_lps(Eigen::Vector3d(i, j, k));
        // Only voxels inside both bracketing slices' fields of view are exact.
        const double along_col = (p - Eigen::Vector3d(-5, -8, 0)).dot(col);
        const double w = p.dot(normal) - Eigen::Vector3d(-5, -8, 0).dot(normal);
        const double shift = w / normal.z() * Eigen::Vector3d(0, 0, 1).dot(col);
        const double y0 = along_col - shift;  // row coordinate (mm) in the local slice
        if (y0 < 1.5 || y0 > (rows - 1) * 0.5 - 1.5) continue;
        ASSERT_NEAR(v.at(i, j, k), field(p), 0.3) << i << " " << j << " " << k;
        ++checked;
      }
  EXPECT_GT(checked, 200);
}

TEST(VolumeIo, DicomMissingMiddleSliceIsAnError) {
  TempDir tmp;
  write_uniform_series(tmp / "gap", 7);
  fs::remove(tmp / "gap/IM003.dcm");
  expect_error<caps::InvalidInput>([&] { caps::read_volume(tmp / "gap"); }, "gap",
                                   "IM002.dcm and IM004.dcm");
  ReadOptions allow;
  allow.allow_missing_slices = true;
  const Volume v = caps::read_volume(tmp / "gap", allow);
  EXPECT_EQ(v.geom.dims[2], 7);
  EXPECT_NEAR(v.geom.spacing_mm[2], 2.0, 1e-6);
  EXPECT_FLOAT_EQ(v.at(0, 0, 3), 300 - 1024.0f);  // interpolated halfway between 200 and 400
}

TEST(VolumeIo, DicomPicksLargestSeriesAndRejectsUnknownUid) {
  TempDir tmp;
  write_uniform_series(tmp / "two", 4, "1.2.3.4.5.1");
  // Second, smaller series in the same folder, under other file names.
  for (int k = 0; k < 2; ++k) {
    SliceSpec s;
    s.ipp = Eigen::Vector3d(0, 0, 5.0 * k);
    s.series_uid = "1.2.3.4.5.2";
    s.instance = k + 1;
    write_dicom_slice(tmp / ("two/B" + std::to_string(k) + ".dcm"), s, [](int, int) { return 7; });
  }
  write_bytes(tmp / "two/README.txt", "not dicom\n");
  const auto series = caps::list_dicom_series(tmp / "two");
  ASSERT_EQ(series.size(), 2u);
  EXPECT_EQ(series[0].uid, "1.2.3.4.5.1");
  EXPECT_EQ(series[0].n_files, 4);
  const Volume big = caps::read_volume(tmp / "two");
  EXPECT_EQ(big.geom.dims[2], 4);
  ReadOptions pick;
  pick.series_uid = "1.2.3.4.5.2";
  const Volume small = caps::read_volume(tmp / "two", pick);
  EXPECT_EQ(small.geom.dims[2], 2);
  EXPECT_FLOAT_EQ(small.at(0, 0, 0), 7 - 1024.0f);
  pick.series_uid = "9.9.9";
  expect_error<caps::InvalidInput>([&] { caps::read_volume(tmp / "two", pick); }, "9.9.9",
                                   "1.2.3.4.5.2");
}

// The 128-byte preamble, "DICM" and a meta group naming `syntax` and nothing else.
std::string part10_preamble(const std::string& syntax) {
  std::string meta;
  element(meta, 0x0002, 0x0001, "OB", std::string("\0\1", 2));
  element(meta, 0x0002, 0x0010, "UI", syntax);
  std::string out(128, '\0');
  out += "DICM";
  std::string len;
  put_le32(len, static_cast<std::uint32_t>(meta.size()));
  element(out, 0x0002, 0x0000, "UL", len);
  return out + meta;
}

// A file written by write_dicom_slice with `insert` placed just before (0020,000D), so that the
// elements stay in tag order.
std::string dicom_variant(const fs::path& p, const std::string& insert) {
  std::string d = read_bytes(p);
  const auto at = d.find(std::string("\x20\x00\x0d\x00UI", 6));
  EXPECT_NE(at, std::string::npos);
  d.insert(at, insert);
  return d;
}

/// Rewrites the file `p` with the first occurrence of `from` replaced by `to`.
void replace_bytes(const fs::path& p, const std::string& from, const std::string& to) {
  std::string d = read_bytes(p);
  const auto at = d.find(from);
  ASSERT_NE(at, std::string::npos) << p;
  d.replace(at, from.size(), to);
  write_bytes(p, d);
}

std::string tag_len(std::uint16_t g, std::uint16_t e, std::uint32_t length) {
  std::string s;
  put_u16(s, g);
  put_u16(s, e);
  put_le32(s, length);
  return s;
}

TEST(VolumeIo, DicomStructureIsCheckedBeforeGdcmReadsIt) {
  TempDir tmp;
  write_uniform_series(tmp / "seq", 3);
  // A well-formed Referenced Image Sequence (0008,1140), SQ of undefined length holding one item
  // of undefined length: read as before.
  std::string sq("\x08\x00\x40\x11SQ\0\0", 8);
  put_le32(sq, 0xffffffffu);
  std::string item_body;
  element(item_body, 0x0008, 0x1150, "UI", "1.2.840.10008.5.1.4.1.1.2");
  const std::string good_sq = sq + tag_len(0xfffe, 0xe000, 0xffffffffu) + item_body +
                              tag_len(0xfffe, 0xe00d, 0) + tag_len(0xfffe, 0xe0dd, 0);
  for (const auto& e : fs::directory_iterator(tmp / "seq"))
    write_bytes(e.path(), dicom_variant(e.path(), good_sq));
  const Volume v = caps::read_volume(tmp / "seq");
  EXPECT_EQ(v.geom.dims, Eigen::Vector3i(8, 6, 3));
  EXPECT_FLOAT_EQ(v.at(7, 5, 2), 200 + 50 + 7 - 1024.0f);

  // The same item without its delimiter: GDCM's parse would go astray; refused as damaged.
  write_uniform_series(tmp / "bad_item", 3);
  const fs::path bad = tmp / "bad_item/IM001.dcm";
  write_bytes(bad, dicom_variant(bad, sq + tag_len(0xfffe, 0xe000, 0xffffffffu) + item_body +
                                          tag_len(0xfffe, 0xe0dd, 0)));
  expect_error<caps::IoError>([&] { caps::read_volume(tmp / "bad_item"); }, "IM001.dcm",
                              "damaged");
  // An item outside any sequence.
  write_uniform_series(tmp / "stray_item", 2);
  const fs::path stray = tmp / "stray_item/IM000.dcm";
  write_bytes(stray, dicom_variant(stray, tag_len(0xfffe, 0xe000, 4) + "abcd"));
  expect_error<caps::IoError>([&] { caps::read_volume(tmp / "stray_item"); }, "IM000.dcm",
                              "outside a sequence");

  // Implicit VR little endian with pixel data of undefined length (found by fuzz_dicom: GDCM
  // asserts, aborting the process): refused before GDCM reads it.
  std::string implicit = part10_preamble("1.2.840.10008.1.2");
  implicit += tag_len(0x0008, 0x0060, 2) + "CT";
  implicit += tag_len(0x0020, 0x000e, 6) + "1.2.3" + std::string(1, '\0');
  implicit += tag_len(0x0028, 0x0010, 2) + us(2) + tag_len(0x0028, 0x0011, 2) + us(2);
  implicit += tag_len(0x7fe0, 0x0010, 0xffffffffu) + tag_len(0xfffe, 0xe000, 8) +
              std::string(8, '\0') + tag_len(0xfffe, 0xe0dd, 0);
  write_bytes(tmp / "implicit.dcm", implicit);
  expect_error<caps::IoError>([&] { caps::read_volume(tmp / "implicit.dcm"); }, "implicit.dcm",
                              "pixel data of undefined length");

  // RLE (compressed) transfer syntax over pixel data of defined length (found by fuzz_dicom:
  // GDCM took fragment lengths from the pixel bytes and allocated 808 MB for a 1 KB file).
  fs::create_directories(tmp / "defined");
  write_dicom_slice(tmp / "defined/rle.dcm", SliceSpec{}, [](int, int) { return 0x3030; });
  replace_bytes(tmp / "defined/rle.dcm", std::string("1.2.840.10008.1.2.1\0", 20),
                std::string("1.2.840.10008.1.2.5\0", 20));
  expect_error<caps::IoError>([&] { caps::read_volume(tmp / "defined/rle.dcm"); }, "rle.dcm",
                              "pixel data of defined length in a compressed transfer syntax");
  // Two transfer syntaxes in the meta group (found by fuzz_dicom: GDCM read the data set in
  // another syntax than the walk and allocated 808 MB): refused.
  fs::create_directories(tmp / "twice");
  write_dicom_slice(tmp / "twice/ts.dcm", SliceSpec{}, [](int, int) { return 0; });
  const std::string ts = std::string("\x02\x00\x10\x00UI\x14\x00", 8) + "1.2.840.10008.1.2.1" +
                         std::string(1, '\0');
  replace_bytes(tmp / "twice/ts.dcm", ts, ts + ts);
  expect_error<caps::IoError>([&] { caps::read_volume(tmp / "twice/ts.dcm"); }, "ts.dcm",
                              "meta group elements repeated or out of order");

  // Deflated Explicit VR Little Endian: refused with what to do (GDCM would inflate it without
  // a bound).
  std::string deflated = part10_preamble("1.2.840.10008.1.2.1.99");
  deflated += deflate_stored(std::string(64, '\0'));
  write_bytes(tmp / "deflated.dcm", deflated);
  expect_error<caps::InvalidInput>([&] { caps::read_volume(tmp / "deflated.dcm"); },
                                   "deflated.dcm", "gdcmconv --raw");
}

TEST(VolumeIo, GeHeadTiltIsResampledToHu) {
  const fs::path p = kData / "ct/ge-head-tilt";
  if (!fs::exists(p)) GTEST_SKIP() << p;
  const Volume v = caps::read_volume(p);
  EXPECT_EQ(v.modality, Modality::CT);
  EXPECT_EQ(v.geom.dims[0], 512);
  EXPECT_GE(v.geom.dims[1], 512);
  // Gaps are 4.0 mm (x13), 1.08 mm (one junction) and 7.0 mm (x13): smallest gap 1.08 mm.
  EXPECT_NEAR(v.geom.spacing_mm[2], 1.081, 0.01);
  EXPECT_NEAR(v.geom.spacing_mm[0], 0.488, 1e-3);
  EXPECT_NEAR(v.geom.dims[2] * v.geom.spacing_mm[2], 145.0, 3.0);
  // The normal of an 18.5 deg tilted gantry.
  EXPECT_NEAR(v.geom.direction(2, 2), std::cos(caps::deg_to_rad(18.5)), 1e-3);
  bool noted = false;
  for (const auto& n : v.notes) noted |= n.find("gantry tilt 18.5 deg") != std::string::npos;
  EXPECT_TRUE(noted);
  // Air in front of the face and brain in the middle of the head, in HU.
  const auto& d = v.geom.dims;
  const float air = v.at(d[0] / 2, 40, d[2] / 2);
  EXPECT_LT(air, -900.0f);
  EXPECT_GT(air, -1100.0f);
  const Eigen::Vector3d mid = v.lps_to_index(Eigen::Vector3d(0, 0, 60));
  const float brain = v.at(static_cast<int>(mid.x()), static_cast<int>(mid.y()),
                           static_cast<int>(mid.z()));
  EXPECT_GT(brain, 10.0f);
  EXPECT_LT(brain, 60.0f);
}

// ---------------------------------------------------------------------------------------------
// Bad inputs

TEST(VolumeIo, BadInputsGiveTheRightErrorNamingTheFile) {
  TempDir tmp;
  // A valid .nii/.nii.gz to damage.
  Volume v;
  v.geom.dims = Eigen::Vector3i(30, 30, 30);
  v.data.assign(v.geom.n_voxels(), 1.0f);
  for (std::size_t n = 0; n < v.data.size(); ++n) v.data[n] = static_cast<float>(n % 977);
  caps::write_nifti(v, tmp / "ok.nii.gz");
  caps::write_nifti(v, tmp / "ok.nii");
  const std::string gz = read_bytes(tmp / "ok.nii.gz");
  write_bytes(tmp / "cut.nii.gz", gz.substr(0, gz.size() / 2));
  expect_error<caps::IoError>([&] { caps::read_volume(tmp / "cut.nii.gz"); }, "cut.nii.gz");
  const std::string nii = read_bytes(tmp / "ok.nii");
  write_bytes(tmp / "cut.nii", nii.substr(0, nii.size() - 100));
  expect_error<caps::IoError>([&] { caps::read_volume(tmp / "cut.nii"); }, "cut.nii",
                              "truncated");

  write_bytes(tmp / "x.nii", "this is a text file, not an image\n");
  expect_error<caps::InvalidInput>([&] { caps::read_volume(tmp / "x.nii"); }, "x.nii");
  expect_error<caps::IoError>([&] { caps::read_volume(tmp / "missing.nrrd"); }, "missing.nrrd");
  expect_error<caps::IoError>([&] { caps::read_volume(tmp / "nothing_here"); }, "nothing_here");
  write_bytes(tmp / "img.xyz", "x");
  expect_error<caps::InvalidInput>([&] { caps::read_volume(tmp / "img.xyz"); }, "img.xyz",
                                   ".nii.gz");

  // NRRD: truncated detached raw data, zero and absurd sizes.
  write_bytes(tmp / "short.raw", std::string(100, '\0'));
  write_bytes(tmp / "short.nhdr", "NRRD0004\ntype: short\ndimension: 3\nsizes: 10 10 10\n"
                                  "encoding: raw\nendian: little\ndata file: short.raw\n");
  expect_error<caps::IoError>([&] { caps::read_volume(tmp / "short.nhdr"); }, "short.nhdr");
  write_bytes(tmp / "zero.nrrd", "NRRD0004\ntype: short\ndimension: 3\nsizes: 10 0 10\n"
                                 "encoding: raw\nendian: little\n\n");
  expect_error<caps::InvalidInput>([&] { caps::read_volume(tmp / "zero.nrrd"); }, "zero.nrrd");
  write_bytes(tmp / "huge.nrrd", "NRRD0004\ntype: short\ndimension: 3\n"
                                 "sizes: 100000 100000 100000\nencoding: raw\nendian: little\n\n");
  expect_error<caps::InvalidInput>([&] { caps::read_volume(tmp / "huge.nrrd"); }, "huge.nrrd",
                                   "sizes");

  // MetaImage: header/data size mismatch, zero dims, absurd dims, corrupt compressed data.
  const std::string mha_head = "ObjectType = Image\nNDims = 3\nElementType = MET_SHORT\n";
  write_bytes(tmp / "mismatch.mha", mha_head + "DimSize = 4 4 4\nElementDataFile = LOCAL\n" +
                                        std::string(100, '\0'));
  expect_error<caps::IoError>([&] { caps::read_volume(tmp / "mismatch.mha"); }, "mismatch.mha",
                              "128");
  write_bytes(tmp / "big.raw", std::string(200, '\0'));
  write_bytes(tmp / "mismatch.mhd", mha_head + "DimSize = 4 4 4\nElementDataFile = big.raw\n");
  expect_error<caps::InvalidInput>([&] { caps::read_volume(tmp / "mismatch.mhd"); },
                                   "mismatch.mhd", "200");
  write_bytes(tmp / "zero.mha", mha_head + "DimSize = 4 0 4\nElementDataFile = LOCAL\n");
  expect_error<caps::InvalidInput>([&] { caps::read_volume(tmp / "zero.mha"); }, "zero.mha",
                                   "DimSize");
  write_bytes(tmp / "huge.mha",
              mha_head + "DimSize = 100000 100000 100000\nElementDataFile = LOCAL\n");
  expect_error<caps::InvalidInput>([&] { caps::read_volume(tmp / "huge.mha"); }, "huge.mha",
                                   "DimSize");
  write_bytes(tmp / "bad.mha", mha_head + "DimSize = 4 4 4\nCompressedData = True\n"
                                          "ElementDataFile = LOCAL\n" + std::string(50, 'z'));
  expect_error<caps::IoError>([&] { caps::read_volume(tmp / "bad.mha"); }, "bad.mha");
  write_bytes(tmp / "nohdr.mhd", "hello = world\n");
  expect_error<caps::InvalidInput>([&] { caps::read_volume(tmp / "nohdr.mhd"); }, "nohdr.mhd");

  // InVesalius: not a tar.
  write_bytes(tmp / "p.inv3", "definitely not a gzipped tar archive\n");
  expect_error<caps::InvalidInput>([&] { caps::read_volume(tmp / "p.inv3"); }, "p.inv3");
  write_bytes(tmp / "gz.inv3", gzip_stored(std::string(2000, 'a')));
  expect_error<caps::InvalidInput>([&] { caps::read_volume(tmp / "gz.inv3"); }, "gz.inv3");

  // DICOM: an empty folder, a folder of non-DICOM files, a non-DICOM .dcm file.
  fs::create_directories(tmp / "empty");
  expect_error<caps::InvalidInput>([&] { caps::read_volume(tmp / "empty"); }, "empty");
  fs::create_directories(tmp / "texts");
  write_bytes(tmp / "texts/a.txt", "hello\n");
  expect_error<caps::InvalidInput>([&] { caps::read_volume(tmp / "texts"); }, "texts");
  write_bytes(tmp / "fake.dcm", std::string(300, 'q'));
  expect_error<caps::InvalidInput>([&] { caps::read_volume(tmp / "fake.dcm"); }, "fake.dcm");
  // A DICOM slice whose pixel data were cut short.
  write_uniform_series(tmp / "trunc", 3);
  const std::string dcm = read_bytes(tmp / "trunc/IM001.dcm");
  write_bytes(tmp / "trunc/IM001.dcm", dcm.substr(0, dcm.size() - 40));
  try {
    caps::read_volume(tmp / "trunc");
    ADD_FAILURE() << "truncated DICOM slice accepted";
  } catch (const caps::Error& e) {
    EXPECT_NE(std::string(e.what()).find("trunc"), std::string::npos) << e.what();
  }
}

// A gzip (or zlib) stream cut short after the bytes its reader needs (the end marker, CRC and
// length lost) was accepted by every reader: each now requires the stream's end.
TEST(VolumeIo, CompressedStreamsCutShortAreRefusedByEveryReader) {
  TempDir tmp;
  Volume v;
  v.geom.dims = Eigen::Vector3i(12, 10, 8);
  v.data.resize(v.geom.n_voxels());
  for (std::size_t n = 0; n < v.data.size(); ++n) v.data[n] = static_cast<float>(n % 301);
  // NIfTI .nii.gz written by caps, its 8-byte gzip trailer cut off.
  caps::write_nifti(v, tmp / "whole.nii.gz");
  const std::string nii = read_bytes(tmp / "whole.nii.gz");
  EXPECT_NO_THROW(caps::read_volume(tmp / "whole.nii.gz"));
  write_bytes(tmp / "cut.nii.gz", nii.substr(0, nii.size() - 8));
  expect_error<caps::IoError>([&] { caps::read_volume(tmp / "cut.nii.gz"); }, "cut.nii.gz",
                              "truncated");

  std::vector<std::uint16_t> vals(6 * 5 * 4);
  for (std::size_t n = 0; n < vals.size(); ++n) vals[n] = static_cast<std::uint16_t>(n * 7);
  const std::string head = "NRRD0004\ntype: ushort\ndimension: 3\nsizes: 6 5 4\n"
                           "spacings: 0.5 0.6 0.7\nendian: little\nencoding: gzip\n";
  const std::string gz = gzip_stored(raw_bytes(vals));
  // NRRD, gzip data attached: whole, then without its trailer.
  write_bytes(tmp / "whole.nrrd", head + "\n" + gz);
  EXPECT_NO_THROW(caps::read_volume(tmp / "whole.nrrd"));
  // teem notices a missing CRC itself; with the CRC there and the length gone it read on.
  write_bytes(tmp / "cut.nrrd", head + "\n" + gz.substr(0, gz.size() - 4));
  expect_error<caps::IoError>([&] { caps::read_volume(tmp / "cut.nrrd"); }, "cut.nrrd",
                              "cut short");
  // NRRD, gzip data in a detached file.
  write_bytes(tmp / "d.raw.gz", gz.substr(0, gz.size() - 4));
  write_bytes(tmp / "d.nhdr", head + "data file: d.raw.gz\n");
  expect_error<caps::IoError>([&] { caps::read_volume(tmp / "d.nhdr"); }, "d.nhdr", "cut short");
  write_bytes(tmp / "d.raw.gz", gz);
  EXPECT_NO_THROW(caps::read_volume(tmp / "d.nhdr"));

  // MetaImage, zlib data without its Adler-32.
  const std::string z = zlib_stored(raw_bytes(vals));
  auto mha = [&](const std::string& data) {
    return "ObjectType = Image\nNDims = 3\nBinaryData = True\nCompressedData = True\n"
           "CompressedDataSize = " + std::to_string(data.size()) +
           "\nDimSize = 6 5 4\nElementType = MET_USHORT\nElementDataFile = LOCAL\n" + data;
  };
  write_bytes(tmp / "whole.mha", mha(z));
  EXPECT_NO_THROW(caps::read_volume(tmp / "whole.mha"));
  write_bytes(tmp / "cut.mha", mha(z.substr(0, z.size() - 4)));
  expect_error<caps::IoError>([&] { caps::read_volume(tmp / "cut.mha"); }, "cut.mha", "cut short");

  // InVesalius: the project's gzipped tar cut short after the image member.
  if (!fs::exists(kCranium)) GTEST_SKIP() << "invesalius-examples not installed";
  const std::string inv = read_bytes(kCranium);
  write_bytes(tmp / "cut.inv3", inv.substr(0, inv.size() - 8));
  expect_error<caps::IoError>([&] { caps::read_volume(tmp / "cut.inv3"); }, "cut.inv3",
                              "truncated");
}

namespace caps {

TEST(VolumeIo, IntegerVolumesAreWrittenAsInt16) {
  Volume v;
  v.geom.dims = {6, 5, 4};
  v.geom.spacing_mm = {0.5, 0.7, 1.2};
  v.geom.origin_lps = {-3, 4, 10};
  v.data.resize(v.geom.n_voxels());
  for (std::size_t i = 0; i < v.data.size(); ++i) v.data[i] = static_cast<float>(int(i * 37 % 3000) - 1024);
  v.source = "ints";
  const auto dir = std::filesystem::temp_directory_path() / ("caps_int16_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  write_nifti(v, dir / "a.nii");
  EXPECT_EQ(std::filesystem::file_size(dir / "a.nii"), 352u + 2u * v.data.size());
  const Volume r = read_volume(dir / "a.nii");
  EXPECT_EQ(r.data, v.data);
  EXPECT_TRUE(r.geom.origin_lps.isApprox(v.geom.origin_lps, 1e-5));
  v.data[3] = 0.25f;  // one fraction: float32
  write_nifti(v, dir / "b.nii");
  EXPECT_EQ(std::filesystem::file_size(dir / "b.nii"), 352u + 4u * v.data.size());
  std::filesystem::remove_all(dir);
}

}  // namespace caps
