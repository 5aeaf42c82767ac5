#include "skin_views.hpp"

#include "caps/core/atomic_output.hpp"
#include "caps/core/error.hpp"
#include "caps/core/units.hpp"
#include "caps/closure/face_domain.hpp"
#include "caps/fem/mesh.hpp"
#include "caps/fem/mesh_io.hpp"
#include "caps/fem/result_io.hpp"
#include "caps/plan/plan.hpp"
#include "caps/render/drawn_skin.hpp"
#include "caps/render/gltf_export.hpp"
#include "caps/render/overlay.hpp"
#include "caps/render/simulation_report.hpp"
#include "caps/render/skin_surface.hpp"
#include "caps/surface/patient_model.hpp"
#include "caps/surface/range_mesh.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cmath>
#include <memory>
#include <vector>

namespace caps::server::detail {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

// A light skin tone for models without colour (sRGB in [0, 1]).
const Eigen::Vector3d kPlainSkin(0.86, 0.72, 0.62);
// Cells flagged invalid in the thickness overlay (no plan can be placed there).
const Eigen::Vector3d kInvalidGrey(0.55, 0.55, 0.55);
// The micropolygons per element edge of the post-operative skin shown on the page: at most this
// many (view_subdivisions()).
constexpr int kMaxResultSubdivisions = 8;
// A model skin vertex the closure moves by less than this (mm) is left where it is.
constexpr double kMovedSkinMm = 1e-3;

json lps_json(const Eigen::Vector3d& p) { return json::array({p.x(), p.y(), p.z()}); }

// The 99th percentile of `values` (0 if empty).
double percentile99(std::vector<double> values) {
  if (values.empty()) return 0;
  const auto k = static_cast<std::ptrdiff_t>(0.99 * static_cast<double>(values.size() - 1));
  std::nth_element(values.begin(), values.begin() + k, values.end());
  return values[static_cast<std::size_t>(k)];
}

// The faces of `s` on the finite-element mesh (its micropolygons and the wound fill) and, with
// `seam`, the seam to the range mesh, with their vertices renumbered: the part of the skin the
// simulation moved (the tension is on the mesh's faces only; the seam has none).
// `kept` (if given) receives the vertex of `s` each of the part's vertices is.
render::SkinSurfaces mesh_part(const render::SkinSurfaces& s, bool seam,
                               std::vector<Eigen::Index>* kept_out = nullptr) {
  std::vector<Eigen::Index> faces;
  for (Eigen::Index f = 0; f < s.pre.n_faces(); ++f)
    if (const render::SkinPart p = s.face_part[static_cast<std::size_t>(f)];
        p == render::SkinPart::Micropolygon || p == render::SkinPart::WoundFill ||
        (seam && p == render::SkinPart::Seam))
      faces.push_back(f);
  std::vector<int> index(static_cast<std::size_t>(s.pre.n_vertices()), -1);
  std::vector<Eigen::Index> kept;
  render::SkinSurfaces part;
  part.pre.F.resize(static_cast<Eigen::Index>(faces.size()), 3);
  for (std::size_t i = 0; i < faces.size(); ++i)
    for (int c = 0; c < 3; ++c) {
      int& v = index[static_cast<std::size_t>(s.pre.F(faces[i], c))];
      if (v < 0) {
        v = static_cast<int>(kept.size());
        kept.push_back(s.pre.F(faces[i], c));
      }
      part.pre.F(static_cast<Eigen::Index>(i), c) = v;
    }
  const auto n = static_cast<Eigen::Index>(kept.size());
  part.pre.V.resize(n, 3);
  part.post.V.resize(n, 3);
  part.color.resize(n, 3);
  for (Eigen::Index v = 0; v < n; ++v) {
    part.pre.V.row(v) = s.pre.V.row(kept[static_cast<std::size_t>(v)]);
    part.post.V.row(v) = s.post.V.row(kept[static_cast<std::size_t>(v)]);
    part.color.row(v) = s.color.row(kept[static_cast<std::size_t>(v)]);
  }
  part.post.F = part.pre.F;
  if (kept_out) *kept_out = std::move(kept);
  return part;
}

// What write_moved_model_skin() wrote.
struct MovedSkin {
  long vertices = 0;  // model skin vertices moved
  double max_mm = 0;  // their largest move
  // The skin tension at the model skin's vertices the closure reaches: records of a uint32 vertex
  // and its maximum principal stress as a float32 (kPa), little endian; empty for a patch-only
  // closure. The page colours the skin around the patch with it, so the map has no patch outline.
  std::string tension_records;
};

// A closure in the whole face moves the skin around the patch as well: the vertices of the
// model's range mesh (write_model_skin_glb(), which the page draws around the patch) that the
// tissue's skin nodes move (closure::skin_displacement(), the field the renderer and the
// feature lines use; within render::kSeamBlendMm of the rim of `patch`, the skin drawn from the
// closure, carried on from the rim's displacement, as displaced_skin() moves the seam), as
// records of a uint32 vertex and its move as three float32 in glTF's frame (metres;
// render::lps_to_gltf), little endian, at `path`. Nothing is written for a
// patch-only closure (no face skin nodes) or where nothing moved. `max_principal_mpa` (one
// value a node of `mesh`) gives MovedSkin::tension_records.
MovedSkin write_moved_model_skin(const PatientModel& model, const fem::Mesh& mesh,
                                 const Eigen::MatrixX3d& u, const Eigen::VectorXd& max_principal_mpa,
                                 const render::SkinSurfaces& patch, const fs::path& path) {
  MovedSkin out;
  if (!mesh.node_sets.count(closure::kFaceSkinNodes)) return out;
  const DisplacementAt field =
      render::seam_field(patch, patch.post.V - patch.pre.V, closure::skin_displacement(mesh, u));
  const auto tension = closure::skin_scalar(mesh, max_principal_mpa);
  const TriMesh range = range_mesh(model.maps(), RangeSurface::Skin);
  std::string bytes;
  for (Eigen::Index v = 0; v < range.n_vertices(); ++v) {
    // Both fields come from the same nodes within the same reach: a vertex the displacement
    // does not reach has no tension either, and most of the head's vertices are such.
    const auto d = field(range.V.row(v).transpose());
    if (!d) continue;
    const std::uint32_t index = static_cast<std::uint32_t>(v);
    const float kpa = static_cast<float>(1e3 * tension(range.V.row(v).transpose()).value_or(0.0));
    out.tension_records.append(reinterpret_cast<const char*>(&index), sizeof index);
    out.tension_records.append(reinterpret_cast<const char*>(&kpa), sizeof kpa);
    if (d->norm() < kMovedSkinMm) continue;
    const Eigen::Vector3d g = render::lps_to_gltf(*d);
    const float xyz[3] = {static_cast<float>(g.x()), static_cast<float>(g.y()), static_cast<float>(g.z())};
    bytes.append(reinterpret_cast<const char*>(&index), sizeof index);
    bytes.append(reinterpret_cast<const char*>(xyz), sizeof xyz);
    ++out.vertices;
    out.max_mm = std::max(out.max_mm, d->norm());
  }
  if (out.vertices) write_text_atomic(path, bytes);
  return out;
}

}  // namespace

std::string write_model_skin_glb(const PatientModel& model, SkinColouring colouring,
                                 const fs::path& path) {
  const CylinderGrid& g = model.grid();
  render::SkinSurfaces s;
  s.pre = range_mesh(model.maps(), RangeSurface::Skin);
  s.post = s.pre;
  const Eigen::Index n = s.pre.n_vertices(), n_grid = Eigen::Index{g.n_theta} * g.n_z;
  s.color.resize(n, 3);
  // Vertex v = k n_theta + j is sample (j, k); the two poles follow (range_mesh()).
  auto theta_z = [&](Eigen::Index v) {
    const Eigen::Index k = std::min(v, n_grid - 1) / g.n_theta;
    const Eigen::Index j = v < n_grid ? v % g.n_theta : 0;
    const Eigen::Index row = v < n_grid ? k : (v == n_grid ? 0 : g.n_z - 1);
    return Eigen::Vector2d(g.theta0_deg + j * g.dtheta_deg(), g.z0_mm + row * g.dz_mm);
  };
  json info{{"colouring", colouring == SkinColouring::Skin ? "skin" : "thickness"},
            {"vertices", n},
            {"faces", s.pre.n_faces()},
            {"has_color", model.has_color()}};
  if (colouring == SkinColouring::Skin) {
    for (Eigen::Index v = 0; v < n; ++v) {
      const Eigen::Vector2d tz = theta_z(v);
      s.color.row(v) = model.has_color() ? model.color_at(tz[0], tz[1]) : kPlainSkin;
    }
  } else {
    Eigen::VectorXd t(n);
    std::vector<double> valid;
    std::vector<bool> ok(static_cast<std::size_t>(n));
    for (Eigen::Index v = 0; v < n; ++v) {
      const Eigen::Vector2d tz = theta_z(v);
      t[v] = model.thickness(tz[0], tz[1]);
      ok[static_cast<std::size_t>(v)] = flags_valid(model.flags_at(tz[0], tz[1]));
      if (ok[static_cast<std::size_t>(v)]) valid.push_back(t[v]);
    }
    const double top = render::scale_top(Eigen::VectorXd::Constant(1, percentile99(valid)), 0);
    s.color = render::scalar_colors(t, top);
    for (Eigen::Index v = 0; v < n; ++v)
      if (!ok[static_cast<std::size_t>(v)]) s.color.row(v) = kInvalidGrey;
    info["scale_max_mm"] = top;
  }
  render::write_gltf(s, path, false);  // the skin before any plan: no post-operative morph
  return info.dump();
}

int view_subdivisions(const PatientModel& model, const fem::Mesh& mesh) {
  std::vector<double> edges;
  double radius = 0;
  for (int e : render::skin_elements(model, mesh)) {
    const fem::Element& el = mesh.elements[static_cast<std::size_t>(e)];
    const int nc = el.type == fem::ElementType::Hex20 ? 4 : 3;
    for (int a = 0; a < nc; ++a) {
      const Eigen::Vector3d p = mesh.nodes.row(el.nodes[static_cast<std::size_t>(a)]);
      const Eigen::Vector3d q = mesh.nodes.row(el.nodes[static_cast<std::size_t>((a + 1) % nc)]);
      edges.push_back((p - q).norm());
      radius += model.to_cylindrical(p).r_mm;
    }
  }
  if (edges.empty()) return 1;
  radius /= static_cast<double>(edges.size());
  std::nth_element(edges.begin(), edges.begin() + static_cast<std::ptrdiff_t>(edges.size() / 2),
                   edges.end());
  const double median = edges[edges.size() / 2];
  const double spacing =
      std::min(model.grid().dz_mm, model.grid().dtheta_deg() * kPi / 180.0 * radius);
  return std::clamp(static_cast<int>(std::ceil(median / spacing)), 1, kMaxResultSubdivisions);
}

ResultView write_result_skin_glbs(const PatientModel& model, const render::DrawnSkin* drawn,
                                  const fs::path& result_dir) {
  using Clock = std::chrono::steady_clock;
  const auto seconds = [](Clock::time_point a, Clock::time_point b) {
    return std::chrono::duration<double>(b - a).count();
  };
  const auto t0 = Clock::now();
  const fem::Mesh mesh = fem::read_mesh_dir(result_dir);
  const Eigen::MatrixX3d u = fem::read_result_displacement(result_dir, mesh.n_nodes());
  const int n = view_subdivisions(model, mesh);
  // Only the part the simulation moved: the page draws the model's own skin around it.
  const render::SkinSurfaces skin =
      render::displaced_skin(model, mesh, &u, n, drawn, render::SkinExtent::Patch);
  const auto t1 = Clock::now();
  const Eigen::VectorXd max_principal = fem::read_result_max_principal(result_dir, mesh.n_nodes());
  const render::ScalarMap tension = render::tension_map(skin, mesh, max_principal, 0);
  const auto [fill_pre_mm2, fill_post_mm2] = render::wound_fill_area_mm2(skin);
  const Eigen::Index n_micro = skin.n_micropolygon_vertices;
  const double peak = n_micro ? tension.value.head(n_micro).maxCoeff() : 0.0;
  const auto t2 = Clock::now();
  // The part of the skin the simulation moved, coloured as the model (the rest is the model's
  // own skin): what the page draws first.
  // Its vertices (`kept`: which of the skin's each is) are those of tension.glb as well.
  std::vector<Eigen::Index> kept;
  render::SkinSurfaces part = mesh_part(skin, true, &kept);
  if (!model.has_color()) part.color.rowwise() = kPlainSkin.transpose();  // as the model's skin
  render::write_gltf(part, result_dir / "skin.glb");
  MovedSkin moved =
      write_moved_model_skin(drawn ? drawn->range : model, mesh, u, max_principal, skin,
                             result_dir / "skin_moved.bin");
  // The wound's and incisions' lips (the incision lines before, the scar after the closure): the
  // page draws them on the skin and moves them with its pre-to-post slider.
  json scars = json::array();
  for (const std::vector<int>& loop : render::suture_loops(skin)) {
    json pre = json::array(), post = json::array();
    for (int v : loop) {
      pre.push_back({skin.pre.V(v, 0), skin.pre.V(v, 1), skin.pre.V(v, 2)});
      post.push_back({skin.post.V(v, 0), skin.post.V(v, 1), skin.post.V(v, 2)});
    }
    scars.push_back({{"pre_lps", std::move(pre)}, {"post_lps", std::move(post)}});
  }
  const auto t3 = Clock::now();
  ResultView view;
  view.json =
      json{{"skin", "skin.glb"},
           {"tension", "tension.glb"},
           {"tension_values", "tension_kpa.f32"},
           {"subdivisions", n},
           {"vertices", skin.pre.n_vertices()},
           {"replaced_cells", skin.replaced_cells},
           {"tension_scale_max_kpa", tension.max_value},
           {"max_skin_tension_kpa", peak},
           {"wound_area_mm2", {{"pre", fill_pre_mm2}, {"post", fill_post_mm2}}},
           {"moved_skin", moved.vertices ? json("skin_moved.bin") : json(nullptr)},
           {"moved_skin_vertices", moved.vertices},
           {"moved_skin_max_mm", moved.max_mm},
           {"moved_skin_tension",
            moved.tension_records.empty() ? json(nullptr) : json("tension_moved_skin_kpa.bin")},
           {"scar_lines", std::move(scars)},
           {"timings_s",
            {{"skin", seconds(t0, t1)}, {"tension", seconds(t1, t2)}, {"glb", seconds(t2, t3)}}}}
          .dump();
  // The mesh faces coloured by the tension: shown only when asked for, so written afterwards.
  view.write_tension = [part = std::move(part), kept = std::move(kept), tension,
                        path = result_dir / "tension.glb",
                        values_path = result_dir / "tension_kpa.f32",
                        moved_path = result_dir / "tension_moved_skin_kpa.bin",
                        moved_records = std::move(moved.tension_records)] {
    // The mesh's part and the seam around it: the seam's outer vertices carry the tension of the
    // tissue around the patch where the closure is in the whole face (0 on a clamped patch, where
    // nothing beyond it moves), as the page's model skin does around them.
    Eigen::VectorXd values(static_cast<Eigen::Index>(kept.size()));
    for (std::size_t v = 0; v < kept.size(); ++v)
      values[static_cast<Eigen::Index>(v)] = tension.value[kept[v]];
    render::SkinSurfaces by_tension = part;
    by_tension.color = render::scalar_colors(values, tension.max_value);
    render::write_gltf(by_tension, path);
    // Its values, so that a viewer can colour several results on one scale: a float32 (little
    // endian, as every machine this runs on) per vertex of tension.glb, in its order, kPa.
    const std::vector<float> kpa(values.data(), values.data() + values.size());
    write_text_atomic(values_path, std::string(reinterpret_cast<const char*>(kpa.data()),
                                               kpa.size() * sizeof(float)));
    if (!moved_records.empty()) write_text_atomic(moved_path, moved_records);
  };
  return view;
}

std::string plan_lines_json(const plan::Plan& plan, const PatientModel& model) {
  json lines = json::array();
  for (const auto& line : render::plan_lines(plan, model)) {
    json l = json::array();
    for (const Eigen::Vector3d& p : line) l.push_back(lps_json(p));
    lines.push_back(std::move(l));
  }
  json points = json::array();
  for (const plan::SkinPoint& p : plan.points)
    points.push_back(lps_json(model.skin_point(p.theta_deg, p.z_mm)));
  // The border loop (the sides of the cut a suture sews): each node where it lies on the skin with
  // the skin's outward normal there, and each edge i -> i + 1 sampled along the skin, as the
  // mesher lays it (straight in (theta, z), excision offsets applied).
  constexpr int kEdgeSamples = 8;
  const plan::BorderLoop loop = plan::border_loop(plan);
  json nodes = json::array(), edges = json::array();
  const int n = loop.size();
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector2d& a = loop.theta_z[static_cast<std::size_t>(i)];
    const Eigen::Vector2d& b = loop.theta_z[static_cast<std::size_t>((i + 1) % n)];
    const double dtheta = std::remainder(b[0] - a[0], 360.0);
    nodes.push_back({{"point", loop.point[static_cast<std::size_t>(i)]},
                     {"lps", lps_json(model.skin_point(a[0], a[1]))},
                     {"normal_lps", lps_json(model.skin_normal(a[0], a[1]))}});
    json edge = json::array();
    for (int k = 0; k <= kEdgeSamples; ++k) {
      const double t = static_cast<double>(k) / kEdgeSamples;
      edge.push_back(lps_json(model.skin_point(a[0] + t * dtheta, a[1] + t * (b[1] - a[1]))));
    }
    edges.push_back(std::move(edge));
  }
  // The handles that rotate and scale the plan, on the skin beyond each end of its x axis (the
  // orientation): the plan's half extent along x (its points' largest |x|) and kHandleGapMm more.
  const plan::PlanFrame& f = plan.frame;
  constexpr double kHandleGapMm = 5;
  double half_mm = 0;
  for (const plan::SkinPoint& p : plan.points)
    half_mm = std::max(half_mm, std::abs(f.to_local(p.theta_deg, p.z_mm).x()));
  const auto on_skin = [&](double x_mm) {
    const Eigen::Vector2d tz = f.to_theta_z(Eigen::Vector2d(x_mm, 0));
    return model.skin_point(tz[0], tz[1]);
  };
  const Eigen::Vector3d axis = (on_skin(0.5) - on_skin(-0.5)).normalized();
  return json{{"lines_lps", lines},
              {"points_lps", points},
              {"loop", {{"nodes", nodes}, {"edges_lps", edges}}},
              {"centre",
               {{"theta_deg", f.theta_deg},
                {"z_mm", f.z_mm},
                {"orientation_deg", f.orientation_deg},
                {"lps", lps_json(model.skin_point(f.theta_deg, f.z_mm))},
                {"normal_lps", lps_json(model.skin_normal(f.theta_deg, f.z_mm))},
                {"axis_lps", lps_json(axis)},
                {"half_extent_mm", half_mm},
                {"handle_gap_mm", kHandleGapMm},
                {"rotate_handle_lps", lps_json(on_skin(-half_mm - kHandleGapMm))},
                {"scale_handle_lps", lps_json(on_skin(half_mm + kHandleGapMm))}}}}
      .dump();
}

}  // namespace caps::server::detail
