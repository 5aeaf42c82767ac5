#pragma once
/// @brief Pictures and reports of simulations: the standard views of a simulated closure, and the
/// measured-versus-constant-thickness comparison with both results side by side.

#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include "caps/study/compare.hpp"
#include "caps/closure/simulate.hpp"
#include "caps/plan/plan.hpp"
#include "caps/render/drawn_skin.hpp"
#include "caps/render/overlay.hpp"
#include "caps/render/render.hpp"
#include "caps/render/skin_surface.hpp"

namespace caps::render {

/// The area (mm^2) of the wound's fill before and after the closure: the excised skin, and what
/// is left of it (about zero once the sutures have closed the wound).
std::pair<double, double> wound_fill_area_mm2(const SkinSurfaces& skin);

/// The displacement-mapped skin of a simulation at full resolution, drawn on `drawn` (null: the
/// model's range image; see displaced_skin()).
SkinSurfaces simulated_skin(const PatientModel& model, const closure::Simulation& sim,
                            const DrawnSkin* drawn = nullptr);

/// The skin tension map of a simulation on simulated_skin(): where it was solved in the whole
/// face, the tissue model's skin carries it on beyond the patch (nodal_field_on_skin()).
ScalarMap simulated_tension_map(const SkinSurfaces& skin, const closure::Simulation& sim);

/// What the pictures of a simulation show besides the skin.
struct SimulationPictures {
  bool tension_map = false;             ///< also tension_<view>.png
  const DrawnSkin* drawn = nullptr;  ///< the skin drawn (load_drawn_skin()); null: the model's
  const plan::Plan* plan = nullptr;     ///< its cutting lines on the pre-operative images
};

/// pre_<view>.png (with the plan's lines) and post_<view>.png (with the suture lines) of a
/// simulation in `dir`, each with a scale bar (see render_views_with_overlays), and with
/// `pictures.tension_map` also tension_<view>.png (the skin tension, see tension_map()).
std::vector<std::filesystem::path> render_simulation(const PatientModel& model,
                                                     const closure::Simulation& sim,
                                                     const std::vector<View>& views,
                                                     const RenderOptions& options,
                                                     const std::filesystem::path& dir,
                                                     const SimulationPictures& pictures = {},
                                                     Reporter* reporter = nullptr);

/// Writes a comparison into an existing folder: measured/ and constant/ (closure::write_simulation
/// plus their pre- and post-operative plan and oblique views), difference_plan.png (the skin
/// after the closure coloured by the distance between the two post-operative skins, mm),
/// comparison.json, and report.html with the table of differences and the results side by side.
/// `pictures.tension_map` is ignored.
void write_comparison_report(const study::Comparison& c, const PatientModel& model,
                             const closure::SimulateOptions& options, const std::filesystem::path& dir,
                             const std::string& plan_name, const RenderOptions& render_options = {},
                             Reporter* reporter = nullptr, const SimulationPictures& pictures = {});

}  // namespace caps::render
