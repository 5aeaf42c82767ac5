#pragma once
/// @brief Overlays on the rendered skin: the displacement as a colour map with a colour bar, and
/// the plan's cutting lines drawn over an image.

#include <Eigen/Core>
#include <filesystem>
#include <string>
#include <vector>

#include "caps/plan/plan.hpp"
#include "caps/render/render.hpp"
#include "caps/render/skin_surface.hpp"

namespace caps::render {

/// Per-vertex colours of the displacement magnitude |post - pre| (mm), viridis from 0 to
/// `max_mm` (0: the largest displacement). Returns #V×3 RGB in [0, 1]; `used_max_mm` receives
/// the top of the scale.
Eigen::MatrixX3d displacement_colors(const SkinSurfaces& skin, double max_mm, double& used_max_mm);

/// Draws a vertical colour bar (viridis, 0 .. max_value) with ticks and a title on the image's
/// right side, over a white panel.
void draw_color_bar(RgbImage& image, double max_value, const std::string& unit,
                    const std::string& title);

/// Pixel position (x right, y down) of an LPS point in an image rendered with `camera`.
Eigen::Vector2d project(const Camera& camera, const RenderOptions& options, const Eigen::Vector3d& p_lps);

/// Draws polylines given in LPS mm (e.g. a plan's cutting paths) over the image, in a dashed dark
/// line, as the surgeon's marker would.
void draw_polylines(RgbImage& image, const Camera& camera, const RenderOptions& options,
                    const std::vector<std::vector<Eigen::Vector3d>>& lines);

/// The plan's cutting paths on the model's skin (LPS mm), each segment sampled along the skin
/// (in theta and z, across the seam the short way) so that the line follows the surface.
std::vector<std::vector<Eigen::Vector3d>> plan_lines(const plan::Plan& plan, const PatientModel& model);

/// What to draw over the standard views.
struct Overlays {
  /// The plan's cutting paths (LPS mm), drawn over the pre-operative images.
  std::vector<std::vector<Eigen::Vector3d>> plan_lines;
  /// Also write displacement_<view>.png: the post-operative skin coloured by |displacement| with
  /// a colour bar in mm.
  bool displacement_map = false;
  double displacement_max_mm = 0;  ///< top of the colour scale (0: the largest displacement)
};

/// render_views() with overlays: pre_<view>.png (with the plan's lines), post_<view>.png, and
/// displacement_<view>.png when asked. Returns the paths written.
std::vector<std::filesystem::path> render_views_with_overlays(const PatientModel& model,
                                                              const SkinSurfaces& skin,
                                                              const std::vector<View>& views,
                                                              const RenderOptions& options,
                                                              const Overlays& overlays,
                                                              const std::filesystem::path& dir);

}  // namespace caps::render
