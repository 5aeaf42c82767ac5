// NIfTI-1/2 reading through nifti2_io. NIfTI world coordinates are RAS; caps is LPS, so the first
// two rows of the chosen affine are negated. Affine priority follows the NIfTI-1 standard
// (nifti1.h, "METHOD 3 / 2 / 1"): sform if sform_code > 0, else qform if qform_code > 0, else the
// pixdim-only Analyze fallback.
//
// Not-a-number voxels: resampling tools write NaN where the output grid leaves the input's field
// of view. A NaN voxel joined to the grid's boundary through NaN voxels (6-neighbours) is taken as
// outside the field of view: it gets the smallest finite value and Volume::acquired 0 (a note
// counts them). A NaN region enclosed by data is damage inside the image: refused.

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "caps/core/error.hpp"
#include "volume_io_detail.hpp"

#include <nifti2_io.h>

namespace fs = std::filesystem;

namespace caps::detail {
namespace {

struct NiftiFree {
  void operator()(nifti_image* nim) const { nifti_image_free(nim); }
};
using NiftiPtr = std::unique_ptr<nifti_image, NiftiFree>;

std::string nifti_element_type(int datatype) {
  switch (datatype) {
    case DT_UINT8: return "u8";
    case DT_INT8: return "i8";
    case DT_UINT16: return "u16";
    case DT_INT16: return "i16";
    case DT_UINT32: return "u32";
    case DT_INT32: return "i32";
    case DT_UINT64: return "u64";
    case DT_INT64: return "i64";
    case DT_FLOAT32: return "f32";
    case DT_FLOAT64: return "f64";
    default: return "";
  }
}

bool is_gz(const fs::path& file) { return to_lower(file.extension().string()) == ".gz"; }

template <typename T>
T swapped(T v, bool swap) {
  if (swap) {
    char b[sizeof(T)];
    std::memcpy(b, &v, sizeof(T));
    std::reverse(b, b + sizeof(T));
    std::memcpy(&v, b, sizeof(T));
  }
  return v;
}

// The header's fields as the file stores them: nifti2_io replaces non-finite pixdim with 1, a
// non-finite quaternion or offset with 0 and an impossible vox_offset with its own, silently.
struct RawHeader {
  std::array<double, 3> pixdim{1, 1, 1};
  double vox_offset = 0;
  int qform_code = 0, sform_code = 0;
  std::array<double, 6> qform{};  ///< quatern_b, c, d, qoffset_x, y, z
  std::array<double, 12> srow{};  ///< srow_x, srow_y, srow_z
  bool read = false;              ///< false: neither a NIfTI-1 nor a NIfTI-2 header
};

RawHeader raw_header(const std::string& name) {
  znzFile f = znzopen(name.c_str(), "rb", nifti_is_gzfile(name.c_str()));
  if (znz_isnull(f)) throw IoError(cat(name, ": cannot open the file for reading (permissions?)"));
  char h[540] = {};
  const std::size_t got = znzread(h, 1, sizeof h, f);
  znzclose(f);
  std::int32_t size = 0;
  std::memcpy(&size, h, 4);
  const bool swap = size != 348 && size != 540;
  size = swapped(size, swap);
  RawHeader out;
  auto f32 = [&](std::size_t at) {
    float x;
    std::memcpy(&x, h + at, 4);
    return static_cast<double>(swapped(x, swap));
  };
  auto f64 = [&](std::size_t at) {
    double x;
    std::memcpy(&x, h + at, 8);
    return swapped(x, swap);
  };
  if (size == 348 && got >= 348) {
    out.read = true;
    for (int d = 1; d <= 3; ++d) out.pixdim[d - 1] = f32(76 + 4 * d);
    out.vox_offset = f32(108);
    std::int16_t q, s;
    std::memcpy(&q, h + 252, 2);
    std::memcpy(&s, h + 254, 2);
    out.qform_code = swapped(q, swap);
    out.sform_code = swapped(s, swap);
    for (int i = 0; i < 6; ++i) out.qform[i] = f32(256 + 4 * i);
    for (int i = 0; i < 12; ++i) out.srow[i] = f32(280 + 4 * i);
  } else if (size == 540 && got >= 540) {
    out.read = true;
    for (int d = 1; d <= 3; ++d) out.pixdim[d - 1] = f64(104 + 8 * d);
    std::int64_t off;
    std::memcpy(&off, h + 168, 8);
    out.vox_offset = static_cast<double>(swapped(off, swap));
    std::int32_t q, s;
    std::memcpy(&q, h + 344, 4);
    std::memcpy(&s, h + 348, 4);
    out.qform_code = swapped(q, swap);
    out.sform_code = swapped(s, swap);
    for (int i = 0; i < 6; ++i) out.qform[i] = f64(352 + 8 * i);
    for (int i = 0; i < 12; ++i) out.srow[i] = f64(400 + 8 * i);
  }
  return out;
}

// Refuses orientation fields that are not numbers where they decide the orientation (the sform
// if sform_code > 0, else the qform if qform_code > 0), and a vox_offset other than the one
// nifti2_io will read from: an orientation invented from zeros, or voxels read from a place the
// header does not say, would be read without a word.
void check_raw_header(const std::string& name, const RawHeader& h, double iname_offset) {
  if (!h.read) return;
  static constexpr const char* kQ[] = {"quatern_b", "quatern_c", "quatern_d",
                                       "qoffset_x", "qoffset_y", "qoffset_z"};
  static constexpr const char* kS[] = {"srow_x", "srow_y", "srow_z"};
  if (h.sform_code > 0) {
    for (int i = 0; i < 12; ++i)
      if (!std::isfinite(h.srow[i]))
        throw InvalidInput(cat(name, ": header field ", kS[i / 4], "[", i % 4, "] = ", h.srow[i],
                               " is not a finite number (sform_code ", h.sform_code,
                               "): the orientation is damaged; re-export the image"));
  } else if (h.qform_code > 0) {
    for (int i = 0; i < 6; ++i)
      if (!std::isfinite(h.qform[i]))
        throw InvalidInput(cat(name, ": header field ", kQ[i], " = ", h.qform[i],
                               " is not a finite number (qform_code ", h.qform_code,
                               ", sform_code 0): the qform, the only orientation the header "
                               "gives, is damaged; re-export the image"));
  }
  // vox_offset below the header is taken as "right after it" (old writers leave 0).
  if (!std::isfinite(h.vox_offset) || h.vox_offset < 0 ||
      (h.vox_offset > 352 && std::floor(h.vox_offset) != iname_offset))
    throw InvalidInput(cat(name, ": header field vox_offset = ", h.vox_offset,
                           " is not where the voxel data can start (the file would be read from ",
                           iname_offset, "); the header is damaged"));
}

// One volume's voxel bytes (`n_bytes` from `skip` bytes past the data offset), read here rather
// than by nifti_image_load, which reads every volume and replaces non-finite floats with 0
// silently. A single-file image (.nii, .nii.gz) is read from `name` itself, never from another
// file nifti2_io finds by its base name; a pair from its .img.
std::vector<char> read_volume_bytes(const std::string& name, const nifti_image& nim,
                                    std::uint64_t skip, std::size_t n_bytes) {
  const bool single = nim.nifti_type == NIFTI_FTYPE_NIFTI1_1 ||
                      nim.nifti_type == NIFTI_FTYPE_NIFTI2_1;
  const std::string data_file = single || !nim.iname ? name : std::string(nim.iname);
  znzFile f = znzopen(data_file.c_str(), "rb", nifti_is_gzfile(data_file.c_str()));
  if (znz_isnull(f))
    throw IoError(cat(data_file, ": cannot open the image data for reading (missing or permissions?)"));
  std::vector<char> raw;
  bool ok = znzseek(f, static_cast<znz_off_t>(nim.iname_offset + skip), SEEK_SET) >= 0;
  if (ok) {
    raw.resize(n_bytes);
    std::size_t got = 0;
    while (ok && got < n_bytes) {
      const std::size_t want = std::min<std::size_t>(n_bytes - got, std::size_t(1) << 28);
      const std::size_t r = znzread(raw.data() + got, 1, want, f);
      got += r;
      ok = r == want;
    }
  }
  znzclose(f);
  if (!ok)
    throw IoError(cat(name, ": the voxel data could not be read (truncated or corrupt ",
                      is_gz(fs::path(data_file)) ? "gzip stream" : "file",
                      data_file == name ? std::string() : cat(" ", data_file),
                      "); re-export or re-download it"));
  // zlib's gzread stops once it has the bytes asked for: a stream cut short after them (its end
  // and checksum) would pass unseen.
  if (nifti_is_gzfile(data_file.c_str()))
    require_whole_gzip(fs::path(name), fs::path(data_file), 0,
                       static_cast<std::uint64_t>(nim.iname_offset) + skip + n_bytes);
  return raw;
}

// Intents whose voxels are not one value of an image at a place: matrices, vectors, point sets,
// meshes, RGB, shapes, FSL warp fields (2006..) and CIFTI (3000..).
bool is_image_intent(int code) { return !((code >= 1004 && code <= 1010) || code >= 2002); }

// The NaN rule above: NaN joined to the boundary -> outside the field (smallest finite value,
// acquired 0); NaN enclosed by data -> InvalidInput.
void mark_nan_outside_field(const std::string& name, Volume& v) {
  const auto& g = v.geom;
  const std::size_t n = v.data.size();
  std::size_t n_nan = 0;
  float lo = std::numeric_limits<float>::infinity();
  for (float x : v.data) {
    if (std::isnan(x)) ++n_nan;
    else if (std::isfinite(x)) lo = std::min(lo, x);
  }
  if (n_nan == 0) return;
  if (!std::isfinite(lo))
    throw InvalidInput(cat(name, ": no voxel holds a finite number; the data are damaged or empty"));
  const int nx = g.dims[0], ny = g.dims[1], nz = g.dims[2];
  std::vector<std::uint8_t> outside(n, 0);
  std::vector<std::size_t> stack;
  auto push = [&](int i, int j, int k) {
    const std::size_t at = g.linear(i, j, k);
    if (!outside[at] && std::isnan(v.data[at])) {
      outside[at] = 1;
      stack.push_back(at);
    }
  };
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i)
        if (i == 0 || j == 0 || k == 0 || i == nx - 1 || j == ny - 1 || k == nz - 1) push(i, j, k);
  while (!stack.empty()) {
    const std::size_t at = stack.back();
    stack.pop_back();
    const int i = static_cast<int>(at % nx), j = static_cast<int>((at / nx) % ny),
              k = static_cast<int>(at / (static_cast<std::size_t>(nx) * ny));
    if (i > 0) push(i - 1, j, k);
    if (i + 1 < nx) push(i + 1, j, k);
    if (j > 0) push(i, j - 1, k);
    if (j + 1 < ny) push(i, j + 1, k);
    if (k > 0) push(i, j, k - 1);
    if (k + 1 < nz) push(i, j, k + 1);
  }
  std::size_t n_out = 0;
  for (std::size_t at = 0; at < n; ++at) {
    if (outside[at]) {
      ++n_out;
      continue;
    }
    if (std::isnan(v.data[at])) {
      const std::size_t inside = n_nan - std::count(outside.begin(), outside.end(), 1);
      throw InvalidInput(cat(name, ": ", inside, " NaN voxel(s) enclosed by data, first at (",
                             at % nx, ", ", (at / nx) % ny, ", ",
                             at / (static_cast<std::size_t>(nx) * ny), "), are not finite "
                             "numbers; NaN is read as outside the field of view only where it "
                             "reaches the edge of the grid: the data are damaged"));
    }
  }
  v.acquired.assign(n, 1);
  for (std::size_t at = 0; at < n; ++at)
    if (outside[at]) {
      v.data[at] = lo;
      v.acquired[at] = 0;
    }
  v.notes.push_back(cat(n_out, " not-a-number voxel(s) reaching the edge of the grid taken as "
                        "outside the field of view (set to the smallest value, ", lo, ")"));
}

}  // namespace

Volume read_nifti(const fs::path& file, const ReadOptions& options) {
  const auto file_bytes = file_size_or_throw(file);
  nifti_set_debug_level(0);
  const std::string name = file.string();

  NiftiPtr nim(nifti_image_read(name.c_str(), 0));
  if (!nim)
    throw InvalidInput(cat(name, ": not a readable NIfTI-1/2 file (the header is missing, damaged "
                                 "or the file is something else); check that the file is a NIfTI "
                                 "image and, if compressed, that it is gzip"));

  if (nim->dim[0] < 1 || nim->dim[0] > 7)
    throw InvalidInput(cat(name, ": header field dim[0] = ", nim->dim[0],
                           " must be 1..7; the header is damaged"));
  if (nim->nifti_type == NIFTI_FTYPE_ANALYZE)
    throw InvalidInput(cat(name, ": an Analyze 7.5 header (no NIfTI magic): it has no "
                                 "orientation, so left and right are unknown; convert it to "
                                 "NIfTI with its orientation set"));
  if (!is_image_intent(nim->intent_code))
    throw InvalidInput(cat(name, ": NIfTI intent ", nim->intent_code, " (",
                           nifti_intent_string(nim->intent_code),
                           ") is not an image of one value per voxel (a matrix, vectors, points, "
                           "a mesh or CIFTI data); caps reads CT/MR volumes"));
  // The header file: a pair named by its .img has its header in nim->fname.
  const std::string header_name = nim->fname ? std::string(nim->fname) : name;
  const RawHeader raw = raw_header(header_name);
  for (int d = 1; d <= 3; ++d)
    if (!std::isfinite(raw.pixdim[d - 1]))
      throw InvalidInput(cat(name, ": header field pixdim[", d, "] = ", raw.pixdim[d - 1],
                             " is not a finite number; the header is damaged"));
  check_raw_header(name, raw, static_cast<double>(nim->iname_offset));
  Volume v;
  v.source = name;
  v.format = nim->nifti_type >= NIFTI_FTYPE_NIFTI2_1 ? "NIfTI-2" : "NIfTI-1";
  double extra = 1;  // a double: dims 4..7 are 64-bit and their product may overflow
  for (int d = 4; d <= nim->dim[0]; ++d) extra *= static_cast<double>(std::max<int64_t>(nim->dim[d], 1));
  if (options.volume_index < 0 || static_cast<double>(options.volume_index) >= extra)
    throw InvalidInput(cat(name, ": volume index ", options.volume_index, " is out of range: the "
                           "file holds ", extra, " volume(s) (dims 4..7), numbered from 0"));
  if (extra > 1)
    v.notes.push_back(cat("the file holds ", extra, " volumes (dims 4..7); read volume ",
                          options.volume_index, " (choose another with --volume-index)"));

  const std::string type = nifti_element_type(nim->datatype);
  if (type.empty())
    throw InvalidInput(cat(name, ": datatype ", nim->datatype, " (",
                           nifti_datatype_string(nim->datatype),
                           ") is not a scalar numeric type; caps reads integer and float images "
                           "only (convert RGB/complex images to a scalar first)"));
  if (static_cast<std::size_t>(nim->nbyper) != type_size(type))
    throw InvalidInput(cat(name, ": bitpix/datatype mismatch (", nim->nbyper,
                           " bytes per voxel for ", nifti_datatype_string(nim->datatype), ")"));

  const double n3 = static_cast<double>(nim->nx) * nim->ny * nim->nz;
  const double needed = static_cast<double>(nim->iname_offset) + n3 * extra * nim->nbyper;
  // Only uncompressed single files can be size-checked up front; for .gz the load below reports
  // a short read.
  if (!is_gz(file) && nim->iname && std::string(nim->iname) == name &&
      static_cast<double>(file_bytes) < needed)
    throw IoError(cat(name, ": truncated: the header needs ", needed, " bytes (offset ",
                      nim->iname_offset, " + ", nim->nx, "x", nim->ny, "x", nim->nz,
                      " voxels of ", nim->nbyper, " bytes) but the file has ", file_bytes,
                      "; re-export or re-download it"));
  // Only one volume is read: its raw bytes are held beside the float volume.
  check_dims(file, "dim[1..3]", {nim->nx, nim->ny, nim->nz}, options, n3 * nim->nbyper);

  auto& g = v.geom;
  g.dims = Eigen::Vector3i(static_cast<int>(nim->nx), static_cast<int>(nim->ny),
                           static_cast<int>(nim->nz));
  {
    const std::size_t volume_bytes = g.n_voxels() * static_cast<std::size_t>(nim->nbyper);
    const std::vector<char> raw = read_volume_bytes(
        name, *nim, static_cast<std::uint64_t>(options.volume_index) * volume_bytes, volume_bytes);
    v.data.resize(g.n_voxels());
    decode_to_float(raw.data(), v.data.size(), type, nim->byteorder != nifti_short_order(),
                    v.data.data());
  }

  const double slope = nim->scl_slope, inter = nim->scl_inter;
  if (std::isfinite(slope) && slope != 0.0 && std::isfinite(inter) &&
      !(slope == 1.0 && inter == 0.0)) {
    for (auto& x : v.data) x = static_cast<float>(slope * x + inter);
    v.notes.push_back(cat("applied scl_slope ", slope, " and scl_inter ", inter));
  }

  double A[3][4];
  auto from = [&](const nifti_dmat44& M) {
    for (int r = 0; r < 3; ++r) {
      const double s = r < 2 ? -1.0 : 1.0;  // RAS -> LPS
      for (int c = 0; c < 4; ++c) A[r][c] = s * M.m[r][c];
    }
  };
  if (nim->sform_code > 0) {
    from(nim->sto_xyz);
    v.notes.push_back(cat("orientation from the sform (code ", nim->sform_code, ")"));
  } else if (nim->qform_code > 0) {
    from(nim->qto_xyz);
    v.notes.push_back(cat("orientation from the qform (code ", nim->qform_code, ")"));
  } else {
    const double dx = nim->dx > 0 ? nim->dx : 1.0, dy = nim->dy > 0 ? nim->dy : 1.0,
                 dz = nim->dz > 0 ? nim->dz : 1.0;
    const double M[3][4] = {{-dx, 0, 0, 0}, {0, -dy, 0, 0}, {0, 0, dz, 0}};
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 4; ++c) A[r][c] = M[r][c];
    v.notes.push_back("no sform or qform: orientation unknown, assumed RAS axes from pixdim "
                      "(NIfTI method 1) with the origin at voxel 0; check left/right before "
                      "planning");
  }
  if (nim->xyz_units == NIFTI_UNITS_METER) {
    for (auto& row : A)
      for (double& x : row) x *= 1000.0;
    v.notes.push_back("xyz units were metres; converted to mm");
  } else if (nim->xyz_units == NIFTI_UNITS_MICRON) {
    for (auto& row : A)
      for (double& x : row) x *= 1e-3;
    v.notes.push_back("xyz units were microns; converted to mm");
  }
  set_geometry_from_affine(g, A);
  const Eigen::Matrix3d gram = g.direction.transpose() * g.direction;
  if ((gram - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() > 1e-4)
    v.notes.push_back("the affine is sheared (axes not orthogonal); kept as is");

  mark_nan_outside_field(name, v);
  v.modality = guess_modality(v.data, v.notes);
  validate_volume(v);
  return v;
}

}  // namespace caps::detail
