#pragma once
/// @brief The pre- to post-operative transition as a looping animated GIF: frames ray-cast with
/// render_image() on the blended skin pre + t (post − pre), t = k / (frames − 1), one camera.
///
/// Colour: one global 256-colour palette for all frames, built by giflib's median-cut
/// GifQuantizeBuffer (giflib 5.2) from the first and last frames together (the intermediate
/// frames' colours lie between them); every frame maps each pixel to the nearest palette colour
/// (squared RGB distance at 6 bits per channel, ties to the lower index). No dithering, so the
/// output is deterministic and pixels that do not change between frames keep their index.
/// Frames after the first are stored as the sub-rectangle that changed (disposal "do not
/// dispose"), which keeps files small when only the operated region moves.
///
/// Timing (GIF delays are in 1/100 s): the pre-operative frame is held kGifHoldPreSeconds, the
/// transition takes about kGifTransitionSeconds, the post-operative frame is held
/// kGifHoldPostSeconds, and the animation loops forever (NETSCAPE2.0 extension, loop count 0).

#include <filesystem>
#include <vector>

#include "caps/core/mesh.hpp"
#include "caps/render/render.hpp"
#include "caps/render/skin_surface.hpp"

namespace caps {
class PatientModel;
}

namespace caps::render {

inline constexpr double kGifHoldPreSeconds = 0.8;
inline constexpr double kGifTransitionSeconds = 2.0;
inline constexpr double kGifHoldPostSeconds = 1.2;
/// Default number of frames of `caps render --animation`.
inline constexpr int kGifDefaultFrames = 24;

/// The skin at t in [0, 1]: pre + t (post − pre) (LPS, mm), pre's triangles; t = 0 and t = 1
/// return pre's and post's positions exactly. Throws InvalidInput for t outside [0, 1].
TriMesh blend_skin(const SkinSurfaces& s, double t);

/// Writes the transition as an animated GIF atomically.
/// @param s        pre and post skin (LPS, mm) with colours
/// @param camera   one camera for every frame (e.g. standard_camera(), framed on pre); its
///                 width_px × height_px is the GIF's size
/// @param options  supersampling, background
/// @param frames   number of frames (2..600): frame 0 is pre, frame frames − 1 is post
/// @param path     the .gif to write
/// Throws InvalidInput (bad frame count, see render_image) or IoError.
void write_transition_gif(const SkinSurfaces& s, const Camera& camera, const RenderOptions& options,
                          int frames, const std::filesystem::path& path);

/// The animations of `caps render --animation`: transition_<view>.gif in `dir` for each view,
/// with the view's standard_camera() (framed on pre). Returns the paths written.
std::vector<std::filesystem::path> write_transition_gifs(const PatientModel& model,
                                                         const SkinSurfaces& s,
                                                         const std::vector<View>& views,
                                                         const RenderOptions& options, int frames,
                                                         const std::filesystem::path& dir);

}  // namespace caps::render
