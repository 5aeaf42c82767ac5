// caps model from-scan / pick: patient models from surface scans, and picking on a model's skin.
//   caps model from-scan ../shared/data/scan/leeperrysmith/LeePerrySmith.glb --texture ../shared/data/scan/leeperrysmith/Map-COL.jpg --flip-v --head-height-mm 230 --thickness 6 --credit "Infinite, 3D Head Scan by Lee Perry-Smith, CC BY 3.0 (www.triplegangers.com)" -o /tmp/lps --force
//   caps model from-scan ../shared/data/scan/fran/fran_cut.vtk --texture ../shared/data/scan/fran/fran_cut.png --scale 1000 --front 1,0,-1 --flip-faces --thickness 6 -o /tmp/fran --force
//   caps model from-scan head_range.json --thickness 6 -o /tmp/cyberware --force
//   caps model from-scan head_range.png --color head_color.png --r-scale 0.1 --z-scale 0.7 --thickness 6 -o /tmp/cyberware --force
//   caps model export-range /tmp/lps -o /tmp/lps_range
//   caps model pick /tmp/lps --ray 0,-400,0,0,1,0 --json
//   caps model color-picture /tmp/lps -o /tmp/lps_color.png --force
#include <iostream>
#include <nlohmann/json.hpp>

#include "caps/core/atomic_output.hpp"
#include "caps/core/error.hpp"
#include "caps/surface/color_picture.hpp"
#include "caps/surface/cylindrical_scan.hpp"
#include "caps/surface/picking.hpp"
#include "caps/surface/scan_model.hpp"
#include "caps/volume/model.hpp"
#include "commands.hpp"

namespace caps::cli {
namespace {

struct FromScanArgs {
  std::string input, output, texture, up, front, credit, axis_origin;
  bool flip_v = false, flip_faces = false;
  double thickness_mm = NAN, scale = NAN, head_height_mm = NAN;
  int n_theta = 512, n_z = 256;
  // Cylindrical range images (Cyberware style): a sidecar .json, or a grey PNG with these.
  std::string color;
  double r_scale = NAN, r_offset = 0, z_scale = NAN, theta_span = 360;
  bool theta_rows = false, theta_reverse = false, bottom_first = false;
};

bool ends_with(const std::string& s, const std::string& tail) {
  return s.size() >= tail.size() && s.compare(s.size() - tail.size(), tail.size(), tail) == 0;
}

ScanMesh read_any_scan(const FromScanArgs& a) {
  if (ends_with(a.input, ".json")) return cylindrical_scan_mesh(read_cylindrical_sidecar(a.input));
  if (std::isfinite(a.r_scale) || std::isfinite(a.z_scale) || !a.color.empty()) {
    CylindricalScanSpec spec;
    spec.range = a.input;
    spec.color = a.color;
    spec.r_scale_mm = std::isfinite(a.r_scale) ? a.r_scale : 0.0;
    spec.r_offset_mm = a.r_offset;
    spec.z_scale_mm = std::isfinite(a.z_scale) ? a.z_scale : 0.0;
    spec.theta_span_deg = a.theta_span;
    spec.theta_along_rows = a.theta_rows;
    spec.theta_reverse = a.theta_reverse;
    spec.top_first = !a.bottom_first;
    return cylindrical_scan_mesh(spec);
  }
  ScanReadOptions ro;
  ro.texture = a.texture;
  ro.flip_v = a.flip_v;
  return read_scan_mesh(a.input, ro);
}

void run_from_scan(const FromScanArgs& a, const Common& common) {
  { OutputDirectory probe(a.output, common.force); }
  const ScanMesh scan = read_any_scan(a);
  ScanModelOptions o;
  o.thickness_mm = a.thickness_mm;
  if (std::isfinite(a.scale)) o.mm_per_unit = a.scale;
  if (std::isfinite(a.head_height_mm)) o.head_height_mm = a.head_height_mm;
  // Defaults: glTF is +y up with the asset facing +z; other formats are taken the same way.
  o.up = parse_axis_name(a.up.empty() ? "+y" : a.up, "--up");
  o.front = parse_axis_name(a.front.empty() ? "+z" : a.front, "--front");
  o.maps.n_theta = a.n_theta;
  o.maps.n_z = a.n_z;
  o.credit = a.credit;
  o.flip_faces = a.flip_faces;
  if (!a.axis_origin.empty()) {
    const auto t = parse_triple(a.axis_origin, "--axis-origin");
    CylinderAxis axis;
    axis.origin_lps = {t[0], t[1], t[2]};
    o.axis = axis;
  }
  const ScanModel m = build_scan_model(scan, o);
  write_scan_model(m, a.output, common.force);
  if (common.json) std::cout << read_model_json(a.output) << "\n";
  else if (!common.quiet) std::cerr << model_summary(a.output);
}

struct PickArgs {
  std::string model, ray;
};

void run_pick(const PickArgs& a, const Common& common) {
  const PatientModel model = PatientModel::load(a.model);
  std::vector<double> v;
  std::stringstream in(a.ray);
  for (std::string item; std::getline(in, item, ',');) {
    char* end = nullptr;
    v.push_back(std::strtod(item.c_str(), &end));
    if (end == item.c_str() || *end) v.push_back(NAN);
  }
  if (v.size() != 6 || !std::all_of(v.begin(), v.end(), [](double x) { return std::isfinite(x); }))
    throw InvalidInput(cat("--ray '", a.ray, "': expected six numbers OX,OY,OZ,DX,DY,DZ (LPS mm)"));
  const Ray ray{{v[0], v[1], v[2]}, {v[3], v[4], v[5]}};
  const SkinPicker picker(model);
  const SkinHit h = picker.pick(ray);
  nlohmann::json j = {{"hit", h.hit}};
  if (h.hit)
    j.update({{"lps", {h.lps[0], h.lps[1], h.lps[2]}}, {"theta_deg", h.theta_deg}, {"z_mm", h.z_mm},
              {"distance_mm", h.distance_mm}, {"flags", describe_flags(h.flags)},
              {"on_pole_cap", h.on_pole_cap}});
  if (common.json) std::cout << j.dump(2) << "\n";
  else if (h.hit) std::cout << "hit theta " << h.theta_deg << " deg, z " << h.z_mm << " mm, LPS ("
                            << h.lps.transpose() << ") mm, " << describe_flags(h.flags) << "\n";
  else std::cout << "miss\n";
}

struct ExportRangeArgs {
  std::string model, output;
  double r_scale_mm = 0.01;
};

void run_export_range(const ExportRangeArgs& a, const Common& common) {
  const PatientModel model = PatientModel::load(a.model);
  OutputDirectory out(a.output, common.force);
  write_cylindrical_scan(model, out.path(), a.r_scale_mm);
  out.commit();
  if (common.json)
    std::cout << nlohmann::json{{"sidecar", (std::filesystem::path(a.output) / "range.json").string()}}.dump(2)
              << "\n";
}

struct ColorPictureArgs {
  std::string model, output;
};

void run_color_picture(const ColorPictureArgs& a, const Common& common) {
  if (std::filesystem::exists(a.output) && !common.force)
    throw InvalidInput(cat(a.output, ": exists; pass --force to replace it"));
  const PatientModel model = PatientModel::load(a.model);
  const auto j = nlohmann::json::parse(read_model_json(a.model));
  const std::string credit = j["source"].value("credit", std::string());
  const std::string name = std::filesystem::path(j["source"].value("path", a.model)).filename();
  write_color_picture(a.output, model, cat("Skin colour, ", name), credit);
}

}  // namespace

void add_model_scan(CLI::App* model, Common& common, Action& action) {
  auto a = std::make_shared<FromScanArgs>();
  auto* fs = model->add_subcommand(
      "from-scan",
      "Build a patient model from a textured surface scan, with a constant soft-tissue thickness\n"
      "(the 1992 CAPS assumption). INPUT is .glb/.gltf, .ply (vertex colours), .obj (+ .mtl and\n"
      "texture) or .vtk (legacy polydata with texture coordinates), or a Cyberware-style\n"
      "cylindrical range image: a sidecar .json, or a grey PNG with --r-scale and --z-scale.\n"
      "Example: caps model from-scan head.glb --head-height-mm 230 --thickness 6 -o head\n"
      "Example: caps model from-scan range.png --color color.png --r-scale 0.1 --z-scale 0.7 "
      "--thickness 6 -o head");
  fs->add_option("INPUT", a->input, "the scan")->required();
  fs->add_option("-o,--output", a->output, "the model directory to create")->required();
  fs->add_option("--thickness", a->thickness_mm, "constant soft-tissue thickness, mm")->required();
  fs->add_option("--texture", a->texture, "colour texture (JPEG or PNG) for the scan's texture "
                                          "coordinates, overriding the file's own");
  fs->add_flag("--flip-v", a->flip_v, "flip the texture's v coordinate (v' = 1 - v)");
  fs->add_option("--scale", a->scale, "millimetres per file unit (glTF default 1000: metres; "
                                      "other formats default 1: mm)");
  fs->add_option("--head-height-mm", a->head_height_mm,
                 "scale the scan so it is this tall along --up (for files in arbitrary units)");
  fs->add_option("--up", a->up, "file direction towards the top of the head: +x -x +y -y +z -z "
                                "or X,Y,Z (default +y)");
  fs->add_option("--front", a->front, "file direction the face looks along, perpendicular to "
                                      "--up (default +z)");
  fs->add_flag("--flip-faces", a->flip_faces, "reverse the faces of a file whose normals point "
                                              "into the head");
  fs->add_option("--axis-origin", a->axis_origin, "a point of the cylinder axis, LPS mm: X,Y,Z "
                                                  "(default: fitted)");
  fs->add_option("--n-theta", a->n_theta, "cylindrical grid: samples around")->capture_default_str();
  fs->add_option("--n-z", a->n_z, "cylindrical grid: samples along the axis")->capture_default_str();
  fs->add_option("--credit", a->credit, "credit line drawn on the pictures and kept in model.json");
  auto* cyl = "Cylindrical range images";
  fs->add_option("--color", a->color, "the colour image of a range image (same layout)")->group(cyl);
  fs->add_option("--r-scale", a->r_scale, "mm per range value")->group(cyl);
  fs->add_option("--r-offset", a->r_offset, "radius in mm for a range value of 0")->group(cyl);
  fs->add_option("--z-scale", a->z_scale, "mm between neighbouring z lines")->group(cyl);
  fs->add_option("--theta-span", a->theta_span, "the image's extent in theta, degrees")
      ->capture_default_str()->group(cyl);
  fs->add_flag("--theta-rows", a->theta_rows, "theta runs down the rows (z across)")->group(cyl);
  fs->add_flag("--theta-reverse", a->theta_reverse, "theta decreases along its axis")->group(cyl);
  fs->add_flag("--bottom-first", a->bottom_first, "the first z line is the bottom")->group(cyl);
  add_common_flags(fs, common, true);
  fs->callback([&common, &action, a] { action = [&common, a] { run_from_scan(*a, common); }; });

  auto p = std::make_shared<PickArgs>();
  auto e = std::make_shared<ExportRangeArgs>();
  auto* ex = model->add_subcommand(
      "export-range", "Write a model's skin as a Cyberware-style cylindrical range image: range.png "
                      "(16-bit grey),\ncolor.png and the sidecar range.json that from-scan reads.\n"
                      "Example: caps model export-range cranium -o cranium_range");
  ex->add_option("MODEL_DIR", e->model, "a model directory")->required();
  ex->add_option("-o,--output", e->output, "the folder to create")->required();
  ex->add_option("--r-scale", e->r_scale_mm, "mm per range value")->capture_default_str();
  add_common_flags(ex, common, true);
  ex->callback([&common, &action, e] { action = [&common, e] { run_export_range(*e, common); }; });

  auto* pk = model->add_subcommand("pick", "Pick the first point of a ray on a model's skin.\n"
                                           "Example: caps model pick head --ray 0,-400,0,0,1,0");
  pk->add_option("MODEL_DIR", p->model, "a model directory")->required();
  pk->add_option("--ray", p->ray, "origin and direction, LPS mm: OX,OY,OZ,DX,DY,DZ")->required();
  add_common_flags(pk, common, false);
  pk->callback([&common, &action, p] { action = [&common, p] { run_pick(*p, common); }; });

  auto c = std::make_shared<ColorPictureArgs>();
  auto* cp = model->add_subcommand("color-picture",
                                   "Draw a model's skin colour with axes and its credit line.\n"
                                   "Example: caps model color-picture head -o head_color.png");
  cp->add_option("MODEL_DIR", c->model, "a model directory with color.png")->required();
  cp->add_option("-o,--output", c->output, "the PNG to write")->required();
  add_common_flags(cp, common, true);
  cp->callback([&common, &action, c] { action = [&common, c] { run_color_picture(*c, common); }; });
}

}  // namespace caps::cli
