#include "caps/fem/result_io.hpp"

#include <nlohmann/json.hpp>

#include "caps/core/atomic_output.hpp"
#include "caps/core/error.hpp"
#include "caps/fem/blas.hpp"
#include "caps/fem/material_registry.hpp"
#include "vtu.hpp"

#include <cmath>
#include <string>

namespace caps::fem {

void write_result_dir(const Mesh& mesh, const SolveResult& r, const std::filesystem::path& dir,
                      const SutureSpacing* sutures) {
  const Eigen::Index n = mesh.n_nodes();
  Eigen::MatrixXd fixed = Eigen::MatrixXd::Zero(n, 1), partner = Eigen::MatrixXd::Constant(n, 1, -1);
  for (int i : mesh.fixed_nodes) fixed(i, 0) = 1;
  for (const FixedDof& f : mesh.fixed_dofs) fixed(f.node, 0) = 1;
  for (const SuturePair& s : mesh.sutures) {
    partner(s.a, 0) = s.b;
    partner(s.b, 0) = s.a;
  }
  Eigen::MatrixXd layer(static_cast<Eigen::Index>(mesh.elements.size()), 1);
  for (std::size_t e = 0; e < mesh.elements.size(); ++e)
    layer(static_cast<Eigen::Index>(e), 0) = mesh.elements[e].layer;
  detail::write_vtu(dir / "result.vtu", mesh.nodes, mesh.elements,
                    {{"displacement", r.displacement_mm, false},
                     {"stress", r.nodal_stress_mpa, false},
                     {"von_mises", r.von_mises_mpa, false},
                     {"max_principal", r.max_principal_mpa, false},
                     {"reaction", r.reaction_n, false},
                     {"fixed", fixed, true},
                     {"suture_partner", partner, true}},
                    {{"layer", layer, true}, {"von_mises_mean", r.element_von_mises_mpa, false}});
  nlohmann::json j;
  j["format"] = "caps-result";
  j["version"] = 1;
  j["units"] = {{"length", "mm"}, {"force", "N"}, {"stress", "MPa"}, {"energy", "mJ"}};
  j["model"] = mesh.model;
  j["plan"] = mesh.plan;
  j["warnings"] = mesh.warnings;
  j["solver"] = r.solver;
  j["precision"] = {{"arithmetic", r.precision}, {"refinement_iterations", r.refinement_iterations},
                    {"fell_back_to_double", r.fell_back_to_double}};
  // The dense kernels the factorizations ran on (fem/blas.hpp): timings depend on them.
  j["blas_kernels"] = blas_core();
  j["sizes"] = {{"nodes", n}, {"elements", mesh.elements.size()}, {"dofs", r.n_dofs},
                {"equations", r.n_equations}, {"matrix_nonzeros_upper", r.n_nonzeros},
                {"factor_nonzeros", r.factor_nonzeros}};
  j["timings_s"] = {{"constraints", r.timings.constraints_s}, {"assembly", r.timings.assembly_s},
                    {"analysis", r.timings.analysis_s}, {"factorization", r.timings.factorization_s},
                    {"solve", r.timings.solve_s}, {"recovery", r.timings.recovery_s},
                    {"total", r.timings.total_s}};
  j["kinematics"] = r.kinematics;
  j["materials"] = nlohmann::json::array();  // what each layer was solved with
  for (const auto& [layer, m] : mesh.materials) {
    nlohmann::json entry = nlohmann::json::parse(material_json(*m));
    entry["layer"] = layer;
    j["materials"].push_back(entry);
  }
  j["prestretch"] = r.prestretch;
  if (!r.newton_steps.empty()) {
    nlohmann::json steps = nlohmann::json::array();
    for (const NewtonStep& s : r.newton_steps)
      steps.push_back({{"step", s.step},
                       {"lambda", s.lambda},
                       {"iterations", s.iterations},
                       {"cutbacks", s.cutbacks},
                       {"factorizations", s.factorizations},
                       {"relative_residuals", s.residual_norms},
                       {"line_search", s.line_search},
                       {"shifts", s.shifts},
                       {"corrections_mm", s.corrections_mm},
                       {"stagnated", s.stagnated}});
    j["newton"] = {{"iterations", r.newton_iterations}, {"factorizations", r.factorizations},
                   {"indefinite_factorizations", r.indefinite_factorizations},
                   {"secant_predictions", r.secant_predictions},
                   {"assemblies", r.assemblies},
                   {"steps", steps}, {"flap_rotations_deg", r.flap_rotations_deg}};
  }
  j["peak_memory_mb"] = r.peak_memory_mb;
  j["relative_residual"] = r.relative_residual;
  j["max_displacement_mm"] = r.displacement_mm.rowwise().norm().maxCoeff();
  j["max_von_mises_mpa"] = r.von_mises_mpa.maxCoeff();
  j["max_principal_mpa"] = r.max_principal_mpa.maxCoeff();
  j["strain_energy_mj"] = r.strain_energy_mj;
  j["total_suture_force_n"] = r.total_suture_force_n;
  j["sum_suture_magnitudes_n"] = r.sum_suture_magnitudes_n;
  if (sutures) {
    const auto stitches = [](const std::vector<SutureStitch>& v) {
      nlohmann::json row = nlohmann::json::array();
      for (const SutureStitch& s : v)
        row.push_back({{"position_mm", {s.position_mm.x(), s.position_mm.y(), s.position_mm.z()}},
                       {"force_n", s.force_n}, {"pairs", s.n_pairs}});
      return row;
    };
    j["sutures_at_spacing"] = {{"spacing_mm", sutures->spacing_mm},
                               {"wound_length_mm", sutures->wound_length_mm},
                               {"n_sutures", sutures->sutures.size()},
                               {"total_force_n", sutures->total_force_n},
                               {"max_suture_force_n", sutures->max_suture_force_n},
                               {"mean_suture_force_n", sutures->mean_suture_force_n},
                               {"force_per_mm_n", sutures->force_per_mm_n},
                               {"sutures", stitches(sutures->sutures)},
                               {"n_compressive", sutures->compressive.size()},
                               {"compressive_force_n", sutures->compressive_force_n},
                               {"compressive", stitches(sutures->compressive)}};
  }
  j["suture_forces"] = nlohmann::json::array();
  for (const SutureForce& s : r.suture_forces)
    j["suture_forces"].push_back({{"a", s.a}, {"b", s.b}, {"magnitude_n", s.magnitude_n},
                                  {"force_on_a_n", {s.force_on_a_n.x(), s.force_on_a_n.y(), s.force_on_a_n.z()}}});
  // Names are checked for UTF-8 where they enter (app); a replaced byte is better than a throw.
  write_text_atomic(dir / "result.json",
                    j.dump(1, ' ', false, nlohmann::json::error_handler_t::replace) + "\n");
}

namespace {

// The point array `name` of `dir`/result.vtu as #N×components, checked for size and finiteness.
Eigen::MatrixXd read_result_point_array(const std::filesystem::path& dir, const std::string& name,
                                        int components, Eigen::Index n_nodes) {
  const std::filesystem::path path = dir / "result.vtu";
  if (!std::filesystem::exists(path))
    throw IoError(cat(path.string(), ": missing; pass a `caps simulate` or `caps solve` output"));
  const detail::VtuContent v = detail::read_vtu(path);
  const auto it = v.arrays.find(name);
  if (it == v.arrays.end() || v.components.at(name) != components)
    throw InvalidInput(cat(path.string(), ": no ", components, "-component point array '", name,
                           "'; rerun `caps solve` or `caps simulate` to write it"));
  if (v.n_points != n_nodes || static_cast<Eigen::Index>(it->second.size()) != components * n_nodes)
    throw InvalidInput(cat(path.string(), ": ", v.n_points, " points, but the mesh has ", n_nodes,
                           " nodes; is it the result of this mesh?"));
  Eigen::MatrixXd out(n_nodes, components);
  for (Eigen::Index i = 0; i < components * n_nodes; ++i) {
    if (!std::isfinite(it->second[i]))
      throw InvalidInput(cat(path.string(), ": ", name, " of node ", i / components, " is not finite"));
    out(i / components, i % components) = it->second[i];
  }
  return out;
}

}  // namespace

Eigen::MatrixX3d read_result_displacement(const std::filesystem::path& dir, Eigen::Index n_nodes) {
  return read_result_point_array(dir, "displacement", 3, n_nodes);
}

Eigen::VectorXd read_result_max_principal(const std::filesystem::path& dir, Eigen::Index n_nodes) {
  return read_result_point_array(dir, "max_principal", 1, n_nodes).col(0);
}

}  // namespace caps::fem
