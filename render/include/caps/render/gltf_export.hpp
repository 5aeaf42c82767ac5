#pragma once
/// @brief glTF 2.0 export of the pre- and post-operative skin as one binary .glb: one mesh whose
/// base positions are the pre-operative skin and whose single morph target ("post-operative")
/// holds the displacements to the post-operative skin, with smooth normals (and their morph
/// displacements), vertex colours (COLOR_0) and an animation that drives the morph weight from 0
/// to 1, so Blender, three.js and web viewers show the closure and can play it.
///
/// Frames and units: caps positions are patient LPS millimetres; glTF is metres, right-handed,
/// +Y up, and an asset faces +Z. The export maps
///   gltf = 0.001 · R · lps,  R = [[1, 0, 0], [0, 0, 1], [0, -1, 0]]   (det R = +1)
/// i.e. x = L (the patient's left, on the viewer's right when facing the patient), y = S,
/// z = -P = A (the face looks along +Z). A proper rotation keeps the triangles' counter-clockwise
/// (outward) winding. Positions keep the patient's origin (no recentring), so the export lines up
/// with other exports of the same patient; viewers frame the bounding box.
///
/// Colours: COLOR_0 is linear RGB in glTF, so the model's sRGB colours are linearised
/// (IEC 61966-2-1). The material is white, non-metallic, roughness 0.6, so the vertex colours
/// are the albedo.

#include <Eigen/Core>
#include <filesystem>

#include "caps/render/skin_surface.hpp"

namespace caps::render {

/// Length (s) of the exported animation: the morph weight goes linearly 0 → 1 over it.
inline constexpr double kGltfTransitionSeconds = 2.0;

/// The name of the morph target (mesh.extras.targetNames, read by Blender and three.js).
inline constexpr const char* kGltfMorphTargetName = "post-operative";

/// A point or displacement from LPS millimetres to glTF metres (x = L, y = S, z = A).
/// @param lps_mm  3-vector, LPS, mm
/// @return        3-vector, glTF frame, m
Eigen::Vector3d lps_to_gltf(const Eigen::Vector3d& lps_mm);

/// Writes `s` as a binary glTF 2.0 file (.glb, one embedded buffer), atomically: the mesh "skin"
/// with POSITION = s.pre.V, NORMAL, COLOR_0 = s.color (linearised), indices = s.pre.F, one morph
/// target (POSITION = s.post.V − s.pre.V, NORMAL = post − pre normals) with default weight 0,
/// and the animation "pre-to-post" (weight 0 at 0 s, 1 at kGltfTransitionSeconds, LINEAR).
/// @param s     pre and post skin (LPS, mm), one topology, #V×3 colours in [0, 1]
/// @param path  the .glb to write
/// Throws InvalidInput for an empty or inconsistent skin or non-finite positions, IoError if
/// the file cannot be written.
/// With `post_operative` false (a model's skin before any plan) the file holds the pre-operative
/// skin alone: no morph target, weights or animation (s.post must still match s.pre's shape).
void write_gltf(const SkinSurfaces& s, const std::filesystem::path& path,
                bool post_operative = true);

}  // namespace caps::render
