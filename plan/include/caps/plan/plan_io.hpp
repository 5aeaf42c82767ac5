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

}  // namespace caps::plan
