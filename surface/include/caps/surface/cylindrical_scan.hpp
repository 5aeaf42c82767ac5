#pragma once
/// @brief Cyberware-style cylindrical range images: a grey range image r(theta, z) and an
/// optional colour image of the same layout, with their scales from a sidecar file or flags.
///
/// The image becomes its polyhedral reconstruction (CAPS 1992, section 5: a vertex per sample,
/// one quad, as two triangles, per four neighbouring samples; the seam closed when the image
/// spans 360 degrees), with texture coordinates into the colour image, and then goes through the
/// same path as any other scan (build_scan_model). In the scan's file frame y is up, theta = 0
/// looks along +z, and theta grows towards +x (right-handed about +y):
///   (x, y, z) = (r sin theta, z, r cos theta).
///
/// Sidecar (JSON, docs/surface.md):
///   {"range": "head_range.png", "color": "head_color.png",
///    "r_scale_mm": 0.1, "r_offset_mm": 0, "z_scale_mm": 0.7, "theta_span_deg": 360,
///    "theta_axis": "columns" | "rows", "theta_reverse": false, "top_first": true,
///    "void_value": 0, "top_z_mm": 0}
/// Range values equal to void_value are missing samples (no vertex there).

#include <filesystem>
#include <string>

#include "caps/surface/patient_model.hpp"
#include "caps/surface/scan_io.hpp"

namespace caps {

struct CylindricalScanSpec {
  std::filesystem::path range;       ///< 8- or 16-bit grey PNG: r = r_offset + r_scale * value
  std::filesystem::path color;       ///< optional colour image (JPEG or PNG), same layout
  double r_scale_mm = 0;             ///< mm per range unit, > 0
  double r_offset_mm = 0;            ///< r for a range value of 0
  double z_scale_mm = 0;             ///< mm between neighbouring z lines, > 0
  double theta_span_deg = 360;       ///< the image's extent in theta, (0, 360]
  bool theta_along_rows = false;     ///< theta runs down the rows (z across the columns)
  bool theta_reverse = false;        ///< theta decreases along its image axis
  bool top_first = true;             ///< the first z line is the top of the head
  unsigned void_value = 0;           ///< range value of a missing sample
  double top_z_mm = 0;               ///< the height of the first (top) z line, mm
};

/// Reads a sidecar; relative paths are taken from the sidecar's folder. Throws IoError /
/// InvalidInput naming the file and the field.
CylindricalScanSpec read_cylindrical_sidecar(const std::filesystem::path& json_path);

/// Checks the spec and builds the polyhedral reconstruction (file units: mm). Throws IoError for
/// unreadable images, InvalidInput for a colour image whose size differs from the range image's,
/// a non-grey range image, scales out of range, or an image without two neighbouring samples.
ScanMesh cylindrical_scan_mesh(const CylindricalScanSpec& spec);

/// Writes a model's skin as a cylindrical range image in `dir` (which must exist): range.png
/// (16-bit grey, r = value * r_scale_mm, theta across the columns starting at theta = 0, the top
/// row first, cells without measured skin void), color.png when the model has colour, and the
/// sidecar range.json. Returns the sidecar's path. Files are written atomically.
std::filesystem::path write_cylindrical_scan(const PatientModel& model,
                                             const std::filesystem::path& dir,
                                             double r_scale_mm = 0.01);

}  // namespace caps
