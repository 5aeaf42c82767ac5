#pragma once
/// @brief Private helpers shared by the volume readers (not installed, not public API).

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "caps/volume/read_volume.hpp"

namespace caps::detail {

Volume read_dicom(const std::filesystem::path& input, const ReadOptions& options);
Volume read_nifti(const std::filesystem::path& file, const ReadOptions& options);
Volume read_nrrd(const std::filesystem::path& file, const ReadOptions& options);
Volume read_metaimage(const std::filesystem::path& file, const ReadOptions& options);
Volume read_inv3(const std::filesystem::path& file, const ReadOptions& options);

/// Size of a regular file in bytes; throws IoError naming the file if it is missing or unreadable.
std::uintmax_t file_size_or_throw(const std::filesystem::path& file);

/// Reads a whole file into memory; throws IoError.
std::vector<char> read_binary_file(const std::filesystem::path& file);

/// Largest size along one axis a reader accepts.
constexpr long long kMaxAxisVoxels = 8192;

/// Throws InvalidInput (naming `file` and `field`) unless every dim is in 1..kMaxAxisVoxels, the
/// voxel count times `n_volumes` is at most options.max_voxels, and the memory the voxels need,
/// 4 bytes a voxel (the float volume) plus `raw_bytes` (the file's raw or decompressed voxel
/// data held alongside), is at most options.max_bytes. Called before any allocation sized by a
/// header.
void check_dims(const std::filesystem::path& file, const std::string& field,
                const std::vector<long long>& dims, const ReadOptions& options,
                double raw_bytes = 0, double n_volumes = 1);

/// The CT heuristic for formats without a modality field: CT if the minimum is <= -900 and at
/// least 5% of the voxels lie in [-1100, -900] (air in HU). Returns CT or Unknown and adds a
/// note saying why.
Modality guess_modality(const std::vector<float>& data, std::vector<std::string>& notes);

/// Geometry from a 3x4 affine whose columns map (i, j, k, 1) to LPS mm.
void set_geometry_from_affine(VolumeGeometry& g, const double affine_lps[3][4]);

/// Decodes `n` elements of a numeric type into floats. `type` is one of "u8","i8","u16","i16",
/// "u32","i32","u64","i64","f32","f64"; `swap` reverses the bytes of each element.
void decode_to_float(const char* src, std::size_t n, const std::string& type, bool swap,
                     float* dst);
std::size_t type_size(const std::string& type);

/// Lower-case copy.
std::string to_lower(std::string s);

/// The file name for slice `i` of a data-file pattern such as "slice%03d.raw" (MetaImage
/// ElementDataFile, NRRD "data file"). The pattern is file text, so it never reaches a
/// printf-style formatter: exactly one %d conversion with an optional 0 flag and width is
/// expanded here, "%%" is a literal %, and anything else is refused (InvalidInput naming `file`
/// and `field`).
std::string slice_file_name(const std::filesystem::path& file, const std::string& field,
                            const std::string& pattern, long long i);

/// Throws IoError naming `file` unless the gzip (or zlib) stream in `data` from byte `offset`
/// is whole: it decompresses without error and ends (end marker, CRC-32 and length checked by
/// zlib) after at least `needed_bytes` decompressed bytes, the part its reader uses. The end is
/// looked for up to `search_bytes` decompressed bytes (default: 1 MiB past `needed_bytes`); a
/// longer stream passes unexamined beyond that. The readers stop inflating once they hold what
/// the header declares, so a stream cut short after that point was accepted. Concatenated gzip
/// members are followed; bytes after the member that completes the data are ignored (as zlib's
/// gzread does). Streams the file through 64 KiB buffers: no allocation sized by the file.
void require_whole_gzip(const std::filesystem::path& file, const std::filesystem::path& data,
                        std::uint64_t offset, std::uint64_t needed_bytes,
                        std::uint64_t search_bytes = 0);

}  // namespace caps::detail
