#include "caps/app/plan.hpp"

#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <unistd.h>
#include <vector>

#include "caps/app/loaded_model.hpp"
#include "caps/app/model.hpp"
#include "caps/app/simulation.hpp"
#include "caps/closure/simulate.hpp"
#include "caps/mesher/continuum_mesher.hpp"
#include "caps/core/atomic_output.hpp"
#include "caps/core/error.hpp"
#include "caps/core/json_file.hpp"
#include "caps/core/units.hpp"
#include "caps/plan/check.hpp"
#include "caps/plan/plan_figure.hpp"
#include "caps/plan/placement.hpp"
#include "caps/plan/plan_io.hpp"
#include "caps/plan/procedures.hpp"
#include "caps/plan/skin_lines.hpp"
#include "caps/surface/patient_model.hpp"
#include "json_fields.hpp"
#include "model_result.hpp"
#include "numbers.hpp"
#include "output_check.hpp"
#include "skin_place.hpp"

CAPS_APP_REQUEST_JSON(caps::app::PlanNewRequest)
CAPS_APP_REQUEST_JSON(caps::app::PlanCheckRequest)
CAPS_APP_REQUEST_JSON(caps::app::PlanShowRequest)
CAPS_APP_REQUEST_JSON(caps::app::SaveProcedureRequest)
CAPS_APP_REQUEST_JSON(caps::app::TemplatesRequest)
CAPS_APP_REQUEST_JSON(caps::app::SkinLinesRequest)
CAPS_APP_RESULT_JSON(caps::app::SkinLinesResult)
CAPS_APP_RESULT_JSON(caps::app::PlanResult)
CAPS_APP_RESULT_JSON(caps::app::TemplatesResult)

namespace caps::app {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

void refuse_existing(const std::string& out, bool force) {
  if (out.empty()) throw InvalidInput("-o: give the output file");
  if (fs::exists(out) && !force) throw InvalidInput(cat(out, " exists; use --force to replace it"));
}

PlanResult plan_result(const plan::Plan& p, const plan::PlanReport& r, const std::string& output,
                       Reporter* reporter) {
  PlanResult s;
  s.output = output;
  json j = json::parse(plan::plan_to_json(p, &r));
  j["ok"] = true;
  s.procedure = p.procedure;
  s.points = r.n_points;
  s.loop_nodes = r.n_loop;
  s.suture_pairs = r.n_sutures;
  s.cut_length_mm = r.cut_length_mm;
  s.warnings = r.warnings;
  if (r.near) {
    s.near = plan::placement_in_words(*r.near);
    j["check"]["near"]["words"] = s.near;  // the planner page says it so
  }
  s.plan_json = j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace);
  for (const auto& w : r.warnings) warn(reporter, w);
  return s;
}

// The model a plan is checked on: the one given, else the one the plan names.
// A plan on a local chart of the model given is checked on that chart (detail::plan_model_dir).
std::string model_of(const std::string& given, const plan::Plan& p, const std::string& plan_path) {
  const std::string dir = !given.empty() ? given : p.model;
  if (dir.empty()) throw InvalidInput(cat(plan_path, ": names no model; give --model MODEL_DIR"));
  return detail::plan_model_dir(dir, p.model, p.model_hash);
}

// The plan's check on the model in `model_dir`, with the warning of a placement from a landmark
// whose measured soft tissue is implausible (placement_doubt()).
plan::PlanReport checked_plan(const plan::Plan& p, const std::string& model_dir,
                              const PatientModel& model) {
  plan::PlanReport report = plan::check_plan(p, model);
  if (std::string doubt = placement_doubt(model_dir, model, p.placement); !doubt.empty())
    report.warnings.push_back(std::move(doubt));
  // Where the centre is from the nearest landmark (a chart's theta and z are not its parent's:
  // not said there).
  // Only the landmarks model.json keeps: finding them anew would cost every check (the page
  // checks on each drag) more than the check itself.
  if (detail::chart_parent(model_dir).empty())
    report.near =
        plan::nearest_kept_landmark_placement(model_dir, model, p.frame.theta_deg, p.frame.z_mm);
  return report;
}

// A free incision: one cutting path through the points (theta deg, z mm), no sutures.
plan::Plan free_incision(const PlanNewRequest& r, const PatientModel& model) {
  if (!r.at.empty() || !r.at_xyz.empty() || !r.parameters.empty())
    throw InvalidInput(
        "incision: the cut is given by its points; drop --at/--at-xyz and the "
        "template parameters");
  if (r.points.empty() == r.points_xyz.empty())
    throw InvalidInput(
        "incision: give the cut's points with --points THETA,Z;THETA,Z;... or "
        "--points-xyz X,Y,Z;X,Y,Z;...");
  std::vector<Eigen::Vector2d> tz;
  if (!r.points.empty()) {
    for (const auto& p : parse_point_list<2>(r.points, "--points", "THETA,Z in degrees and mm"))
      tz.emplace_back(p[0], p[1]);
  } else {
    for (const auto& p : parse_point_list<3>(r.points_xyz, "--points-xyz", "LPS X,Y,Z in mm")) {
      const CylindricalPoint cp = model.to_cylindrical({p[0], p[1], p[2]});
      tz.emplace_back(cp.theta_deg, cp.z_mm);
    }
  }
  if (tz.size() < 2)
    throw InvalidInput(cat("incision: ", tz.size(), " point given; a cut needs at least 2"));
  // Theta unwrapped about the first point, so a cut across theta = +-180 has a mean on the cut.
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  for (const Eigen::Vector2d& p : tz)
    mean += Eigen::Vector2d(tz[0][0] + std::remainder(p[0] - tz[0][0], 360.0), p[1]);
  mean /= static_cast<double>(tz.size());
  // Orientation: the direction from the first point to the last in the skin's tangent plane at
  // the centre. At orientation 0, x is superior and +theta is along +-y (docs/plan.md, "Frame").
  const plan::PlanFrame up = plan::make_frame(model, mean[0], mean[1], 0.0);
  const Eigen::Vector2d d =
      up.to_local(tz.back()[0], tz.back()[1]) - up.to_local(tz.front()[0], tz.front()[1]);
  const Eigen::Vector2d theta_dir = up.local_to_theta_z.inverse() * Eigen::Vector2d(1, 0);
  const double orientation =
      d.norm() > 0 ? rad_to_deg(std::atan2(theta_dir[1] > 0 ? d[1] : -d[1], d[0])) : 90.0;
  plan::Plan p;
  p.procedure = "custom";
  p.frame = plan::make_frame(model, mean[0], mean[1], orientation);
  p.paths.emplace_back();
  for (const Eigen::Vector2d& t : tz) {
    plan::SkinPoint sp;
    sp.theta_deg = std::remainder(t[0], 360.0);
    if (sp.theta_deg >= 180.0) sp.theta_deg -= 360.0;
    sp.z_mm = t[1];
    sp.lps = model.skin_point(sp.theta_deg, sp.z_mm);
    p.paths.back().push_back(static_cast<int>(p.points.size()));
    p.points.push_back(sp);
  }
  p.notes = cat("a free incision through ", tz.size(), " points; add its sutures");
  return p;
}

// The plan's points are on cells the model can hold, but the wound's patch with the simulation's
// defaults may not stand (its first ring of elements on grazing cells beside the nose): then
// plan::SkinNotHeld, when the cells it cannot stand on are ones a local chart facing that skin
// would hold. Any other refusal is left to caps simulate to report with its own options.
void check_patch_stands(const plan::Plan& p, const PatientModel& model) {
  try {
    const closure::SimulateOptions o = simulate_options(MeshingFields{}, SolverFields{});
    mesher::mesh_wound(plan::wound_border(p), model, o.surface, o.continuum);
  } catch (const mesher::OffModelError& e) {
    if (std::isfinite(e.theta_deg) && flags_chart_would_hold(model.flags_at(e.theta_deg, e.z_mm)))
      throw plan::SkinNotHeld(e.what());
  } catch (const Error&) {
  }
}

// Whether caps model chart can measure a local chart of the model in `dir`
// (detail::refuse_unchartable()).
bool chartable(const std::string& dir) {
  try {
    detail::refuse_unchartable(dir);
    return true;
  } catch (const std::exception&) {
    return false;
  }
}

// The plan on a local chart facing the skin at `tz` of the model, where the model's own image
// cannot hold it (`why`, check_plan's refusal): the chart is made aside (PLAN.chart.making-PID)
// and moved beside the plan (PLAN.chart) just before the plan is written, so a refusal leaves
// neither; the procedure lies at the chart's centre with the request's orientation (both from
// superior towards the patient's left, the chart keeping superior up).
PlanResult plan_on_chart(const PlanNewRequest& r, const plan::LocalProcedure& proc,
                         const Eigen::Vector2d& tz,
                         const std::optional<plan::LandmarkPlacement>& placement,
                         const std::string& why, Reporter* reporter) {
  const fs::path chart = fs::path(r.output).replace_extension(".chart");
  if (chart == fs::path(r.output))
    throw InvalidInput(cat(why, ". caps would plan it on a local chart facing this skin, made "
                           "beside the plan as PLAN.chart: name the plan file otherwise than ",
                           r.output, " (plan.json)"));
  if (fs::exists(chart) && !r.force)
    throw InvalidInput(cat(why, ". caps would plan it on a local chart facing this skin, in ",
                           chart.string(), ", which exists: use --force to replace it"));
  const fs::path aside = cat(chart.string(), ".making-", ::getpid());
  struct Aside {
    fs::path path;
    ~Aside() {
      std::error_code ec;
      fs::remove_all(path, ec);
    }
  } cleanup{aside};
  ChartRequest cr;
  cr.model = fs::absolute(r.model).lexically_normal().string();  // found from anywhere
  cr.at = cat(round_to(tz[0], 3), ",", round_to(tz[1], 3));
  cr.output = aside.string();
  cr.force = true;
  run_chart(cr, reporter);
  const PatientModel chart_model = PatientModel::load(aside.string());
  plan::Plan p = plan::place_procedure(proc, chart_model, 0, 0, r.orientation);
  p.placement = placement;
  p.model = chart.string();
  p.model_hash = chart_model.content_hash();
  plan::PlanReport report;
  try {
    report = plan::check_plan(p, chart_model);
  } catch (const InvalidInput& e) {
    throw InvalidInput(cat(why, ". On a local chart facing this skin it cannot be operated "
                           "either: ", e.what()));
  }
  report.warnings.insert(
      report.warnings.begin(),
      cat("the model's cylindrical image cannot hold the skin at theta ", round_to(tz[0], 1),
          " deg, z ", round_to(tz[1], 1), " mm (its rays meet that skin edge-on or behind other "
          "skin): planned on a local chart facing it, made in ", chart.string(),
          " (as caps model chart ", r.model, " --at ", cr.at, "); its closure is solved in ",
          r.model, "'s whole face"));
  if (std::string doubt = placement_doubt(r.model, *loaded_model(r.model), placement);
      !doubt.empty())
    report.warnings.push_back(std::move(doubt));
  if (fs::exists(chart)) fs::remove_all(chart);
  fs::rename(aside, chart);
  try {
    plan::write_plan(r.output, p, &report);
  } catch (...) {
    std::error_code ec;
    fs::remove_all(chart, ec);
    throw;
  }
  PlanResult result = plan_result(p, report, r.output, reporter);
  result.chart = chart.string();
  return result;
}

}  // namespace

std::string summary(const PlanResult& r) {
  return cat(r.output.empty() ? "plan" : r.output, ": ", r.procedure, ", ", r.points,
             " points, border loop of ", r.loop_nodes, " nodes, ", r.suture_pairs,
             " suture pairs, cut ", round_to(r.cut_length_mm, 1), " mm on the skin",
             r.near.empty() ? "" : cat(", centre ", r.near), "; can be operated",
             r.chart.empty() ? "" : cat(" (on the local chart ", r.chart, ")"));
}

PlanResult run_plan_new(const PlanNewRequest& r, Reporter* reporter) {
  detail::refuse_output_over_inputs(r);
  refuse_existing(r.output, r.force);
  if (r.procedure == kFreeIncision) {
    const auto loaded = loaded_model(r.model);
    plan::Plan p = free_incision(r, *loaded);
    p.model = r.model;
    p.model_hash = loaded->content_hash();
    const plan::PlanReport report = plan::check_plan(p, *loaded);
    plan::write_plan(r.output, p, &report);
    return plan_result(p, report, r.output, reporter);
  }
  if (!r.points.empty() || !r.points_xyz.empty())
    throw InvalidInput(cat("--points and --points-xyz are for a free incision (caps plan new ",
                           kFreeIncision, "); ", r.procedure, " is placed with --at"));
  if (r.at.empty() == r.at_xyz.empty())
    throw InvalidInput("give the centre with --at THETA,Z, --at LANDMARK+LEFT,UP or --at-xyz X,Y,Z");
  // The plan records its model's folder to find it again: with its bytes replaced it could not.
  require_utf8(r.model, "the model folder");
  const bool from_file = fs::path(r.procedure).extension() == ".json";
  if (from_file && !r.parameters.empty())
    throw InvalidInput("a procedure file has no parameters; drop --length/--width/--angle/...");
  if (!std::isfinite(r.orientation))
    throw InvalidInput("--orientation: give an angle in degrees");
  plan::LocalProcedure proc =
      from_file ? plan::parse_procedure_json(
                      read_json_text(r.procedure, "give a procedure file (caps plan "
                                                  "save-procedure) or a template's name"),
                      r.procedure)
                : plan::layout_procedure(r.procedure, r.parameters);
  const auto loaded = loaded_model(r.model);
  const PatientModel& model = *loaded;
  std::optional<plan::LandmarkPlacement> placement;
  const Eigen::Vector2d tz = resolve_at(r.model, model, r.at, r.at_xyz, &placement);
  plan::Plan p = plan::place_procedure(proc, model, tz[0], tz[1], r.orientation);
  p.placement = placement;
  p.model = r.model;
  p.model_hash = model.content_hash();
  plan::PlanReport report;
  try {
    report = checked_plan(p, r.model, model);
    if (!r.no_chart && chartable(r.model)) check_patch_stands(p, model);
  } catch (const plan::SkinNotHeld& e) {
    if (r.no_chart || !chartable(r.model)) throw;
    return plan_on_chart(r, proc, tz, placement, e.what(), reporter);
  }
  plan::write_plan(r.output, p, &report);
  return plan_result(p, report, r.output, reporter);
}

PlanResult run_plan_check(const PlanCheckRequest& r, Reporter* reporter) {
  const plan::Plan p = plan::read_plan(r.plan);
  const std::string model_dir = model_of(r.model, p, r.plan);
  const auto loaded = loaded_model(model_dir);
  const PatientModel& model = *loaded;
  return plan_result(p, checked_plan(p, model_dir, model), "", reporter);
}

PlanResult run_plan_show(const PlanShowRequest& r, Reporter* reporter) {
  detail::refuse_output_over_inputs(r);
  refuse_existing(r.output, r.force);
  const plan::Plan p = plan::read_plan(r.plan);
  const auto loaded = loaded_model(model_of(r.model, p, r.plan));
  const PatientModel& model = *loaded;
  const plan::PlanReport report = plan::check_plan(p, model);
  plan::PlanFigureOptions o;
  o.use_thickness = r.thickness;
  plan::write_plan_png(r.output, p, model, o);
  return plan_result(p, report, r.output, reporter);
}

PlanResult run_save_procedure(const SaveProcedureRequest& r, Reporter* reporter) {
  detail::refuse_output_over_inputs(r);
  refuse_existing(r.output, r.force);
  const plan::Plan p = plan::read_plan(r.plan);
  const plan::PlanReport report = plan::check_plan_structure(p);
  write_text_atomic(r.output, plan::procedure_to_json(plan::procedure_from_plan(p)) + "\n");
  return plan_result(p, report, r.output, reporter);
}

SkinLinesResult run_skin_lines(const SkinLinesRequest& r, Reporter*) {
  const PatientModel model = PatientModel::load(r.model);
  const plan::SkinLineMap& map = plan::borges_map();
  SkinLinesResult out;
  out.model = r.model;
  out.map = map.name;
  out.source = map.source;
  const std::vector<plan::SkinLinePath> paths = plan::trace_skin_lines(
      map, model, plan::model_landmarks(r.model, model), r.spacing_mm, r.half_length_mm,
      &out.note);
  json lines = json::array();
  std::map<std::string, int> per_zone;
  for (const plan::SkinLinePath& p : paths) {
    json lps = json::array(), tz = json::array();
    for (std::size_t i = 0; i < p.theta_deg.size(); ++i) {
      const Eigen::Vector3d x = model.skin_point(p.theta_deg[i], p.z_mm[i]);
      lps.push_back({round_to(x.x(), 3), round_to(x.y(), 3), round_to(x.z(), 3)});
      tz.push_back({round_to(p.theta_deg[i], 4), round_to(p.z_mm[i], 3)});
    }
    lines.push_back({{"zone", p.zone}, {"points_lps", lps}, {"theta_z", tz}});
    ++per_zone[p.zone];
  }
  out.count = static_cast<int>(paths.size());
  out.lines_json = lines.dump();
  std::ostringstream text;
  for (const plan::SkinLineZone& z : map.zones)
    if (per_zone.count(z.name))
      text << "  " << z.name << ": " << per_zone[z.name] << " lines; they run " << z.says << "\n";
  out.zones_text = text.str();
  return out;
}

std::string summary(const SkinLinesResult& r) {
  if (r.count == 0) return cat("no skin lines traced on ", r.model, ": ", r.note);
  return cat(r.count, " skin lines traced on ", r.model, " (", r.map, "):\n", r.zones_text,
             "source: ", r.source);
}

TemplatesResult run_templates(const TemplatesRequest&, Reporter*) {
  json j = json::array();
  std::ostringstream text;
  for (const auto& t : plan::procedure_library()) {
    json pj = json::array();
    text << t.name << ": " << t.summary << "\n";
    for (const auto& q : t.parameters) {
      pj.push_back({{"name", q.name}, {"unit", q.unit}, {"default", q.default_value},
                    {"min", q.min}, {"max", q.max}, {"meaning", q.meaning}});
      if (!q.alternative_to.empty()) pj.back()["alternative_to"] = q.alternative_to;
      text << "    --" << dashed(q.name) << " " << q.unit << "  default " << q.default_value
           << ", range [" << q.min << ", " << q.max << "]: " << q.meaning << "\n";
    }
    j.push_back({{"name", t.name}, {"summary", t.summary}, {"parameters", pj}});
  }
  text << "every template: --at THETA,Z (or --at-xyz X,Y,Z) and --orientation DEG (from superior "
          "towards +theta)";
  return {j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace), text.str()};
}

std::string summary(const TemplatesResult& r) { return r.text; }

std::vector<std::string> template_parameter_names() {
  std::set<std::string> keys;
  for (const auto& t : plan::procedure_library())
    for (const auto& q : t.parameters) keys.insert(q.name);
  return {keys.begin(), keys.end()};
}

}  // namespace caps::app
