#pragma once
/// @brief Overlays on the rendered skin: scalar fields (the displacement, the skin tension) as a
/// colour map with a colour bar, and the plan's cutting lines drawn over an image.

#include <Eigen/Core>
#include <filesystem>
#include <string>
#include <vector>

#include "caps/core/reporter.hpp"
#include "caps/fem/mesh.hpp"
#include "caps/plan/plan.hpp"
#include "caps/render/render.hpp"
#include "caps/render/skin_surface.hpp"

namespace caps::render {

/// A scalar per skin vertex shown as a colour map (viridis) with a colour bar: the displacement,
/// the skin tension, or any other field on the displacement-mapped skin.
struct ScalarMap {
  std::string name;       ///< images are written as <name>_<view>.png
  Eigen::VectorXd value;  ///< #V, one per vertex of the SkinSurfaces, in `unit`
  /// Top of the scale (> 0): values at or above it take viridis' last colour, values at or below
  /// 0 its first.
  double max_value = 1;
  std::string unit;   ///< after each tick label ("mm", "kPa")
  std::string title;  ///< above the bar; '\n' starts a new line
  std::string note;   ///< under the bar (may be empty); '\n' starts a new line
};

/// The top of a colour scale: `max_value` if it is positive, else the largest of `value`, else 1
/// (all values <= 0: the scale stays readable and every vertex takes the first colour).
double scale_top(const Eigen::VectorXd& value, double max_value);

/// Per-vertex colours viridis(clamp(value / max_value, 0, 1)): #V×3 RGB in [0, 1]. Throws
/// InvalidInput unless max_value > 0.
Eigen::MatrixX3d scalar_colors(const Eigen::VectorXd& value, double max_value);

/// |post - pre| per skin vertex (#V, mm).
Eigen::VectorXd displacement_magnitude_mm(const SkinSurfaces& skin);

/// The displacement map ("displacement", mm): |post - pre| per vertex, scale 0 .. `max_mm`
/// (0: the largest displacement).
ScalarMap displacement_map(const SkinSurfaces& skin, double max_mm = 0);

/// The tension map ("tension", kPa): the maximum principal stress at the skin surface. The nodal
/// values of `mesh` (fem::SolveResult::max_principal_mpa, MPa) are carried to the skin vertices by
/// the element's shape functions on its top face (nodal_field_on_skin) and converted to kPa
/// (1 MPa = 1000 kPa); the range mesh off the FE mesh gets 0. Scale 0 .. `max_kpa` (0: the 99th
/// percentile over the skin faces, as the peaks at sutured corners are singular; the note under
/// the bar then gives the peak); compression (<= 0) takes the bottom colour.
/// @param skin               displaced_skin() of `mesh`
/// @param max_principal_mpa  #N nodal maximum principal stress (MPa)
ScalarMap tension_map(const SkinSurfaces& skin, const fem::Mesh& mesh,
                      const Eigen::VectorXd& max_principal_mpa, double max_kpa = 0);

/// Draws a vertical colour bar (viridis, 0 .. max_value) with ticks labelled in `unit`, the
/// title above it and the note under it (each may hold several lines separated by '\n') on the
/// image's right side, over a white panel. Throws InvalidInput unless max_value > 0.
void draw_color_bar(RgbImage& image, double max_value, const std::string& unit,
                    const std::string& title, const std::string& note = "");

/// The colour of a signed value t in [-1, 1] (clamped): blue at -1, white at 0, red at +1.
Eigen::Vector3d signed_colour(double t);

/// Per-vertex colours signed_colour(value / max_value) of a signed field (e.g. a difference):
/// #V×3 RGB in [0, 1]. Throws InvalidInput unless max_value > 0.
Eigen::MatrixX3d signed_colors(const Eigen::VectorXd& value, double max_value);

/// draw_color_bar() for signed_colors(): from -max_value (bottom) to +max_value (top), positive
/// ticks with a '+'. Throws InvalidInput unless max_value > 0.
void draw_signed_color_bar(RgbImage& image, double max_value, const std::string& unit,
                           const std::string& title, const std::string& note = "");

/// Draws polylines given in LPS mm (e.g. a plan's cutting paths) over the image, in a dashed dark
/// line, as the surgeon's marker would, at their pixels camera.project(p). With `hits`
/// (pixel_hits() of the surface drawn, same camera) the parts of the lines behind the surface
/// (deeper than its hit in their pixel by more than 1 mm) are left out. Throws InvalidInput
/// unless the image (and the hits) are the camera's size.
void draw_polylines(RgbImage& image, const Camera& camera,
                    const std::vector<std::vector<Eigen::Vector3d>>& lines,
                    const PixelHits* hits = nullptr);

/// Draws the suture (scar) lines over a post-operative image: solid, dark red, at
/// camera.project(p) of each polyline's points (LPS mm), hidden parts left out given `hits` (see
/// draw_polylines()). Throws InvalidInput unless the image (and the hits) are the camera's size.
void draw_suture_lines(RgbImage& image, const Camera& camera,
                       const std::vector<std::vector<Eigen::Vector3d>>& lines,
                       const PixelHits* hits = nullptr);

/// The micropolygons' border loops other than the outer rim, as vertex indices of `skin` (each
/// wound's and incision's lips, which the closure brings together), in order around each loop
/// (not repeating its first vertex).
std::vector<std::vector<int>> suture_loops(const SkinSurfaces& skin);

/// The suture lines of the closed skin: the post-operative positions (LPS mm) of suture_loops(),
/// each loop closed.
std::vector<std::vector<Eigen::Vector3d>> suture_lines(const SkinSurfaces& skin);

/// The length (mm) of a scale bar for an image `width_mm` wide: the largest of 1, 2, 5, 10, 20,
/// 50, 100 mm (× powers of ten) that is at most a fifth of the width.
double scale_bar_length_mm(double width_mm);

/// Draws a scale bar in the image's lower left corner over a white panel: a black bar
/// scale_bar_length_mm() long at the camera's scale (width_mm / width_px mm per pixel) with end
/// ticks and its length ("10 mm"). Only for orthographic cameras (a perspective image has no one
/// scale): throws InvalidInput for a perspective camera or an image not the camera's size.
void draw_scale_bar(RgbImage& image, const Camera& camera);

/// The plan's cutting paths on the model's skin (LPS mm), each segment sampled along the skin
/// (in theta and z, across the seam the short way) so that the line follows the surface.
std::vector<std::vector<Eigen::Vector3d>> plan_lines(const plan::Plan& plan, const PatientModel& model);

/// What to draw over the standard views.
struct Overlays {
  /// The plan's cutting paths (LPS mm), drawn over the pre-operative images.
  std::vector<std::vector<Eigen::Vector3d>> plan_lines;
  /// Draw suture_lines() of the skin over the post-operative images.
  bool suture_lines = false;
  /// Draw a scale bar (mm) on every image of an orthographic view.
  bool scale_bar = false;
  /// Also write <name>_<view>.png for each: the post-operative skin coloured by the map, with its
  /// colour bar (displacement_map(), tension_map()).
  std::vector<ScalarMap> scalar_maps;
};

/// render_views() with overlays: pre_<view>.png (with the plan's lines), post_<view>.png (with the
/// suture lines), each with the scale bar if asked, and
/// <name>_<view>.png for each scalar map (e.g. displacement_<view>.png, tension_<view>.png).
/// Returns the paths written. Throws InvalidInput if a map's size is not the skin's vertex count.
std::vector<std::filesystem::path> render_views_with_overlays(const PatientModel& model,
                                                              const SkinSurfaces& skin,
                                                              const std::vector<View>& views,
                                                              const RenderOptions& options,
                                                              const Overlays& overlays,
                                                              const std::filesystem::path& dir,
                                                              Reporter* reporter = nullptr);

}  // namespace caps::render
