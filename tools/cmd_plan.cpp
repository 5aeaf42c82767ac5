// caps plan: surgical plans on a patient model (CAPS 1992, section 5).
//   caps plan templates
//   caps plan new z-plasty --model /tmp/cranium --at 0,95 --length 20 --angle 60 --orientation 90 -o /tmp/z.json
//   caps plan new ellipse --model /tmp/cranium --at 0,95 --length 30 --width 9 -o /tmp/e.json --force
//   caps plan check /tmp/z.json --json
//   caps plan show /tmp/z.json -o /tmp/z.png
//   caps plan save-procedure /tmp/z.json -o /tmp/my_z.json
//   caps plan new /tmp/my_z.json --model /tmp/cranium --at 20,90 -o /tmp/z2.json
#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>

#include "caps/core/atomic_output.hpp"
#include "caps/core/error.hpp"
#include "caps/core/progress.hpp"
#include "caps/plan/check.hpp"
#include "caps/plan/plan_figure.hpp"
#include "caps/plan/plan_io.hpp"
#include "caps/plan/procedures.hpp"
#include "caps/surface/picking.hpp"
#include "commands.hpp"

namespace fs = std::filesystem;

namespace caps::cli {
namespace {

struct PlanArgs {
  std::string templ, model, at, at_xyz, output, plan;
  std::map<std::string, double> values;
  double orientation_deg = 0;
  bool thickness = false;
};

void refuse_existing(const std::string& out, bool force) {
  if (out.empty()) throw InvalidInput("-o: give the output file");
  if (fs::exists(out) && !force)
    throw InvalidInput(cat(out, " exists; use --force to replace it"));
}

std::string read_text(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw IoError(cat(path, ": cannot read"));
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

void print_report(const plan::Plan& p, const plan::PlanReport& r, const Common& common,
                  const std::string& what) {
  if (common.json) {
    nlohmann::json j = nlohmann::json::parse(plan::plan_to_json(p, &r));
    j["ok"] = true;
    std::cout << j.dump(2) << "\n";
    return;
  }
  for (const auto& w : r.warnings) warn(w);
  if (!common.quiet)
    std::cerr << what << ": " << p.procedure << ", " << r.n_points << " points, border loop of "
              << r.n_loop << " nodes, " << r.n_sutures << " suture pairs, cut "
              << std::round(r.cut_length_mm * 10) / 10 << " mm on the skin; can be operated\n";
}

void run_new(const PlanArgs& a, const Common& common) {
  refuse_existing(a.output, common.force);
  const PatientModel model = PatientModel::load(a.model);
  double theta = 0, z = 0;
  if (a.at.empty() == a.at_xyz.empty()) throw InvalidInput("give the centre with --at THETA,Z or --at-xyz X,Y,Z");
  if (!a.at.empty()) {
    char c = 0;
    std::istringstream in(a.at);
    if (!(in >> theta >> c >> z) || c != ',' || !in.eof())
      throw InvalidInput(cat("--at '", a.at, "': expected THETA,Z in degrees and mm, e.g. --at 0,95"));
  } else {
    const auto t = parse_triple(a.at_xyz, "--at-xyz");
    const CylindricalPoint cp = model.to_cylindrical({t[0], t[1], t[2]});
    theta = cp.theta_deg;
    z = cp.z_mm;
  }
  plan::LocalProcedure proc =
      a.templ.size() > 5 && a.templ.substr(a.templ.size() - 5) == ".json"
          ? plan::parse_procedure_json(read_text(a.templ), a.templ)
          : plan::layout_procedure(a.templ, a.values);
  if (a.templ.ends_with(".json") && !a.values.empty())
    throw InvalidInput("a procedure file has no parameters; drop --length/--width/--angle/...");
  plan::Plan p = plan::place_procedure(proc, model, theta, z, a.orientation_deg);
  p.model = a.model;
  const plan::PlanReport r = plan::check_plan(p, model);
  plan::write_plan(a.output, p, &r);
  print_report(p, r, common, a.output);
}

void run_check(const PlanArgs& a, const Common& common) {
  const plan::Plan p = plan::read_plan(a.plan);
  const std::string dir = !a.model.empty() ? a.model : p.model;
  if (dir.empty()) throw InvalidInput(cat(a.plan, ": names no model; give --model MODEL_DIR"));
  const PatientModel model = PatientModel::load(dir);
  print_report(p, plan::check_plan(p, model), common, a.plan);
}

void run_show(const PlanArgs& a, const Common& common) {
  refuse_existing(a.output, common.force);
  const plan::Plan p = plan::read_plan(a.plan);
  const std::string dir = !a.model.empty() ? a.model : p.model;
  if (dir.empty()) throw InvalidInput(cat(a.plan, ": names no model; give --model MODEL_DIR"));
  const PatientModel model = PatientModel::load(dir);
  const plan::PlanReport r = plan::check_plan(p, model);
  plan::PlanFigureOptions o;
  o.use_thickness = a.thickness;
  plan::write_plan_png(a.output, p, model, o);
  print_report(p, r, common, a.output);
}

void run_templates(const Common& common) {
  nlohmann::json j = nlohmann::json::array();
  std::ostringstream text;
  for (const auto& t : plan::procedure_library()) {
    nlohmann::json pj = nlohmann::json::array();
    text << t.name << ": " << t.summary << "\n";
    for (const auto& q : t.parameters) {
      pj.push_back({{"name", q.name}, {"unit", q.unit}, {"default", q.default_value},
                    {"min", q.min}, {"max", q.max}, {"meaning", q.meaning}});
      std::string flag = q.name;
      std::replace(flag.begin(), flag.end(), '_', '-');
      text << "    --" << flag << " " << q.unit << "  default " << q.default_value << ", range ["
           << q.min << ", " << q.max << "]: " << q.meaning << "\n";
    }
    j.push_back({{"name", t.name}, {"summary", t.summary}, {"parameters", pj}});
  }
  text << "every template: --at THETA,Z (or --at-xyz X,Y,Z) and --orientation DEG (from superior "
          "towards +theta)\n";
  std::cout << (common.json ? j.dump(2) + "\n" : text.str());
}

}  // namespace

void add_plan(CLI::App& app, Common& common, Action& action) {
  auto* plan = app.add_subcommand("plan", "Surgical plans: incisions, excisions, sutures");
  plan->require_subcommand(1);
  auto a = std::make_shared<PlanArgs>();

  auto* nw = plan->add_subcommand(
      "new", "Lay a procedure from the library (or a procedure file) on the model and check it.\n"
             "Example: caps plan new z-plasty --model cranium --at 0,95 --length 20 -o z.json");
  nw->add_option("TEMPLATE", a->templ, "a template (caps plan templates) or a procedure file .json")->required();
  nw->add_option("--model", a->model, "the patient model directory")->required();
  nw->add_option("--at", a->at, "the centre on the skin: THETA,Z (deg, mm)");
  nw->add_option("--at-xyz", a->at_xyz, "the centre as an LPS point X,Y,Z (mm)");
  nw->add_option("--orientation", a->orientation_deg,
                 "deg from superior towards +theta (the patient's left)")->capture_default_str();
  // One flag per parameter name in the library (apex_angle -> --apex-angle).
  std::set<std::string> keys;
  for (const auto& t : plan::procedure_library())
    for (const auto& q : t.parameters) keys.insert(q.name);
  for (const std::string& key : keys) {
    std::string name = key;
    std::replace(name.begin(), name.end(), '_', '-');
    nw->add_option_function<double>(cat("--", name), [a, key](double v) { a->values[key] = v; },
                                    "template parameter (see caps plan templates)");
  }
  nw->add_option("-o,--output", a->output, "the plan file to write")->required();
  add_common_flags(nw, common, true);
  nw->callback([&common, &action, a] { action = [&common, a] { run_new(*a, common); }; });

  auto* ck = plan->add_subcommand("check", "Check that a plan can be operated (exit 2 if not).\n"
                                           "Example: caps plan check z.json");
  ck->add_option("PLAN", a->plan, "the plan file")->required();
  ck->add_option("--model", a->model, "the model directory (default: the one the plan names)");
  add_common_flags(ck, common, false);
  ck->callback([&common, &action, a] { action = [&common, a] { run_check(*a, common); }; });

  auto* sh = plan->add_subcommand("show", "Draw the plan over the model: loop numbered, sutures marked.\n"
                                          "Example: caps plan show z.json -o z.png");
  sh->add_option("PLAN", a->plan, "the plan file")->required();
  sh->add_option("--model", a->model, "the model directory (default: the one the plan names)");
  sh->add_flag("--thickness", a->thickness, "draw over the thickness map even if the model has colour");
  sh->add_option("-o,--output", a->output, "the PNG to write")->required();
  add_common_flags(sh, common, true);
  sh->callback([&common, &action, a] { action = [&common, a] { run_show(*a, common); }; });

  auto* sv = plan->add_subcommand("save-procedure", "Save a plan's procedure (points, paths, excisions, "
                                                    "sutures) to reuse elsewhere with caps plan new FILE.json");
  sv->add_option("PLAN", a->plan, "the plan file")->required();
  sv->add_option("-o,--output", a->output, "the procedure file to write")->required();
  add_common_flags(sv, common, true);
  sv->callback([&common, &action, a] {
    action = [&common, a] {
      refuse_existing(a->output, common.force);
      const plan::Plan p = plan::read_plan(a->plan);
      plan::check_plan_structure(p);
      write_text_atomic(a->output, plan::procedure_to_json(plan::procedure_from_plan(p)) + "\n");
    };
  });

  auto* tp = plan->add_subcommand("templates", "List the procedure library and its parameters.");
  add_common_flags(tp, common, false);
  tp->callback([&common, &action] { action = [&common] { run_templates(common); }; });
}

}  // namespace caps::cli
