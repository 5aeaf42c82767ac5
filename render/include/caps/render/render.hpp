#pragma once
/// @brief Headless images of a coloured triangle mesh: orthographic ray casting (Embree), Lambert
/// shading from a head light and a key light plus a little ambient, per-vertex colours
/// interpolated over each triangle, and PNG output.
///
/// Shading is two-sided (the normal is turned towards the viewer), with smooth vertex normals
/// (area-weighted face normals). Pixels are deterministic: the same mesh and camera give the same
/// bytes, so pre- and post-operative images differ exactly where the skin moved.

#include <Eigen/Core>
#include <filesystem>
#include <string>
#include <vector>

#include "caps/core/mesh.hpp"
#include "caps/render/skin_surface.hpp"
#include "caps/image/rgb_image.hpp"

namespace caps {
class PatientModel;
}

namespace caps::render {

/// An orthographic camera (LPS mm).
struct Camera {
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();  ///< the point at the image's centre
  Eigen::Vector3d forward{0, 1, 0};                  ///< unit viewing direction
  Eigen::Vector3d up{0, 0, 1};                       ///< towards the image's top (made orthogonal)
  double width_mm = 300;                             ///< the image's width in the scene
};

struct RenderOptions {
  int width = 800, height = 800;  ///< pixels
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

/// The camera of a standard view, framed on `skin.pre` (head views: the whole head; plan: the
/// mesh and its surroundings, 1.6 × its diameter). Use the same camera for pre and post.
Camera standard_camera(View view, const PatientModel& model, const SkinSurfaces& skin,
                       double aspect = 1.0);

/// Ray-casts `mesh` (V #V×3 LPS mm, F #F×3) with per-vertex colours `color` (#V×3, [0, 1]).
/// Throws InvalidInput for an empty mesh, mismatched colours or a bad image size.
RgbImage render_image(const TriMesh& mesh, const Eigen::MatrixX3d& color, const Camera& camera,
                      const RenderOptions& options = {});

/// The images of `caps render`: pre_<view>.png and post_<view>.png for each view, same camera.
/// Returns the paths written.
std::vector<std::filesystem::path> render_views(const PatientModel& model,
                                                const SkinSurfaces& skin,
                                                const std::vector<View>& views,
                                                const RenderOptions& options,
                                                const std::filesystem::path& dir);

}  // namespace caps::render
