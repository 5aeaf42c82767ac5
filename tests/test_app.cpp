// The application layer (app/): requests read and written as JSON with their declared fields;
// one request run through app:: directly and through the caps program gives the same result
// JSON; warnings reach the result files; the reporter sees progress and can cancel.
#include <gtest/gtest.h>

#include "caps/app/model.hpp"
#include "caps/app/plan.hpp"
#include "caps/app/render.hpp"
#include "caps/app/simulation.hpp"
#include "caps/app/verbs.hpp"
#include "caps/core/error.hpp"
#include "caps/surface/landmarks.hpp"
#include "caps/core/units.hpp"
#include "caps/fem/mesh_io.hpp"
#include "caps/fem/result_io.hpp"
#include "caps/plan/plan_io.hpp"
#include "cli_run.hpp"
#include "phantom_model.hpp"

#include <Eigen/Geometry>

#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

namespace fs = std::filesystem;
using namespace caps;
using nlohmann::json;

namespace {

const fs::path kTmp = fs::temp_directory_path() / "caps_test_app";
const std::string kModel = (kTmp / "model").string();

using caps_test::slurp;

// The result JSON without what differs between two runs of the same request by design: the
// output folder's name and the wall-clock timings.
json comparable(json j) {
  j.erase("output");
  j.erase("timings_s");
  return j;
}

class AppWithModel : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    fs::remove_all(kTmp);
    fs::create_directories(kTmp);
    caps_test::make_phantom_model(kTmp, kModel);
  }
};

// Plans `procedure` at `at` on `model` into kTmp/`name` through app:: (replacing it).
app::PlanResult plan_at(const std::string& procedure, const std::string& at,
                        const std::map<std::string, double>& parameters, const std::string& name,
                        const std::string& model = kModel, double orientation = 0) {
  app::PlanNewRequest pn;
  pn.procedure = procedure;
  pn.model = model;
  pn.at = at;
  pn.orientation = orientation;
  pn.parameters = parameters;
  pn.output = (kTmp / name).string();
  pn.force = true;
  return app::run_plan_new(pn);
}

// A reporter that records what it is told, and cancels once asked to.
class RecordingReporter : public Reporter {
 public:
  std::vector<std::string> steps;
  bool cancel = false;
  bool is_cancelled() const override { return cancel; }

 protected:
  void on_progress(const std::string& step, double) override {
    if (steps.empty() || steps.back() != step) steps.push_back(step);
  }
};

}  // namespace

TEST(Fields, RequestJsonRoundTripKeepsEveryFieldAndTheLibraryDefaults) {
  const auto r = app::read_request<app::MeshRequest>(
      R"({"model": "m", "output": "o", "plan": "p.json", "mesh_size": 1.5, "rim": "free"})");
  EXPECT_EQ(r.model, "m");
  EXPECT_EQ(r.meshing.mesh_size, 1.5);
  EXPECT_EQ(r.meshing.rim, "free");
  // Unset fields take the documented defaults (docs/mesher.md: 2 element layers through the
  // tissue, stage 1 at t1 = 30 deg, undermining 10 mm), which the request takes from the
  // library's options: a changed default in either place fails here.
  EXPECT_EQ(r.meshing.layers, 2);
  EXPECT_EQ(mesher::ContinuumMeshOptions{}.n_layers, 2);
  EXPECT_EQ(r.meshing.t1, 30.0);
  EXPECT_EQ(mesher::SurfaceMeshOptions{}.t1_deg, 30.0);
  const auto back = app::read_request<app::MeshRequest>(app::write_request(r));
  EXPECT_EQ(app::write_request(back), app::write_request(r));
  const json j = json::parse(app::write_request(r));
  EXPECT_EQ(j["mesh_size"], 1.5);
  EXPECT_EQ(j["undermine"], 10.0);
  EXPECT_EQ(mesher::ContinuumMeshOptions{}.undermine_mm, 10.0);
  EXPECT_TRUE(j.contains("stage1_angle"));
}

TEST(Fields, BadRequestsNameTheKey) {
  auto refused = [](const std::string& text, const std::string& what) {
    try {
      app::read_request<app::SimulateRequest>(text, "req.json");
      ADD_FAILURE() << "accepted: " << text;
    } catch (const InvalidInput& e) {
      EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("req.json"), std::string::npos) << e.what();
    }
  };
  refused(R"({"model": "m", "plan": "p", "output": "o", "layers": "two"})", "\"layers\" must be a whole number");
  refused(R"({"model": "m", "plan": "p", "output": "o", "layers": 2.5})", "\"layers\" must be a whole number");
  refused(R"({"model": "m", "plan": "p", "output": "o", "sizee": 2})", "unknown key \"sizee\"");
  refused(R"({"model": "m", "output": "o"})", "\"plan\" is required");
  refused(R"({"model": "m", "plan": "p", "output": "o", "render": 1})", "\"render\" must be true or false");
  refused(R"([1, 2])", "expected a JSON object");
  refused(R"({"model": )", "not valid JSON");
}

TEST(ResultFields, ASimulateResultRoundTripsThroughItsDeclaredFields) {
  app::SimulateResult r;
  r.output = "out";
  r.elements = 11;
  r.nodes = 12;
  r.suture_pairs = 13;
  r.max_displacement_mm = 1.25;
  r.closing_force_n = 2.5;
  r.max_suture_force_n = 0.375;
  r.max_suture_gap_mm = 1e-7;
  r.strain_energy_mj = 4.5;
  r.material = "goh";
  r.prestretch = 1.1;
  r.gape_mm = 0.75;
  r.load_steps = 3;
  r.newton_iterations = 17;
  r.inverted_elements = 2;
  r.suture_spacing_mm = 5;
  r.max_force_per_suture_n = 0.5;
  r.force_per_mm_n = 0.0625;
  r.wound_length_mm = 40;
  r.sutures = 8;
  r.corner_a = 2;
  r.corner_b = 5;
  r.corner_length_before_mm = 20;
  r.corner_length_after_mm = 25;
  r.axis_length_before_mm = 20;
  r.axis_length_after_mm = 21;
  r.sutures_total_force_n = 2.75;
  r.compressive_sutures = 1;
  r.compressive_force_n = -0.25;
  r.images = {"pre_front.png", "post_front.png"};
  r.warnings = {"a warning"};
  r.solve_s = 9.5;
  const std::string text = app::to_json(r);
  // The nesting and the computed values as the result's readers know them.
  const json j = json::parse(text);
  EXPECT_EQ(j.at("sutures_at_spacing").at("max_force_per_suture_n"), 0.5);
  EXPECT_EQ(j.at("lengthening").at("mm"), 5.0);
  EXPECT_EQ(j.at("lengthening").at("percent"), 25.0);
  EXPECT_EQ(j.at("lengthening").at("corners"), json::array({2, 5}));
  EXPECT_EQ(j.at("lengthening").at("between"), "closed corners 2 and 5");
  EXPECT_EQ(j.at("lengthening").at("axis_projection").at("mm"), 1.0);
  EXPECT_NEAR(j.at("lengthening").at("axis_projection").at("percent").get<double>(), 5.0, 1e-12);
  EXPECT_EQ(j.at("sutures_at_spacing").at("compressive_force_n"), -0.25);
  EXPECT_EQ(j.at("timings_s").at("solve"), 9.5);
  EXPECT_EQ(j.at("material"), "goh");
  const auto back = app::result_from_json<app::SimulateResult>(text);
  EXPECT_EQ(app::to_json(back), text);
  EXPECT_EQ(back.axis_length_after_mm, 21);
  EXPECT_EQ(back.corner_b, 5);
  EXPECT_EQ(back.compressive_sutures, 1);
  EXPECT_EQ(back.sutures, 8);
  EXPECT_EQ(back.images, r.images);
  EXPECT_EQ(back.solve_s, 9.5);
  // A key that is no field is refused, naming where it is.
  json extra = j;
  extra["lengthening"]["gain"] = 1;
  try {
    app::result_from_json<app::SimulateResult>(extra.dump(), "result.json");
    ADD_FAILURE() << "accepted an unknown key";
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("unknown key \"lengthening.gain\""), std::string::npos)
        << e.what();
  }
}

TEST(ResultFields, OptionalFieldsAndDocumentsRoundTrip) {
  // Fields written only when they hold: the flag comes back from their presence.
  app::RenderResult with;
  with.output = "img";
  with.has_tension = true;
  with.max_skin_tension_kpa = 12.5;
  with.gltf = true;
  with.frames = 24;
  with.animations = {"transition_plan.gif"};
  const json wj = json::parse(app::to_json(with));
  EXPECT_EQ(wj.at("gltf"), "skin.glb");
  EXPECT_EQ(wj.at("frames"), 24);
  EXPECT_EQ(wj.at("wound_area_mm2").at("pre"), 0.0);
  const auto wback = app::result_from_json<app::RenderResult>(wj.dump());
  EXPECT_TRUE(wback.has_tension && wback.gltf);
  EXPECT_EQ(app::to_json(wback), app::to_json(with));
  const app::RenderResult without;
  const json oj = json::parse(app::to_json(without));
  EXPECT_FALSE(oj.contains("gltf") || oj.contains("frames") || oj.contains("max_skin_tension_kpa"));
  EXPECT_FALSE(app::result_from_json<app::RenderResult>(oj.dump()).has_tension);

  app::SiteResult site;
  site.lps = {1.5, -2, 3};
  EXPECT_FALSE(json::parse(app::to_json(site)).contains("layers_mm"));
  site.has_layers = true;
  site.fat_mm = 2.25;
  const auto sback = app::result_from_json<app::SiteResult>(app::to_json(site));
  EXPECT_TRUE(sback.has_layers);
  EXPECT_EQ(sback.fat_mm, 2.25);
  EXPECT_EQ(sback.lps, site.lps);

  // A document written elsewhere (model.json) sits beside the declared keys, which win.
  app::ModelResult m;
  m.model_json = R"({"format": "caps-model", "grid": {"n_theta": 8}, "output": "old"})";
  m.output = "new";
  const json mj = json::parse(app::to_json(m));
  EXPECT_EQ(mj.at("output"), "new");
  EXPECT_EQ(mj.at("grid").at("n_theta"), 8);
  const auto mback = app::result_from_json<app::ModelResult>(mj.dump());
  EXPECT_EQ(mback.output, "new");
  EXPECT_EQ(json::parse(mback.model_json), json::parse(R"({"format": "caps-model", "grid": {"n_theta": 8}})"));
  // A document alone may be any JSON value: the templates are an array.
  app::TemplatesResult t;
  t.json = R"([{"name": "ellipse"}])";
  EXPECT_EQ(json::parse(app::to_json(t)), json::parse(t.json));
}

TEST(Verbs, EveryVerbIsACommandOfTheProgramWithItsHelp) {
  ASSERT_FALSE(app::verbs().empty());
  for (const app::VerbEntry& v : app::verbs()) {
    const auto r = caps_test::caps(v.name + " --help");
    EXPECT_EQ(r.code, 0) << v.name << ": " << r.out;
    EXPECT_EQ(r.out.rfind(v.help + "\n", 0), 0u) << v.name << ": " << r.out;
    EXPECT_EQ(&app::find_verb(v.key), &v);
    EXPECT_EQ(&app::find_verb(v.name), &v);
    EXPECT_TRUE(json::parse(v.defaults_json()).is_object()) << v.name;
  }
  EXPECT_NO_THROW(app::find_verb("compare-models"));
  EXPECT_NO_THROW(app::find_verb("model sensitivity"));
  EXPECT_THROW(app::find_verb("simulte"), InvalidInput);
}

TEST(JsonReaders, ALandmarksJsonNestedTooDeepIsRefusedNamingTheFile) {
  const int deep = 100000;
  const std::string text = R"({"items": {"glabella": )" + std::string(deep, '[') +
                           std::string(deep, ']') + "}}";
  try {
    landmarks_from_json(text, "m/model.json");
    ADD_FAILURE() << "accepted";
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("m/model.json"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("nested more than"), std::string::npos) << e.what();
  }
}

TEST(Fields, OptionNamesAreTheDashedKeys) {
  EXPECT_EQ(app::option_name({"mesh_size", "", app::FieldKind::Option}), "--mesh-size");
  EXPECT_EQ(app::option_name({"output", "", app::FieldKind::Required, "-o,--output"}), "--output");
  EXPECT_EQ(app::option_name({"model", "", app::FieldKind::Positional, "MODEL_DIR"}), "MODEL_DIR");
}

TEST(Errors, ConflictingTemplateParametersAreRefusedAndSpelledAsTyped) {
  app::PlanNewRequest r;
  r.procedure = "ellipse";
  r.model = "nowhere";
  r.at = "0,60";
  r.output = (kTmp / "never.json").string();
  r.parameters = {{"width", 10}, {"apex_angle", 30}};
  try {
    app::run_plan_new(r);
    ADD_FAILURE() << "accepted width and apex_angle together";
  } catch (const InvalidParameter& e) {
    EXPECT_EQ(std::string(e.what()), "ellipse: give width or apex_angle, not both (the one sets the other)");
    EXPECT_EQ(e.spelled([](const std::string& k) { return "--" + app::dashed(k); }),
              "ellipse: give --width or --apex-angle, not both (the one sets the other)");
  }
  EXPECT_FALSE(fs::exists(r.output));
}

TEST_F(AppWithModel, SimulateThroughAppAndThroughTheCliGivesTheSameResultJson) {
  // plan new: the same plan file both ways.
  app::PlanNewRequest pn;
  pn.procedure = "v-y-advancement";
  pn.model = kModel;
  pn.at = "0,60";
  pn.orientation = 90;
  pn.parameters = {{"length", 12}, {"advance", 3}};
  pn.output = (kTmp / "vy_app.json").string();
  const app::PlanResult planned = app::run_plan_new(pn);
  const std::string cli_plan = (kTmp / "vy_cli.json").string();
  const auto p = caps_test::caps("plan new v-y-advancement --model " + kModel +
                                 " --at 0,60 --orientation 90 --length 12 --advance 3 -q --json -o " +
                                 cli_plan);
  ASSERT_EQ(p.code, 0) << p.out;
  EXPECT_EQ(json::parse(p.out), json::parse(app::to_json(planned)));
  EXPECT_EQ(json::parse(slurp(cli_plan)), json::parse(slurp(pn.output)));

  // simulate: the request built in code, and the same options typed.
  app::SimulateRequest s;
  s.model = kModel;
  s.plan = pn.output;
  s.output = (kTmp / "vy_sim").string();
  s.meshing.mesh_size = 2.5;
  s.meshing.undermine = 4;
  RecordingReporter reporter;
  const app::SimulateResult direct = app::run_simulate(s, &reporter);
  EXPECT_GT(direct.closing_force_n, 0);
  EXPECT_LT(direct.max_suture_gap_mm, 1e-6);
  EXPECT_FALSE(reporter.steps.empty());  // progress was reported
  const auto c = caps_test::caps("simulate --model " + kModel + " --plan " + pn.output + " -o " +
                                 s.output + " --mesh-size 2.5 --undermine 4 --force -q --json");
  ASSERT_EQ(c.code, 0) << c.out;
  EXPECT_EQ(comparable(json::parse(c.out)), comparable(json::parse(app::to_json(direct))));
  // The old spelling still works, with a note.
  const auto old = caps_test::caps("simulate --model " + kModel + " --plan " + pn.output + " -o " +
                                   s.output + " --size 2.5 --undermine 4 --force --json");
  ASSERT_EQ(old.code, 0) << old.out;
  EXPECT_NE(old.out.find("--size is now --mesh-size"), std::string::npos) << old.out;
  // Without the meshing pictures (the planner's first answer): the same result, no surface.png
  // or section.png.
  EXPECT_TRUE(fs::exists(fs::path(s.output) / "surface.png"));
  const auto bare = caps_test::caps("simulate --model " + kModel + " --plan " + pn.output +
                                    " -o " + s.output + " --mesh-size 2.5 --undermine 4 "
                                    "--no-mesh-pictures --force -q --json");
  ASSERT_EQ(bare.code, 0) << bare.out;
  EXPECT_EQ(comparable(json::parse(bare.out)), comparable(json::parse(app::to_json(direct))));
  EXPECT_FALSE(fs::exists(fs::path(s.output) / "surface.png"));
  EXPECT_FALSE(fs::exists(fs::path(s.output) / "section.png"));
  EXPECT_TRUE(fs::exists(fs::path(s.output) / "result.vtu"));
}

TEST_F(AppWithModel, TheCliNamesTemplateOptionsAsTyped) {
  const auto r = caps_test::caps("plan new ellipse --model " + kModel +
                                 " --at 0,60 --width 10 --apex-angle 30 -o " +
                                 (kTmp / "both.json").string());
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.out.find("give --width or --apex-angle, not both"), std::string::npos) << r.out;
  EXPECT_FALSE(fs::exists(kTmp / "both.json"));
  const auto range = caps_test::caps("plan new z-plasty --model " + kModel +
                                     " --at 0,60 --angle 20 -o " + (kTmp / "z.json").string());
  EXPECT_EQ(range.code, 2);
  EXPECT_NE(range.out.find("--angle = 20 deg is outside its clinical range"), std::string::npos)
      << range.out;
}

TEST_F(AppWithModel, ACancelledRunStopsAndLeavesNoOutput) {
  app::SimulateRequest s;
  s.model = kModel;
  s.plan = (kTmp / "cancel_plan.json").string();
  s.output = (kTmp / "cancelled").string();
  plan_at("ellipse", "0,60", {{"length", 15}, {"width", 4}}, "cancel_plan.json", kModel, 90);
  RecordingReporter reporter;
  reporter.cancel = true;
  EXPECT_THROW(app::run_simulate(s, &reporter), Cancelled);
  EXPECT_FALSE(fs::exists(s.output));
}

TEST_F(AppWithModel, WarningsReachResultJsonSummaryJsonAndTheReport) {
  // An ellipse low on the phantom's side: the automatic extent (3 x the wound) would leave the
  // valid cells, so the mesher limits it and warns.
  const std::string plan = plan_at("ellipse", "90,-65", {{"length", 15}, {"width", 4}}, "top.json").output;
  const std::string limited = "the extent was limited to";

  app::MeshRequest m;
  m.model = kModel;
  m.plan = plan;
  m.output = (kTmp / "top_mesh").string();
  RecordingReporter reporter;
  const app::MeshResult mesh = app::run_mesh(m, &reporter);
  ASSERT_EQ(mesh.warnings.size(), 1u);
  EXPECT_NE(mesh.warnings[0].find(limited), std::string::npos) << mesh.warnings[0];
  EXPECT_EQ(reporter.warnings(), mesh.warnings);  // the caller heard it too
  EXPECT_LT(mesh.extent_mm, 3 * mesh.wound_size_mm);
  const json summary = json::parse(slurp(kTmp / "top_mesh" / "summary.json"));
  EXPECT_EQ(summary["warnings"], json(mesh.warnings));
  EXPECT_EQ(json::parse(slurp(kTmp / "top_mesh" / "mesh.json"))["warnings"], json(mesh.warnings));

  app::SimulateRequest s;
  s.model = kModel;
  s.plan = plan;
  s.output = (kTmp / "top_sim").string();
  s.domain.domain = "patch";  // the clamped patch's warning (the whole face has none)
  const app::SimulateResult sim = app::run_simulate(s);
  EXPECT_EQ(sim.warnings, mesh.warnings);
  EXPECT_EQ(json::parse(slurp(kTmp / "top_sim" / "result.json"))["warnings"], json(mesh.warnings));

  app::CompareRequest c;
  c.model = kModel;
  c.plan = plan;
  c.output = (kTmp / "top_compare").string();
  c.domain.domain = "patch";  // the whole face (compare's default too) has no such warning
  const app::CompareResult cmp = app::run_compare(c);
  ASSERT_FALSE(cmp.warnings.empty());
  EXPECT_EQ(cmp.warnings[0], "measured: " + mesh.warnings[0]);
  const std::string html = slurp(kTmp / "top_compare" / "report.html");
  EXPECT_NE(html.find("class=\"warnings\""), std::string::npos);
  EXPECT_NE(html.find(limited), std::string::npos);
  EXPECT_EQ(json::parse(slurp(kTmp / "top_compare" / "comparison.json"))["warnings"],
            json(cmp.warnings));
  // Its largest suture is simulate's (the largest force on one suture at the spacing), and the
  // measured layers are compared with the measured thickness as well.
  const json measured = json::parse(slurp(kTmp / "top_compare" / "comparison.json"))["measured"];
  EXPECT_NEAR(measured["max_suture_at_spacing_n"].get<double>(), sim.max_force_per_suture_n,
              1e-9 * sim.max_force_per_suture_n);
  char cell[64];
  std::snprintf(cell, sizeof cell, "</td><td>N</td><td>%.2f</td>", sim.max_force_per_suture_n);
  EXPECT_NE(html.find("largest force on one suture (sutures every 5.0 mm, as caps simulate)" +
                      std::string(cell)),
            std::string::npos);
  // Three columns: the third, the measured tissue layers (or one material where the model has
  // none), has its own folder with the same files and its own pictures.
  const std::string third = cmp.layers_tissue == "measured" ? "measured layers"
                                                            : "one material (no layers)";
  EXPECT_NE(html.find("<th>" + third + "</th>"), std::string::npos);
  EXPECT_NE(html.find("<th>" + third + " vs measured</th>"), std::string::npos);
  EXPECT_NE(html.find("src=\"layers/post_plan.png\""), std::string::npos);
  EXPECT_TRUE(fs::exists(kTmp / "top_compare" / "layers" / "section.png"));
  EXPECT_NEAR(json::parse(slurp(kTmp / "top_compare" / "layers" / "result.json"))
                  ["max_displacement_mm"].get<double>(),
              cmp.layers_max_displacement_mm, 1e-9);
}

TEST_F(AppWithModel, APlanFindsItsCopiedModelAndRefusesAnother) {
  // A plan and its model copied together: the copy is found beside the plan (model_relative),
  // and its content hash matches.
  const fs::path site = kTmp / "site";
  fs::create_directories(site);
  const fs::path model_here = site / "model";
  fs::copy(kModel, model_here, fs::copy_options::recursive);
  const std::string plan = plan_at("ellipse", "0,60", {}, "site/e.json", model_here.string()).output;
  EXPECT_EQ(json::parse(slurp(plan))["model_relative"], "model");
  const fs::path copy = kTmp / "copy";
  fs::create_directories(copy);
  fs::copy(site, copy / "site", fs::copy_options::recursive);
  fs::remove_all(model_here);  // the original model is gone: the copy must be used
  app::PlanCheckRequest check;
  check.plan = (copy / "site" / "e.json").string();
  const app::PlanResult checked = app::run_plan_check(check);
  EXPECT_EQ(checked.procedure, "ellipse");

  // Another model (another grid of the same CT): refused, naming the cause.
  app::FromVolumeRequest fv;
  fv.input = (kTmp / "ct.nii.gz").string();
  fv.output = (kTmp / "other_model").string();
  fv.n_theta = 96;
  fv.n_z = 64;
  app::run_from_volume(fv);
  check.model = fv.output;
  try {
    app::run_plan_check(check);
    ADD_FAILURE() << "a plan was accepted on another model";
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("the plan was made on another model"), std::string::npos)
        << e.what();
  }
  app::SimulateRequest s;
  s.model = fv.output;
  s.plan = check.plan;
  s.output = (kTmp / "never").string();
  EXPECT_THROW(app::run_simulate(s), InvalidInput);
  EXPECT_FALSE(fs::exists(s.output));
}

TEST_F(AppWithModel, AWoundNearTheModelsTopIsMeshedSoThatItCanBeDrawn) {
  // 20 mm below the top of the phantom's grid the automatic extent would reach the last rows,
  // where the renderer cannot stitch the skin: the mesher keeps clear of them (and says so), so
  // the simulation renders instead of failing after the solve.
  const std::string plan = plan_at("ellipse", "90,55", {{"length", 15}, {"width", 4}}, "near_top.json").output;
  app::SimulateRequest s;
  s.model = kModel;
  s.plan = plan;
  s.output = (kTmp / "near_top").string();
  s.domain.domain = "patch";  // the clamped patch's own extent near the top
  s.render = true;
  const app::SimulateResult r = app::run_simulate(s);
  EXPECT_EQ(r.images.size(), 8u);
  ASSERT_EQ(r.warnings.size(), 1u);
  EXPECT_NE(r.warnings[0].find("the extent was limited"), std::string::npos);
  EXPECT_TRUE(fs::exists(kTmp / "near_top" / "post_plan.png"));
}

TEST_F(AppWithModel, AFreeIncisionIsOnePathThroughItsPointsWithNoSutures) {
  auto request = [](const std::string& points, const std::string& points_xyz,
                    const std::string& at) {
    app::PlanNewRequest r;
    r.procedure = app::kFreeIncision;
    r.model = kModel;
    r.points = points;
    r.points_xyz = points_xyz;
    r.at = at;
    r.output = (kTmp / "incision.json").string();
    r.force = true;
    return r;
  };
  auto incision = [&](const std::string& points, const std::string& points_xyz = "") {
    return json::parse(app::to_json(app::run_plan_new(request(points, points_xyz, ""))));
  };
  // Three points along z = 60, theta increasing (towards the patient's left): orientation 90.
  const json h = incision("-10,60; 0,60; 10,61");
  EXPECT_EQ(h["procedure"]["name"], "custom");
  ASSERT_EQ(h["points"].size(), 3u);
  const double theta[] = {-10, 0, 10}, z[] = {60, 60, 61};
  for (int i = 0; i < 3; ++i) {
    EXPECT_DOUBLE_EQ(h["points"][i]["theta_deg"].get<double>(), theta[i]);
    EXPECT_DOUBLE_EQ(h["points"][i]["z_mm"].get<double>(), z[i]);
  }
  EXPECT_EQ(h["paths"], json::parse("[[0, 1, 2]]"));
  EXPECT_TRUE(h["sutures"].empty());
  // The Figure 2 loop 0 1 2 1: four border edges, all left open (a warning).
  EXPECT_EQ(h["border_loop"].size(), 4u);
  ASSERT_FALSE(h["check"]["warnings"].empty());
  EXPECT_NEAR(h["frame"]["theta_deg"].get<double>(), 0.0, 1e-9);
  EXPECT_NEAR(h["frame"]["z_mm"].get<double>(), 181.0 / 3, 1e-9);
  // From the first point to the last: along +theta, tilted up by 1 mm over about 2 x 10 deg.
  const double o = h["frame"]["orientation_deg"].get<double>();
  EXPECT_GT(o, 80.0);
  EXPECT_LT(o, 90.0);
  // Straight along +theta, along -theta, up and down: 90, -90, 0 and 180. Orientation 90 is
  // along constant z exactly; 0 is perpendicular to it on the skin, which a line of constant theta
  // is only where the skin's radius does not change with theta (0.009 deg off here).
  EXPECT_NEAR(incision("-10,60;10,60")["frame"]["orientation_deg"].get<double>(), 90.0, 1e-6);
  EXPECT_NEAR(incision("10,60;-10,60")["frame"]["orientation_deg"].get<double>(), -90.0, 1e-6);
  EXPECT_NEAR(incision("0,50;0,70")["frame"]["orientation_deg"].get<double>(), 0.0, 0.05);
  EXPECT_NEAR(std::abs(incision("0,70;0,50")["frame"]["orientation_deg"].get<double>()), 180.0,
              0.05);
  // The same cut given by LPS points on the skin: the same (theta, z).
  std::string xyz;
  for (const auto& p : h["points"])
    xyz += std::to_string(p["lps"][0].get<double>()) + "," +
           std::to_string(p["lps"][1].get<double>()) + "," +
           std::to_string(p["lps"][2].get<double>()) + ";";
  const json x = incision("", xyz);
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(x["points"][i]["theta_deg"].get<double>(), theta[i], 1e-4);
    EXPECT_NEAR(x["points"][i]["z_mm"].get<double>(), z[i], 1e-4);
  }
  // The command line takes the same request.
  const auto cli = caps_test::caps("plan new incision --model " + kModel +
                                   " --points '-10,60;0,60;10,61' -q --json --force -o " +
                                   (kTmp / "incision_cli.json").string());
  ASSERT_EQ(cli.code, 0) << cli.out;
  EXPECT_EQ(json::parse(cli.out)["points"], h["points"]);
  // Refusals.
  auto message = [&](const std::string& points, const std::string& at) {
    try {
      app::run_plan_new(request(points, "", at));
    } catch (const InvalidInput& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_EQ(message("0,60", ""), "incision: 1 point given; a cut needs at least 2");
  EXPECT_NE(message("0,60;5,60", "0,60").find("drop --at"), std::string::npos);
  EXPECT_NE(message("0,60;five,60", "").find("--points 'five,60'"), std::string::npos);
}

// The lengthening along a plan's axis, worked by hand on a Z-plasty's loop (length 20, 60 deg;
// plan.md: points 0 (0, 17.32), 1 (-10, 0), 2 (10, 0), 3 (0, -17.32); loop 0 1 2 3 4 5 with 4 on
// 2 and 5 on 1), the axis along x: before, 20 mm between the limb's ends. After a closure that
// moves the closed corners 5 to x = -12 and 2 to x = 13 and swings the flap tips 1 and 4 onto
// x = 0 (1 to 3's place, 4 to 0's: 34.6 mm apart, across the axis), the limb is 25 mm: +5 mm,
// +25 %. The same in a tilted frame (the axis turned 30 deg about z, everything shifted).
TEST(AxisLengthening, ZPlastyLoopWorkedByHand) {
  const double h = 20 * std::sin(kPi / 3);
  Eigen::MatrixX3d pre(6, 3), post(6, 3);
  pre << 0, h, 0, -10, 0, 0, 10, 0, 0, 0, -h, 0, 10, 0, 0, -10, 0, 0;
  post << 0.5, h, 0, 0, -h, 0, 13, 0, 0, -0.5, -h, 0, 0, h, 0, -12, 0, 0;
  const app::AxisLengthening l = app::axis_lengthening(pre, post, Eigen::Vector3d::UnitX());
  EXPECT_NEAR(l.before_mm, 20, 1e-12);
  EXPECT_NEAR(l.after_mm, 25, 1e-12);
  EXPECT_NEAR(l.change_mm(), 5, 1e-12);
  EXPECT_NEAR(l.change_percent(), 25, 1e-12);
  const Eigen::Matrix3d R = Eigen::AngleAxisd(kPi / 6, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  const Eigen::RowVector3d shift(3, -4, 7);
  const app::AxisLengthening t = app::axis_lengthening(
      (pre * R.transpose()).rowwise() + shift, (post * R.transpose()).rowwise() + shift,
      R * Eigen::Vector3d::UnitX());
  EXPECT_NEAR(t.before_mm, 20, 1e-9);
  EXPECT_NEAR(t.after_mm, 25, 1e-9);
  EXPECT_THROW(app::axis_lengthening(pre, post.topRows(5), Eigen::Vector3d::UnitX()), InvalidInput);
}

// A simulated Z-plasty lengthens its central limb, by less than the rigid flaps' geometric
// sqrt(5 - 4 cos 60) - 1 = 73 % (tests/test_fem_mesher.cpp); the result JSON carries it.
TEST_F(AppWithModel, AZPlastyReportsTheLengtheningOfItsCentralLimb) {
  app::SimulateRequest s;
  s.model = kModel;
  s.plan = plan_at("z-plasty", "0,60", {{"length", 15}}, "z_lengthening.json", kModel, 90).output;
  s.output = (kTmp / "z_lengthening").string();
  s.meshing.mesh_size = 2.5;
  s.force = true;
  const app::SimulateResult r = app::run_simulate(s);
  EXPECT_NEAR(r.axis_length_before_mm, 15, 0.5);
  EXPECT_NEAR(r.corner_length_before_mm, 15, 0.5);
  const json l = json::parse(app::to_json(r)).at("lengthening");
  EXPECT_GT(l.at("mm").get<double>(), 0.1 * 15);
  EXPECT_LT(l.at("percent").get<double>(), 100 * (std::sqrt(5 - 4 * std::cos(kPi / 3)) - 1));
  EXPECT_NEAR(l.at("mm").get<double>(), r.corner_length_after_mm - r.corner_length_before_mm, 1e-12);
  EXPECT_NEAR(l.at("axis_projection").at("mm").get<double>(),
              r.axis_length_after_mm - r.axis_length_before_mm, 1e-12);
}

// A Z-plasty's gain as surgeons measure it: its central limb corner to corner. The closed
// corners, worked by hand on the loop of the axis test above (quadruples as
// plan::oriented_suture() writes the paper's pairs: 5 and 2 are shared, the corners), moved to
// (-12, -3) and (13, 3): 25.71 mm from 20, +28.6 %, where the axis projection says 25 mm.
TEST(CornerLengthening, ZPlastyLoopWorkedByHand) {
  const double h = 20 * std::sin(kPi / 3);
  Eigen::MatrixX3d pre(6, 3), post(6, 3);
  pre << 0, h, 0, -10, 0, 0, 10, 0, 0, 0, -h, 0, 10, 0, 0, -10, 0, 0;
  post << 0.5, h, 0, 0, -h, 0, 13, 3, 0, -0.5, -h, 0, 0, h, 0, -12, -3, 0;
  const std::vector<std::array<int, 4>> sutures{{5, 0, 5, 4}, {2, 3, 2, 1}, {0, 1, 4, 3}};
  const app::CornerLengthening c = app::corner_lengthening(pre, post, sutures);
  EXPECT_EQ(c.corner_a, 2);
  EXPECT_EQ(c.corner_b, 5);
  EXPECT_NEAR(c.before_mm, 20, 1e-12);
  EXPECT_NEAR(c.after_mm, std::hypot(25.0, 6.0), 1e-12);
  EXPECT_NEAR(app::axis_lengthening(pre, post, Eigen::Vector3d::UnitX()).after_mm, 25, 1e-12);
  // Without two closed corners there is no corner-to-corner length.
  const app::CornerLengthening none = app::corner_lengthening(pre, post, {{0, 1, 4, 3}});
  EXPECT_EQ(none.corner_a, -1);
  EXPECT_EQ(none.before_mm, 0);
}

// The 90 deg Z-plasty's reported gain is its corner-to-corner gain, found here from the files
// alone: the nodes at the plan's points 1 and 2 (one on each lip), the one of each that stays
// (the closed corner; the flap tip swings across), their distance before and after. On
// Cranium's forehead the axis projection said 4.3 % where the corners moved 40.7 % apart.
TEST_F(AppWithModel, A90DegreeZPlastyReportsItsCornerToCornerGain) {
  app::SimulateRequest s;
  s.model = kModel;
  s.plan = plan_at("z-plasty", "0,60", {{"length", 15}, {"angle", 90}}, "z90.json", kModel, 90).output;
  s.output = (kTmp / "z90").string();
  s.meshing.mesh_size = 2.5;
  // What is checked here is that the report reads the corners of the whole face's mesh as the
  // files hold them, for any material: the linear closure takes 3 s, the finite-strain one of a
  // 90 degree Z-plasty 50 s (docs/benchmarks.md, "Build and test time").
  s.solver.material = "linear";
  s.force = true;
  const app::SimulateResult r = app::run_simulate(s);
  const json l = json::parse(app::to_json(r)).at("lengthening");
  const plan::Plan p = plan::read_plan(s.plan);
  const fem::Mesh m = fem::read_mesh_dir(s.output);
  const Eigen::MatrixX3d u = fem::read_result_displacement(s.output, m.n_nodes());
  auto corner = [&](int point, bool after) -> Eigen::Vector3d {
    int best = -1, near = 0;
    for (Eigen::Index n = 0; n < m.n_nodes(); ++n)
      if ((m.nodes.row(n).transpose() - p.points[point].lps).norm() < 0.05) {
        ++near;
        if (best < 0 || u.row(n).norm() < u.row(best).norm()) best = static_cast<int>(n);
      }
    EXPECT_EQ(near, 2) << "point " << point;
    const Eigen::RowVector3d x = m.nodes.row(best) + (after ? 1.0 : 0.0) * u.row(best);
    return x.transpose();
  };
  const double before = (corner(2, false) - corner(1, false)).norm();
  const double after = (corner(2, true) - corner(1, true)).norm();
  std::printf("90 deg Z-plasty: corners %.2f -> %.2f mm (%+.1f %%), axis projection %+.1f %%\n",
              before, after, 100 * (after / before - 1),
              l.at("axis_projection").at("percent").get<double>());
  EXPECT_NEAR(l.at("before_mm").get<double>(), before, 1e-9);
  EXPECT_NEAR(l.at("after_mm").get<double>(), after, 1e-9);
  EXPECT_NEAR(l.at("percent").get<double>(), 100 * (after / before - 1), 1e-6);
  EXPECT_EQ(l.at("corners"), json::array({2, 5}));
}
