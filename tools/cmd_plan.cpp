// caps plan: bound to app/ (caps/app/plan.hpp).
//   caps plan templates
//   caps plan new z-plasty --model /tmp/cranium --at 0,95 --length 20 --angle 60 --orientation 90 -o /tmp/z.json
//   caps plan new ellipse --model /tmp/cranium --at 0,95 --length 30 --width 9 -o /tmp/e.json --force
//   caps plan check /tmp/z.json --json
//   caps plan show /tmp/z.json -o /tmp/z.png
//   caps plan save-procedure /tmp/z.json -o /tmp/my_z.json
//   caps plan new /tmp/my_z.json --model /tmp/cranium --at 20,90 -o /tmp/z2.json
//   caps plan new incision --model /tmp/cranium --points '20,100;28,108;36,100' -o /tmp/cut.json
#include "caps/app/plan.hpp"
#include "commands.hpp"

namespace caps::cli {

void add_plan(CLI::App& app, Common& common, Action& action) {
  auto* plan = app.add_subcommand("plan", "Surgical plans: incisions, excisions, sutures");
  plan->require_subcommand(1);
  add_verb(plan, "new",
           "Lay a procedure from the library (or a procedure file) on the model and check it.\n"
           "Example: caps plan new z-plasty --model cranium --at 0,95 --length 20 -o z.json",
           &app::run_plan_new, common, action);
  add_verb(plan, "check",
           "Check that a plan can be operated (exit 2 if not).\nExample: caps plan check z.json",
           &app::run_plan_check, common, action);
  add_verb(plan, "show",
           "Draw the plan over the model: loop numbered, sutures marked.\n"
           "Example: caps plan show z.json -o z.png",
           &app::run_plan_show, common, action);
  add_verb(plan, "save-procedure",
           "Save a plan's procedure (points, paths, excisions, sutures) to reuse elsewhere with "
           "caps plan new FILE.json",
           &app::run_save_procedure, common, action);
  add_verb(plan, "templates", "List the procedure library and its parameters.",
           &app::run_templates, common, action, Print::Stdout);
}

}  // namespace caps::cli
