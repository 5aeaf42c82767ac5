#include "caps/volume/read_volume.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstring>
#include <new>
#include <stdexcept>
#include <fstream>

#include "caps/core/error.hpp"
#include "caps/core/file_access.hpp"
#include "volume_io_detail.hpp"

namespace fs = std::filesystem;

namespace caps {

namespace detail {

std::string to_lower(std::string s) {
  for (auto& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

std::uintmax_t file_size_or_throw(const fs::path& file) {
  require_readable(file, false, "check the path and its permissions");
  std::error_code ec;
  if (!fs::is_regular_file(file, ec)) throw IoError(cat(file.string(), ": is not a regular file"));
  const auto size = fs::file_size(file, ec);
  if (ec) throw IoError(cat(file.string(), ": cannot get the file size: ", ec.message()));
  return size;
}

std::vector<char> read_binary_file(const fs::path& file) {
  const auto size = file_size_or_throw(file);
  std::ifstream in(file, std::ios::binary);
  if (!in) throw IoError(cat(file.string(), ": cannot open the file for reading (permissions?)"));
  std::vector<char> bytes(size);
  if (size > 0 && !in.read(bytes.data(), static_cast<std::streamsize>(size)))
    throw IoError(cat(file.string(), ": read failed after ", in.gcount(), " of ", size, " bytes"));
  return bytes;
}

void check_dims(const fs::path& file, const std::string& field,
                const std::vector<long long>& dims, const ReadOptions& options, double raw_bytes,
                double n_volumes) {
  double total = 1;
  std::string shown;
  for (std::size_t a = 0; a < dims.size(); ++a) {
    if (a) shown += 'x';
    shown += std::to_string(dims[a]);
  }
  for (long long d : dims) {
    if (d <= 0)
      throw InvalidInput(cat(file.string(), ": ", field, " = ", shown,
                             " has a zero or negative size; the header is damaged or the file is "
                             "not an image volume"));
    if (d > kMaxAxisVoxels)
      throw InvalidInput(cat(file.string(), ": ", field, " = ", shown, " exceeds ", kMaxAxisVoxels,
                             " voxels along an axis; the header is probably damaged"));
    total *= static_cast<double>(d);
  }
  total *= std::max(1.0, n_volumes);
  if (!(total <= options.max_voxels))
    throw InvalidInput(cat(file.string(), ": ", field, " = ", shown,
                           n_volumes > 1 ? cat(" x ", n_volumes, " volumes") : std::string(),
                           " is ", total, " voxels, more than the limit of ", options.max_voxels,
                           " (max_voxels); crop or downsample the volume, or raise --max-voxels "
                           "if the header is right"));
  const double bytes = 4.0 * total / std::max(1.0, n_volumes) + raw_bytes;
  if (!(bytes <= options.max_bytes))
    throw InvalidInput(cat(file.string(), ": ", field, " = ", shown, " needs ", bytes,
                           " bytes of memory, more than the limit of ", options.max_bytes,
                           " (max_bytes); crop or downsample the volume, or raise --max-bytes "
                           "if the header is right"));
}

Modality guess_modality(const std::vector<float>& data, std::vector<std::string>& notes) {
  if (data.empty()) return Modality::Unknown;
  float lo = data[0];
  std::size_t n_air = 0;
  for (float v : data) {
    lo = std::min(lo, v);
    n_air += (v >= -1100.0f && v <= -900.0f);
  }
  const double air_fraction = static_cast<double>(n_air) / static_cast<double>(data.size());
  if (lo <= -900.0f && air_fraction >= 0.05) {
    notes.push_back(cat("modality guessed CT from the intensities (minimum ", lo, ", ",
                        std::round(air_fraction * 1000) / 10,
                        "% of voxels in the air range -1100..-900 HU)"));
    return Modality::CT;
  }
  // A CT stored unsigned, HU + 1024 (VTK's headsq, the Stanford CThead, many raw exports):
  // air at 0..200, the soft tissue's peak at 1024 +- 150 (-150..150 HU) holding much of the rest,
  // bone beyond 1324 (300 HU) up to 2000 or more, and almost nothing between air and fat (324..824:
  // -700..-200 HU, the skin's partial volume and the sinuses) where an MR has its CSF, muscle and
  // grey matter. All five together, on whole numbers.
  if (lo >= -50.0f) {
    std::size_t n_low = 0, n_tissue = 0, n_soft = 0, n_gap = 0, n_bone = 0, n_fraction = 0;
    float hi = lo;
    for (float v : data) {
      hi = std::max(hi, v);
      n_fraction += v != std::floor(v);
      if (v <= 200.0f) {
        ++n_low;
        continue;
      }
      ++n_tissue;
      n_soft += (v >= 874.0f && v <= 1174.0f);
      n_gap += (v >= 324.0f && v <= 824.0f);
      n_bone += v > 1324.0f;
    }
    const double all = static_cast<double>(data.size()), tissue = static_cast<double>(n_tissue);
    if (n_fraction == 0 && n_tissue > 0 && n_low >= 0.1 * all && n_soft >= 0.25 * tissue &&
        n_gap <= 0.15 * tissue && n_bone >= 0.02 * tissue && hi >= 2000.0f) {
      notes.push_back(cat("modality guessed CT stored unsigned (HU + 1024) from the intensities (",
                          std::round(1000 * n_low / all) / 10, "% of voxels at 0..200, ",
                          std::round(1000 * n_soft / tissue) / 10,
                          "% of the rest at 874..1174, the soft tissue's 0 HU; ",
                          std::round(1000 * n_bone / tissue) / 10, "% above 1324, bone; ",
                          std::round(1000 * n_gap / tissue) / 10,
                          "% between air and fat; maximum ", hi,
                          "); give --modality MR if it is not a CT"));
      return Modality::CT;
    }
  }
  notes.push_back(cat("modality unknown: the format has no modality field and the intensities "
                      "(minimum ", lo, ") do not look like CT in HU"));
  return Modality::Unknown;
}

void set_geometry_from_affine(VolumeGeometry& g, const double A[3][4]) {
  for (int c = 0; c < 3; ++c) {
    Eigen::Vector3d col(A[0][c], A[1][c], A[2][c]);
    const double len = col.norm();
    g.spacing_mm[c] = len;
    g.direction.col(c) = len > 0 ? Eigen::Vector3d(col / len) : Eigen::Vector3d::Zero();
    g.origin_lps[c] = A[c][3];
  }
}

std::size_t type_size(const std::string& t) {
  if (t == "u8" || t == "i8") return 1;
  if (t == "u16" || t == "i16") return 2;
  if (t == "u32" || t == "i32" || t == "f32") return 4;
  if (t == "u64" || t == "i64" || t == "f64") return 8;
  return 0;
}

namespace {
template <typename T>
void decode_typed(const char* src, std::size_t n, bool swap, float* dst) {
  for (std::size_t i = 0; i < n; ++i) {
    char b[sizeof(T)];
    std::memcpy(b, src + i * sizeof(T), sizeof(T));
    if (swap) std::reverse(b, b + sizeof(T));
    T v;
    std::memcpy(&v, b, sizeof(T));
    dst[i] = static_cast<float>(v);
  }
}
}  // namespace

void decode_to_float(const char* src, std::size_t n, const std::string& t, bool swap,
                     float* dst) {
  if (t == "u8") decode_typed<std::uint8_t>(src, n, false, dst);
  else if (t == "i8") decode_typed<std::int8_t>(src, n, false, dst);
  else if (t == "u16") decode_typed<std::uint16_t>(src, n, swap, dst);
  else if (t == "i16") decode_typed<std::int16_t>(src, n, swap, dst);
  else if (t == "u32") decode_typed<std::uint32_t>(src, n, swap, dst);
  else if (t == "i32") decode_typed<std::int32_t>(src, n, swap, dst);
  else if (t == "u64") decode_typed<std::uint64_t>(src, n, swap, dst);
  else if (t == "i64") decode_typed<std::int64_t>(src, n, swap, dst);
  else if (t == "f32") decode_typed<float>(src, n, swap, dst);
  else if (t == "f64") decode_typed<double>(src, n, swap, dst);
  else throw Error(cat("decode_to_float: unknown element type ", t));
}

}  // namespace detail

namespace {

constexpr const char* kAccepted =
    "a DICOM folder or .dcm file, .nii, .nii.gz, a NIfTI .hdr/.img pair, .nrrd, .nhdr, .mha, "
    ".mhd or .inv3";

}  // namespace

namespace {

Volume read_by_kind(const fs::path& input, const ReadOptions& options, bool is_directory) {
  if (is_directory) return detail::read_dicom(input, options);
  const std::string name = detail::to_lower(input.filename().string());
  auto ends_with = [&](const std::string& suffix) {
    return name.size() >= suffix.size() &&
           name.compare(name.size() - suffix.size(), suffix.size(), suffix) == 0;
  };
  if (ends_with(".nii") || ends_with(".nii.gz") || ends_with(".hdr") || ends_with(".hdr.gz") ||
      ends_with(".img") || ends_with(".img.gz"))
    return detail::read_nifti(input, options);
  if (ends_with(".nrrd") || ends_with(".nhdr")) return detail::read_nrrd(input, options);
  if (ends_with(".mha") || ends_with(".mhd")) return detail::read_metaimage(input, options);
  if (ends_with(".inv3")) return detail::read_inv3(input, options);
  if (ends_with(".dcm") || ends_with(".dicom") || !input.has_extension())
    return detail::read_dicom(input, options);
  throw InvalidInput(cat(input.string(), ": unrecognised file type '",
                         input.extension().string(), "'; caps reads ", kAccepted));
}

}  // namespace

Volume read_volume(const fs::path& input, const ReadOptions& options) {
  if (!(options.max_voxels >= 1) || !(options.max_bytes >= 1))
    throw InvalidInput(cat("max_voxels (", options.max_voxels, ") and max_bytes (",
                           options.max_bytes, ") must be positive numbers"));
  std::error_code ec;
  const bool is_directory = fs::is_directory(input, ec);
  require_readable(input, is_directory, "check the path and its permissions");
  // Errors of the libraries underneath (allocation, containers) are the file's fault.
  try {
    return read_by_kind(input, options, is_directory);
  } catch (const std::bad_alloc&) {
    throw IoError(cat(input.string(), ": not enough memory to read it within max_bytes (",
                      options.max_bytes, "); lower --max-bytes or free memory"));
  } catch (const std::logic_error& e) {  // out_of_range, length_error, invalid_argument
    throw InvalidInput(cat(input.string(), ": damaged or inconsistent (", e.what(), ")"));
  }
}

}  // namespace caps
