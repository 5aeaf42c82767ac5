#pragma once
/// @brief Reading CT and MR volumes from DICOM, NIfTI, NRRD, MetaImage and InVesalius files.
///
/// Every reader lands in one Volume in patient LPS mm (see volume.hpp). CT values are returned
/// in Hounsfield units (rescale slope/intercept applied).

#include <filesystem>
#include <string>
#include <vector>

#include "caps/volume/volume.hpp"

namespace caps {

/// Default largest voxel count a reader accepts (2^31; caps reads the first volume of a 4-D file).
constexpr double kDefaultMaxVoxels = 2147483648.0;
/// Default largest memory in bytes a reader allocates for voxel data (8 GiB): the float volume
/// (4 bytes a voxel) plus the file's raw or decompressed voxel bytes.
constexpr double kDefaultMaxBytes = 8589934592.0;

struct ReadOptions {
  std::string series_uid;  ///< DICOM: the SeriesInstanceUID to read; empty = the largest series
  /// DICOM: interpolate across slices that look missing instead of throwing InvalidInput.
  bool allow_missing_slices = false;
  /// A header declaring more voxels than this is refused (InvalidInput) before any allocation.
  double max_voxels = kDefaultMaxVoxels;
  /// A header whose voxels need more bytes than this (float volume + raw data) is refused
  /// before any allocation.
  double max_bytes = kDefaultMaxBytes;
  /// NIfTI with several volumes (dims 4..7, e.g. an fMRI time series): the volume to read,
  /// counted from 0 with dim 4 fastest. Out of range is an InvalidInput naming the count.
  long long volume_index = 0;
};

/// One DICOM series found in a folder.
struct DicomSeriesInfo {
  std::string uid;
  std::string description;
  std::string modality;
  int n_files = 0;
};

/// Reads a volume. `input` is a DICOM folder (or one DICOM file), .nii/.nii.gz, a NIfTI-1/2
/// pair (.hdr + .img, either named, optionally .gz), .nrrd/.nhdr, .mha/.mhd or .inv3. Throws IoError (missing, unreadable, truncated) or InvalidInput (not an
/// image, inconsistent header, missing slices) with the file named and what to do.
Volume read_volume(const std::filesystem::path& input, const ReadOptions& options = {});

/// Lists the DICOM series in a folder, largest first (damaged files are left out).
std::vector<DicomSeriesInfo> list_dicom_series(const std::filesystem::path& folder);

/// Writes a volume as NIfTI-1 (.nii, or gzip-compressed .nii.gz), float32, with qform and sform
/// set from the LPS geometry (NIfTI stores RAS; the conversion is done here).
void write_nifti(const Volume& v, const std::filesystem::path& path);

}  // namespace caps
