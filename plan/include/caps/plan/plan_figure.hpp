#pragma once
/// @brief The plan drawn over the model (the paper's Figures 1 and 2 from real data): the
/// colour map (or the thickness map) around the plan, the cutting paths, the border loop with
/// its nodes numbered, and the suture pairs marked.

#include <filesystem>

#include "caps/plan/plan.hpp"
#include "caps/surface/patient_model.hpp"

namespace caps::plan {

struct PlanFigureOptions {
  double margin_mm = 12.0;      ///< around the plan's extent
  double pixels_per_mm = 8.0;   ///< before the size limit
  int max_size_px = 720;        ///< the map area's larger side
  bool use_thickness = false;   ///< thickness map even when the model has colour
};

/// Writes the plan figure as a PNG, atomically. The view is the local tangent frame (mm, the
/// model's superior up, theta to the right, as when facing the patient). Throws IoError.
void write_plan_png(const std::filesystem::path& path, const Plan& plan,
                    const PatientModel& model, const PlanFigureOptions& options = {});

}  // namespace caps::plan
