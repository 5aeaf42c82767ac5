#include "caps/render/gltf_export.hpp"

#include "caps/core/atomic_output.hpp"
#include "caps/core/error.hpp"

#include <tiny_gltf.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace caps::render {
namespace {

constexpr int kFloat = TINYGLTF_COMPONENT_TYPE_FLOAT;

double srgb_to_linear(double c) {
  c = std::clamp(c, 0.0, 1.0);
  return c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4);
}

// One buffer, one view per accessor, tightly packed (every component is 4 bytes, so every view
// starts 4-aligned as glTF requires).
class GltfBuilder {
 public:
  explicit GltfBuilder(tinygltf::Model& m) : m_(m) { m_.buffers.resize(1); }

  // A float accessor of `rows` × `cols` values (cols 1 = SCALAR, 3 = VEC3), with min/max of
  // the float values as stored (the validator compares them exactly).
  int add_float(const std::vector<float>& data, int cols, int target, bool with_bounds) {
    const std::size_t rows = data.size() / cols;
    const int view = add_view(data.data(), data.size() * sizeof(float), target);
    tinygltf::Accessor a;
    a.bufferView = view;
    a.componentType = kFloat;
    a.count = rows;
    a.type = cols == 1 ? TINYGLTF_TYPE_SCALAR : TINYGLTF_TYPE_VEC3;
    if (with_bounds) {
      a.minValues.assign(cols, 1e300);
      a.maxValues.assign(cols, -1e300);
      for (std::size_t r = 0; r < rows; ++r)
        for (int c = 0; c < cols; ++c) {
          a.minValues[c] = std::min(a.minValues[c], double(data[r * cols + c]));
          a.maxValues[c] = std::max(a.maxValues[c], double(data[r * cols + c]));
        }
    }
    m_.accessors.push_back(std::move(a));
    return int(m_.accessors.size()) - 1;
  }

  int add_indices(const std::vector<std::uint32_t>& data) {
    const int view = add_view(data.data(), data.size() * sizeof(std::uint32_t),
                              TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER);
    tinygltf::Accessor a;
    a.bufferView = view;
    a.componentType = TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT;
    a.count = data.size();
    a.type = TINYGLTF_TYPE_SCALAR;
    m_.accessors.push_back(std::move(a));
    return int(m_.accessors.size()) - 1;
  }

 private:
  int add_view(const void* bytes, std::size_t n, int target) {
    std::vector<unsigned char>& buf = m_.buffers[0].data;
    tinygltf::BufferView v;
    v.buffer = 0;
    v.byteOffset = buf.size();
    v.byteLength = n;
    if (target != 0) v.target = target;
    const auto* p = static_cast<const unsigned char*>(bytes);
    buf.insert(buf.end(), p, p + n);
    m_.bufferViews.push_back(v);
    return int(m_.bufferViews.size()) - 1;
  }

  tinygltf::Model& m_;  // not owned; outlives the builder
};

std::vector<float> to_gltf_floats(const Eigen::MatrixX3d& M_lps_mm) {
  std::vector<float> out(static_cast<std::size_t>(M_lps_mm.rows()) * 3);
  for (Eigen::Index v = 0; v < M_lps_mm.rows(); ++v) {
    const Eigen::Vector3d g = lps_to_gltf(M_lps_mm.row(v).transpose());
    for (int c = 0; c < 3; ++c) out[3 * v + c] = static_cast<float>(g[c]);
  }
  return out;
}

// Unit normals in the glTF frame (a rotation: no scale). A vertex without a normal (in no
// non-degenerate triangle) gets `fallback`'s row, or +Y, so every NORMAL is unit length.
Eigen::MatrixX3d gltf_normals(const Eigen::MatrixX3d& N_lps, const Eigen::MatrixX3d* fallback) {
  Eigen::MatrixX3d out(N_lps.rows(), 3);
  for (Eigen::Index v = 0; v < N_lps.rows(); ++v) {
    if (N_lps.row(v).squaredNorm() > 0.5)
      out.row(v) = (1000.0 * lps_to_gltf(N_lps.row(v).transpose())).transpose();
    else if (fallback)
      out.row(v) = fallback->row(v);
    else
      out.row(v) = Eigen::RowVector3d(0, 1, 0);
  }
  return out;
}

void check_skin(const SkinSurfaces& s, const std::filesystem::path& path) {
  const std::string where = path.string();
  if (s.pre.V.rows() == 0 || s.pre.F.rows() == 0)
    throw InvalidInput(cat(where, ": the skin is empty; nothing to export"));
  if (s.post.V.rows() != s.pre.V.rows() || s.post.F.rows() != s.pre.F.rows() ||
      s.color.rows() != s.pre.V.rows())
    throw InvalidInput(cat(where, ": pre (", s.pre.V.rows(), " vertices), post (", s.post.V.rows(),
                           ") and colours (", s.color.rows(),
                           ") must match; rebuild the skin with ", "displaced_skin()"));
  if (!s.pre.V.allFinite() || !s.post.V.allFinite() || !s.color.allFinite())
    throw InvalidInput(cat(where, ": the skin has non-finite positions or colours"));
  if (s.pre.F.minCoeff() < 0 || s.pre.F.maxCoeff() >= s.pre.V.rows())
    throw InvalidInput(cat(where, ": a triangle index is outside 0..", s.pre.V.rows() - 1));
}

}  // namespace

Eigen::Vector3d lps_to_gltf(const Eigen::Vector3d& p) {
  return 1e-3 * Eigen::Vector3d(p.x(), p.z(), -p.y());
}

void write_gltf(const SkinSurfaces& s, const std::filesystem::path& path, bool post_operative) {
  check_skin(s, path);
  const Eigen::Index nv = s.pre.V.rows();

  tinygltf::Model model;
  model.asset.version = "2.0";
  model.asset.generator = "caps (caps::render::write_gltf)";
  GltfBuilder b(model);

  const Eigen::MatrixX3d n_pre = gltf_normals(shading_normals(s, 0.0), nullptr);
  const Eigen::MatrixX3d n_post = gltf_normals(shading_normals(s, 1.0), &n_pre);

  const std::vector<float> pos = to_gltf_floats(s.pre.V);
  std::vector<float> nrm(3 * nv), col(3 * nv), dpos(3 * nv), dnrm(3 * nv);
  for (Eigen::Index v = 0; v < nv; ++v) {
    // the displacement in double before rounding, so small motions keep their precision
    const Eigen::Vector3d d = lps_to_gltf((s.post.V.row(v) - s.pre.V.row(v)).transpose());
    for (int c = 0; c < 3; ++c) {
      nrm[3 * v + c] = static_cast<float>(n_pre(v, c));
      col[3 * v + c] = static_cast<float>(srgb_to_linear(s.color(v, c)));
      dpos[3 * v + c] = static_cast<float>(d[c]);
      dnrm[3 * v + c] = static_cast<float>(n_post(v, c) - n_pre(v, c));
    }
  }
  std::vector<std::uint32_t> idx(3 * s.pre.F.rows());
  for (Eigen::Index f = 0; f < s.pre.F.rows(); ++f)
    for (int c = 0; c < 3; ++c) idx[3 * f + c] = static_cast<std::uint32_t>(s.pre.F(f, c));

  constexpr int kArray = TINYGLTF_TARGET_ARRAY_BUFFER;
  tinygltf::Primitive prim;
  prim.mode = TINYGLTF_MODE_TRIANGLES;
  prim.attributes["POSITION"] = b.add_float(pos, 3, kArray, true);
  prim.attributes["NORMAL"] = b.add_float(nrm, 3, kArray, false);
  prim.attributes["COLOR_0"] = b.add_float(col, 3, kArray, false);
  prim.indices = b.add_indices(idx);
  // glTF requires min/max on every POSITION accessor, morph targets included
  if (post_operative)
    prim.targets.push_back({{"POSITION", b.add_float(dpos, 3, kArray, true)},
                            {"NORMAL", b.add_float(dnrm, 3, kArray, false)}});
  prim.material = 0;

  tinygltf::Mesh mesh;
  mesh.name = "skin";
  mesh.primitives.push_back(std::move(prim));
  if (post_operative) {
    mesh.weights = {0.0};
    mesh.extras = tinygltf::Value(tinygltf::Value::Object{
        {"targetNames", tinygltf::Value(tinygltf::Value::Array{
                            tinygltf::Value(std::string(kGltfMorphTargetName))})}});
  }
  model.meshes.push_back(std::move(mesh));

  tinygltf::Material mat;
  mat.name = "skin";
  mat.pbrMetallicRoughness.baseColorFactor = {1.0, 1.0, 1.0, 1.0};
  mat.pbrMetallicRoughness.metallicFactor = 0.0;
  mat.pbrMetallicRoughness.roughnessFactor = 0.6;
  model.materials.push_back(std::move(mat));

  tinygltf::Node node;
  node.name = "skin";
  node.mesh = 0;
  model.nodes.push_back(std::move(node));
  tinygltf::Scene scene;
  scene.name = "caps";
  scene.nodes = {0};
  model.scenes.push_back(std::move(scene));
  model.defaultScene = 0;

  if (post_operative) {
    tinygltf::AnimationSampler sampler;
    sampler.input = b.add_float({0.0f, static_cast<float>(kGltfTransitionSeconds)}, 1, 0, true);
    sampler.output = b.add_float({0.0f, 1.0f}, 1, 0, false);
    sampler.interpolation = "LINEAR";
    tinygltf::AnimationChannel channel;
    channel.sampler = 0;
    channel.target_node = 0;
    channel.target_path = "weights";
    tinygltf::Animation anim;
    anim.name = "pre-to-post";
    anim.samplers.push_back(sampler);
    anim.channels.push_back(channel);
    model.animations.push_back(std::move(anim));
  }

  // WriteGltfSceneToStream is WriteGltfSceneToFile's binary path without its unchecked ofstream:
  // the bytes go through write_file_atomic with a checked write.
  std::ostringstream glb(std::ios::binary);
  tinygltf::TinyGLTF gltf;
  if (!gltf.WriteGltfSceneToStream(&model, glb, false, true))
    throw IoError(cat(path.string(), ": TinyGLTF could not serialise the glTF model"));
  const std::string bytes = std::move(glb).str();
  write_file_atomic(path, [&](const std::filesystem::path& tmp) {
    std::ofstream f(tmp, std::ios::binary);
    f.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    f.close();
    if (!f) throw IoError(cat(path.string(), ": cannot write the glTF file (disk full?)"));
  });
}

}  // namespace caps::render
