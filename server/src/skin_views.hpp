#pragma once
// The skin as the planner page shows it: binary glTF files written by render::write_gltf (frames
// and units in caps/render/gltf_export.hpp: glTF metres, x = L, y = S, z = A) and the plan's cutting
// lines on the skin. Internal to the server.

#include <filesystem>
#include <functional>
#include <string>

namespace caps {
class PatientModel;
}
namespace caps::fem {
struct Mesh;
}
namespace caps::plan {
struct Plan;
}
namespace caps::render {
struct DrawnSkin;
}

namespace caps::server::detail {

/// What the pre-operative skin is coloured by.
enum class SkinColouring { Skin, Thickness };

/// The model's skin range mesh (one vertex per (theta, z) sample, poles closed) as a .glb at
/// `path`, coloured by the model's colour (a plain skin tone where it has none) or by the radial
/// soft-tissue thickness (viridis from 0 to the 99th percentile over the valid cells, grey on
/// cells flagged invalid). @return the JSON {"colouring", "scale_max_mm" (thickness), "vertices",
/// "faces"}.
std::string write_model_skin_glb(const PatientModel& model, SkinColouring colouring,
                                 const std::filesystem::path& path);

/// The micropolygons per element edge of a simulation's skin on the page: the model's finest
/// sample spacing (dz, or dtheta as arc at the skin) on the median skin-face edge, at most 8. The
/// pictures of `caps render` take the longest edge (render::full_resolution_subdivisions()), which
/// on a graded mesh is a rim element that hardly moves; the median is the size of the elements
/// where the skin moves, and 2-4 times fewer micropolygons (measured in docs/benchmarks.md).
int view_subdivisions(const PatientModel& model, const fem::Mesh& mesh);

/// A simulation's skin as the page shows it (write_result_skin_glbs()).
struct ResultView {
  std::string json;                     ///< its description (see write_result_skin_glbs())
  std::function<void()> write_tension;  ///< writes tension.glb (the page asks for it later)
};

/// The pre- and post-operative skin of the simulation in `result_dir` (caps simulate's folder)
/// on `model` drawn as `drawn` (its DrawnSkin, or null for the model's range as measured: the
/// seam's range vertices and the moved skin's vertices are those of the skin the page draws,
/// write_model_skin_glb() of `drawn->range`), with the post-operative skin as the morph target
/// (render::write_gltf): skin.glb, written now, the part of render::displaced_skin() the simulation moved (the micropolygons at
/// view_subdivisions(), the wound fill and the seam) coloured as the model, and tension.glb,
/// written by the returned write_tension, the same part coloured by the skin tension
/// (render::tension_map, viridis from 0 to the 99th percentile; the seam's outer vertices carry
/// the tissue model's tension in a whole-face closure), and beside it
/// tension_kpa.f32, the tension at each of its vertices (float32, little endian, kPa), for
/// colouring several results on one scale. The rest is the model's
/// own skin (write_model_skin_glb()) without the cells listed in "replaced_cells". The JSON:
/// {"skin", "tension", "tension_values", "replaced_cells" (cells q = k n_theta + j of range_mesh(), faces 2q and
/// 2q + 1), "subdivisions", "vertices", "tension_scale_max_kpa", "max_skin_tension_kpa",
/// "wound_area_mm2": {"pre", "post"}, "moved_skin" (null for a patch-only closure, or
/// skin_moved.bin: the model's skin vertices the whole-face closure moves around the patch, as
/// records of a uint32 vertex of write_model_skin_glb()'s mesh and its move as three float32,
/// glTF metres, little endian), "moved_skin_vertices", "moved_skin_max_mm", "moved_skin_tension"
/// (null for a patch-only closure, or tension_moved_skin_kpa.bin, written with tension.glb: the
/// model's skin vertices the closure reaches, as records of a uint32 vertex and its tension as a
/// float32, kPa, little endian), "scar_lines" (the
/// lips of each wound and incision, render::suture_loops(): [{"pre_lps", "post_lps"}], each a
/// closed loop of points, LPS mm, before and after the closure), "timings_s":
/// {"skin" (reading the result and building the
/// skin), "tension" (its values), "glb" (writing skin.glb)}}.
ResultView write_result_skin_glbs(const PatientModel& model, const render::DrawnSkin* drawn,
                                  const std::filesystem::path& result_dir);

/// The plan's cutting paths and points on the skin, LPS mm: {"lines_lps": [[[x, y, z], ...],
/// ...], "points_lps": [[x, y, z], ...], "loop": {"nodes": [{"point", "lps", "normal_lps"}],
/// "edges_lps": [edge i -> i + 1 as 9 points along the skin]} (the border loop, excision offsets
/// applied), "centre": {"theta_deg", "z_mm", "orientation_deg", "lps", "normal_lps", "axis_lps"
/// (unit tangent along the plan's x axis, its orientation), "half_extent_mm" (the points' largest
/// |x|), "handle_gap_mm", "rotate_handle_lps" and "scale_handle_lps" (on the skin at x = -/+
/// (half_extent_mm + handle_gap_mm): where the page draws the handles that turn and scale it)}}.
std::string plan_lines_json(const plan::Plan& plan, const PatientModel& model);

}  // namespace caps::server::detail
