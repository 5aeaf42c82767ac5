#include "caps/app/plan.hpp"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>

#include "caps/core/atomic_output.hpp"
#include "caps/core/error.hpp"
#include "caps/core/json_limits.hpp"
#include "caps/plan/check.hpp"
#include "caps/plan/plan_figure.hpp"
#include "caps/plan/plan_io.hpp"
#include "caps/plan/procedures.hpp"
#include "caps/app/loaded_model.hpp"
#include "caps/surface/patient_model.hpp"
#include "json_fields.hpp"
#include "numbers.hpp"
#include "output_check.hpp"

CAPS_APP_REQUEST_JSON(caps::app::PlanNewRequest)
CAPS_APP_REQUEST_JSON(caps::app::PlanCheckRequest)
CAPS_APP_REQUEST_JSON(caps::app::PlanShowRequest)
CAPS_APP_REQUEST_JSON(caps::app::SaveProcedureRequest)
CAPS_APP_REQUEST_JSON(caps::app::TemplatesRequest)

namespace caps::app {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

void refuse_existing(const std::string& out, bool force) {
  if (out.empty()) throw InvalidInput("-o: give the output file");
  if (fs::exists(out) && !force) throw InvalidInput(cat(out, " exists; use --force to replace it"));
}

std::string read_text(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw IoError(cat(path, ": cannot read"));
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

PlanResult plan_result(const plan::Plan& p, const plan::PlanReport& r, const std::string& output,
                       Reporter* reporter) {
  PlanResult s;
  s.output = output;
  json j = json::parse(plan::plan_to_json(p, &r));
  j["ok"] = true;
  s.plan_json = j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace);
  s.procedure = p.procedure;
  s.points = r.n_points;
  s.loop_nodes = r.n_loop;
  s.suture_pairs = r.n_sutures;
  s.cut_length_mm = r.cut_length_mm;
  s.warnings = r.warnings;
  for (const auto& w : r.warnings) warn(reporter, w);
  return s;
}

// The model a plan is checked on: the one given, else the one the plan names.
std::string model_of(const std::string& given, const plan::Plan& p, const std::string& plan_path) {
  const std::string dir = !given.empty() ? given : p.model;
  if (dir.empty()) throw InvalidInput(cat(plan_path, ": names no model; give --model MODEL_DIR"));
  return dir;
}

}  // namespace

std::string to_json(const PlanResult& r) { return r.plan_json; }

std::string summary(const PlanResult& r) {
  return cat(r.output.empty() ? "plan" : r.output, ": ", r.procedure, ", ", r.points,
             " points, border loop of ", r.loop_nodes, " nodes, ", r.suture_pairs,
             " suture pairs, cut ", round_to(r.cut_length_mm, 1),
             " mm on the skin; can be operated");
}

PlanResult run_plan_new(const PlanNewRequest& r, Reporter* reporter) {
  detail::refuse_output_over_inputs(r);
  refuse_existing(r.output, r.force);
  if (r.at.empty() == r.at_xyz.empty())
    throw InvalidInput("give the centre with --at THETA,Z or --at-xyz X,Y,Z");
  // The plan records its model's folder to find it again: with its bytes replaced it could not.
  require_utf8(r.model, "the model folder");
  const bool from_file = fs::path(r.procedure).extension() == ".json";
  if (from_file && !r.parameters.empty())
    throw InvalidInput("a procedure file has no parameters; drop --length/--width/--angle/...");
  if (!std::isfinite(r.orientation))
    throw InvalidInput("--orientation: give an angle in degrees");
  plan::LocalProcedure proc = from_file ? plan::parse_procedure_json(read_text(r.procedure), r.procedure)
                                        : plan::layout_procedure(r.procedure, r.parameters);
  const auto loaded = loaded_model(r.model);
  const PatientModel& model = *loaded;
  double theta = 0, z = 0;
  if (!r.at.empty()) {
    const auto tz = parse_numbers<2>(r.at, "--at", "THETA,Z in degrees and mm, e.g. --at 0,95");
    theta = tz[0];
    z = tz[1];
  } else {
    const auto t = parse_numbers<3>(r.at_xyz, "--at-xyz", "an LPS point X,Y,Z in mm");
    const CylindricalPoint cp = model.to_cylindrical({t[0], t[1], t[2]});
    theta = cp.theta_deg;
    z = cp.z_mm;
  }
  plan::Plan p = plan::place_procedure(proc, model, theta, z, r.orientation);
  p.model = r.model;
  p.model_hash = model.content_hash();
  const plan::PlanReport report = plan::check_plan(p, model);
  plan::write_plan(r.output, p, &report);
  return plan_result(p, report, r.output, reporter);
}

PlanResult run_plan_check(const PlanCheckRequest& r, Reporter* reporter) {
  const plan::Plan p = plan::read_plan(r.plan);
  const auto loaded = loaded_model(model_of(r.model, p, r.plan));
  const PatientModel& model = *loaded;
  return plan_result(p, plan::check_plan(p, model), "", reporter);
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

std::string to_json(const TemplatesResult& r) { return r.json; }
std::string summary(const TemplatesResult& r) { return r.text; }

std::vector<std::string> template_parameter_names() {
  std::set<std::string> keys;
  for (const auto& t : plan::procedure_library())
    for (const auto& q : t.parameters) keys.insert(q.name);
  return {keys.begin(), keys.end()};
}

}  // namespace caps::app
