#pragma once
/// @brief An analytic head CT phantom whose every surface is known in closed form.
///
/// The head is built around a vertical axis through `axis_point()` (LPS mm). In cylindrical
/// coordinates (theta, z, r) about that axis (theta = 0 anterior, increasing towards the patient's
/// left, z superior), it has
///   skin        r < R_skin(theta, z): an ellipsoid-like head, plus a nose (anterior) and a marker
///               bump on the patient's left, above the centre (so left/right, front/back and
///               up/down can all be told apart);
///   skull       R_bone - kSkullMm < r < R_bone, with R_bone = R_head - thickness(theta, z): the
///               soft-tissue thickness varies smoothly and is known exactly;
///   brain       inside the skull, with an enclosed air cavity (a "sinus");
///   head holder a plastic arc behind the head on a 1.5 mm foam pad, joined to it by a thin strap.
/// The layered variant (`layered`) puts the soft tissue in three layers of known depth: dermis
/// (kDermisHu) from the skin to R_fat_top = R_head - dermis(theta, z), subcutaneous fat (kFatHu)
/// down to R_fat_bottom = R_fat_top - fat(theta, z), then deep tissue (muscle, kMuscleHu) down to
/// the bone; its soft-tissue thickness is dermis + fat + deep (4.2 .. 12.2 mm).
/// The thin-bone variant (`thin_bone`) replaces the skull under the patient's right cheek
/// (thin_bone_mm() > 0) by a plate 0.5 .. 1.5 mm thick (kThinBoneHu) over soft tissue, imaged with
/// a blur of kThinBoneBlurMm: its partial-volume peak (kTissueHu + (kThinBoneHu - kTissueHu)
/// t / kThinBoneBlurMm, 227 .. 600 HU) is below the 250 HU bone threshold where the plate is
/// thinner than 0.56 mm, and sampled along oblique rays below it to about 0.65 mm, as the
/// anterior maxilla and the nasal bones are in a head CT.
/// The face variant (`face`) replaces the plain nose by a face of analytic features on the midline
/// (theta = 0) and both sides, each a separable Gaussian bump or dip added to the head radius
/// (face_relief()): a brow (glabella), a nasion dip, a nose, a subnasale dip, upper and lower
/// lips, a labiomental fold, a chin (pogonion), eye depressions (exocanthion), cheek
/// prominences (zygion) and ears (tragion), so the anatomical landmarks have known positions
/// (docs/landmarks.md).
/// Voxels carry partial-volume values (a linear ramp one voxel wide across each interface), so
/// sub-voxel measurements can be checked against the analytic surfaces.

#include <Eigen/Core>

#include "caps/volume/volume.hpp"

namespace caps {

struct PhantomOptions {
  Eigen::Vector3i dims{256, 256, 240};     ///< voxels along L, P, S
  Eigen::Vector3d spacing_mm{1.0, 1.0, 1.0};
  bool head_holder = true;                 ///< include the plastic head-holder arc
  bool layered = false;  ///< dermis, fat and muscle instead of one soft tissue (HeadPhantom)
  bool thin_bone = false;  ///< a thin bone plate under the right cheek (HeadPhantom)
  bool face = false;       ///< a face of analytic landmarks instead of the plain nose (HeadPhantom)
  /// A dental metal block (a crown or filling) in the upper jaw in front, with the streak
  /// artefacts it makes in the axial slices through it (HeadPhantom::metal_*; docs/volume.md,
  /// "Metal"): values clipped to the 12-bit range a CT stores without its extended scale.
  bool metal = false;
  double metal_z_mm = -40.0;  ///< metal: the block's height on the head's axis (mm, -90 .. 60)
  double scale = 1.0;      ///< the head's size: every length of the head times this (0.7 .. 1.3)
  /// The head's pose in the scanner, about HeadPhantom::axis_point(): leaning towards the
  /// patient's left shoulder (the vertex towards the left) by `roll_deg`, then tilted forward
  /// (chin towards the chest) by `pitch_deg`, then turned towards the patient's left by
  /// `yaw_deg` (each -45 .. 45 deg; the head holder stays where it is).
  double pitch_deg = 0, yaw_deg = 0, roll_deg = 0;
};

/// Analytic description of the phantom head (all lengths in mm, angles in radians).
class HeadPhantom {
 public:
  /// The single-tissue phantom, or with `layered` the three-layer one (dermis, fat, muscle).
  explicit HeadPhantom(bool layered = false, bool thin_bone = false, bool face = false,
                       double scale = 1.0)
      : layered_(layered), thin_bone_(thin_bone), face_(face), scale_(scale) {}

  static constexpr double kAirHu = -1000.0;
  static constexpr double kTissueHu = 40.0;
  static constexpr double kDermisHu = 55.0;   ///< layered: dermis
  static constexpr double kFatHu = -100.0;    ///< layered: subcutaneous fat
  static constexpr double kMuscleHu = 45.0;   ///< layered: deep tissue (muscle, fascia)
  static constexpr double kBoneHu = 1200.0;
  static constexpr double kBrainHu = 35.0;
  static constexpr double kHolderHu = 100.0;
  static constexpr double kSkullMm = 6.0;
  static constexpr double kThinBoneHu = 600.0;    ///< thin_bone: the plate's CT number
  static constexpr double kThinBoneBlurMm = 1.5;  ///< thin_bone: the plate's edge ramp width (mm)
  /// thin_bone: the plate's region, theta in radians (patient's right cheek), z in mm.
  static constexpr double kThinThetaMin = -70.0 * 3.14159265358979323846 / 180.0;
  static constexpr double kThinThetaMax = -30.0 * 3.14159265358979323846 / 180.0;
  static constexpr double kThinZMin = -50.0, kThinZMax = -10.0;

  /// A point on the head's axis at z = 0 (LPS mm). The axis is parallel to LPS +z.
  Eigen::Vector3d axis_point() const { return {2.0, 6.0, 0.0}; }
  /// Unit vector of the ray at theta: (sin theta, -cos theta, 0) in LPS.
  static Eigen::Vector3d ray_direction(double theta);

  /// Skin radius without the nose and marker bumps.
  double head_radius(double theta, double z) const;
  /// Skin radius (outer envelope) including the nose (or the face) and the marker.
  double skin_radius(double theta, double z) const;
  bool has_face() const { return face_; }
  double scale() const { return scale_; }
  /// face: the relief the face adds to the head radius at (theta rad, z mm), mm (0 without
  /// `face`): glabella bump 5 mm at z = 28, nasion dip 3 mm at z = 12, nose 16 mm at z = -12,
  /// subnasale dip 4 mm at z = -27, lips 4 and 3.5 mm at z = -36 and -48, labiomental dip 2.5 mm
  /// at z = -58, chin 6 mm at z = -70 (all on the midline); eye dips 5 mm at theta = +-20 deg,
  /// z = 5; cheeks 7 mm at theta = +-65 deg, z = -5; ears 14 mm at theta = +-100 deg, z = 0.
  /// These and every other analytic function here describe the head at scale 1: with scale s the
  /// volume's point p is the point axis_point() + (p - axis_point()) / s of that head.
  double face_relief(double theta, double z) const;
  bool is_layered() const { return layered_; }
  bool has_thin_bone() const { return thin_bone_; }
  /// thin_bone: the plate's thickness (mm) under (theta, z), 0.5 mm at kThinZMin rising as the
  /// cube of the height to 1.5 mm at kThinZMax (most of the plate is under 1 mm); 0 outside the
  /// region (the 6 mm skull) or without thin_bone. Its outer face is bone_radius(theta, z).
  double thin_bone_mm(double theta, double z) const;
  /// Soft-tissue thickness of the head without bumps, radially: 2.5 .. 8.5 mm (layered:
  /// dermis + fat + deep, 4.2 .. 12.2 mm).
  double thickness(double theta, double z) const;
  /// Layered phantom: radial depths (mm) of the dermis (1.4 .. 2.2), the fat (1.0 .. 5.0) and
  /// the deep tissue (1.8 .. 5.0) under the head radius (without the nose and marker bumps).
  double dermis_depth(double theta, double z) const;
  double fat_depth(double theta, double z) const;
  double deep_depth(double theta, double z) const;
  /// Layered phantom: radii of the top (dermis/fat) and bottom (fat/deep) of the fat.
  double fat_top_radius(double theta, double z) const;
  double fat_bottom_radius(double theta, double z) const;
  /// Outer bone radius: head_radius - thickness (may be <= 0 near the vertex: no bone there).
  double bone_radius(double theta, double z) const;

  /// Hounsfield value at an LPS point for a voxel of the given size (partial volume).
  double hu_at(const Eigen::Vector3d& p, const Eigen::Vector3d& voxel_mm,
               bool head_holder = true) const;
  /// The value at p of the head holder laid over `hu` (the head's value there without it):
  /// hu_at(p, voxel_mm, true) is holder_over(p, voxel_mm, hu_at(p, voxel_mm, false)).
  double holder_over(const Eigen::Vector3d& p, const Eigen::Vector3d& voxel_mm, double hu) const;

  /// metal: a block of dental metal (a crown) in the front of the upper jaw, inside the 6 mm
  /// skull shell that stands for the alveolar bone: centred on the midline (theta = 0) at
  /// z = kMetalZ (PhantomOptions::metal_z_mm), 3 mm inside the bone's outer surface (85 mm from
  /// the axis at z = -40), kMetalHalfMm half-sizes (tangential, radial, axial).
  /// Its attenuation is that of kMetalHu; a scanner without its extended CT scale stores it,
  /// and every value, clipped to [kStoredMinHu, kStoredMaxHu] (12 bits).
  static constexpr double kMetalZ = -40.0;
  static constexpr double kMetalHalfMm[3] = {3.0, 2.5, 2.0};
  static constexpr double kMetalHu = 20000.0;
  static constexpr double kStoredMinHu = -1024.0, kStoredMaxHu = 3071.0;
  /// The streaks' caricature (docs/volume.md, "Metal"): in a slice through the metal, kStreakLines
  /// straight lines through the metal's centre, kPi / kStreakLines apart, alternately bright and
  /// dark, of amplitude kStreakHu * kStreakDecayMm / (kStreakDecayMm + rho) at distance rho (mm)
  /// from the metal, Gaussian across the line (half-width 1.2 mm + 1 % of rho), times the part
  /// of the slice the metal fills.
  static constexpr int kStreakLines = 12;
  static constexpr double kStreakHu = 3000.0, kStreakDecayMm = 50.0;
  /// The metal's centre at height z (LPS mm, upright head at scale 1).
  Eigen::Vector3d metal_centre(double z = kMetalZ) const {
    return axis_point() + Eigen::Vector3d(0.0, -(bone_radius(0.0, z) - 3.0), z);
  }

  /// theta and z of the nose tip and of the marker centre.
  static constexpr double kNoseZ = -20.0;
  static constexpr double kMarkerTheta = 1.5707963267948966;  // patient's left
  static constexpr double kMarkerZ = 50.0;

 private:
  bool layered_ = false;
  bool thin_bone_ = false;
  bool face_ = false;
  double scale_ = 1.0;
};

/// Samples the phantom on a grid centred on the head, identity direction, as a CT in HU
/// (options.layered: the layered HeadPhantom; options.thin_bone: with the thin plate; options.face:
/// the face of analytic landmarks; options.scale: the head's size).
Volume make_phantom(const PhantomOptions& options = {});

}  // namespace caps
