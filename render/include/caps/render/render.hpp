#pragma once
/// @brief Headless images of a coloured triangle mesh: ray casting (Embree) through the pixels of
/// a caps::Camera (surface/camera.hpp; the standard views are orthographic), Lambert
/// shading from a head light and a key light plus a little ambient, per-vertex colours
/// interpolated over each triangle, and PNG output.
///
/// Shading is two-sided (the normal is turned towards the viewer), with smooth vertex normals
/// (given, as the skin's shading normals, or area-weighted face normals). Embree runs in its
/// robust (watertight) mode: no ray slips through an edge. Pixels are deterministic: the same mesh and camera give the same
/// bytes, so pre- and post-operative images differ exactly where the skin moved.

#include <Eigen/Core>
#include <filesystem>
#include <string>
#include <vector>

#include "caps/core/mesh.hpp"
#include "caps/render/skin_surface.hpp"
#include "caps/image/rgb_image.hpp"
#include "caps/surface/camera.hpp"

namespace caps {
class PatientModel;
}

namespace caps::render {

/// Shading and sampling of render_image(). The image size is the camera's (width_px ×
/// height_px); `width` and `height` size the views that the functions framing their own cameras
/// (render_views(), render_views_with_overlays(), write_transition_gifs()) make, through
/// standard_camera().
struct RenderOptions {
  int width = 800, height = 800;  ///< pixels of the standard views framed by the batch functions
  int samples_per_side = 2;       ///< supersampling: s × s rays per pixel, box-filtered
  Eigen::Vector3d background{0.12, 0.12, 0.14};  ///< RGB in [0, 1]
  double ambient = 0.15;
};

/// The standard views: front (theta 0), oblique (theta 45 deg, the patient's left), side
/// (theta 90 deg) and plan (straight at the mesh's centre along the skin normal).
enum class View { Front, Oblique, Side, Plan };

/// "front" / "oblique" / "side" / "plan".
const char* view_name(View view);
/// Parses a view name; throws InvalidInput naming the valid ones.
View parse_view(const std::string& name);

/// The orthographic camera of a standard view for a width_px × height_px image, framed on
/// `skin.pre` (head views: the whole head; plan: the mesh and its surroundings, 1.6 × its
/// diameter). Use the same camera for pre and post, and for picking on the image: its
/// distance_mm puts the eye outside the pre-operative skin's bounding sphere about the target.
Camera standard_camera(View view, const PatientModel& model, const SkinSurfaces& skin, int width_px,
                       int height_px);

/// Ray-casts `mesh` (V #V×3 LPS mm, F #F×3) with per-vertex colours `color` (#V×3, [0, 1])
/// into a camera.width_px × camera.height_px image: pixel (x, y) averages the rays
/// camera.ray(x + (i + 0.5) / s, y + (j + 0.5) / s), i, j = 0 .. s − 1 (s = samples_per_side).
/// Orthographic rays start outside the mesh's bounding sphere about the camera's target,
/// whatever the camera's distance_mm. Throws InvalidInput for an empty mesh, mismatched colours,
/// an invalid camera or a bad sample count.
RgbImage render_image(const TriMesh& mesh, const Eigen::MatrixX3d& color, const Camera& camera,
                      const RenderOptions& options = {});

/// render_image() with given shading normals `normals` (#V×3 unit, LPS; e.g. the skin's
/// normal_pre / normal_post) instead of the mesh's vertex_normals().
RgbImage render_image(const TriMesh& mesh, const Eigen::MatrixX3d& color,
                      const Eigen::MatrixX3d& normals, const Camera& camera,
                      const RenderOptions& options = {});

/// The skin blended pre + t (post - pre) (t in [0, 1]; 0: pre, 1: post exactly) with its
/// shading_normals(skin, t) and per-vertex colours `color` (#V×3, e.g. skin.color).
RgbImage render_skin(const SkinSurfaces& skin, double t, const Eigen::MatrixX3d& color,
                     const Camera& camera, const RenderOptions& options = {});

/// What the renderer's ray through each pixel's centre, camera.ray(x + 0.5, y + 0.5), meets
/// (the one sample of render_image() with samples_per_side = 1), row-major, y down.
struct PixelHits {
  int width = 0, height = 0;     ///< pixels
  std::vector<int> face;         ///< #pixels: the triangle of `mesh` shaded there, −1: background
  std::vector<double> depth_mm;  ///< #pixels: Camera::depth_mm of the hit, +inf: background
};

/// The renderer's hits at the pixel centres of `camera` on `mesh` (V #V×3 LPS mm, F #F×3),
/// computed exactly as render_image() casts its rays (Embree, single precision). Throws
/// InvalidInput for an empty mesh or an invalid camera.
PixelHits pixel_hits(const TriMesh& mesh, const Camera& camera);

/// The images of `caps render`: pre_<view>.png and post_<view>.png for each view, same camera.
/// Returns the paths written.
std::vector<std::filesystem::path> render_views(const PatientModel& model,
                                                const SkinSurfaces& skin,
                                                const std::vector<View>& views,
                                                const RenderOptions& options,
                                                const std::filesystem::path& dir);

}  // namespace caps::render
