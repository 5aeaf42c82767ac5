#pragma once
/// @brief Pictures and reports of simulations: the standard views of a simulated closure, and the
/// measured-versus-constant-thickness comparison with both results side by side.

#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include "caps/fem/compare.hpp"
#include "caps/fem/simulate.hpp"
#include "caps/render/render.hpp"
#include "caps/render/skin_surface.hpp"

namespace caps::render {

/// The area (mm^2) of the wound's fill before and after the closure: the excised skin, and what
/// is left of it (about zero once the sutures have closed the wound).
std::pair<double, double> wound_fill_area_mm2(const SkinSurfaces& skin);

/// The displacement-mapped skin of a simulation at full resolution.
SkinSurfaces simulated_skin(const PatientModel& model, const fem::Simulation& sim);

/// pre_<view>.png and post_<view>.png of a simulation in `dir` (see render_views), and with
/// `tension_map` also tension_<view>.png (the skin tension, see tension_map() in overlay.hpp).
std::vector<std::filesystem::path> render_simulation(const PatientModel& model,
                                                     const fem::Simulation& sim,
                                                     const std::vector<View>& views,
                                                     const RenderOptions& options,
                                                     const std::filesystem::path& dir,
                                                     bool tension_map = false,
                                                     Reporter* reporter = nullptr);

/// Writes a comparison into an existing folder: measured/ and constant/ (fem::write_simulation
/// plus their pre- and post-operative plan and oblique views), comparison.json, and report.html
/// with the table of differences and the two results side by side.
void write_comparison_report(const fem::Comparison& c, const PatientModel& model,
                             const fem::SimulateOptions& options, const std::filesystem::path& dir,
                             const std::string& plan_name, const RenderOptions& render_options = {},
                             Reporter* reporter = nullptr);

}  // namespace caps::render
