#include "caps/app/register.hpp"

#include <Eigen/LU>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "caps/core/atomic_output.hpp"
#include "caps/core/error.hpp"
#include "caps/image/canvas.hpp"
#include "caps/render/overlay.hpp"
#include "caps/render/render.hpp"
#include "caps/surface/scan_io.hpp"
#include "caps/surface/scan_model.hpp"
#include "caps/volume/mesh_io.hpp"
#include "caps/volume/model_dir.hpp"
#include "json_fields.hpp"
#include "model_result.hpp"
#include "numbers.hpp"
#include "output_check.hpp"

CAPS_APP_REQUEST_JSON(caps::app::RegisterRequest)
CAPS_APP_REQUEST_JSON(caps::app::FuseRequest)
CAPS_APP_RESULT_JSON(caps::app::RegisterResult)

namespace caps::app {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

constexpr char kRegistrationJson[] = "registration.json";
constexpr char kDistancePly[] = "distance.ply";
constexpr char kDistancePng[] = "distance.png";

RegistrationOptions registration_options(const ScanRegistrationFields& r) {
  RegistrationOptions o;
  o.mm_per_unit = r.scan_scale;
  o.estimate_scale = r.estimate_scale;
  o.voxel_mm = r.voxel;
  o.icp_final_mm = r.icp_distance;
  o.overlap_mm = r.overlap_distance;
  o.max_rms_mm = r.max_rms;
  o.max_median_mm = r.max_median;
  o.min_overlap = r.min_overlap;
  o.max_scale_change = r.max_scale_change;
  o.max_orientation_deg = r.max_orientation;
  if (r.up.empty() != r.front.empty())
    throw InvalidParameter("give both {up} and {front} (the scan file's axes), or neither");
  if (!r.up.empty())
    o.orientation = scan_to_lps_rotation(parse_axis_name(r.up, "--up"), parse_axis_name(r.front, "--front"));
  return o;
}

ScanMesh read_scan(const std::string& input, const ScanRegistrationFields& r) {
  ScanReadOptions ro;
  ro.texture = r.texture;
  ro.flip_v = r.flip_v;
  return read_scan_mesh(input, ro);
}

// The model's skin mesh (skin.ply, LPS mm).
TriMesh model_skin(const std::string& dir) {
  read_model_info(dir);  // a model directory, checked
  return read_ply(fs::path(dir) / model_file::kSkinMesh);
}

// Registers and refuses another head unless told to accept it.
ScanRegistration register_checked(const ScanMesh& scan, const TriMesh& skin,
                                  const ScanRegistrationFields& r, const std::string& model,
                                  Reporter* reporter) {
  ScanRegistration reg = register_scan(scan.mesh, skin, registration_options(r), reporter);
  if (!reg.same_head) {
    if (!r.accept_other_head)
      throw InvalidInput(cat(scan.source, " against ", model, ": ", reg.verdict,
                             ". Pass --accept-other-head to write the distance map anyway"));
    warn(reporter, cat(scan.source, ": ", reg.verdict));
  }
  return reg;
}

json matrix_json(const Eigen::Matrix4d& T) {
  json rows = json::array();
  for (int i = 0; i < 4; ++i) rows.push_back({T(i, 0), T(i, 1), T(i, 2), T(i, 3)});
  return rows;
}

json residual_json(const ResidualStatistics& s) {
  return {{"vertices", s.vertices},
          {"overlapping", s.overlapping},
          {"overlap_fraction", s.overlap_fraction},
          {"rms_mm", s.rms_mm},
          {"rms_all_mm", s.rms_all_mm},
          {"median_mm", s.median_mm},
          {"p90_mm", s.p90_mm},
          {"p95_mm", s.p95_mm},
          {"p99_mm", s.p99_mm},
          {"max_mm", s.max_mm},
          {"mean_signed_mm", s.mean_signed_mm}};
}

// The registered scan seen from the front of the model (its axis' theta = 0), coloured by
// |distance| from 0 to `top_mm`, with a colour bar and a scale bar.
void write_distance_picture(const fs::path& path, const TriMesh& registered,
                            const Eigen::VectorXd& distance_mm, const CylinderAxis& axis,
                            double top_mm, const std::string& credit) {
  render::RenderOptions ro;
  Camera cam;
  cam.projection = Projection::Orthographic;
  cam.forward = -axis.front;
  cam.up = axis.direction;
  cam.width_px = 1100;  // the scan in the left 800 pixels, the colour bar on the right
  cam.height_px = 800;
  const Eigen::Vector3d right = cam.forward.cross(cam.up);
  const Eigen::Vector3d lo = registered.V.colwise().minCoeff(), hi = registered.V.colwise().maxCoeff();
  cam.target = 0.5 * (lo + hi);
  double extent = 0, radius = 0;
  for (Eigen::Index v = 0; v < registered.V.rows(); ++v) {
    const Eigen::Vector3d d = registered.V.row(v).transpose() - cam.target;
    extent = std::max({extent, std::abs(d.dot(right)), std::abs(d.dot(cam.up))});
    radius = std::max(radius, d.norm());
  }
  cam.width_mm = std::max(2.3 * extent, 10.0) * 1100.0 / 800.0;
  cam.target += right * (150.0 * cam.width_mm / 1100.0);
  cam.distance_mm = 2 * radius + 10;
  const Eigen::VectorXd a = distance_mm.cwiseAbs();
  RgbImage image = render::render_image(registered, render::scalar_colors(a, top_mm), cam, ro);
  render::draw_scale_bar(image, cam);
  render::draw_color_bar(image, top_mm, "mm", "Scan to skin", "|distance|, mm");
  Canvas canvas(image);
  TextStyle small;
  small.halo = true;
  canvas.text(12, 24, "Registered scan, front view", small);
  if (!credit.empty()) canvas.text(12, 44, credit, small);
  canvas.write_png(path);
}

}  // namespace

// ---- register -----------------------------------------------------------------------------

RegisterResult run_register(const RegisterRequest& r, Reporter* reporter) {
  detail::refuse_output_over_inputs(r);
  { OutputDirectory probe(r.output, r.force); }
  if (!(r.distance_scale > 0))
    throw InvalidParameter(cat("{distance_scale} ", r.distance_scale, " mm must be positive"));
  const TriMesh skin = model_skin(r.to);
  const ModelInfo info = read_model_info(r.to);
  const ScanMesh scan = read_scan(r.input, r);
  ScanRegistration reg = register_checked(scan, skin, r, r.to, reporter);

  const TriMesh registered{transform_points(reg.scan_to_model, scan.mesh.V), scan.mesh.F};
  OutputDirectory out(r.output, r.force);
  const PlyScalar distance{"distance", reg.distance_mm};
  write_ply(registered, out.path() / kDistancePly, nullptr, &distance);
  write_distance_picture(out.path() / kDistancePng, registered, reg.distance_mm, info.axis,
                         r.distance_scale, r.credit);
  json j{{"scan", r.input},
         {"model", r.to},
         {"frame", "model LPS mm: p_model = scan_to_model [p_scan; 1]"},
         {"scan_to_model", matrix_json(reg.scan_to_model)},
         {"scale_mm_per_unit", reg.scale},
         {"scale_source", reg.scale_source},
         {"residual", residual_json(reg.residual)},
         {"same_head", reg.same_head},
         {"verdict", reg.verdict},
         {"coarse_fitness", reg.coarse_fitness},
         {"icp_fitness", reg.icp_fitness},
         {"seconds", reg.seconds},
         {"options", json::parse(write_request(r))},
         {"files", {{"distance_ply", kDistancePly}, {"distance_png", kDistancePng}}},
         {"credit", r.credit}};
  RegisterResult result;
  result.output = r.output;
  result.json = j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace);
  write_text_atomic(out.path() / kRegistrationJson, result.json + "\n");
  out.commit();
  reg.distance_mm.resize(0);
  result.registration = reg;
  if (!reg.same_head) result.warnings.push_back(reg.verdict);
  return result;
}

std::string summary(const RegisterResult& r) {
  const auto& g = r.registration;
  const auto& s = g.residual;
  return cat("caps model register: ", g.verdict, "\n  scale ", round_to(g.scale, 4), " mm per unit (",
             g.scale_source, "), RMS ", round_to(s.rms_mm, 3), " mm over ",
             round_to(100 * s.overlap_fraction, 1), " % of the scan, median ",
             round_to(s.median_mm, 3), " mm, 95th percentile ", round_to(s.p95_mm, 2), " mm, ",
             round_to(g.seconds, 2), " s\n  -> ", r.output);
}

// ---- fuse ---------------------------------------------------------------------------------

Eigen::Matrix4d read_registration_matrix(const std::string& path) {
  const json j = read_json_file<json>(path, "give the registration.json of `caps model register`");
  Eigen::Matrix4d T;
  try {
    const auto& rows = j.at("scan_to_model");
    if (!rows.is_array() || rows.size() != 4) throw InvalidInput("not 4 rows");
    for (int i = 0; i < 4; ++i)
      for (int k = 0; k < 4; ++k) T(i, k) = rows.at(i).at(k).get<double>();
  } catch (const std::exception& e) {
    throw InvalidInput(cat(path, ": no 4x4 \"scan_to_model\" matrix (", e.what(),
                           "); give the registration.json of `caps model register`"));
  }
  if (!T.allFinite()) throw InvalidInput(cat(path, ": the \"scan_to_model\" matrix is not finite"));
  return T;
}

ModelResult run_fuse(const FuseRequest& r, Reporter* reporter) {
  detail::refuse_output_over_inputs(r);
  { OutputDirectory probe(r.output, r.force); }
  const ModelInfo info = read_model_info(r.to);
  ModelContent ct;
  ct.maps = read_model_maps(r.to, info);
  ct.color = read_model_color(r.to, info);
  ct.stats = info.stats;
  ct.skin = read_ply(fs::path(r.to) / model_file::kSkinMesh);
  ct.bone = read_ply(fs::path(r.to) / model_file::kBoneMesh);
  const ScanMesh scan = read_scan(r.input, r);
  Eigen::Matrix4d T;
  std::string how;
  if (!r.registration.empty()) {
    T = read_registration_matrix(r.registration);
    how = r.registration;
  } else {
    T = register_checked(scan, ct.skin, r, r.to, reporter).scan_to_model;
    how = "registered now";
  }
  FuseOptions fo;
  fo.scan_skin = r.scan_skin;
  fo.max_gap_mm = r.max_gap;
  const FusedModel fused = fuse_scan(ct, scan, T, fo, reporter);

  ModelProvenance p;
  json source = json::parse(info.source_json);
  source["fused_scan"] = {{"path", r.input},
                          {"registration", how},
                          {"scan_to_model", matrix_json(T)},
                          {"scan_skin", r.scan_skin},
                          {"max_gap_mm", r.max_gap},
                          {"colored_cells", fused.colored_cells},
                          {"skin_cells", fused.skin_cells},
                          {"gap_cells", fused.gap_cells},
                          {"median_gap_mm", fused.median_gap_mm},
                          {"credit", r.credit}};
  if (!r.credit.empty()) source["credit"] = r.credit;
  p.source_json = source.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
  p.segmentation_json = info.segmentation_json;
  json thickness = json::parse(info.thickness_json);
  if (r.scan_skin)
    thickness["fused_scan"] = "where the scan covers, r_skin is the scan's; the radial thickness "
                              "changes by the same amount, the normal thickness and the layers "
                              "in proportion; the bone is the CT's";
  p.thickness_json = thickness.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
  p.name = cat(fs::path(source.value("path", r.to)).filename().string(), " + ",
               fs::path(r.input).filename().string());
  p.credit = r.credit;
  write_model_directory(fused, p, r.output, r.force, reporter);
  return detail::model_result(r.output, r.output);
}

}  // namespace caps::app
