#pragma once
/// @brief Plan files: JSON, format "caps-plan", version 1 (docs/plan-format.md).

#include <filesystem>
#include <string>

#include "caps/plan/check.hpp"
#include "caps/plan/plan.hpp"

namespace caps::plan {

/// The plan as JSON text (points with theta, z and LPS; paths; the border loop and its
/// correspondence to the points; excisions; sutures; the procedure; notes). `report`, when
/// given, adds the edge lengths and warnings for reading.
std::string plan_to_json(const Plan& plan, const PlanReport* report = nullptr);

/// Parses a plan. Throws InvalidInput naming the field (wrong format, version, types, values).
Plan parse_plan_json(const std::string& text, const std::string& source);

/// Reads a plan file. Throws IoError (unreadable) or InvalidInput.
Plan read_plan(const std::filesystem::path& path);

/// Writes a plan file atomically.
void write_plan(const std::filesystem::path& path, const Plan& plan,
                const PlanReport* report = nullptr);

/// Reads a bare wound border file (`caps mesh --border`):
/// {"loop_theta_z": [[theta_deg, z_mm], ...], "sutures": [[a, b, c, d], ...]}. Throws IoError
/// (unreadable) or InvalidInput naming the file and the expected layout.
WoundBorder read_wound_border(const std::filesystem::path& path);

}  // namespace caps::plan
