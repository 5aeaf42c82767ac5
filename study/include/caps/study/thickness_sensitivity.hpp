#pragma once
/// @brief Where a constant thickness misleads (`caps model sensitivity`): a standard small plan
/// placed at a grid of points over the face and simulated twice at each, with the thickness
/// measured in the volume and with one constant thickness for the whole face (what a model
/// built from a surface scan alone must assume), and the relative change in the closing force
/// and in the largest displacement between the two.

#include <map>
#include <string>
#include <vector>

#include "caps/core/reporter.hpp"
#include "caps/closure/simulate.hpp"

namespace caps::study {

struct SensitivityOptions {
  std::string procedure = "ellipse";  ///< a template of the procedure library
  /// The template's parameters (mm, deg, counts): a 20 × 7 mm ellipse by default.
  std::map<std::string, double> parameters{{"length", 20.0}, {"width", 7.0}};
  double orientation_deg = 90.0;      ///< deg from superior towards +theta: 90 = horizontal
  double theta_min_deg = -75.0, theta_max_deg = 75.0, theta_step_deg = 15.0;  ///< plan centres
  /// z range of the plan centres (mm); z_min > z_max (the default): the model's rows, less
  /// `margin_mm` at each end.
  double z_min_mm = 1.0, z_max_mm = 0.0, z_step_mm = 10.0;
  double margin_mm = 15.0;
  /// The constant thickness (mm); 0: the median of the measured thickness over the mapped
  /// region's valid cells (one number for the whole face, as a scan-built model assumes).
  double constant_thickness_mm = 0.0;
  /// Simulations run at once, >= 1; with more than one, MUMPS (whose sequential build is not
  /// thread-safe) is replaced by CHOLMOD.
  int threads = 2;
  closure::SimulateOptions simulate;           ///< meshing and solver options of every run
};

/// One plan centre of the map.
struct SensitivityPoint {
  double theta_deg = 0, z_mm = 0;
  bool planned = false;        ///< both runs succeeded
  std::string reason;          ///< why not (the plan check's or the mesher's message)
  double thickness_mean_mm = 0;       ///< measured, under the wound
  double closing_force_measured_n = 0, closing_force_constant_n = 0;
  double max_displacement_measured_mm = 0, max_displacement_constant_mm = 0;
  /// (constant - measured) / measured: + where the constant thickness overestimates.
  double force_change = 0, displacement_change = 0;
  std::vector<std::string> warnings;  ///< of both runs
};

struct SensitivityMap {
  SensitivityOptions options;         ///< as used (the solver may have been changed)
  double constant_thickness_mm = 0;   ///< the constant used
  std::vector<double> theta_deg, z_mm;  ///< the grid's columns and rows
  /// theta fastest: point (i, k) is points[k * theta_deg.size() + i].
  std::vector<SensitivityPoint> points;
  int planned = 0;                    ///< points with both runs
  double seconds = 0;                 ///< wall time
};

/// The grid of plan centres, the constant thickness, and both runs at every centre, in
/// `options.threads` threads (each simulation is single-threaded). A centre where the plan
/// cannot be placed, checked, meshed or solved is kept with planned = false and the reason.
/// Progress: one step per centre. Throws InvalidInput for options out of range or an unknown
/// procedure.
SensitivityMap thickness_sensitivity(const PatientModel& model, const SensitivityOptions& options = {},
                                     Reporter* reporter = nullptr);

/// The map as JSON (sensitivity.json): the options, the constant, the grid and every point.
std::string sensitivity_json(const SensitivityMap& map);

/// The map as CSV, one row per point (sensitivity.csv).
std::string sensitivity_csv(const SensitivityMap& map);

}  // namespace caps::study
