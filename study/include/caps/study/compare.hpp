#pragma once
/// @brief Measured versus constant thickness: the same plan on the same skin, meshed once with the
/// soft-tissue thickness measured in the volume and once with a constant thickness (the 1992
/// paper's assumption for surface scans), so that the two results differ only in depth; and a
/// third time with the measured thickness in the model's measured tissue layers (dermis, fat,
/// deep tissue, each its own material) instead of one material.

#include <filesystem>
#include <string>
#include <vector>

#include "caps/closure/simulate.hpp"

namespace caps::study {

/// What a surgeon compares between two simulations of one plan (clinical units).
struct SimulationSummary {
  std::string label;
  std::string tissue;  ///< the tissue layering of the mesh: "uniform" or "measured"
  double thickness_mean_mm = 0, thickness_min_mm = 0, thickness_max_mm = 0;  ///< under the wound
  double max_displacement_mm = 0;   ///< over the skin (top) nodes
  double mean_displacement_mm = 0;  ///< over the skin nodes within one wound size of the wound
  double closing_force_n = 0;       ///< net force across the wound
  double max_suture_force_n = 0;    ///< the largest force on one sutured node pair
  /// The largest single-suture force with sutures every SimulateOptions::suture_spacing_mm (N).
  double max_suture_at_spacing_n = 0;
  double max_skin_tension_kpa = 0;  ///< largest maximum principal stress at a skin node
  double strain_energy_mj = 0;
  int elements = 0, nodes = 0;
};

struct Comparison {
  /// measured: measured thickness, one material; constant: constant thickness, one material;
  /// layered: measured thickness in measured tissue layers (one material where the model has no
  /// measured layers under the mesh: then a warning says so).
  closure::Simulation measured, constant, layered;
  SimulationSummary measured_summary, constant_summary, layered_summary;
  double constant_thickness_mm = 0;
  /// The warnings of both simulations, each prefixed with its side ("measured: ...").
  std::vector<std::string> warnings;
};

/// Summarises a simulation; `model` gives the thickness under the wound.
SimulationSummary summarize(const closure::Simulation& sim, const PatientModel& model, const std::string& label,
                            double constant_thickness_mm = 0);

/// Simulates the plan with the model's measured thickness and with a constant one, both in one
/// material (options.continuum.material): `constant_mm` > 0, or 0 for the median measured
/// thickness under the wound, so that the comparison shows the effect of the thickness's
/// variation rather than of its mean; and with the measured thickness in the measured tissue
/// layers (TissueLayers::Auto, options.continuum's dermis, fat and deep materials) on the same
/// surface mesh.
Comparison compare_thickness(const PatientModel& model, const plan::Plan& plan, double constant_mm,
                             const closure::SimulateOptions& options = {}, Reporter* reporter = nullptr);

/// The comparison's table as JSON (comparison.json): the plan, the constant thickness, and each
/// column's summary ("measured", "constant", "layers").
std::string comparison_json(const Comparison& c, const std::string& plan_name);

}  // namespace caps::study
