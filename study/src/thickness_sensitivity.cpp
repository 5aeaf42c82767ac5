#include "caps/study/thickness_sensitivity.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <exception>
#include <mutex>
#include <thread>

#include "caps/core/error.hpp"
#include "caps/study/compare.hpp"
#include "caps/plan/procedures.hpp"
#include "caps/surface/patient_model.hpp"

namespace caps::study {

using namespace caps::fem;
using namespace caps::mesher;
using namespace caps::closure;
namespace {

constexpr int kMaxThreads = 64;
constexpr int kMaxPoints = 10000;

std::vector<double> steps(double lo, double hi, double step) {
  std::vector<double> v;
  for (int i = 0; lo + i * step <= hi + 1e-9; ++i) v.push_back(lo + i * step);
  return v;
}

void check_options(const SensitivityOptions& o) {
  if (o.threads < 1 || o.threads > kMaxThreads)
    throw InvalidInput(cat("sensitivity: threads ", o.threads, " must be in [1, ", kMaxThreads, "]"));
  if (!(o.theta_step_deg > 0) || !(o.z_step_mm > 0))
    throw InvalidInput(cat("sensitivity: the grid steps (", o.theta_step_deg, " deg, ", o.z_step_mm,
                           " mm) must be positive"));
  if (!(o.theta_min_deg >= -180 && o.theta_max_deg <= 180 && o.theta_min_deg <= o.theta_max_deg))
    throw InvalidInput(cat("sensitivity: the theta range [", o.theta_min_deg, ", ", o.theta_max_deg,
                           "] deg must lie in [-180, 180] with min <= max"));
  if (!(o.constant_thickness_mm >= 0 && o.constant_thickness_mm <= 50))
    throw InvalidInput(cat("sensitivity: constant thickness ", o.constant_thickness_mm,
                           " mm must be in [0, 50] (0: the median measured)"));
  if (!(o.margin_mm >= 0)) throw InvalidInput(cat("sensitivity: margin ", o.margin_mm, " mm must be >= 0"));
}

// Both runs at one centre; any caps::Error (the plan cannot be placed, checked, meshed or
// solved there) marks the point as not planned.
SensitivityPoint run_point(const PatientModel& model, const plan::LocalProcedure& local,
                           const SensitivityOptions& o, double constant_mm, double theta, double z) {
  SensitivityPoint p;
  p.theta_deg = theta;
  p.z_mm = z;
  try {
    const plan::Plan plan = plan::place_procedure(local, model, theta, z, o.orientation_deg);
    SimulateOptions measured = o.simulate;
    measured.continuum.constant_thickness_mm = 0;
    const Simulation a = simulate(model, plan, measured);
    SimulateOptions constant = o.simulate;
    constant.continuum.constant_thickness_mm = constant_mm;
    constant.surface.extent_mm = a.wound.surface.extent_mm;
    const Simulation b = simulate(model, plan, constant);
    const SimulationSummary sa = summarize(a, model, "measured");
    const SimulationSummary sb = summarize(b, model, "constant", constant_mm);
    p.thickness_mean_mm = sa.thickness_mean_mm;
    p.closing_force_measured_n = sa.closing_force_n;
    p.closing_force_constant_n = sb.closing_force_n;
    p.max_displacement_measured_mm = sa.max_displacement_mm;
    p.max_displacement_constant_mm = sb.max_displacement_mm;
    if (!(sa.closing_force_n > 0) || !(sa.max_displacement_mm > 0))
      throw SolverError("the measured closure moved nothing");
    p.force_change = (sb.closing_force_n - sa.closing_force_n) / sa.closing_force_n;
    p.displacement_change = (sb.max_displacement_mm - sa.max_displacement_mm) / sa.max_displacement_mm;
    for (const std::string& w : a.wound.continuum.mesh.warnings) p.warnings.push_back("measured: " + w);
    for (const std::string& w : b.wound.continuum.mesh.warnings) p.warnings.push_back("constant: " + w);
    p.planned = true;
  } catch (const Cancelled&) {
    throw;
  } catch (const Error& e) {
    p.planned = false;
    p.reason = e.what();
  }
  return p;
}

}  // namespace

SensitivityMap thickness_sensitivity(const PatientModel& model, const SensitivityOptions& options,
                                     Reporter* reporter) {
  check_options(options);
  const auto t0 = std::chrono::steady_clock::now();
  const plan::LocalProcedure local = plan::layout_procedure(options.procedure, options.parameters);
  SensitivityMap map;
  map.options = options;
  // The sequential MUMPS build keeps global state and fails when two factorizations run at
  // once; CHOLMOD's are independent, and the two direct solvers agree to round-off.
  if (options.threads > 1 && map.options.simulate.solve.solver != SolverKind::Cholmod)
    map.options.simulate.solve.solver = SolverKind::Cholmod;
  const CylinderGrid& g = model.grid();
  const double z_first = g.z0_mm, z_last = g.z0_mm + (g.n_z - 1) * g.dz_mm;
  double z_lo = options.z_min_mm, z_hi = options.z_max_mm;
  if (z_lo > z_hi) {
    z_lo = z_first + options.margin_mm;
    z_hi = z_last - options.margin_mm;
  }
  map.theta_deg = steps(options.theta_min_deg, options.theta_max_deg, options.theta_step_deg);
  map.z_mm = steps(z_lo, z_hi, options.z_step_mm);
  const std::size_t n = map.theta_deg.size() * map.z_mm.size();
  if (n == 0)
    throw InvalidInput(cat("sensitivity: no plan centre in theta [", options.theta_min_deg, ", ",
                           options.theta_max_deg, "] deg and z [", z_lo, ", ", z_hi,
                           "] mm (the model's rows run from ", z_first, " to ", z_last, " mm)"));
  if (n > kMaxPoints)
    throw InvalidInput(cat("sensitivity: ", n, " plan centres; at most ", kMaxPoints,
                           " (coarsen the steps)"));
  // The constant: the median measured thickness over the valid cells of the mapped region.
  map.constant_thickness_mm = options.constant_thickness_mm;
  if (map.constant_thickness_mm == 0) {
    std::vector<double> t;
    for (int k = 0; k < g.n_z; ++k) {
      const double z = g.z0_mm + k * g.dz_mm;
      if (z < z_lo || z > z_hi) continue;
      for (int j = 0; j < g.n_theta; ++j) {
        const double theta = std::remainder(g.theta_deg(j), 360.0);
        if (theta < options.theta_min_deg || theta > options.theta_max_deg) continue;
        if ((model.flags_at(theta, z) & kInvalidFlags) != 0) continue;
        const double x = model.thickness(theta, z);
        if (std::isfinite(x) && x > 0) t.push_back(x);
      }
    }
    if (t.empty())
      throw InvalidInput("sensitivity: no valid thickness in the mapped region; give the constant "
                         "thickness");
    std::nth_element(t.begin(), t.begin() + t.size() / 2, t.end());
    map.constant_thickness_mm = t[t.size() / 2];
  }
  map.points.resize(n);
  Progress progress(reporter, cat("simulating ", n, " plans twice"), static_cast<double>(n));
  std::atomic<std::size_t> next{0}, finished{0};
  std::atomic<bool> stop{false};
  std::exception_ptr failure;
  std::mutex failure_mutex;
  auto worker = [&] {
    for (;;) {
      const std::size_t i = next++;
      if (i >= n || stop) return;
      try {
        map.points[i] = run_point(model, local, map.options, map.constant_thickness_mm,
                                  map.theta_deg[i % map.theta_deg.size()],
                                  map.z_mm[i / map.theta_deg.size()]);
      } catch (...) {
        const std::lock_guard<std::mutex> lock(failure_mutex);
        if (!failure) failure = std::current_exception();
        stop = true;
      }
      ++finished;
    }
  };
  std::vector<std::thread> pool;
  const int n_threads = std::min<int>(options.threads, static_cast<int>(n));
  for (int i = 0; i < n_threads; ++i) pool.emplace_back(worker);
  try {
    while (finished < n && !stop) {
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
      progress.update(static_cast<double>(finished));
    }
  } catch (...) {  // cancelled through the reporter: let the running simulations finish
    stop = true;
    for (auto& t : pool) t.join();
    throw;
  }
  for (auto& t : pool) t.join();
  if (failure) std::rethrow_exception(failure);
  progress.done();
  for (const auto& p : map.points) map.planned += p.planned;
  map.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return map;
}

std::string sensitivity_json(const SensitivityMap& m) {
  const SensitivityOptions& o = m.options;
  nlohmann::json points = nlohmann::json::array();
  for (const auto& p : m.points) {
    nlohmann::json j{{"theta_deg", p.theta_deg}, {"z_mm", p.z_mm}, {"planned", p.planned}};
    if (p.planned) {
      j["thickness_under_wound_mm"] = p.thickness_mean_mm;
      j["closing_force_n"] = {{"measured", p.closing_force_measured_n}, {"constant", p.closing_force_constant_n}};
      j["max_displacement_mm"] = {{"measured", p.max_displacement_measured_mm},
                                  {"constant", p.max_displacement_constant_mm}};
      j["force_change"] = p.force_change;
      j["displacement_change"] = p.displacement_change;
      j["warnings"] = p.warnings;
    } else {
      j["reason"] = p.reason;
    }
    points.push_back(j);
  }
  return nlohmann::json{
      {"procedure", o.procedure},
      {"parameters", o.parameters},
      {"orientation_deg", o.orientation_deg},
      {"solver", solver_name(o.simulate.solve.solver)},
      {"threads", o.threads},
      {"constant_thickness_mm", m.constant_thickness_mm},
      {"constant_thickness_source", o.constant_thickness_mm > 0 ? "given" : "median measured over the region"},
      {"theta_deg", m.theta_deg},
      {"z_mm", m.z_mm},
      {"planned", m.planned},
      {"change", "(constant - measured) / measured"},
      {"points", points}}
      .dump(1, ' ', false, nlohmann::json::error_handler_t::replace);
}

std::string sensitivity_csv(const SensitivityMap& m) {
  std::string out =
      "theta_deg,z_mm,planned,thickness_under_wound_mm,closing_force_measured_n,"
      "closing_force_constant_n,force_change,max_displacement_measured_mm,"
      "max_displacement_constant_mm,displacement_change\n";
  char buf[512];
  for (const auto& p : m.points) {
    std::snprintf(buf, sizeof buf, "%.3f,%.3f,%d,%.4f,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g\n", p.theta_deg,
                  p.z_mm, p.planned ? 1 : 0, p.thickness_mean_mm, p.closing_force_measured_n,
                  p.closing_force_constant_n, p.force_change, p.max_displacement_measured_mm,
                  p.max_displacement_constant_mm, p.displacement_change);
    out += buf;
  }
  return out;
}

}  // namespace caps::study
