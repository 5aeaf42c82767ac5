// The planner's server (server/), run in-process on a free loopback port and driven by httplib's
// client: a plan made and simulated through the API equals app::'s and the caps program's result
// for the same inputs; bad requests (path traversal, an oversized body, malformed JSON, a wrong
// field type) each get their 4xx with the CLI's message and the server keeps serving; a newer
// simulation cancels an older one (409); the landmarks are the CLI's and a plan placed at one is
// the CLI's plan.
#include <gtest/gtest.h>

#include "caps/app/loaded_model.hpp"
#include "caps/app/model.hpp"
#include "caps/app/plan.hpp"
#include "caps/app/simulation.hpp"
#include "caps/app/suggest.hpp"
#include "caps/core/error.hpp"
#include "caps/server/planner_server.hpp"
#include "caps/server/serve.hpp"
#include "caps/surface/patient_model.hpp"
#include "cli_run.hpp"
#include "phantom_model.hpp"
#include "../server/src/page_words.hpp"  // the page's words, tested directly
#include "../server/src/skin_views.hpp"  // the skin's glTF, written directly to compare
#include "caps/render/drawn_skin.hpp"

#include <httplib.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <array>
#include <cstring>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <mutex>
#include <sstream>
#include <set>
#include <string>
#include <thread>

namespace fs = std::filesystem;
using namespace caps;
using nlohmann::json;

namespace {

const fs::path kTmp = fs::temp_directory_path() / "caps_test_server";
const std::string kModel = (kTmp / "model").string();

using caps_test::slurp;

// Records warnings; once armed, holds the first progress report until released, so that a test
// can send a second request while the first simulation is surely running.
class HoldingReporter : public Reporter {
 public:
  void arm() {
    std::lock_guard<std::mutex> lock(m_);
    armed_ = true;
    started_ = released_ = false;
  }
  bool wait_started() {
    std::unique_lock<std::mutex> lock(m_);
    return cv_.wait_for(lock, std::chrono::seconds(60), [this] { return started_; });
  }
  void release() {
    std::lock_guard<std::mutex> lock(m_);
    released_ = true;
    cv_.notify_all();
  }

 protected:
  void on_progress(const std::string&, double) override {
    std::unique_lock<std::mutex> lock(m_);
    if (!armed_) return;
    armed_ = false;
    started_ = true;
    cv_.notify_all();
    cv_.wait_for(lock, std::chrono::seconds(60), [this] { return released_; });
  }

 private:
  std::mutex m_;
  std::condition_variable cv_;
  bool armed_ = false, started_ = false, released_ = false;
};

class ServerTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    fs::remove_all(kTmp);
    fs::create_directories(kTmp / "web");
    caps_test::make_phantom_model(kTmp, kModel);
    std::ofstream(kTmp / "web" / "index.html") << "<!doctype html><title>planner</title>";
    std::ofstream(kTmp / "web" / "app.js") << "export const planner = 1;\n";
    std::ofstream(kTmp / "secret.txt") << "not to be served";

    server::ServerOptions o;
    o.model_dir = kModel;
    o.port = 0;
    o.web_root = (kTmp / "web").string();
    reporter_ = std::make_unique<HoldingReporter>();
    server_ = std::make_unique<server::PlannerServer>(o, reporter_.get());
    server_->bind();
    thread_ = std::thread([] { server_->listen(); });
  }
  static void TearDownTestSuite() {
    server_->stop();
    thread_.join();
    server_.reset();
  }

  static httplib::Client client() {
    httplib::Client c("127.0.0.1", server_->port());
    c.set_read_timeout(300, 0);
    c.set_url_encode(false);  // send the paths exactly as written
    c.set_default_headers({{server::kTokenHeader, server_->token()}});  // as the page does
    return c;
  }
  static httplib::Result post(const std::string& path, const std::string& body) {
    return client().Post(path.c_str(), body, "application/json");
  }
  static httplib::Result get(const std::string& path) { return client().Get(path.c_str()); }
  // POST /api/simulate of a plan (its JSON text) with a 2.5 mm mesh.
  static httplib::Result simulate_coarse(const std::string& plan) {
    return post("/api/simulate",
                json{{"plan", json::parse(plan)}, {"options", {{"mesh_size", 2.5}}}}.dump());
  }

  // The server still answers a good request after a bad one.
  static void expect_still_serving() {
    const auto r = get("/api/templates");
    ASSERT_TRUE(r);
    EXPECT_EQ(r->status, 200);
    EXPECT_EQ(json::parse(r->body), json::parse(app::to_json(app::run_templates({}))));
  }

  static std::string error_of(const httplib::Result& r) {
    return json::parse(r->body).at("error").get<std::string>();
  }

  static inline std::unique_ptr<HoldingReporter> reporter_;
  static inline std::unique_ptr<server::PlannerServer> server_;
  static inline std::thread thread_;
};

json plan_body() {
  return {{"procedure", "v-y-advancement"},
          {"at", "0,60"},
          {"orientation", 90},
          {"parameters", {{"length", 12}, {"advance", 3}}}};
}

// The message of the caps error `run` throws ("" if none).
template <class F>
std::string message_of(F&& run) {
  try {
    run();
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

double norm3(const json& v) {
  return std::sqrt(v[0].get<double>() * v[0].get<double>() + v[1].get<double>() * v[1].get<double>() +
                   v[2].get<double>() * v[2].get<double>());
}

json comparable(json j) {
  for (const char* k : {"output", "timings_s", "result_id", "result_url"}) j.erase(k);
  return j;
}

}  // namespace

TEST(ServerDefaults, BindsLoopbackUnlessToldOtherwise) {
  EXPECT_EQ(std::string(server::kDefaultHost), "127.0.0.1");
  EXPECT_EQ(server::ServerOptions{}.host, "127.0.0.1");
  EXPECT_EQ(server::ServeRequest{}.host, "127.0.0.1");
  EXPECT_EQ(server::kMaxBodyBytes, 1u << 20);
  EXPECT_TRUE(server::is_loopback("127.0.0.1"));
  EXPECT_TRUE(server::is_loopback("::1"));
  EXPECT_TRUE(server::is_loopback("localhost"));
  EXPECT_FALSE(server::is_loopback("0.0.0.0"));
  EXPECT_FALSE(server::is_loopback("192.168.1.5"));
}

TEST(ServerErrors, EachErrorKindHasItsStatusAndKeepsItsMessage) {
  EXPECT_EQ(server::error_response(InvalidInput("bad value")).status, 400);
  EXPECT_EQ(server::error_response(InvalidInput("bad value")).message, "bad value");
  EXPECT_EQ(server::error_response(IoError("x.json: cannot read")).status, 400);
  const auto named = server::error_response(InvalidParameter("give {apex_angle} or {width}"));
  EXPECT_EQ(named.status, 400);
  EXPECT_EQ(named.message, "give apex_angle or width");  // the JSON keys
  EXPECT_EQ(server::error_response(Cancelled("cancelled by the caller")).status, 409);
  const SolverError solver("singular stiffness", 3, 0, 1);
  EXPECT_EQ(server::error_response(solver).status, 422);
  EXPECT_EQ(server::error_response(solver).message, solver.what());
  EXPECT_EQ(server::error_response(Error("internal")).status, 500);
  EXPECT_EQ(server::error_response(std::runtime_error("other")).status, 500);
}

TEST_F(ServerTest, ListensOnLoopbackAndWarnsForAnotherAddress) {
  EXPECT_GT(server_->port(), 0);
  EXPECT_EQ(server_->url(), "http://127.0.0.1:" + std::to_string(server_->port()) + "/");
  Reporter reporter;
  server::ServerOptions o;
  o.model_dir = kModel;
  o.port = 0;
  server::PlannerServer quiet(o, &reporter);
  quiet.bind();
  EXPECT_TRUE(reporter.warnings().empty());
  o.host = "0.0.0.0";
  server::PlannerServer open(o, &reporter);
  open.bind();
  ASSERT_EQ(reporter.warnings().size(), 1u);
  EXPECT_NE(reporter.warnings()[0].find("0.0.0.0"), std::string::npos);
}

TEST_F(ServerTest, AMissingModelIsRefusedWithTheCliMessage) {
  server::ServerOptions o;
  o.model_dir = (kTmp / "nowhere").string();
  const std::string cli_message = message_of([&] { PatientModel::load(o.model_dir); });
  ASSERT_FALSE(cli_message.empty());
  EXPECT_EQ(message_of([&] { server::PlannerServer refused(o); }), cli_message);
}

TEST_F(ServerTest, ServesTheModelTemplatesAndStaticFilesWithTheirTypes) {
  const auto model = get("/api/model");
  ASSERT_TRUE(model);
  EXPECT_EQ(model->status, 200);
  EXPECT_EQ(model->get_header_value("Content-Type"), "application/json");
  EXPECT_EQ(json::parse(model->body), json::parse(slurp(fs::path(kModel) / "model.json")));
  const auto skin = get("/api/model/skin.ply");
  ASSERT_TRUE(skin);
  EXPECT_EQ(skin->status, 200);
  EXPECT_EQ(skin->body, slurp(fs::path(kModel) / "skin.ply"));
  expect_still_serving();
  const auto index = get("/");
  ASSERT_TRUE(index);
  EXPECT_EQ(index->status, 200);
  EXPECT_EQ(index->get_header_value("Content-Type"), "text/html; charset=utf-8");
  EXPECT_NE(index->body.find("planner"), std::string::npos);
  const auto js = get("/app.js");
  ASSERT_TRUE(js);
  EXPECT_EQ(js->status, 200);
  EXPECT_EQ(js->get_header_value("Content-Type"), "text/javascript; charset=utf-8");
  const auto none = get("/nothing.js");
  ASSERT_TRUE(none);
  EXPECT_EQ(none->status, 404);
  EXPECT_NE(error_of(none).find("no such file"), std::string::npos);
}

TEST_F(ServerTest, NoPathOutsideTheWebRootIsServed) {
  for (const std::string path :
       {"/../../etc/passwd", "/%2e%2e/%2e%2e/etc/passwd", "/..%2f..%2fsecret.txt", "/../secret.txt",
        "/%2E%2E/secret.txt", "/api/model/../../secret.txt", "/api/model/%2e%2e/secret.txt",
        "/api/results/1/..%2f..%2f..%2f..%2fetc%2fpasswd"}) {
    const auto r = get(path);
    ASSERT_TRUE(r) << path;
    EXPECT_EQ(r->status, 403) << path;
    EXPECT_NE(error_of(r).find("leaves the served folder"), std::string::npos) << path;
    EXPECT_EQ(r->body.find("root:"), std::string::npos) << path;
    EXPECT_EQ(r->body.find("not to be served"), std::string::npos) << path;
    expect_still_serving();
  }
  // A symbolic link out of the root is refused too.
  fs::create_symlink(kTmp / "secret.txt", kTmp / "web" / "link.txt");
  const auto link = get("/link.txt");
  ASSERT_TRUE(link);
  EXPECT_EQ(link->status, 403);
  EXPECT_EQ(link->body.find("not to be served"), std::string::npos);
  expect_still_serving();
}

TEST_F(ServerTest, BadRequestsGetTheirStatusAndTheCliMessage) {
  // Oversized body: 413, before anything is parsed.
  const auto big = post("/api/plan/check", std::string(server::kMaxBodyBytes + 1, ' '));
  ASSERT_TRUE(big);
  EXPECT_EQ(big->status, 413);
  EXPECT_NE(error_of(big).find("larger than"), std::string::npos);
  expect_still_serving();

  // Malformed JSON: 400.
  for (const char* path : {"/api/plan/new", "/api/plan/check", "/api/simulate"}) {
    const auto bad = post(path, R"({"procedure": )");
    ASSERT_TRUE(bad);
    EXPECT_EQ(bad->status, 400) << path;
    EXPECT_NE(error_of(bad).find("not valid JSON"), std::string::npos) << bad->body;
    expect_still_serving();
  }

  // A wrong field type: 400 naming the key, as the JSON request reader of the CLI does.
  json wrong = plan_body();
  wrong["orientation"] = "ninety";
  const auto typed = post("/api/plan/new", wrong.dump());
  ASSERT_TRUE(typed);
  EXPECT_EQ(typed->status, 400);
  EXPECT_EQ(error_of(typed), "plan new request: \"orientation\" must be a number, not \"ninety\"");
  expect_still_serving();
  const auto sim_typed = post("/api/simulate", R"({"plan": {}, "options": {"layers": "two"}})");
  ASSERT_TRUE(sim_typed);
  EXPECT_EQ(sim_typed->status, 400);
  EXPECT_NE(error_of(sim_typed).find("\"layers\" must be a whole number"), std::string::npos);

  // The server's own keys are refused.
  json with_model = plan_body();
  with_model["model"] = "/etc";
  const auto own = post("/api/plan/new", with_model.dump());
  ASSERT_TRUE(own);
  EXPECT_EQ(own->status, 400);
  EXPECT_NE(error_of(own).find("\"model\" is set by the server"), std::string::npos);

  // No file named in a request is opened.
  const auto file = post("/api/plan/new", R"({"procedure": "/etc/passwd.json", "at": "0,60"})");
  ASSERT_TRUE(file);
  EXPECT_EQ(file->status, 400);
  EXPECT_NE(error_of(file).find("the server opens no procedure files"), std::string::npos);

  // A parameter outside its clinical range: the app's own message (the CLI's, keys as in JSON).
  json range = {{"procedure", "z-plasty"}, {"at", "0,60"}, {"parameters", {{"angle", 20}}}};
  app::PlanNewRequest pn;
  pn.procedure = "z-plasty";
  pn.model = kModel;
  pn.at = "0,60";
  pn.parameters = {{"angle", 20}};
  pn.output = (kTmp / "refused.json").string();
  const std::string app_message = message_of([&] { app::run_plan_new(pn); });
  ASSERT_FALSE(app_message.empty());
  const auto refused = post("/api/plan/new", range.dump());
  ASSERT_TRUE(refused);
  EXPECT_EQ(refused->status, 400);
  EXPECT_EQ(error_of(refused), app_message);

  // A plan that cannot be checked: the message of caps plan check on the same file.
  const std::string broken = R"({"format": "caps-plan", "points": "none"})";
  std::ofstream(kTmp / "broken.json") << broken;
  app::PlanCheckRequest pc;
  pc.plan = (kTmp / "broken.json").string();
  pc.model = kModel;
  const std::string check_message = message_of([&] { app::run_plan_check(pc); });
  ASSERT_FALSE(check_message.empty());
  const auto check = post("/api/plan/check", broken);
  ASSERT_TRUE(check);
  EXPECT_EQ(check->status, 400);
  // The same message, naming the server's copy of the body instead of the user's file.
  const std::string got = error_of(check);
  EXPECT_EQ(got.substr(got.find(".json") + 5),
            check_message.substr(check_message.find(".json") + 5));

  // No such route.
  const auto route = post("/api/nothing", "{}");
  ASSERT_TRUE(route);
  EXPECT_EQ(route->status, 404);
  EXPECT_NE(error_of(route).find("no such route"), std::string::npos);
  expect_still_serving();
}

TEST_F(ServerTest, APlanCheckRefusalIsTheCliMessageWithoutTheServersPaths) {
  // The message `caps plan check plan.json` prints in the plan's folder, for a broken file and for
  // a plan the model cannot take (a point below the model's z range).
  const fs::path dir = kTmp / "cli-check";
  fs::create_directories(dir);
  json made = json::parse(post("/api/plan/new", plan_body().dump())->body);
  json off_model = made;
  for (auto& p : off_model["points"]) p["z_mm"] = -500.0;
  for (const std::string& body :
       {std::string(R"({"format": "caps-plan", "points": "none"})"), off_model.dump()}) {
    for (const std::string& name : {std::string("plan.json"), std::string("my-z.json")}) {
      std::ofstream(dir / name) << body;
      app::PlanCheckRequest pc;
      pc.plan = (dir / name).string();
      pc.model = kModel;
      std::string cli = message_of([&] { app::run_plan_check(pc); });
      ASSERT_FALSE(cli.empty());
      for (std::size_t at; (at = cli.find(dir.string() + "/")) != std::string::npos;)
        cli.erase(at, dir.string().size() + 1);
      const auto r =
          post(name == "plan.json" ? "/api/plan/check" : "/api/plan/check?name=" + name, body);
      ASSERT_TRUE(r);
      EXPECT_EQ(r->status, 400);
      const std::string got = error_of(r);
      EXPECT_EQ(got, cli);
      EXPECT_EQ(got.find(server_->work_dir().string()), std::string::npos) << got;
      EXPECT_EQ(got.find("caps-serve-"), std::string::npos) << got;
    }
  }
  // A name that is not a plain file name is not used.
  const auto r = post("/api/plan/check?name=../../etc/passwd", R"({"points": 1})");
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 400);
  EXPECT_EQ(error_of(r).rfind("plan.json", 0), 0u) << error_of(r);
  expect_still_serving();
}

TEST_F(ServerTest, APlanMadeAndSimulatedThroughTheApiEqualsTheAppResult) {
  // plan new through the API and through app:: with the same inputs.
  const auto planned = post("/api/plan/new", plan_body().dump());
  ASSERT_TRUE(planned);
  ASSERT_EQ(planned->status, 200) << planned->body;
  const json plan = json::parse(planned->body);
  app::PlanNewRequest pn;
  pn.procedure = "v-y-advancement";
  pn.model = kModel;
  pn.at = "0,60";
  pn.orientation = 90;
  pn.parameters = {{"length", 12}, {"advance", 3}};
  pn.output = (kTmp / "vy.json").string();
  pn.force = true;
  EXPECT_EQ(plan, json::parse(app::to_json(app::run_plan_new(pn))));
  EXPECT_EQ(plan.at("ok"), true);

  // plan check of the plan the API returned.
  const auto checked = post("/api/plan/check", planned->body);
  ASSERT_TRUE(checked);
  ASSERT_EQ(checked->status, 200) << checked->body;
  EXPECT_EQ(json::parse(checked->body).at("ok"), true);

  // simulate through the API and through app:: with the same options.
  const json body = {{"plan", plan}, {"options", {{"mesh_size", 2.5}, {"undermine", 4}}}};
  const auto simulated = post("/api/simulate", body.dump());
  ASSERT_TRUE(simulated);
  ASSERT_EQ(simulated->status, 200) << simulated->body;
  const json api = json::parse(simulated->body);
  app::SimulateRequest s;
  s.model = kModel;
  s.plan = pn.output;
  s.output = (kTmp / "vy_sim").string();
  s.force = true;
  s.meshing.mesh_size = 2.5;
  s.meshing.undermine = 4;
  const app::SimulateResult direct = app::run_simulate(s);
  ASSERT_GT(direct.closing_force_n, 0);
  EXPECT_NEAR(api.at("closing_force_n").get<double>(), direct.closing_force_n,
              1e-9 * direct.closing_force_n);
  EXPECT_EQ(comparable(api), comparable(json::parse(app::to_json(direct))));
  // ... and through the caps program, on the plan file the API returned.
  const fs::path api_plan = kTmp / "vy_api.json";
  std::ofstream(api_plan) << planned->body;
  const auto cli = caps_test::caps("simulate --model " + kModel + " --plan " + api_plan.string() +
                                   " -o " + (kTmp / "vy_cli").string() +
                                   " --mesh-size 2.5 --undermine 4 --force -q --json");
  ASSERT_EQ(cli.code, 0) << cli.out;
  const json typed = json::parse(cli.out);
  EXPECT_NEAR(api.at("closing_force_n").get<double>(), typed.at("closing_force_n").get<double>(),
              1e-9 * direct.closing_force_n);
  EXPECT_EQ(comparable(api), comparable(typed));

  // The result's files are served from the server's work folder.
  const std::string url = api.at("result_url");
  const auto result = get(url + "result.json");
  ASSERT_TRUE(result);
  EXPECT_EQ(result->status, 200);
  EXPECT_EQ(result->get_header_value("Content-Type"), "application/json");
  EXPECT_EQ(json::parse(result->body),
            json::parse(slurp(fs::path(api.at("output").get<std::string>()) / "result.json")));
  const auto vtu = get(url + "result.vtu");
  ASSERT_TRUE(vtu);
  EXPECT_EQ(vtu->status, 200);
  EXPECT_TRUE(fs::path(api.at("output").get<std::string>())
                  .string()
                  .rfind(server_->work_dir().string(), 0) == 0);
}

// The first answer (docs/planner.md): asked for, a finite-strain simulation is preceded by the
// linear closure of the same plan on the clamped patch, a result of its own that /api/progress carries while the
// finite-strain one runs and keeps when that one stops at its time limit.
TEST_F(ServerTest, AFiniteStrainSimulationGivesTheLinearAnswerFirstAndKeepsItWhenItStops) {
  const auto planned = post("/api/plan/new", plan_body().dump());
  ASSERT_TRUE(planned);
  ASSERT_EQ(planned->status, 200);
  const json plan = json::parse(planned->body);
  const auto wrong = post("/api/simulate", json{{"plan", plan}, {"first_answer", "yes"}}.dump());
  ASSERT_TRUE(wrong);
  EXPECT_EQ(wrong->status, 400);
  EXPECT_NE(error_of(wrong).find("first_answer"), std::string::npos) << wrong->body;

  const json body = {{"plan", plan}, {"options", {{"mesh_size", 2.5}}}, {"first_answer", true}};
  const auto simulated = post("/api/simulate", body.dump());
  ASSERT_TRUE(simulated);
  ASSERT_EQ(simulated->status, 200) << simulated->body;
  const json final_answer = json::parse(simulated->body);
  EXPECT_EQ(final_answer.at("material"), "neo-hookean");
  const int first_id = final_answer.at("first_answer_id").get<int>();
  EXPECT_NE(first_id, final_answer.at("result_id").get<int>());
  EXPECT_GT(final_answer.at("timings_s").at("first_answer").get<double>(), 0);
  EXPECT_LT(final_answer.at("timings_s").at("first_answer").get<double>(),
            final_answer.at("timings_s").at("simulate").get<double>());
  // The first answer is on the progress board: the linear closure on the clamped patch, as caps
  // simulate gives it.
  const json first = json::parse(get("/api/progress")->body).at("first_answer");
  EXPECT_EQ(first.at("result_id").get<int>(), first_id);
  EXPECT_EQ(first.at("material"), "linear");
  const fs::path plan_file = kTmp / "first_answer_plan.json";
  std::ofstream(plan_file) << planned->body;
  const auto cli = caps_test::caps("simulate --model " + kModel + " --plan " + plan_file.string() +
                                   " -o " + (kTmp / "first_answer_linear").string() +
                                   " --mesh-size 2.5 --material linear --domain patch --force -q --json");
  ASSERT_EQ(cli.code, 0) << cli.out;
  const json linear = json::parse(cli.out);
  EXPECT_NEAR(first.at("closing_force_n").get<double>(), linear.at("closing_force_n").get<double>(),
              1e-9 * linear.at("closing_force_n").get<double>());
  EXPECT_EQ(comparable(first), comparable(linear));
  EXPECT_GT(std::abs(final_answer.at("closing_force_n").get<double>() -
                     first.at("closing_force_n").get<double>()), 1e-6);
  const auto view = get(cat("/api/results/", first_id, "/view"));
  ASSERT_TRUE(view);
  EXPECT_EQ(view->status, 200);

  // A finite-strain closure that runs out of its time limit is answered 422 saying so; the first
  // answer, a new one, stays on the board with its view.
  json limited = body;
  limited["options"]["time_limit"] = 1e-6;
  const auto stopped = post("/api/simulate", limited.dump());
  ASSERT_TRUE(stopped);
  EXPECT_EQ(stopped->status, 422) << stopped->body;
  EXPECT_NE(error_of(stopped).find("time limit"), std::string::npos) << stopped->body;
  const json kept = json::parse(get("/api/progress")->body);
  EXPECT_EQ(kept.at("running"), false);
  const int kept_id = kept.at("first_answer").at("result_id").get<int>();
  EXPECT_GT(kept_id, first_id);
  EXPECT_EQ(kept.at("first_answer").at("closing_force_n"), first.at("closing_force_n"));
  EXPECT_EQ(get(cat("/api/results/", kept_id, "/view"))->status, 200);
  // The next request clears it as soon as it arrives, even one refused at once (the page polls
  // the board while its request waits).
  const auto refused = post("/api/simulate", json{{"plan", plan}, {"options", {{"steps", "ten"}}},
                                                  {"first_answer", true}}.dump());
  ASSERT_TRUE(refused);
  EXPECT_EQ(refused->status, 400);
  EXPECT_FALSE(json::parse(get("/api/progress")->body).contains("first_answer"));
  // A linear simulation has no first answer.
  const auto plain = post("/api/simulate",
                          json{{"plan", plan}, {"options", {{"mesh_size", 2.5}, {"material", "linear"}}},
                               {"first_answer", true}}.dump());
  ASSERT_TRUE(plain);
  ASSERT_EQ(plain->status, 200);
  EXPECT_FALSE(json::parse(plain->body).contains("first_answer_id"));
  EXPECT_FALSE(json::parse(get("/api/progress")->body).contains("first_answer"));
}

TEST_F(ServerTest, ANewerSimulationCancelsTheOlderOne) {
  const auto planned = post("/api/plan/new", plan_body().dump());
  ASSERT_TRUE(planned);
  ASSERT_EQ(planned->status, 200);
  const std::string body =
      json{{"plan", json::parse(planned->body)}, {"options", {{"mesh_size", 2.5}}}}.dump();
  reporter_->arm();
  int first_status = 0, second_status = 0;
  std::string first_body;
  std::thread first([&] {
    const auto r = post("/api/simulate", body);
    first_status = r ? r->status : -1;
    first_body = r ? r->body : "";
  });
  ASSERT_TRUE(reporter_->wait_started());
  std::thread second([&] {
    const auto r = post("/api/simulate", body);
    second_status = r ? r->status : -1;
  });
  // The second request is taken as soon as it arrives; then the first may go on (and stop).
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  reporter_->release();
  first.join();
  second.join();
  EXPECT_EQ(first_status, 409);
  EXPECT_NE(first_body.find("cancelled by a newer simulate request"), std::string::npos);
  EXPECT_EQ(second_status, 200);
  expect_still_serving();
}

// POST /api/suggest (the page's Suggest): caps plan suggest for a lesion on the served model, its
// answer suggestions.json as the verb writes it, the polar plot and each design's plan served
// from the result's folder; the server's own keys and a bad lesion are refused with the CLI's
// words, and a newer simulation cancels a running suggestion.
TEST_F(ServerTest, SuggestsClosuresForALesionAndServesTheirPlansAndPlot) {
  const json request{{"at", "0,40"}, {"diameter", 4},       {"margin", 1}, {"step", 45},
                     {"refine", 0},  {"material", "linear"}, {"extent", 8}};
  const auto r = post("/api/suggest", request.dump());
  ASSERT_TRUE(r);
  ASSERT_EQ(r->status, 200) << r->body;
  const json j = json::parse(r->body);
  ASSERT_EQ(j.at("designs").size(), 4u);  // 0, 45, 90, 135 deg
  const std::string url = j.at("result_url").get<std::string>();
  // The answer is the suggestions.json the verb wrote, with where to find its files.
  const auto written = get(url + "suggestions.json");
  ASSERT_TRUE(written);
  ASSERT_EQ(written->status, 200);
  EXPECT_EQ(json::parse(written->body).at("designs"), j.at("designs"));
  // Ranked least force on one suture first.
  double last = 0;
  for (const json& d : j.at("designs")) {
    ASSERT_FALSE(d.contains("refused")) << d.dump();
    EXPECT_EQ(d.at("rank").get<int>(), &d - &j.at("designs")[0] + 1);
    EXPECT_GE(d.at("objective").get<double>(), last);
    last = d.at("objective").get<double>();
    // Each design's plan, as the page opens it.
    const auto plan = get(url + d.at("plan").get<std::string>());
    ASSERT_TRUE(plan);
    ASSERT_EQ(plan->status, 200);
    EXPECT_EQ(json::parse(plan->body).at("procedure").at("name"), "ellipse");
  }
  const auto plot = get(url + "suggestions.png");
  ASSERT_TRUE(plot);
  ASSERT_EQ(plot->status, 200);
  EXPECT_EQ(plot->get_header_value("Content-Type"), "image/png");
  EXPECT_EQ(plot->body.substr(1, 3), "PNG");

  const auto own = post("/api/suggest", json{{"at", "0,40"}, {"diameter", 4}, {"output", "x"}}.dump());
  ASSERT_TRUE(own);
  EXPECT_EQ(own->status, 400);
  EXPECT_NE(error_of(own).find("\"output\" is set by the server"), std::string::npos) << own->body;
  const auto no_lesion = post("/api/suggest", json{{"at", "0,40"}, {"diameter", 0}}.dump());
  ASSERT_TRUE(no_lesion);
  EXPECT_EQ(no_lesion->status, 400);
  EXPECT_EQ(error_of(no_lesion),
            message_of([] {
              app::SuggestRequest s;
              s.model = kModel;
              s.at = "0,40";
              s.output = (kTmp / "not-written").string();
              app::run_plan_suggest(s);
            }));
  EXPECT_FALSE(fs::exists(kTmp / "not-written"));

  // A newer simulation cancels a running suggestion (409), as it cancels an older simulation.
  const auto planned = post("/api/plan/new", plan_body().dump());
  ASSERT_TRUE(planned);
  ASSERT_EQ(planned->status, 200);
  reporter_->arm();
  int suggest_status = 0, simulate_status = 0;
  std::thread first([&] {
    const auto s = post("/api/suggest", request.dump());
    suggest_status = s ? s->status : -1;
  });
  ASSERT_TRUE(reporter_->wait_started());
  std::thread second([&] {
    const auto s = simulate_coarse(planned->body);
    simulate_status = s ? s->status : -1;
  });
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  reporter_->release();
  first.join();
  second.join();
  EXPECT_EQ(suggest_status, 409);
  EXPECT_EQ(simulate_status, 200);
  expect_still_serving();
}

TEST_F(ServerTest, WithoutAWebRootServesThePlaceholderPageOnly) {
  server::ServerOptions o;
  o.model_dir = kModel;
  o.port = 0;
  server::PlannerServer placeholder(o);
  EXPECT_EQ(placeholder.web_root(), server::default_web_root());
  placeholder.bind();
  std::thread t([&] { placeholder.listen(); });
  httplib::Client c("127.0.0.1", placeholder.port());
  const auto index = c.Get("/");
  const auto other = c.Get("/README.md");
  placeholder.stop();
  t.join();
  ASSERT_TRUE(index);
  EXPECT_EQ(index->status, 200);
  EXPECT_EQ(index->get_header_value("Content-Type"), "text/html; charset=utf-8");
  if (server::default_web_root().filename() != "dist")  // the placeholder, not a built page
    EXPECT_NE(index->body.find("/api/simulate"), std::string::npos);  // the API is listed
  ASSERT_TRUE(other);
  EXPECT_EQ(other->status, 404);
}

TEST_F(ServerTest, ServesTheSkinAsGlbWithColourAndThickness) {
  const auto info = get("/api/skin");
  ASSERT_TRUE(info);
  ASSERT_EQ(info->status, 200) << info->body;
  const json j = json::parse(info->body);
  // The range mesh of the 128 x 64 grid: a vertex per sample and the two poles; two triangles per
  // cell around (the seam closed) over 63 rows, and a fan of 128 at each pole.
  for (const char* k : {"skin", "thickness"}) {
    EXPECT_EQ(j.at(k).at("vertices"), 128 * 64 + 2) << k;
    EXPECT_EQ(j.at(k).at("faces"), 2 * 128 * 63 + 2 * 128) << k;
  }
  EXPECT_EQ(j.at("skin").at("has_color"), false);  // a CT: a plain skin tone
  const double top = j.at("thickness").at("scale_max_mm");
  // The phantom's soft tissue is a few mm to about a centimetre thick.
  EXPECT_GT(top, 3.0);
  EXPECT_LT(top, 20.0);
  std::size_t size = 0;
  for (const char* k : {"skin", "thickness"}) {
    const auto glb = get(j.at(k).at("url").get<std::string>());
    ASSERT_TRUE(glb);
    ASSERT_EQ(glb->status, 200);
    EXPECT_EQ(glb->get_header_value("Content-Type"), "model/gltf-binary");
    EXPECT_EQ(glb->body.substr(0, 4), "glTF");  // the binary glTF magic
    if (size) EXPECT_EQ(glb->body.size(), size);  // the same mesh, other colours
    size = glb->body.size();
  }
  const auto other = get("/api/skin/bone.glb");
  ASSERT_TRUE(other);
  EXPECT_EQ(other->status, 404);
  // The skin is the drawn skin's range (slice terraces filtered, resampled from the skin
  // isosurface), as caps render draws it: byte for byte the file written from it, not the one
  // written from the model's range as measured.
  const auto served = get(j.at("skin").at("url").get<std::string>());
  ASSERT_TRUE(served);
  const std::shared_ptr<const PatientModel> model = app::loaded_model(kModel);
  const render::DrawnSkin drawn = render::load_drawn_skin(*model, kModel);
  const fs::path drawn_glb = fs::path(kTmp) / "drawn_skin.glb", raw_glb = fs::path(kTmp) / "raw_skin.glb";
  (void)server::detail::write_model_skin_glb(drawn.range, server::detail::SkinColouring::Skin, drawn_glb);
  (void)server::detail::write_model_skin_glb(*model, server::detail::SkinColouring::Skin, raw_glb);
  const auto bytes = [](const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), {});
  };
  EXPECT_EQ(served->body, bytes(drawn_glb));
  EXPECT_NE(served->body, bytes(raw_glb));
  expect_still_serving();
}

TEST_F(ServerTest, PlanLinesFollowThePlanOnTheSkin) {
  const auto planned = post("/api/plan/new", plan_body().dump());
  ASSERT_TRUE(planned);
  ASSERT_EQ(planned->status, 200) << planned->body;
  const json plan = json::parse(planned->body);
  const auto lines = post("/api/plan/lines", planned->body);
  ASSERT_TRUE(lines);
  ASSERT_EQ(lines->status, 200) << lines->body;
  const json l = json::parse(lines->body);
  // One skin point per plan point, at the plan file's own LPS point.
  ASSERT_EQ(l.at("points_lps").size(), plan.at("points").size());
  for (std::size_t i = 0; i < plan.at("points").size(); ++i)
    for (int c = 0; c < 3; ++c)
      EXPECT_NEAR(l["points_lps"][i][c].get<double>(),
                  plan["points"][i]["lps"][c].get<double>(), 1e-6);
  // A line per cutting path, from its first point to its last.
  ASSERT_EQ(l.at("lines_lps").size(), plan.at("paths").size());
  const json& path = plan["paths"][0];
  const json& line = l["lines_lps"][0];
  ASSERT_GE(line.size(), path.size());
  for (int c = 0; c < 3; ++c) {
    EXPECT_NEAR(line.front()[c].get<double>(),
                plan["points"][path.front().get<int>()]["lps"][c].get<double>(), 1e-6);
    EXPECT_NEAR(line.back()[c].get<double>(),
                plan["points"][path.back().get<int>()]["lps"][c].get<double>(), 1e-6);
  }
  EXPECT_EQ(l["centre"]["theta_deg"], plan["frame"]["theta_deg"]);
  EXPECT_EQ(l["centre"]["z_mm"], plan["frame"]["z_mm"]);
  EXPECT_NEAR(norm3(l["centre"]["normal_lps"]), 1.0, 1e-9);
  const auto bad = post("/api/plan/lines", "[1, 2]");
  ASSERT_TRUE(bad);
  EXPECT_EQ(bad->status, 400);
  EXPECT_NE(error_of(bad).find("expected a JSON object"), std::string::npos);
  expect_still_serving();
}

TEST_F(ServerTest, PlanLinesCarryTheBorderLoopASutureSews) {
  // A free incision of three points: the loop 0 1 2 1' (Figure 2), four edges, each from its
  // node to the next along the skin; the twin 1' lies on point 1.
  const auto planned =
      post("/api/plan/new", R"({"procedure": "incision", "points": "-10,58;0,60;10,58"})");
  ASSERT_TRUE(planned);
  ASSERT_EQ(planned->status, 200) << planned->body;
  const json plan = json::parse(planned->body);
  EXPECT_EQ(plan["procedure"]["name"], "custom");
  const auto lines = post("/api/plan/lines", planned->body);
  ASSERT_TRUE(lines);
  ASSERT_EQ(lines->status, 200) << lines->body;
  const json loop = json::parse(lines->body).at("loop");
  const json& nodes = loop.at("nodes");
  const json& edges = loop.at("edges_lps");
  ASSERT_EQ(nodes.size(), 4u);
  ASSERT_EQ(edges.size(), 4u);
  const int point_of[] = {0, 1, 2, 1};
  for (int i = 0; i < 4; ++i) {
    EXPECT_EQ(nodes[i]["point"].get<int>(), point_of[i]);
    EXPECT_NEAR(norm3(nodes[i]["normal_lps"]), 1.0, 1e-9);
    for (int c = 0; c < 3; ++c) {
      const double p = plan["points"][point_of[i]]["lps"][c].get<double>();
      EXPECT_NEAR(nodes[i]["lps"][c].get<double>(), p, 1e-6);
      EXPECT_NEAR(edges[i].front()[c].get<double>(), p, 1e-6);
      EXPECT_NEAR(edges[(i + 3) % 4].back()[c].get<double>(), p, 1e-6);
    }
  }
  // A suture pair added to the plan's JSON is checked with it: edge 0 (0 -> 1, the left side of
  // the first segment) sewn to edge 3 (1' -> 0, its right side) closes the cut as it was.
  json sewn = plan;
  sewn["sutures"] = json::parse("[[[0, 1], [3, 0]]]");
  const auto checked = post("/api/plan/check", sewn.dump());
  ASSERT_TRUE(checked);
  ASSERT_EQ(checked->status, 200) << checked->body;
  EXPECT_EQ(json::parse(checked->body)["suture_quadruples"], json::parse("[[0, 1, 0, 3]]"));
  // The same edge twice is refused with the check's message.
  sewn["sutures"] = json::parse("[[[0, 1], [3, 0]], [[1, 0], [1, 2]]]");
  const auto twice = post("/api/plan/check", sewn.dump());
  ASSERT_TRUE(twice);
  EXPECT_EQ(twice->status, 400);
  expect_still_serving();
}

TEST_F(ServerTest, AResultIsExportedAsCapsRenderWritesIt) {
  const auto planned = post("/api/plan/new", plan_body().dump());
  ASSERT_TRUE(planned);
  const auto simulated = simulate_coarse(planned->body);
  ASSERT_TRUE(simulated);
  ASSERT_EQ(simulated->status, 200) << simulated->body;
  const std::string base =
      "/api/results/" + std::to_string(json::parse(simulated->body).at("result_id").get<int>());
  const auto exported = post(base + "/export", "{}");
  ASSERT_TRUE(exported);
  ASSERT_EQ(exported->status, 200) << exported->body;
  const json e = json::parse(exported->body);
  std::map<std::string, std::string> files;
  for (const auto& f : e.at("files")) files[f.at("name")] = f.at("url");
  // The plan simulated, its result, and what `caps render --gltf --tension-map` writes: pictures
  // before, after and of the tension in its four views, and the skin with its morph.
  for (const char* name : {"plan.json", "result.json", "skin.glb", "pre_front.png", "post_plan.png",
                           "tension_oblique.png"})
    ASSERT_TRUE(files.count(name)) << name << " in " << exported->body;
  EXPECT_EQ(e.at("render").at("gltf"), "skin.glb");
  EXPECT_EQ(json::parse(get(files["plan.json"])->body), json::parse(planned->body));
  EXPECT_EQ(json::parse(get(files["result.json"])->body).at("total_suture_force_n"),
            json::parse(simulated->body).at("closing_force_n"));
  const auto glb = get(files["skin.glb"]);
  ASSERT_TRUE(glb);
  EXPECT_EQ(glb->body.substr(0, 4), "glTF");
  const auto png = get(files["post_plan.png"]);
  ASSERT_TRUE(png);
  EXPECT_EQ(png->body.substr(1, 3), "PNG");
  EXPECT_EQ(png->get_header_value("Content-Type"), "image/png");
  // Asked again: the same files, not rendered again.
  EXPECT_EQ(json::parse(post(base + "/export", "{}")->body), e);
  const auto none = post("/api/results/99999/export", "{}");
  ASSERT_TRUE(none);
  EXPECT_EQ(none->status, 404);
  expect_still_serving();
}

TEST_F(ServerTest, ASimulationsSkinAndTensionAreServedAsGlb) {
  const auto idle = get("/api/progress");
  ASSERT_TRUE(idle);
  EXPECT_EQ(json::parse(idle->body).at("running"), false);
  const auto planned = post("/api/plan/new", plan_body().dump());
  ASSERT_TRUE(planned);
  const auto simulated = simulate_coarse(planned->body);
  ASSERT_TRUE(simulated);
  ASSERT_EQ(simulated->status, 200) << simulated->body;
  const int id = json::parse(simulated->body).at("result_id");
  const auto view = get("/api/results/" + std::to_string(id) + "/view");
  ASSERT_TRUE(view);
  ASSERT_EQ(view->status, 200) << view->body;
  const json v = json::parse(view->body);
  EXPECT_GE(v.at("subdivisions").get<int>(), 1);
  EXPECT_LE(v.at("subdivisions").get<int>(), 8);
  EXPECT_GT(v.at("tension_scale_max_kpa").get<double>(), 0);
  EXPECT_GE(v.at("max_skin_tension_kpa").get<double>(), v.at("tension_scale_max_kpa").get<double>());
  // The model's cells the simulation's skin replaces: around the plan, not the whole head. The
  // phantom's grid is 128 x 64 (63 rows of cells, 2.8125 deg wide); the cell under the plan's
  // centre is one of them.
  const json& cells = v.at("replaced_cells");
  ASSERT_FALSE(cells.empty());
  EXPECT_LT(cells.size(), 128u * 63u / 4u);
  EXPECT_TRUE(std::is_sorted(cells.begin(), cells.end()));
  EXPECT_GE(cells.front().get<int>(), 0);
  EXPECT_LT(cells.back().get<int>(), 128 * 63);
  const json grid = json::parse(slurp(fs::path(kModel) / "model.json")).at("grid");
  const json frame = json::parse(planned->body).at("frame");
  const int j = static_cast<int>(std::floor(
      (frame["theta_deg"].get<double>() - grid["theta0_deg"].get<double>()) / 2.8125));
  const int k = static_cast<int>(std::floor(
      (frame["z_mm"].get<double>() - grid["z0_mm"].get<double>()) / grid["dz_mm"].get<double>()));
  EXPECT_NE(std::find(cells.begin(), cells.end(), json(k * 128 + j)), cells.end()) << j << ", " << k;
  // A V-Y advancement excises nothing: no wound to fill before the closure.
  EXPECT_NEAR(v.at("wound_area_mm2").at("pre").get<double>(), 0.0, 1e-9);
  // The scar lines: each lip loop of the cut before and after, point for point; the closure
  // moves them (the V's flap advances) by no more than the result's largest displacement.
  const json& scars = v.at("scar_lines");
  ASSERT_FALSE(scars.empty()) << v.dump().substr(0, 400);
  const double max_u = json::parse(simulated->body).at("max_displacement_mm").get<double>();
  double moved_most = 0;
  for (const json& loop : scars) {
    ASSERT_EQ(loop.at("pre_lps").size(), loop.at("post_lps").size());
    ASSERT_GE(loop.at("pre_lps").size(), 3u);
    for (std::size_t i = 0; i < loop.at("pre_lps").size(); ++i) {
      const auto a = loop["pre_lps"][i].get<std::array<double, 3>>();
      const auto b = loop["post_lps"][i].get<std::array<double, 3>>();
      const double d = std::hypot(a[0] - b[0], a[1] - b[1], a[2] - b[2]);
      EXPECT_LE(d, max_u + 1e-6);
      moved_most = std::max(moved_most, d);
    }
  }
  EXPECT_GT(moved_most, 0.1);
  for (const char* k : {"skin", "tension"}) {
    const auto glb = get(v.at(k).get<std::string>());
    ASSERT_TRUE(glb);
    ASSERT_EQ(glb->status, 200) << k;
    EXPECT_EQ(glb->body.substr(0, 4), "glTF");
    EXPECT_NE(glb->body.find("post-operative"), std::string::npos);  // the morph target
  }
  // The tension at each vertex of tension.glb, as float32 kPa: their largest is the peak.
  const auto values = get(v.at("tension_values").get<std::string>());
  ASSERT_TRUE(values);
  ASSERT_EQ(values->status, 200);
  ASSERT_EQ(values->body.size() % 4, 0u);
  ASSERT_GT(values->body.size(), 0u);
  std::vector<float> kpa(values->body.size() / 4);
  std::memcpy(kpa.data(), values->body.data(), values->body.size());
  EXPECT_NEAR(*std::max_element(kpa.begin(), kpa.end()), v.at("max_skin_tension_kpa").get<double>(),
              1e-5 * v.at("max_skin_tension_kpa").get<double>());
  // The closure is in the whole face (the phantom model has its tissue model): the model's skin
  // around the patch moves too. Records of a uint32 vertex of the model's skin (GET /api/skin)
  // and its move (float32 x y z, glTF metres), in vertex order, the largest as the view says.
  ASSERT_TRUE(v.at("moved_skin").is_string()) << v.dump();
  const auto moved = get(v.at("moved_skin").get<std::string>());
  ASSERT_TRUE(moved);
  ASSERT_EQ(moved->status, 200);
  ASSERT_EQ(moved->body.size(), 16u * v.at("moved_skin_vertices").get<std::size_t>());
  ASSERT_GT(moved->body.size(), 0u);
  const long skin_vertices = json::parse(get("/api/skin")->body).at("skin").at("vertices");
  long previous = -1;
  double largest_mm = 0;
  for (std::size_t at = 0; at < moved->body.size(); at += 16) {
    std::uint32_t vertex = 0;
    float xyz[3];
    std::memcpy(&vertex, moved->body.data() + at, 4);
    std::memcpy(xyz, moved->body.data() + at + 4, 12);
    EXPECT_GT(static_cast<long>(vertex), previous);
    EXPECT_LT(static_cast<long>(vertex), skin_vertices);
    previous = vertex;
    largest_mm = std::max(largest_mm, 1000.0 * std::sqrt(double(xyz[0]) * xyz[0] +
                                                         double(xyz[1]) * xyz[1] + double(xyz[2]) * xyz[2]));
  }
  EXPECT_NEAR(largest_mm, v.at("moved_skin_max_mm").get<double>(), 1e-4);
  EXPECT_GE(largest_mm, 1e-3);  // a vertex moved less is left out (a V-Y on the phantom: 4 um)
  // The tension of the model's skin around the patch (records of a uint32 vertex and its float32
  // kPa): the map goes on across the patch's rim. Not all 0, and below the patch's peak (this
  // closure's patch reaches far: the tissue beyond it carries at most 0.1 kPa of the 33).
  ASSERT_TRUE(v.at("moved_skin_tension").is_string()) << v.dump();
  const auto rest = get(v.at("moved_skin_tension").get<std::string>());
  ASSERT_TRUE(rest);
  ASSERT_EQ(rest->status, 200);
  ASSERT_EQ(rest->body.size() % 8, 0u);
  ASSERT_GT(rest->body.size(), 0u);
  double rest_most = 0;
  for (std::size_t at = 0; at < rest->body.size(); at += 8) {
    std::uint32_t vertex = 0;
    float value = 0;
    std::memcpy(&vertex, rest->body.data() + at, 4);
    std::memcpy(&value, rest->body.data() + at + 4, 4);
    EXPECT_LT(static_cast<long>(vertex), skin_vertices);
    ASSERT_TRUE(std::isfinite(value));
    rest_most = std::max(rest_most, std::abs(double(value)));
  }
  EXPECT_GT(rest_most, 0.0);
  EXPECT_LT(rest_most, v.at("max_skin_tension_kpa").get<double>());
  // Asked again: the same answer, from the files written the first time.
  const auto again = get("/api/results/" + std::to_string(id) + "/view");
  ASSERT_TRUE(again);
  EXPECT_EQ(json::parse(again->body), v);
  const auto none = get("/api/results/99999/view");
  ASSERT_TRUE(none);
  EXPECT_EQ(none->status, 404);
  const auto after = get("/api/progress");
  ASSERT_TRUE(after);
  EXPECT_EQ(json::parse(after->body).at("running"), false);
  expect_still_serving();
}

// GET /api/landmarks is `caps model landmarks --no-write --json` of the served model and leaves
// model.json alone; POST /api/plan/new at "glabella+15,20" places as `caps plan new --at` does
// and the plan records the landmark and its offsets. On the face phantom (landmarks found) with a
// server of its own; on the plain phantom (none found) a landmark placement is refused with the
// app's message naming why.
TEST_F(ServerTest, LandmarksAreTheCliAnswerAndAPlanIsPlacedAtOneAsTheCliPlacesIt) {
  const fs::path dir = kTmp / "face";
  fs::create_directories(dir);
  const std::string face = (dir / "model").string();
  caps_test::make_phantom_model(dir, face, 128, 64, /*face=*/true);
  const std::string model_json = slurp(fs::path(face) / "model.json");
  const auto written = fs::last_write_time(fs::path(face) / "model.json");
  server::ServerOptions o;
  o.model_dir = face;
  o.port = 0;
  o.web_root = (kTmp / "web").string();
  server::PlannerServer s(o);
  s.bind();
  std::thread t([&s] { s.listen(); });
  struct Join {
    server::PlannerServer& s;
    std::thread& t;
    ~Join() {
      s.stop();
      t.join();
    }
  } join{s, t};
  httplib::Client c("127.0.0.1", s.port());
  c.set_read_timeout(120, 0);
  c.set_default_headers({{server::kTokenHeader, s.token()}});

  // A route's answer, which must be the caps program's JSON answer to `verb`.
  const auto the_clis_answer = [&](const char* route, const std::string& verb) {
    const auto got = c.Get(route);
    EXPECT_TRUE(got && got->status == 200) << route << ": " << (got ? got->body : "no answer");
    const auto cli = caps_test::caps(verb + " --json -q");
    EXPECT_EQ(cli.code, 0) << cli.out;
    const json answer = got && got->status == 200 ? json::parse(got->body) : json();
    EXPECT_EQ(answer, json::parse(cli.out)) << route;
    return answer;
  };
  const json got = the_clis_answer("/api/landmarks", "model landmarks " + face + " --no-write");
  const json glabella = got.at("items").at("glabella");
  ASSERT_EQ(glabella.at("found"), true) << glabella.dump();
  EXPECT_GT(glabella.at("thickness_mm").get<double>(), 0);
  EXPECT_EQ(slurp(fs::path(face) / "model.json"), model_json);
  EXPECT_EQ(fs::last_write_time(fs::path(face) / "model.json"), written);
  // GET /api/skin-lines is `caps plan skin-lines --json` of the served model: the face
  // phantom's nasion and subnasale lay Borges's map on it, every line's points on its skin.
  const json traced = the_clis_answer("/api/skin-lines", "plan skin-lines " + face);
  ASSERT_GT(traced.at("count").get<int>(), 50) << traced.dump().substr(0, 400);
  EXPECT_EQ(traced.at("lines").size(), traced.at("count").get<std::size_t>());
  std::set<std::string> zones;
  for (const json& l : traced.at("lines")) {
    zones.insert(l.at("zone").get<std::string>());
    EXPECT_EQ(l.at("points_lps").size(), l.at("theta_z").size());
  }
  EXPECT_TRUE(zones.count("forehead") && zones.count("nose") && zones.count("lips"))
      << traced.dump().substr(0, 400);

  // 15 mm to the patient's left and 20 mm up from the glabella: the CLI's plan, recorded so.
  const json request = {{"procedure", "z-plasty"},
                        {"at", "glabella+15,20"},
                        {"parameters", {{"length", 12}}}};
  const auto planned = c.Post("/api/plan/new", request.dump(), "application/json");
  ASSERT_TRUE(planned);
  ASSERT_EQ(planned->status, 200) << planned->body;
  const json plan = json::parse(planned->body);
  const fs::path cli_plan = dir / "cli-plan.json";
  const auto typed = caps_test::caps("plan new z-plasty --model " + face +
                                     " --at glabella+15,20 --length 12 -o " + cli_plan.string() +
                                     " --force -q");
  ASSERT_EQ(typed.code, 0) << typed.out;
  const json file = json::parse(slurp(cli_plan));
  EXPECT_EQ(plan.at("at"), file.at("at"));
  EXPECT_EQ(plan.at("frame"), file.at("frame"));
  EXPECT_EQ(plan.at("points"), file.at("points"));
  EXPECT_EQ(plan.at("at").at("landmark"), "glabella");
  EXPECT_EQ(plan.at("at").at("left_mm"), 15);
  EXPECT_EQ(plan.at("at").at("up_mm"), 20);
  // Left is +theta (the patient's left), up is +z, from the glabella.
  EXPECT_GT(plan.at("frame").at("theta_deg").get<double>(),
            glabella.at("theta_deg").get<double>() + 5);
  EXPECT_GT(plan.at("frame").at("z_mm").get<double>(), glabella.at("z_mm").get<double>() + 15);

  // The plain phantom has no landmarks: each absent with its reason, and a placement at one is
  // refused with the app's (the CLI's) message.
  const auto none = get("/api/landmarks");
  ASSERT_TRUE(none);
  ASSERT_EQ(none->status, 200);
  for (const auto& [name, l] : json::parse(none->body).at("items").items()) {
    EXPECT_EQ(l.at("found"), false) << name;
    EXPECT_FALSE(l.at("note").get<std::string>().empty()) << name;
  }
  // ... nor skin lines, and the answer says why.
  const auto no_lines = get("/api/skin-lines");
  ASSERT_TRUE(no_lines);
  ASSERT_EQ(no_lines->status, 200) << no_lines->body;
  EXPECT_EQ(json::parse(no_lines->body).at("count"), 0);
  EXPECT_NE(json::parse(no_lines->body).at("note").get<std::string>().find("nasion"),
            std::string::npos) << no_lines->body;
  app::PlanNewRequest pn;
  pn.procedure = "z-plasty";
  pn.model = kModel;
  pn.at = "glabella+15,20";
  pn.output = (kTmp / "at-glabella.json").string();
  const std::string app_message = message_of([&] { app::run_plan_new(pn); });
  ASSERT_NE(app_message.find("glabella"), std::string::npos) << app_message;
  const auto refused = post("/api/plan/new", json{{"procedure", "z-plasty"}, {"at", "glabella+15,20"}}.dump());
  ASSERT_TRUE(refused);
  EXPECT_EQ(refused->status, 400);
  // The command line's message in the page's words: the same reason, the placement by a click.
  EXPECT_NE(app_message.find("--at THETA,Z"), std::string::npos) << app_message;
  const std::string page_message = error_of(refused);
  EXPECT_EQ(page_message.substr(0, 40), app_message.substr(0, 40));
  EXPECT_NE(page_message.find("place the plan with a click on the skin or another landmark"),
            std::string::npos) << page_message;
  EXPECT_EQ(page_message.find("--"), std::string::npos) << page_message;
  EXPECT_EQ(page_message.find("theta"), std::string::npos) << page_message;
  expect_still_serving();
}

TEST_F(ServerTest, TheLibrarysMessagesAreSaidInThePagesWords) {
  // The phantom model keeps no found landmark: a place is said as "(there)". (Where the model
  // has landmarks, the nearest one's offsets: planner_e2e_cranium and CliLandmarks.)
  const auto model = app::loaded_model(kModel);
  const auto words = [&](const std::string& m) { return server::detail::page_words(m, *model, kModel); };
  const std::string refused = words(
      "loop node 0 (point 2), /points/2 at (theta -6.12987 deg, z 55 mm) lies where the model "
      "cannot represent the skin yet (grazing): the ray from the head's axis crosses the skin "
      "twice (undercut: nostrils, under the nose and the chin, ears) or meets it edge-on "
      "(grazing), so its cylindrical image does not hold this skin; move the plan onto skin that "
      "faces the axis, or make a local chart that faces this skin (caps model chart MODEL --at "
      "THETA,Z) and plan on it at --at 0,0 (docs/mesher.md, \"Local charts\") (here: caps model "
      "chart cranium --at -6.1,55 -o CHART)");
  EXPECT_EQ(refused.rfind("the cut's point 3 at (there) lies where the model cannot represent", 0), 0u)
      << refused;
  EXPECT_NE(refused.find("or make a local chart here (the button below)"), std::string::npos) << refused;
  for (const char* engineers : {"theta", "loop node", "/points", "caps model", "--", "CHART", "docs/"})
    EXPECT_EQ(refused.find(engineers), std::string::npos) << engineers << " in: " << refused;
  EXPECT_EQ(words("suture 1 ((2,1),(2,3)): sides of 3.0 and 6.0 mm, ratio 2.00; expect puckering"),
            "suture pair 2: sides of 3.0 and 6.0 mm, ratio 2.00; expect puckering");
  EXPECT_EQ(words("border edges not sutured (the wound stays open there): (0,1), (3,4)"),
            "some of the wound's edges are not sutured (the wound stays open there)");
  EXPECT_EQ(words("one material (`--tissue uniform`, the default) overstates it: `--tissue auto` "
                  "models the measured fat"),
            "one material (the Tissue setting's one material, the default) overstates it: the "
            "Tissue setting's measured layers models the measured fat");
  EXPECT_EQ(words("rebuild the model with a deeper --bone-cap"),
            "rebuild the model with a deeper a setting of the command line (bone-cap)");
  // Nothing to reword, and text too long to reword, stay as they are.
  const std::string plain = "angle = 20 deg is outside its clinical range (30..90 deg)";
  EXPECT_EQ(words(plain), plain);
  const std::string echoed = "unknown key \"" + std::string(5000, 'x') + " loop node 1\"";
  EXPECT_EQ(words(echoed), echoed);
}

TEST(LoadedModel, IsReadOnceAndAgainWhenItsFilesChange) {
  const fs::path dir = fs::temp_directory_path() / "caps_test_server_loaded";
  fs::remove_all(dir);
  fs::create_directories(dir);
  const std::string model = (dir / "model").string();
  caps_test::make_phantom_model(dir, model);
  const auto first = app::loaded_model(model);
  EXPECT_EQ(app::loaded_model(model), first);  // the same object: not read again
  EXPECT_EQ(app::loaded_model(model + "/"), first);
  // A rewritten map (a new modification time) is read again.
  const fs::path map = fs::path(model) / "thickness.nrrd";
  fs::last_write_time(map, fs::last_write_time(map) + std::chrono::seconds(5));
  const auto second = app::loaded_model(model);
  EXPECT_NE(second, first);
  EXPECT_EQ(second->content_hash(), first->content_hash());
  // A broken model: PatientModel::load's message.
  fs::remove(map);
  const std::string load_message = message_of([&] { PatientModel::load(model); });
  ASSERT_FALSE(load_message.empty());
  EXPECT_EQ(message_of([&] { app::loaded_model(model); }), load_message);
}

TEST_F(ServerTest, ALocalChartIsMadeServedAndLeft) {
  // Bad requests: 400 with the reason, and the model served is still the started one.
  const auto unknown = post("/api/chart", R"({"where": "here"})");
  ASSERT_TRUE(unknown);
  EXPECT_EQ(unknown->status, 400);
  EXPECT_NE(error_of(unknown).find("unknown key"), std::string::npos) << error_of(unknown);
  const auto none = post("/api/chart", "{}");
  EXPECT_EQ(none->status, 400);
  const auto garbled = post("/api/chart", R"({"at_xyz": "1,2"})");
  EXPECT_EQ(garbled->status, 400);
  EXPECT_NE(error_of(garbled).find("X,Y,Z"), std::string::npos) << error_of(garbled);
  EXPECT_FALSE(json::parse(get("/api/model")->body).at("source").contains("chart"));

  // A chart at (20, 60) of the started model: made, answered and served from then on; plans are
  // made on it (theta 0, z 0 is that skin point); the head again with {"head": true}.
  const auto made = post("/api/chart", R"({"at": "20,60"})");
  ASSERT_TRUE(made);
  ASSERT_EQ(made->status, 200) << made->body;
  EXPECT_EQ(json::parse(made->body).at("source").at("chart").at("at"), "20,60");
  const json served = json::parse(get("/api/model")->body);
  EXPECT_EQ(served.at("source").at("chart").at("at"), "20,60");
  EXPECT_EQ(served.value("made_here", false), true);
  const auto skin = get("/api/skin");
  ASSERT_EQ(skin->status, 200);
  const auto planned = post("/api/plan/new",
                            R"({"procedure": "ellipse", "at": "0,0", "parameters": {"length": 12, "width": 4}})");
  ASSERT_EQ(planned->status, 200) << planned->body;
  const json plan = json::parse(planned->body);
  EXPECT_NEAR(plan.at("frame").at("theta_deg").get<double>(), 0.0, 1e-6);
  EXPECT_NE(plan.at("model").get<std::string>().find("charts"), std::string::npos);
  const auto back = post("/api/chart", R"({"head": true})");
  ASSERT_EQ(back->status, 200);
  EXPECT_FALSE(json::parse(get("/api/model")->body).at("source").contains("chart"));
  EXPECT_FALSE(json::parse(get("/api/model")->body).contains("made_here"));
  EXPECT_EQ(json::parse(get("/api/model")->body).at("content_hash"),
            json::parse(slurp(fs::path(kModel) / "model.json")).at("content_hash"));
  expect_still_serving();
}
