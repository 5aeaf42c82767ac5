#include "caps/study/compare.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <vector>

#include "caps/core/error.hpp"
#include "caps/surface/patient_model.hpp"

namespace caps::study {

using namespace caps::fem;
using namespace caps::mesher;
using namespace caps::closure;
namespace {

double median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

// The thickness at the wound's border loop points (theta, z): what lies under the wound.
std::vector<double> thickness_under_wound(const Simulation& sim, const PatientModel& model) {
  const auto& s = sim.wound.surface;
  std::vector<double> t;
  for (int v : s.loop_vertex) t.push_back(model.thickness(s.theta_z(v, 0), s.theta_z(v, 1)));
  return t;
}

std::string fmt(double x, int digits = 2) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*f", digits, x);
  return buf;
}

}  // namespace

SimulationSummary summarize(const Simulation& sim, const PatientModel& model, const std::string& label,
                            double constant_thickness_mm) {
  SimulationSummary s;
  s.label = label;
  s.tissue = tissue_layers_name(sim.wound.continuum.tissue);
  if (constant_thickness_mm > 0) {
    s.thickness_mean_mm = s.thickness_min_mm = s.thickness_max_mm = constant_thickness_mm;
  } else {
    const auto t = thickness_under_wound(sim, model);
    s.thickness_min_mm = *std::min_element(t.begin(), t.end());
    s.thickness_max_mm = *std::max_element(t.begin(), t.end());
    for (double x : t) s.thickness_mean_mm += x / t.size();
  }
  const auto& c = sim.wound.continuum;
  const auto& r = sim.result;
  const auto& surf = sim.wound.surface;
  // Skin nodes near the wound: within one wound size of the wound's centre, in (theta, z) mm.
  const double mm_per_deg = surf.ref_radius_mm * 3.14159265358979323846 / 180.0;
  int near = 0;
  for (Eigen::Index i = 0; i < c.mesh.n_nodes(); ++i) {
    if (c.node_level[i] != 0) continue;
    const double u = r.displacement_mm.row(i).norm();
    s.max_displacement_mm = std::max(s.max_displacement_mm, u);
    s.max_skin_tension_kpa = std::max(s.max_skin_tension_kpa, 1e3 * r.max_principal_mpa[i]);
    const double dx = std::remainder(c.node_theta_z(i, 0) - surf.theta_c_deg, 360.0) * mm_per_deg;
    const double dz = c.node_theta_z(i, 1) - surf.z_c_mm;
    if (std::hypot(dx, dz) <= surf.wound_size_mm) {
      s.mean_displacement_mm += u;
      ++near;
    }
  }
  if (near) s.mean_displacement_mm /= near;
  s.closing_force_n = r.total_suture_force_n;
  s.max_suture_force_n = max_suture_pair_force_n(r);
  s.max_suture_at_spacing_n = sim.sutures.max_suture_force_n;
  s.strain_energy_mj = r.strain_energy_mj;
  s.elements = static_cast<int>(c.mesh.n_elements());
  s.nodes = static_cast<int>(c.mesh.n_nodes());
  return s;
}

Comparison compare_thickness(const PatientModel& model, const plan::Plan& plan, double constant_mm,
                             const SimulateOptions& options, Reporter* reporter) {
  if (constant_mm < 0 || constant_mm > 50)
    throw InvalidInput(cat("constant thickness ", constant_mm, " mm must be in [0, 50] (0: the median "
                           "measured under the wound)"));
  Comparison c;
  SimulateOptions measured = options;
  measured.continuum.constant_thickness_mm = 0;
  measured.continuum.tissue = TissueLayers::Uniform;
  c.measured = simulate(model, plan, measured, reporter);
  c.constant_thickness_mm =
      constant_mm > 0 ? constant_mm : median(thickness_under_wound(c.measured, model));
  SimulateOptions constant = options;
  constant.continuum.constant_thickness_mm = c.constant_thickness_mm;
  constant.continuum.tissue = TissueLayers::Uniform;
  // The same surface mesh for both: fix the extent the measured run settled on.
  constant.surface.extent_mm = c.measured.wound.surface.extent_mm;
  c.constant = simulate(model, plan, constant, reporter);
  SimulateOptions layered = measured;
  layered.continuum.tissue = TissueLayers::Auto;
  layered.surface.extent_mm = c.measured.wound.surface.extent_mm;
  c.layered = simulate(model, plan, layered, reporter);
  c.measured_summary = summarize(c.measured, model, "measured thickness (volume)");
  c.constant_summary = summarize(c.constant, model,
                                 cat("constant ", fmt(c.constant_thickness_mm, 1), " mm (1992 assumption)"),
                                 c.constant_thickness_mm);
  for (const std::string& w : c.measured.wound.continuum.mesh.warnings) c.warnings.push_back("measured: " + w);
  for (const std::string& w : c.constant.wound.continuum.mesh.warnings) c.warnings.push_back("constant: " + w);
  const bool has_layers = c.layered.wound.continuum.tissue == TissueLayers::Measured;
  c.layered_summary = summarize(c.layered, model,
                                has_layers ? "measured layers (dermis, fat, deep tissue)"
                                           : "measured layers (none measured: one material)");
  for (const std::string& w : c.layered.wound.continuum.mesh.warnings) c.warnings.push_back("layers: " + w);
  if (!has_layers)
    c.warnings.push_back("layers: the model has no measured tissue layers under this mesh (no "
                         "layer maps, or no fat or skin interface seen there): the third column "
                         "is one material, as the first");
  return c;
}

std::string comparison_json(const Comparison& c, const std::string& plan_name) {
  auto side = [](const SimulationSummary& s) {
    return nlohmann::json{{"label", s.label},
                          {"tissue", s.tissue},
                          {"thickness_under_wound_mm", {{"mean", s.thickness_mean_mm},
                                                        {"min", s.thickness_min_mm},
                                                        {"max", s.thickness_max_mm}}},
                          {"max_displacement_mm", s.max_displacement_mm},
                          {"mean_displacement_near_wound_mm", s.mean_displacement_mm},
                          {"closing_force_n", s.closing_force_n},
                          {"max_suture_force_n", s.max_suture_force_n},
                          {"max_suture_at_spacing_n", s.max_suture_at_spacing_n},
                          {"max_skin_tension_kpa", s.max_skin_tension_kpa},
                          {"strain_energy_mj", s.strain_energy_mj},
                          {"elements", s.elements},
                          {"nodes", s.nodes}};
  };
  return nlohmann::json{{"plan", plan_name},
                        {"constant_thickness_mm", c.constant_thickness_mm},
                        {"measured", side(c.measured_summary)},
                        {"constant", side(c.constant_summary)},
                        {"layers", side(c.layered_summary)},
                        {"warnings", c.warnings}}
      .dump(2, ' ', false, nlohmann::json::error_handler_t::replace);
}

}  // namespace caps::study
