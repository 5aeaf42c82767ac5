// caps::render exports: the glTF 2.0 skin with its post-operative morph target (read back with
// TinyGLTF: counts, bounding box, displacements, the LPS → glTF frame on a synthetic face) and the
// pre-to-post GIF (decoded with giflib: frames, delays, loop, first/last frame against the
// renders of pre and post).
#include <gif_lib.h>
#include <gtest/gtest.h>

#include "synthetic_model.hpp"
#include <tiny_gltf.h>

#include <unistd.h>
#include <Eigen/Geometry>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <string>

#include "caps/core/units.hpp"
#include "caps/closure/simulate.hpp"
#include "caps/plan/procedures.hpp"
#include "caps/render/animation.hpp"
#include "caps/render/gltf_export.hpp"
#include "caps/render/render.hpp"
#include "caps/render/skin_surface.hpp"
#include "caps/surface/patient_model.hpp"

using namespace caps;
using namespace caps::render;
namespace fs = std::filesystem;

namespace {

// A bumpy cylinder about the LPS z axis (r = 70 mm ± 2), z in [-100, 100], 5 mm of tissue.
const PatientModel& bumpy() {
  static const PatientModel model = [] {
    CylindricalMaps m = caps_test::synthetic_maps(
        caps_test::grid(360, 201, -100, 1),
        [](double theta, double z) {
          return 70.0 + 2.0 * std::sin(deg_to_rad(3 * theta)) * std::cos(z / 15.0);
        },
        [](double, double) { return 5.0; });
    return PatientModel(std::move(m));
  }();
  return model;
}

const closure::Simulation& sim() {
  static const closure::Simulation s = [] {
    const plan::Plan p =
        plan::place_procedure(plan::layout_procedure("ellipse", {{"length", 20.0}, {"width", 6.0}}),
                              bumpy(), 10.0, 5.0, 90.0);
    closure::SimulateOptions o;
    o.surface.size_mm = 3.0;
    o.continuum.undermine_mm = 0;  // the sutured columns only: the closure's shading stays local
    return closure::simulate(bumpy(), p, o);
  }();
  return s;
}

const SkinSurfaces& closed_skin() {
  static const SkinSurfaces s =
      displaced_skin(bumpy(), sim().wound.continuum.mesh, &sim().result, 3);
  return s;
}

fs::path scratch(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / cat("caps_test_render_export_", ::getpid());
  fs::create_directories(dir);
  return dir / name;
}

// ---- glTF read-back
tinygltf::Model load_glb(const fs::path& path) {
  tinygltf::TinyGLTF loader;
  tinygltf::Model m;
  std::string err, warn;
  const bool ok = loader.LoadBinaryFromFile(&m, &err, &warn, path.string());
  EXPECT_TRUE(ok) << err;
  EXPECT_TRUE(err.empty()) << err;
  return m;
}

// The float VEC3/SCALAR values of an accessor as #count × cols doubles.
Eigen::MatrixXd floats(const tinygltf::Model& m, int accessor) {
  const tinygltf::Accessor& a = m.accessors.at(accessor);
  EXPECT_EQ(a.componentType, TINYGLTF_COMPONENT_TYPE_FLOAT);
  const int cols = a.type == TINYGLTF_TYPE_VEC3 ? 3 : 1;
  const tinygltf::BufferView& v = m.bufferViews.at(a.bufferView);
  const std::size_t stride = v.byteStride ? v.byteStride : 4 * cols;
  const unsigned char* p = m.buffers.at(v.buffer).data.data() + v.byteOffset + a.byteOffset;
  Eigen::MatrixXd out(a.count, cols);
  for (std::size_t r = 0; r < a.count; ++r)
    for (int c = 0; c < cols; ++c) {
      float f;
      std::memcpy(&f, p + r * stride + 4 * c, 4);
      out(r, c) = f;
    }
  return out;
}

Eigen::MatrixX3d to_gltf(const Eigen::MatrixX3d& lps_mm) {
  // expected mapping, written out independently of lps_to_gltf: x = L, y = S, z = -P
  Eigen::MatrixX3d g(lps_mm.rows(), 3);
  g.col(0) = 1e-3 * lps_mm.col(0);
  g.col(1) = 1e-3 * lps_mm.col(2);
  g.col(2) = -1e-3 * lps_mm.col(1);
  return g;
}

// ---- GIF read-back: the composited frames as RGB images
struct DecodedGif {
  int width = 0, height = 0;
  std::vector<RgbImage> frames;
  std::vector<int> delays_cs;
  bool loops_forever = false;
};

DecodedGif read_gif(const fs::path& path) {
  DecodedGif out;
  int err = 0;
  GifFileType* g = DGifOpenFileName(path.c_str(), &err);
  if (!g) {
    ADD_FAILURE() << GifErrorString(err);
    return out;
  }
  EXPECT_EQ(DGifSlurp(g), GIF_OK) << GifErrorString(g->Error);
  out.width = g->SWidth;
  out.height = g->SHeight;
  RgbImage canvas;
  canvas.width = g->SWidth;
  canvas.height = g->SHeight;
  canvas.rgb.assign(std::size_t(canvas.width) * canvas.height * 3, 0);
  const auto scan = [&](int n, const ExtensionBlock* b) {
    for (int i = 0; i + 1 < n; ++i)
      if (b[i].Function == APPLICATION_EXT_FUNC_CODE && b[i].ByteCount == 11 &&
          std::memcmp(b[i].Bytes, "NETSCAPE2.0", 11) == 0 && b[i + 1].ByteCount == 3 &&
          b[i + 1].Bytes[0] == 1 && b[i + 1].Bytes[1] == 0 && b[i + 1].Bytes[2] == 0)
        out.loops_forever = true;
  };
  scan(g->ExtensionBlockCount, g->ExtensionBlocks);
  for (int k = 0; k < g->ImageCount; ++k) {
    const SavedImage& im = g->SavedImages[k];
    scan(im.ExtensionBlockCount, im.ExtensionBlocks);
    const ColorMapObject* map = im.ImageDesc.ColorMap ? im.ImageDesc.ColorMap : g->SColorMap;
    const GifImageDesc& d = im.ImageDesc;
    for (int y = 0; y < d.Height; ++y)
      for (int x = 0; x < d.Width; ++x) {
        const GifColorType c = map->Colors[im.RasterBits[std::size_t(y) * d.Width + x]];
        const std::size_t i = (std::size_t(d.Top + y) * canvas.width + d.Left + x) * 3;
        canvas.rgb[i] = c.Red;
        canvas.rgb[i + 1] = c.Green;
        canvas.rgb[i + 2] = c.Blue;
      }
    out.frames.push_back(canvas);
    GraphicsControlBlock gcb;
    EXPECT_EQ(DGifSavedExtensionToGCB(g, k, &gcb), GIF_OK);
    EXPECT_EQ(gcb.DisposalMode, DISPOSE_DO_NOT);
    out.delays_cs.push_back(gcb.DelayTime);
  }
  DGifCloseFile(g, &err);
  return out;
}

struct Diff {
  double mean = 0;
  int max = 0;
};
Diff diff(const RgbImage& a, const RgbImage& b) {
  Diff d;
  for (std::size_t i = 0; i < a.rgb.size(); ++i) {
    const int e = std::abs(int(a.rgb[i]) - int(b.rgb[i]));
    d.mean += e;
    d.max = std::max(d.max, e);
  }
  d.mean /= double(a.rgb.size());
  return d;
}

}  // namespace

TEST(GltfExport, MeshMorphTargetAndAnimationReadBack) {
  const SkinSurfaces& s = closed_skin();
  const fs::path path = scratch("skin.glb");
  write_gltf(s, path);
  const tinygltf::Model m = load_glb(path);
  ASSERT_EQ(m.meshes.size(), 1u);
  ASSERT_EQ(m.meshes[0].primitives.size(), 1u);
  const tinygltf::Primitive& prim = m.meshes[0].primitives[0];
  EXPECT_EQ(prim.mode, TINYGLTF_MODE_TRIANGLES);
  for (const char* attr : {"POSITION", "NORMAL", "COLOR_0"}) {
    ASSERT_TRUE(prim.attributes.count(attr)) << attr;
    EXPECT_EQ(m.accessors[prim.attributes.at(attr)].count, std::size_t(s.pre.V.rows())) << attr;
  }
  EXPECT_EQ(m.accessors[prim.indices].count, std::size_t(3 * s.pre.F.rows()));
  ASSERT_EQ(prim.targets.size(), 1u);
  ASSERT_TRUE(prim.targets[0].count("POSITION"));
  ASSERT_EQ(m.meshes[0].weights, std::vector<double>{0.0});
  ASSERT_TRUE(m.meshes[0].extras.Has("targetNames"));
  EXPECT_EQ(m.meshes[0].extras.Get("targetNames").Get(0).Get<std::string>(), "post-operative");

  // base positions = pre, base + displacement = post (metres; float precision at ~0.1 m)
  const Eigen::MatrixXd P = floats(m, prim.attributes.at("POSITION"));
  const Eigen::MatrixXd D = floats(m, prim.targets[0].at("POSITION"));
  const Eigen::MatrixX3d pre = to_gltf(s.pre.V), post = to_gltf(s.post.V);
  EXPECT_LT((P - pre).cwiseAbs().maxCoeff(), 1e-7);
  EXPECT_LT((P + D - post).cwiseAbs().maxCoeff(), 1e-7);
  const double max_move_m = 1e-3 * (s.post.V - s.pre.V).rowwise().norm().maxCoeff();
  EXPECT_GT(max_move_m, 0.5e-3);
  EXPECT_NEAR(D.rowwise().norm().maxCoeff(), max_move_m, 1e-6 * max_move_m);

  // declared bounds = the skin's bounding box, converted
  const tinygltf::Accessor& pa = m.accessors[prim.attributes.at("POSITION")];
  ASSERT_EQ(pa.minValues.size(), 3u);
  ASSERT_EQ(pa.maxValues.size(), 3u);
  for (int c = 0; c < 3; ++c) {
    EXPECT_NEAR(pa.minValues[c], pre.col(c).minCoeff(), 1e-7) << c;
    EXPECT_NEAR(pa.maxValues[c], pre.col(c).maxCoeff(), 1e-7) << c;
  }
  const tinygltf::Accessor& da = m.accessors[prim.targets[0].at("POSITION")];
  EXPECT_EQ(da.minValues.size(), 3u);  // required on morph-target positions too

  // unit normals, colours in [0, 1]
  const Eigen::MatrixXd N = floats(m, prim.attributes.at("NORMAL"));
  EXPECT_LT((N.rowwise().norm().array() - 1.0).abs().maxCoeff(), 1e-5);
  const Eigen::MatrixXd C = floats(m, prim.attributes.at("COLOR_0"));
  EXPECT_GE(C.minCoeff(), 0.0);
  EXPECT_LE(C.maxCoeff(), 1.0);

  // the animation drives the morph weight 0 → 1 over 2 s
  ASSERT_EQ(m.animations.size(), 1u);
  const tinygltf::Animation& an = m.animations[0];
  ASSERT_EQ(an.channels.size(), 1u);
  EXPECT_EQ(an.channels[0].target_path, "weights");
  EXPECT_EQ(an.channels[0].target_node, 0);
  EXPECT_EQ(m.nodes.at(0).mesh, 0);
  const tinygltf::AnimationSampler& sa = an.samplers.at(an.channels[0].sampler);
  EXPECT_EQ(sa.interpolation, "LINEAR");
  const Eigen::MatrixXd t = floats(m, sa.input), w = floats(m, sa.output);
  ASSERT_EQ(t.rows(), 2);
  ASSERT_EQ(w.rows(), 2);
  EXPECT_EQ(t(0, 0), 0.0);
  EXPECT_EQ(t(1, 0), 2.0);
  EXPECT_EQ(w(0, 0), 0.0);
  EXPECT_EQ(w(1, 0), 1.0);
  EXPECT_EQ(m.accessors[sa.input].maxValues, std::vector<double>{2.0});
  fs::remove_all(path.parent_path());
}

TEST(GltfExport, ASkinBeforeAnyPlanHasNoMorphTarget) {
  // A model's skin (the planner's GET /api/skin, before any plan) is written without the
  // post-operative morph target, its weights and its animation (issue 38); its positions,
  // normals and colours are the same as with them.
  const SkinSurfaces& s = closed_skin();
  const fs::path with = scratch("with.glb"), without = scratch("without.glb");
  write_gltf(s, with);
  write_gltf(s, without, false);
  const tinygltf::Model a = load_glb(with), b = load_glb(without);
  const tinygltf::Primitive& pb = b.meshes.at(0).primitives.at(0);
  EXPECT_TRUE(pb.targets.empty());
  EXPECT_TRUE(b.meshes[0].weights.empty());
  EXPECT_FALSE(b.meshes[0].extras.Has("targetNames"));
  EXPECT_TRUE(b.animations.empty());
  const tinygltf::Primitive& pa = a.meshes.at(0).primitives.at(0);
  for (const char* attr : {"POSITION", "NORMAL", "COLOR_0"})
    EXPECT_EQ(floats(a, pa.attributes.at(attr)), floats(b, pb.attributes.at(attr))) << attr;
  EXPECT_LT(fs::file_size(without), fs::file_size(with));
  fs::remove_all(with.parent_path());
}

TEST(GltfExport, FaceLooksAlongPlusZWithYUp) {
  // A synthetic face: a square in the coronal plane 80 mm anterior (LPS y = -80), its outward
  // normal anterior (-y), counter-clockwise seen from the front.
  SkinSurfaces s;
  s.pre.V.resize(4, 3);
  s.pre.V << -10, -80, -10, 10, -80, -10, 10, -80, 10, -10, -80, 10;
  s.pre.F.resize(2, 3);
  s.pre.F << 0, 1, 2, 0, 2, 3;
  s.post = s.pre;
  // post: 2 mm to the patient's left, 3 mm anterior, 5 mm superior
  s.post.V.rowwise() += Eigen::RowVector3d(2, -3, 5);
  s.color = Eigen::MatrixX3d::Constant(4, 3, 0.5);
  const fs::path path = scratch("face.glb");
  write_gltf(s, path);
  const tinygltf::Model m = load_glb(path);
  const tinygltf::Primitive& prim = m.meshes.at(0).primitives.at(0);
  const Eigen::MatrixXd P = floats(m, prim.attributes.at("POSITION"));
  const Eigen::MatrixXd N = floats(m, prim.attributes.at("NORMAL"));
  const Eigen::MatrixXd D = floats(m, prim.targets.at(0).at("POSITION"));
  // the face is at glTF z = +0.08 m and faces +Z (normals and winding)
  EXPECT_NEAR(P.col(2).minCoeff(), 0.08, 1e-7);
  EXPECT_NEAR(P.col(2).maxCoeff(), 0.08, 1e-7);
  for (int v = 0; v < 4; ++v) EXPECT_LT((N.row(v) - Eigen::RowVector3d(0, 0, 1)).norm(), 1e-6);
  const Eigen::Vector3d a = P.row(0), b = P.row(1), c = P.row(2);
  EXPECT_GT((b - a).cross(c - a).z(), 0.0);
  // left → +X, anterior → +Z, superior → +Y, millimetres → metres
  for (int v = 0; v < 4; ++v)
    EXPECT_LT((D.row(v) - Eigen::RowVector3d(0.002, 0.005, 0.003)).norm(), 1e-9);
  // the mapping is a rotation (determinant +1) times 0.001
  Eigen::Matrix3d R;
  for (int k = 0; k < 3; ++k) R.col(k) = 1e3 * lps_to_gltf(Eigen::Vector3d::Unit(k));
  EXPECT_NEAR(R.determinant(), 1.0, 1e-12);
  EXPECT_LT((R.transpose() * R - Eigen::Matrix3d::Identity()).norm(), 1e-12);
  // colours are linearised sRGB: 0.5 → 0.214
  EXPECT_NEAR(floats(m, prim.attributes.at("COLOR_0"))(0, 0), 0.2140, 1e-4);
  fs::remove_all(path.parent_path());
}

TEST(GltfExport, RejectsInconsistentSkin) {
  SkinSurfaces s;
  EXPECT_THROW(write_gltf(s, scratch("empty.glb")), InvalidInput);
  s.pre.V = Eigen::MatrixX3d::Zero(3, 3);
  s.pre.F = Eigen::MatrixX3i(1, 3);
  s.pre.F << 0, 1, 2;
  s.post = s.pre;
  s.color = Eigen::MatrixX3d::Zero(2, 3);
  EXPECT_THROW(write_gltf(s, scratch("bad.glb")), InvalidInput);
  fs::remove_all(scratch("x").parent_path());
}

TEST(TransitionGif, FirstAndLastFramesArePreAndPost) {
  const SkinSurfaces& s = closed_skin();
  RenderOptions o;
  o.width = o.height = 128;
  const Camera cam = standard_camera(View::Plan, bumpy(), s, o.width, o.height);
  const fs::path path = scratch("transition.gif");
  const int frames = 5;
  write_transition_gif(s, cam, o, frames, path);
  const DecodedGif gif = read_gif(path);
  ASSERT_EQ(gif.width, 128);
  ASSERT_EQ(gif.height, 128);
  ASSERT_EQ(int(gif.frames.size()), frames);
  EXPECT_TRUE(gif.loops_forever);
  EXPECT_EQ(gif.delays_cs.front(), 80);
  EXPECT_EQ(gif.delays_cs.back(), 120);
  EXPECT_EQ(gif.delays_cs[1], 50);  // 2 s over 4 steps

  // the skin's images (its shading normals blended like its positions)
  const RgbImage pre = render_skin(s, 0.0, s.color, cam, o);
  const RgbImage post = render_skin(s, 1.0, s.color, cam, o);
  const RgbImage mid = render_skin(s, 0.5, s.color, cam, o);
  // one 256-colour palette: quantisation costs about half a level on average (measured 0.5, max 6)
  const Diff d0 = diff(gif.frames.front(), pre), d1 = diff(gif.frames.back(), post),
             dm = diff(gif.frames[2], mid);
  EXPECT_LT(d0.mean, 1.0);
  EXPECT_LT(d1.mean, 1.0);
  EXPECT_LT(dm.mean, 1.0);
  EXPECT_LE(d0.max, 8);
  EXPECT_LE(d1.max, 8);
  EXPECT_LE(dm.max, 8);
  // and the first frame is pre, not post (and the last post, not pre): over the channels where
  // the renders differ clearly (the closure changes the plan view by up to ~15 levels at this
  // size), frame 0 is much closer to pre than to post
  int distinct = 0;
  double f0_pre = 0, f0_post = 0, fl_post = 0, fl_pre = 0;
  for (std::size_t i = 0; i < pre.rgb.size(); ++i) {
    if (std::abs(int(pre.rgb[i]) - int(post.rgb[i])) < 8) continue;
    ++distinct;
    const int f0 = gif.frames.front().rgb[i], fl = gif.frames.back().rgb[i];
    f0_pre += std::abs(f0 - pre.rgb[i]);
    f0_post += std::abs(f0 - post.rgb[i]);
    fl_post += std::abs(fl - post.rgb[i]);
    fl_pre += std::abs(fl - pre.rgb[i]);
  }
  EXPECT_GT(distinct, 10);
  EXPECT_LT(f0_pre, 0.5 * f0_post);
  EXPECT_LT(fl_post, 0.5 * fl_pre);
  EXPECT_NE(gif.frames.front().rgb, gif.frames.back().rgb);
  fs::remove_all(path.parent_path());
}

TEST(TransitionGif, ZeroDisplacementGivesIdenticalFrames) {
  const SkinSurfaces s = displaced_skin(bumpy(), sim().wound.continuum.mesh,
                                        static_cast<const Eigen::MatrixX3d*>(nullptr), 3);
  RenderOptions o;
  o.width = 96;
  o.height = 64;
  const Camera cam = standard_camera(View::Front, bumpy(), s, o.width, o.height);
  const fs::path path = scratch("still.gif");
  write_transition_gif(s, cam, o, 4, path);
  const DecodedGif gif = read_gif(path);
  ASSERT_EQ(int(gif.frames.size()), 4);
  EXPECT_EQ(gif.width, 96);
  EXPECT_EQ(gif.height, 64);
  EXPECT_TRUE(gif.loops_forever);
  for (const RgbImage& f : gif.frames) EXPECT_EQ(f.rgb, gif.frames[0].rgb);
  const Diff d = diff(gif.frames[0], render_image(s.pre, s.color, cam, o));
  EXPECT_LT(d.mean, 1.0);
  EXPECT_LE(d.max, 8);
  EXPECT_THROW(write_transition_gif(s, cam, o, 1, scratch("one.gif")), InvalidInput);
  EXPECT_THROW(blend_skin(s, 1.5), InvalidInput);
  fs::remove_all(path.parent_path());
}
