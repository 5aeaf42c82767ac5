#pragma once
/// @brief A figure of a model's skin colour (color.png) for people: the unwrapped colour image,
/// enlarged, with theta and z axes, a title and a credit line (e.g. a scan's licence).

#include <filesystem>
#include <string>

#include "caps/surface/patient_model.hpp"

namespace caps {

/// Writes the colour figure as PNG, atomically: theta across (-180 .. 180, the face in the
/// middle), superior at the top. Throws InvalidInput if the model has no colour.
void write_color_picture(const std::filesystem::path& path, const PatientModel& model,
                         const std::string& title, const std::string& credit = "");

}  // namespace caps
