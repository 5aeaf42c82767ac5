#include "caps/app/compare_models.hpp"

#include <Eigen/LU>
#include <algorithm>
#include <cctype>
#include <cmath>
#include <map>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "caps/app/loaded_model.hpp"
#include "caps/app/register.hpp"
#include "caps/core/atomic_output.hpp"
#include "caps/core/error.hpp"
#include "caps/core/json_limits.hpp"
#include "caps/study/compare_models.hpp"
#include "caps/image/image_io.hpp"
#include "caps/plan/plan_io.hpp"
#include "caps/render/model_comparison_report.hpp"
#include "caps/render/sensitivity_picture.hpp"
#include "caps/surface/patient_model.hpp"
#include "caps/volume/model_dir.hpp"
#include "json_fields.hpp"
#include "numbers.hpp"
#include "output_check.hpp"

CAPS_APP_REQUEST_JSON(caps::app::CompareModelsRequest)
CAPS_APP_REQUEST_JSON(caps::app::SensitivityRequest)
CAPS_APP_RESULT_JSON(caps::app::CompareModelsResult)
CAPS_APP_RESULT_JSON(caps::app::SensitivityResult)

namespace caps::app {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

// A scan-built model's map from its scan file's units and frame to its LPS mm (model.json
// "source": to_lps, mm_per_unit; surface/scan_model.cpp): p_model = mm_per_unit R p_file.
Eigen::Matrix4d scan_file_to_model(const std::string& dir, double* thickness_mm) {
  const ModelInfo info = read_model_info(dir);
  Eigen::Matrix4d S = Eigen::Matrix4d::Identity();
  try {
    const json source = json::parse(info.source_json);
    if (source.at("kind").get<std::string>() != "scan")
      throw InvalidInput("its source is not a surface scan");
    const double s = source.at("mm_per_unit").get<double>();
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) S(r, c) = s * source.at("to_lps").at(r).at(c).get<double>();
    *thickness_mm = json::parse(info.thickness_json).value("thickness_mm", 0.0);
  } catch (const std::exception& e) {
    throw InvalidInput(cat(dir, ": not a model built by `caps model from-scan` (", e.what(),
                           "); give the scan-built model as --scan-model"));
  }
  if (!S.allFinite() || !(S.topLeftCorner<3, 3>().determinant() > 0))
    throw InvalidInput(cat(dir, ": model.json's scan frame (to_lps, mm_per_unit) is not a rotation with a scale"));
  return S;
}

bool same_axis(const CylinderAxis& a, const CylinderAxis& b) {
  return (a.origin_lps - b.origin_lps).norm() < 1e-6 && (a.direction - b.direction).norm() < 1e-9 &&
         (a.front - b.front).norm() < 1e-9;
}

double median_of(std::vector<double> v) {
  if (v.empty()) return 0;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

}  // namespace

CompareModelsResult run_compare_models(const CompareModelsRequest& r, Reporter* reporter) {
  detail::refuse_output_over_inputs(r);
  if (r.scan_model.empty() && r.fused_model.empty())
    throw InvalidInput("compare-models needs --scan-model (with --registration) or --fused-model, or both");
  if (!r.scan_model.empty() && r.registration.empty())
    throw InvalidInput("--scan-model needs --registration: the registration.json of `caps model register "
                       "SCAN --to MODEL` for the scan the model was built from");
  if (r.meshing.constant_thickness != 0)
    throw InvalidInput("compare-models uses each model's own thickness; --constant-thickness does not apply");
  const closure::SimulateOptions o = simulate_options(r.meshing, r.solver);
  require_utf8(r.model, "the model folder");
  require_utf8(r.plan, "the plan file");
  const plan::Plan plan = plan::read_plan(r.plan);
  const auto ct = loaded_model(r.model);
  check_mesh_budget(plan::wound_border(plan), *ct, r.meshing);
  std::shared_ptr<const PatientModel> scan, fused;
  std::vector<study::ComparedModel> others;
  if (!r.scan_model.empty()) {
    double thickness_mm = 0;
    const Eigen::Matrix4d file_to_scan_model = scan_file_to_model(r.scan_model, &thickness_mm);
    const Eigen::Matrix4d scan_file_to_ct = read_registration_matrix(r.registration);
    if (!(scan_file_to_ct.topLeftCorner<3, 3>().determinant() > 0))
      throw InvalidInput(cat(r.registration, ": the scan_to_model matrix is not a rotation with a scale"));
    scan = loaded_model(r.scan_model);
    // CT LPS -> scan file (the registration's inverse) -> the scan model's LPS.
    others.push_back({"scan", cat("scan only (constant ", round_to(thickness_mm, 1), " mm)"), scan.get(),
                      file_to_scan_model * scan_file_to_ct.inverse()});
  }
  if (!r.fused_model.empty()) {
    fused = loaded_model(r.fused_model);
    if (!same_axis(fused->axis(), ct->axis()))
      throw InvalidInput(cat(r.fused_model, ": its axis is not the CT model's; give the model `caps model "
                             "fuse` made from ", r.model));
    others.push_back({"fused", "fused (scan + CT depths)", fused.get(), Eigen::Matrix4d::Identity()});
  }
  OutputDirectory out(r.output, r.force);
  const study::ComparedModel reference{"ct", "CT (measured thickness)", ct.get(), Eigen::Matrix4d::Identity()};
  const study::ModelComparison c = study::compare_models(reference, plan, others, o, reporter);
  const std::string name = fs::path(r.plan).filename().string();
  std::vector<const PatientModel*> models{ct.get()};
  for (const auto& m : others) models.push_back(m.model);
  render::write_model_comparison_report(c, models, o, out.path(), name, {}, reporter);
  out.commit();
  CompareModelsResult s;
  s.output = r.output;
  s.comparison_json = study::model_comparison_json(c, name);
  for (const auto& side : c.sides)
    s.sides.push_back({side.key, side.label, side.plan.frame.theta_deg, side.plan.frame.z_mm,
                       side.plan.frame.orientation_deg, side.centre_gap_mm, side.summary.closing_force_n,
                       side.summary.max_suture_force_n, side.summary.max_skin_tension_kpa,
                       side.summary.max_displacement_mm, side.summary.thickness_mean_mm});
  s.warnings = c.warnings;
  return s;
}

std::string summary(const CompareModelsResult& s) {
  std::string out = "caps compare-models: closing force";
  for (std::size_t i = 0; i < s.sides.size(); ++i)
    out += cat(i ? ", " : " ", round_to(s.sides[i].closing_force_n, 2), " N (", s.sides[i].key, ")");
  out += "; largest displacement";
  for (std::size_t i = 0; i < s.sides.size(); ++i)
    out += cat(i ? ", " : " ", round_to(s.sides[i].max_displacement_mm, 2), " mm (", s.sides[i].key, ")");
  return out + " -> " + s.output + "/report.html";
}

SensitivityResult run_sensitivity(const SensitivityRequest& r, Reporter* reporter) {
  detail::refuse_output_over_inputs(r);
  require_utf8(r.model, "the model folder");
  study::SensitivityOptions o;
  o.procedure = r.procedure;
  o.parameters = {{"length", r.length}};
  if (r.procedure == "ellipse") o.parameters["width"] = r.width;
  o.orientation_deg = r.orientation;
  const auto t = parse_numbers<3>(r.theta, "--theta", "first,last,step in degrees");
  o.theta_min_deg = t[0];
  o.theta_max_deg = t[1];
  o.theta_step_deg = t[2];
  if (!r.z.empty()) {
    const auto z = parse_numbers<3>(r.z, "--z", "first,last,step in mm");
    o.z_min_mm = z[0];
    o.z_max_mm = z[1];
    o.z_step_mm = z[2];
    if (o.z_min_mm > o.z_max_mm) throw InvalidInput(cat("--z ", r.z, ": first must not exceed last"));
  }
  o.margin_mm = r.margin;
  o.constant_thickness_mm = r.thickness;
  o.threads = r.threads;
  if (r.meshing.constant_thickness != 0)
    throw InvalidInput("sensitivity meshes the measured and a constant thickness itself; give the "
                       "constant one with --thickness, not --constant-thickness");
  o.simulate = simulate_options(r.meshing, r.solver);
  // Every centre's wound is the template's: about its length across, its border twice its
  // length and width.
  check_mesh_budget(std::max(r.length, r.width), 2.0 * (r.length + r.width), r.meshing);
  const auto model = loaded_model(r.model);
  if (model->thickness_kind() == "constant")
    throw InvalidInput(cat(r.model, ": its thickness is a constant (a scan-built model); the map needs a "
                           "model with a measured thickness (caps model from-volume)"));
  OutputDirectory out(r.output, r.force);
  const study::SensitivityMap map = study::thickness_sensitivity(*model, o, reporter);
  const std::string title = cat("Where a constant thickness misleads: ", r.procedure, " ", r.length, " mm",
                                r.procedure == "ellipse" ? cat(" x ", r.width, " mm") : std::string(),
                                " at ", map.points.size(), " points, ",
                                fs::path(r.model).filename().string());
  write_png(out.path() / "sensitivity.png", render::sensitivity_picture(map, *model, title, r.credit));
  write_text_atomic(out.path() / "sensitivity.json", study::sensitivity_json(map) + "\n");
  write_text_atomic(out.path() / "sensitivity.csv", study::sensitivity_csv(map));
  out.commit();
  SensitivityResult s;
  s.output = r.output;
  s.points = static_cast<int>(map.points.size());
  s.planned = map.planned;
  s.constant_thickness_mm = map.constant_thickness_mm;
  std::vector<double> f, d;
  int within = 0;
  std::map<std::string, std::pair<std::string, int>> warning_kinds;
  for (const auto& p : map.points) {
    if (!p.planned) continue;
    f.push_back(std::abs(p.force_change));
    d.push_back(std::abs(p.displacement_change));
    within += std::abs(p.force_change) <= 0.1 && std::abs(p.displacement_change) <= 0.1;
    for (const auto& w : p.warnings) {
      // One line per kind of warning (its text without the numbers), with how many centres had it.
      std::string kind;
      for (char ch : w) kind += std::isdigit(static_cast<unsigned char>(ch)) || ch == '.' ? '#' : ch;
      auto& [first, count] = warning_kinds[kind];
      if (count++ == 0) first = cat("(theta ", p.theta_deg, " deg, z ", p.z_mm, " mm) ", w);
    }
  }
  for (const auto& [kind, entry] : warning_kinds)
    s.warnings.push_back(entry.second > 1 ? cat(entry.first, " (and at ", entry.second - 1, " more centres)")
                                          : entry.first);
  if (!f.empty()) {
    s.median_force_change = median_of(f);
    s.max_force_change = *std::max_element(f.begin(), f.end());
    s.median_displacement_change = median_of(d);
    s.max_displacement_change = *std::max_element(d.begin(), d.end());
    s.within_10_percent = double(within) / f.size();
  }
  s.seconds = map.seconds;
  return s;
}

std::string summary(const SensitivityResult& s) {
  return cat("caps model sensitivity: ", s.planned, " of ", s.points, " plan centres, constant ",
             round_to(s.constant_thickness_mm, 1), " mm; |closing force change| median ",
             round_to(100 * s.median_force_change, 1), " %, largest ", round_to(100 * s.max_force_change, 1),
             " %; |displacement change| median ", round_to(100 * s.median_displacement_change, 1),
             " %, largest ", round_to(100 * s.max_displacement_change, 1), " %; ",
             round_to(100 * s.within_10_percent, 0), " % of centres within 10 % -> ", s.output,
             "/sensitivity.png");
}

}  // namespace caps::app
