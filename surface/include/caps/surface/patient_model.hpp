#pragma once
/// @brief The patient model, one API whatever built it (a CT/MR volume or a surface scan):
/// loading a model directory, bilinear sampling over (theta, z), frame conversions, skin normals.
///
/// Angles at this API are degrees, lengths millimetres, positions patient LPS. theta follows
/// docs/model-format.md: 0 at the face, +90 at the patient's left, the seam at +-180 (the back of
/// the head).
///
/// Seam: sampling is periodic in theta. Any finite theta is accepted and wrapped into
/// [theta0, theta0 + 360); the cell between the last column (j = n_theta - 1) and the first
/// (j = 0) is interpolated like any other, so values and normals are continuous across +-180.
/// Poles: z is not periodic. Between the first and last rows the maps are interpolated; outside
/// [z_first, z_last] the samplers clamp z to the nearest row (has_z() tells whether a z is inside).
/// The axis itself (r = 0) has no theta; to_cylindrical() returns theta = 0 there.

#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <string>

#include "caps/volume/cylindrical_map.hpp"
#include "caps/image/rgb_image.hpp"

namespace caps {

/// A point in the model's cylindrical frame.
struct CylindricalPoint {
  double theta_deg = 0;  ///< [-180, 180)
  double z_mm = 0;       ///< along the axis from its origin
  double r_mm = 0;       ///< distance from the axis
};

/// A patient model in memory: the maps of a model directory and its colour.
class PatientModel {
 public:
  /// Reads a model directory written by `caps model from-volume` or `caps model from-scan`:
  /// checks model.json (format, version, files), reads the maps and color.png if present.
  /// Throws IoError (missing or unreadable files) or InvalidInput (wrong format or sizes).
  static PatientModel load(const std::filesystem::path& dir);

  /// A model from maps in memory (e.g. just built); `color` is empty or n_theta × n_z.
  explicit PatientModel(CylindricalMaps maps, RgbImage color = {}, std::string source_kind = "",
                        std::string thickness_kind = "");

  const CylindricalMaps& maps() const { return maps_; }
  const CylinderAxis& axis() const { return maps_.axis; }
  const CylinderGrid& grid() const { return maps_.grid; }
  bool has_color() const { return !color_.rgb.empty(); }
  /// color.png: n_theta wide, n_z high, superior (the last row) on top.
  const RgbImage& color() const { return color_; }
  const std::string& source_kind() const { return source_kind_; }        ///< "volume" | "scan"
  const std::string& thickness_kind() const { return thickness_kind_; }  ///< e.g. "constant"
  /// The model's identity (volume's content_hash() of its maps; model.json "content_hash").
  std::string content_hash() const;

  /// Whether z (mm) lies between the first and the last row of the grid.
  bool has_z(double z_mm) const;

  /// Bilinear samples at (theta deg, z mm), periodic in theta, z clamped (see @brief). mm.
  double r_skin(double theta_deg, double z_mm) const;
  double r_bone(double theta_deg, double z_mm) const;
  double thickness(double theta_deg, double z_mm) const;
  double thickness_normal(double theta_deg, double z_mm) const;
  /// Bilinear sample of any of the maps' images (e.g. maps().thickness_skin_normal) at
  /// (theta deg, z mm), as the samplers above. `img` holds grid().size() values.
  double sample(const std::vector<float>& img, double theta_deg, double z_mm) const;
  /// Whether the model carries tissue-layer maps (CT models: thickness_{skin,fat,deep}.nrrd).
  bool has_layers() const { return maps_.has_layers(); }
  /// Bilinear radial depths (mm) of the tissue layers along the same ray as thickness():
  /// skin (dermis, surface to the top of the fat), subcutaneous fat, deep tissue (fat to bone);
  /// they sum to thickness(). 0 when the model has no layers (has_layers()).
  double thickness_skin(double theta_deg, double z_mm) const;
  double thickness_fat(double theta_deg, double z_mm) const;
  double thickness_deep(double theta_deg, double z_mm) const;
  /// The OR of the radial layer flags (LayerFlag) of the cells the bilinear sample uses: 0 means
  /// every cell it blends had its layers measured; kLayerNoThickness without layer maps.
  std::uint8_t layer_flags_at(double theta_deg, double z_mm) const;
  /// Bilinear colour, RGB in [0, 1]; (0.5, 0.5, 0.5) when the model has no colour.
  Eigen::Vector3d color_at(double theta_deg, double z_mm) const;
  /// The OR of the validity flags of the (up to four) cells that the bilinear sample uses:
  /// 0 means every sample it blends was measured and valid.
  std::uint8_t flags_at(double theta_deg, double z_mm) const;

  /// (theta deg, z mm, r mm) to LPS mm.
  Eigen::Vector3d to_lps(double theta_deg, double z_mm, double r_mm) const;
  Eigen::Vector3d to_lps(const CylindricalPoint& c) const;
  /// LPS mm to (theta deg in [-180, 180), z mm, r mm).
  CylindricalPoint to_cylindrical(const Eigen::Vector3d& p_lps) const;
  /// The skin point at (theta, z): to_lps(theta, z, r_skin(theta, z)).
  Eigen::Vector3d skin_point(double theta_deg, double z_mm) const;
  Eigen::Vector3d bone_point(double theta_deg, double z_mm) const;
  /// Outward unit normal of the skin range surface r_skin(theta, z) at (theta, z), LPS. From the
  /// bilinear slopes: n ~ e_r - (dr/dtheta / r) e_theta - (dr/dz) e_z. Near the axis (r < 1 mm)
  /// the theta slope is ignored.
  Eigen::Vector3d skin_normal(double theta_deg, double z_mm) const;

 private:
  struct Stencil {
    std::size_t c00, c10, c01, c11;
    double fu, fv;
  };
  Stencil stencil(double theta_deg, double z_mm) const;
  // The OR of the flags of the cells the bilinear sample uses.
  std::uint8_t or_flags(const std::vector<std::uint8_t>& img, double theta_deg, double z_mm) const;

  CylindricalMaps maps_;
  RgbImage color_;
  std::string source_kind_, thickness_kind_;
};

}  // namespace caps
