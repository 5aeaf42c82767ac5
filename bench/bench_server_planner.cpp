// The planner's latency as the page sees it, through the HTTP server on loopback (in-process
// server, httplib client): placing or moving a template until its check and lines are back
// (POST /api/plan/new + /api/plan/lines), checking a plan (POST /api/plan/check), and Simulate
// until the post-operative skin can be drawn (POST /api/simulate + GET /api/results/ID/view + its
// skin.glb; tension.glb, written after the view's answer, is read afterwards and not counted), on
// the demo's model and its Z-plasty (scripts/demo.sh: at 30,105, length 15), and the page's
// default Z-plasty on the forehead, the cheek and beside the eye.
//   scripts/demo.sh   (or build/tools/caps model from-volume .../Cranium.inv3 -o out/cranium)
//   CAPS_BENCH_MODEL=out/cranium build/bench/bench_server_planner
// Also: the model read from disk (what every request cost before the server kept its model).
#include <benchmark/benchmark.h>

#include "caps/core/error.hpp"
#include "caps/server/planner_server.hpp"
#include "caps/surface/patient_model.hpp"
#include "blas_context.hpp"

#include <httplib.h>
#include <nlohmann/json.hpp>

#include <chrono>
#include <cstdlib>
#include <map>
#include <memory>
#include <string>
#include <thread>

using nlohmann::json;

namespace {

std::string model_dir() {
  const char* m = std::getenv("CAPS_BENCH_MODEL");
  return m ? m : "out/cranium";
}

// One server for the whole program, on a free loopback port.
struct Server {
  std::unique_ptr<caps::server::PlannerServer> server;
  std::thread thread;
  Server() {
    caps::server::ServerOptions o;
    o.model_dir = model_dir();
    o.port = 0;
    server = std::make_unique<caps::server::PlannerServer>(o);
    server->bind();
    thread = std::thread([this] { server->listen(); });
  }
  ~Server() {
    server->stop();
    thread.join();
  }
  httplib::Client client() const {
    httplib::Client c("127.0.0.1", server->port());
    c.set_read_timeout(600, 0);
    c.set_default_headers({{caps::server::kTokenHeader, server->token()}});  // as the page does
    return c;
  }
};

Server& server() {
  static Server s;
  return s;
}

// Where a Z-plasty is laid: the demo's (15 mm limbs at 30,105) and the page's default (20 mm,
// 60 deg) on the forehead, on the cheek below the eye and on the temple beside it (lateral to
// Cranium's left exocanthion at 14 deg, 55 mm; nearer, a 20 mm Z-plasty reaches the lids).
struct Place {
  double theta, z, orientation, length;
};
constexpr Place kDemo{30, 105, 90, 15}, kForehead{30, 110, 90, 20}, kCheek{30, 32, 0, 20},
    kBesideEye{45, 55, 90, 20};

json z_plasty(double theta, const Place& p = kDemo) {
  return {{"procedure", "z-plasty"},
          {"at", std::to_string(theta) + "," + std::to_string(p.z)},
          {"orientation", p.orientation},
          {"parameters", {{"length", p.length}}}};
}

std::string post(httplib::Client& c, const std::string& path, const std::string& body) {
  const auto r = c.Post(path.c_str(), body, "application/json");
  if (!r || r->status != 200)
    throw caps::Error(path + ": " + (r ? r->body : std::string("no answer")));
  return r->body;
}

std::string get(httplib::Client& c, const std::string& path) {
  const auto r = c.Get(path.c_str());
  if (!r || r->status != 200)
    throw caps::Error(path + ": " + (r ? r->body : std::string("no answer")));
  return r->body;
}

// Moving a template: each iteration lays it 0.5 deg further along theta (a drag step), checks
// it and gets its lines, as the page does on every move.
void BM_MoveTemplateToCheckAndLines(benchmark::State& state) {
  auto c = server().client();
  int i = 0;
  for (auto _ : state) {
    const std::string plan = post(c, "/api/plan/new", z_plasty(30 + 0.5 * (i++ % 8)).dump());
    benchmark::DoNotOptimize(post(c, "/api/plan/lines", plan));
  }
}
BENCHMARK(BM_MoveTemplateToCheckAndLines)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_PlanCheck(benchmark::State& state) {
  auto c = server().client();
  const std::string plan = post(c, "/api/plan/new", z_plasty(30).dump());
  for (auto _ : state) benchmark::DoNotOptimize(post(c, "/api/plan/check", plan));
}
BENCHMARK(BM_PlanCheck)->Unit(benchmark::kMillisecond)->UseRealTime();

// What each plan request cost before the server kept its model: reading the model folder.
void BM_ModelReadFromDisk(benchmark::State& state) {
  for (auto _ : state) benchmark::DoNotOptimize(caps::PatientModel::load(model_dir()));
}
BENCHMARK(BM_ModelReadFromDisk)->Unit(benchmark::kMillisecond)->UseRealTime();

// Simulate until the post-operative skin can be drawn; counters split the time.
// Each iteration simulates the Z-plasty moved 0.5 deg further (a new mesh, as after a drag).
void simulate(benchmark::State& state, const std::string& material, const Place& place = kDemo) {
  auto c = server().client();
  int i = 0;
  double solve = 0, view = 0, files = 0, mb = 0, solver = 0, meshing_and_solving = 0;
  std::map<std::string, double> parts;
  for (auto _ : state) {
    state.PauseTiming();
    const json plan = json::parse(post(c, "/api/plan/new", z_plasty(place.theta + 0.5 * i++, place).dump()));
    state.ResumeTiming();
    const auto t0 = std::chrono::steady_clock::now();
    const json r = json::parse(
        post(c, "/api/simulate", json{{"plan", plan}, {"options", {{"material", material}}}}.dump()));
    const auto t1 = std::chrono::steady_clock::now();
    const json v = json::parse(get(c, "/api/results/" + std::to_string(r.at("result_id").get<int>()) + "/view"));
    const auto t2 = std::chrono::steady_clock::now();
    const std::size_t bytes = get(c, v.at("skin")).size();
    const auto t3 = std::chrono::steady_clock::now();
    state.PauseTiming();
    benchmark::DoNotOptimize(get(c, v.at("tension")));
    // The solver's own phases (result.json "timings_s").
    const json solved = json::parse(get(c, r.at("result_url").get<std::string>() + "result.json"));
    for (const char* k : {"assembly", "analysis", "factorization", "solve", "recovery"})
      parts["solver_" + std::string(k)] += solved.at("timings_s").value(k, 0.0);
    state.ResumeTiming();
    solver += r.at("timings_s").at("solve").get<double>();
    meshing_and_solving += r.at("timings_s").at("steps").value("meshing and solving", 0.0);
    solve += std::chrono::duration<double>(t1 - t0).count();
    view += std::chrono::duration<double>(t2 - t1).count();
    files += std::chrono::duration<double>(t3 - t2).count();
    mb = bytes / 1e6;
    for (const char* k : {"skin", "tension", "glb"}) parts[k] += v.at("timings_s").at(k).get<double>();
  }
  const double n = static_cast<double>(state.iterations());
  state.counters["simulate_s"] = solve / n;
  state.counters["view_s"] = view / n;
  state.counters["download_s"] = files / n;
  state.counters["glb_MB"] = mb;
  state.counters["simulate_solver_s"] = solver / n;
  state.counters["simulate_meshing_s"] = (meshing_and_solving - solver) / n;
  for (const auto& [k, t] : parts)
    state.counters[(k.rfind("solver_", 0) == 0 ? k : "view_" + k) + "_s"] = t / n;
}

// CPU is the whole process's (the server's threads, the solver's and the client's): on this
// shared machine the wall time grows with the other engineers' load, the CPU time much less.
void BM_SimulateToPostOperativeSkin_Linear(benchmark::State& state) { simulate(state, "linear"); }
BENCHMARK(BM_SimulateToPostOperativeSkin_Linear)
    ->Unit(benchmark::kMillisecond)->UseRealTime()->MeasureProcessCPUTime()->Iterations(5);

void BM_SimulateToPostOperativeSkin_NeoHookean(benchmark::State& state) {
  simulate(state, "neo-hookean");
}
BENCHMARK(BM_SimulateToPostOperativeSkin_NeoHookean)
    ->Unit(benchmark::kMillisecond)->UseRealTime()->MeasureProcessCPUTime()->Iterations(1);

// The page's default Z-plasty (20 mm, 60 deg), neo-Hookean in the whole face (the defaults),
// simulated twice: placed, then moved 0.5 deg (about 0.7 mm; issue 35's re-simulate after a
// small move, which today is a new solve).
void BM_PageZPlastyToPostOperativeSkin_Forehead(benchmark::State& state) {
  simulate(state, "neo-hookean", kForehead);
}
void BM_PageZPlastyToPostOperativeSkin_Cheek(benchmark::State& state) {
  simulate(state, "neo-hookean", kCheek);
}
void BM_PageZPlastyToPostOperativeSkin_BesideTheEye(benchmark::State& state) {
  simulate(state, "neo-hookean", kBesideEye);
}
BENCHMARK(BM_PageZPlastyToPostOperativeSkin_Forehead)
    ->Unit(benchmark::kMillisecond)->UseRealTime()->MeasureProcessCPUTime()->Iterations(2);
BENCHMARK(BM_PageZPlastyToPostOperativeSkin_Cheek)
    ->Unit(benchmark::kMillisecond)->UseRealTime()->MeasureProcessCPUTime()->Iterations(2);
BENCHMARK(BM_PageZPlastyToPostOperativeSkin_BesideTheEye)
    ->Unit(benchmark::kMillisecond)->UseRealTime()->MeasureProcessCPUTime()->Iterations(2);

}  // namespace

BENCHMARK_MAIN();
