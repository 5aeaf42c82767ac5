#include "caps/fem/compare.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <vector>

#include "caps/core/atomic_output.hpp"
#include "caps/core/error.hpp"
#include "caps/surface/patient_model.hpp"

namespace caps::fem {
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
  for (const auto& f : r.suture_forces) s.max_suture_force_n = std::max(s.max_suture_force_n, f.magnitude_n);
  s.strain_energy_mj = r.strain_energy_mj;
  s.elements = static_cast<int>(c.mesh.n_elements());
  s.nodes = static_cast<int>(c.mesh.n_nodes());
  return s;
}

Comparison compare_thickness(const PatientModel& model, const plan::Plan& plan, double constant_mm,
                             const SimulateOptions& options) {
  if (constant_mm < 0 || constant_mm > 50)
    throw InvalidInput(cat("constant thickness ", constant_mm, " mm must be in [0, 50] (0: the median "
                           "measured under the wound)"));
  Comparison c;
  SimulateOptions measured = options;
  measured.continuum.constant_thickness_mm = 0;
  c.measured = simulate(model, plan, measured);
  c.constant_thickness_mm =
      constant_mm > 0 ? constant_mm : median(thickness_under_wound(c.measured, model));
  SimulateOptions constant = options;
  constant.continuum.constant_thickness_mm = c.constant_thickness_mm;
  // The same surface mesh for both: fix the extent the measured run settled on.
  constant.surface.extent_mm = c.measured.wound.surface.extent_mm;
  c.constant = simulate(model, plan, constant);
  c.measured_summary = summarize(c.measured, model, "measured thickness (volume)");
  c.constant_summary = summarize(c.constant, model,
                                 cat("constant ", fmt(c.constant_thickness_mm, 1), " mm (1992 assumption)"),
                                 c.constant_thickness_mm);
  return c;
}

void write_comparison(const Comparison& c, const PatientModel& model, const SimulateOptions& options,
                      const std::filesystem::path& dir, const std::string& plan_name) {
  namespace fs = std::filesystem;
  fs::create_directories(dir / "measured");
  fs::create_directories(dir / "constant");
  write_simulation(c.measured, model, options, dir / "measured", plan_name + ", measured thickness");
  SimulateOptions constant = options;
  constant.continuum.constant_thickness_mm = c.constant_thickness_mm;
  write_simulation(c.constant, model, constant, dir / "constant", plan_name + ", constant thickness");
  const auto& a = c.measured_summary;
  const auto& b = c.constant_summary;
  auto side = [](const SimulationSummary& s) {
    return nlohmann::json{{"label", s.label},
                          {"thickness_under_wound_mm", {{"mean", s.thickness_mean_mm},
                                                        {"min", s.thickness_min_mm},
                                                        {"max", s.thickness_max_mm}}},
                          {"max_displacement_mm", s.max_displacement_mm},
                          {"mean_displacement_near_wound_mm", s.mean_displacement_mm},
                          {"closing_force_n", s.closing_force_n},
                          {"max_suture_force_n", s.max_suture_force_n},
                          {"max_skin_tension_kpa", s.max_skin_tension_kpa},
                          {"strain_energy_mj", s.strain_energy_mj},
                          {"elements", s.elements},
                          {"nodes", s.nodes}};
  };
  const nlohmann::json j{{"plan", plan_name},
                         {"constant_thickness_mm", c.constant_thickness_mm},
                         {"measured", side(a)},
                         {"constant", side(b)}};
  write_text_atomic(dir / "comparison.json", j.dump(2) + "\n");

  auto row = [&](const std::string& what, const std::string& unit, double x, double y, int d = 2) {
    const double diff = y != 0 ? 100.0 * (x - y) / std::abs(y) : 0.0;
    return "<tr><td>" + what + "</td><td>" + unit + "</td><td>" + fmt(x, d) + "</td><td>" + fmt(y, d) +
           "</td><td>" + (y != 0 ? fmt(diff, 1) + " %" : "") + "</td></tr>\n";
  };
  std::string html =
      "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\n<title>caps compare: " +
      plan_name +
      "</title>\n<style>body{font-family:DejaVu Sans,Arial,sans-serif;max-width:1100px;margin:2em "
      "auto;color:#222}table{border-collapse:collapse}td,th{border:1px solid #bbb;padding:4px "
      "10px;text-align:right}td:first-child,th:first-child{text-align:left}img{max-width:100%;"
      "border:1px solid #ddd}.pair{display:flex;gap:12px}.pair div{flex:1}</style></head><body>\n"
      "<h1>Measured versus constant soft-tissue thickness</h1>\n<p>The plan <b>" + plan_name +
      "</b> simulated on the same skin twice: with the thickness measured in the patient's volume, "
      "and with a constant " + fmt(c.constant_thickness_mm, 1) +
      " mm (the median measured under the wound), the assumption the 1992 CAPS system made for "
      "surface scans. Both use the same surface mesh, so the results differ only in depth. "
      "Linear elasticity, the wound closed by suture constraints (docs/fem.md).</p>\n"
      "<table><tr><th>quantity</th><th>unit</th><th>measured</th><th>constant</th>"
      "<th>measured vs constant</th></tr>\n" +
      row("thickness under the wound, mean", "mm", a.thickness_mean_mm, b.thickness_mean_mm) +
      row("thickness under the wound, min", "mm", a.thickness_min_mm, b.thickness_min_mm) +
      row("thickness under the wound, max", "mm", a.thickness_max_mm, b.thickness_max_mm) +
      row("largest skin displacement", "mm", a.max_displacement_mm, b.max_displacement_mm) +
      row("mean skin displacement near the wound", "mm", a.mean_displacement_mm, b.mean_displacement_mm) +
      row("closing force across the wound", "N", a.closing_force_n, b.closing_force_n) +
      row("largest force on one suture pair", "N", a.max_suture_force_n, b.max_suture_force_n) +
      row("largest skin tension (max principal stress)", "kPa", a.max_skin_tension_kpa, b.max_skin_tension_kpa, 1) +
      row("strain energy", "mJ", a.strain_energy_mj, b.strain_energy_mj) +
      "</table>\n<h2>Cross-sections</h2>\n<div class=\"pair\"><div><p>measured</p><img "
      "src=\"measured/section.png\" alt=\"cross-section, measured thickness\"></div><div><p>constant"
      "</p><img src=\"constant/section.png\" alt=\"cross-section, constant thickness\"></div></div>\n"
      "<h2>Surface mesh (the same for both)</h2>\n<img src=\"measured/surface.png\" alt=\"surface "
      "mesh\">\n<p>Files: measured/ and constant/ hold mesh.vtu, result.vtu (ParaView), mesh.inp "
      "(CalculiX) and result.json; comparison.json holds this table.</p>\n</body></html>\n";
  write_text_atomic(dir / "report.html", html);
}

}  // namespace caps::fem
