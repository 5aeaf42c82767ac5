#include "caps/fem/solve.hpp"

#include <sys/resource.h>
#include <tbb/blocked_range.h>
#include <tbb/global_control.h>
#include <tbb/task_arena.h>
#include <tbb/parallel_for.h>

#include <Eigen/Dense>
#include <atomic>
#include <chrono>
#include <future>
#include <cmath>
#include <optional>

#include "caps/core/error.hpp"
#include "caps/fem/elements.hpp"
#include "assemble.hpp"
#include "constraints.hpp"
#include "direct_solver.hpp"
#include "elements_impl.hpp"
#include "solve_impl.hpp"

namespace caps::fem {
namespace {

using detail::Clock;
using detail::peak_rss_mb;
using detail::seconds_since;

// Pair forces of one suture group: node reactions R_n = sum over its pairs of +-lambda_k; the
// minimum-norm lambda (unique for a single pair, a tree of pairs or a consistent cycle).
void group_pair_forces(const Mesh& mesh, const std::vector<int>& members,
                       const std::vector<int>& pairs, const Eigen::MatrixX3d& R,
                       std::vector<SutureForce>& out) {
  const Eigen::Index nm = static_cast<Eigen::Index>(members.size());
  const Eigen::Index np = static_cast<Eigen::Index>(pairs.size());
  Eigen::MatrixXd D = Eigen::MatrixXd::Zero(nm, np);
  Eigen::MatrixXd Rm(nm, 3);
  auto local = [&](int node) {
    return static_cast<Eigen::Index>(std::find(members.begin(), members.end(), node) - members.begin());
  };
  for (Eigen::Index k = 0; k < np; ++k) {
    D(local(mesh.sutures[pairs[k]].a), k) += 1;
    D(local(mesh.sutures[pairs[k]].b), k) -= 1;
  }
  for (Eigen::Index i = 0; i < nm; ++i) Rm.row(i) = R.row(members[i]);
  const Eigen::MatrixXd L = D.completeOrthogonalDecomposition().solve(Rm);
  for (Eigen::Index k = 0; k < np; ++k) {
    SutureForce& s = out[pairs[k]];
    s.force_on_a_n = L.row(k).transpose();
    s.magnitude_n = s.force_on_a_n.norm();
  }
}

// The first element that uses `node`, -1 if none does (or node is -1).
int first_element_using(const Mesh& mesh, int node) {
  if (node < 0) return -1;
  for (std::size_t e = 0; e < mesh.elements.size(); ++e) {
    const Element& el = mesh.elements[e];
    for (int a = 0; a < el.n_nodes(); ++a)
      if (el.nodes[a] == node) return static_cast<int>(e);
  }
  return -1;
}

// Each layer's material must have a form under the solve's kinematics (material.hpp).
void check_materials(const Mesh& mesh, const SolveOptions& options) {
  for (const auto& [layer, material] : mesh.materials) {
    if (options.kinematics == Kinematics::Linear) {
      detail::small_strain_material(mesh, layer);
    } else if (!material->hyperelastic()) {
      throw InvalidInput(cat("layer ", layer, ": the finite-strain solve was given the '",
                             material->name(), "' material, which is not objective (a rotation "
                             "stresses it); use neo-hookean, or the small-strain solve"));
    }
  }
  // A tetrahedron has no layer plane (mesh.hpp): fibres in the skin's plane and the skin's
  // prestretch (layer 0, SolveOptions::prestretch) cannot be placed in it.
  if (options.kinematics != Kinematics::Finite) return;
  for (std::size_t e = 0; e < mesh.elements.size(); ++e) {
    const Element& el = mesh.elements[e];
    if (el.type != ElementType::Tet10) continue;
    const Material& m = *mesh.materials.at(el.layer);
    if (m.uses_layer_normal() || (options.prestretch != 1.0 && el.layer == 0))
      throw InvalidInput(cat("element ", e, " (Tet10, layer ", el.layer, "): ",
                             m.uses_layer_normal() ? cat("the '", m.name(), "' material")
                                                   : cat("prestretch ", options.prestretch),
                             " needs the plane of the skin's layer, which a tetrahedron does not "
                             "define; use neo-hookean without prestretch on Tet10 elements"));
  }
}

// A warm start (SolveOptions::initial_displacement_mm) is for the finite-strain solve, with one
// finite displacement per node.
void check_initial_displacement(const Mesh& mesh, const SolveOptions& options) {
  const Eigen::MatrixX3d& u0 = options.initial_displacement_mm;
  if (u0.size() > 0 && (options.kinematics != Kinematics::Finite || u0.rows() != mesh.n_nodes() ||
                        !u0.allFinite()))
    throw InvalidInput(cat("initial displacement (", u0.rows(), " rows): a warm start needs the "
                           "finite-strain solve and a finite displacement for each of the mesh's ",
                           mesh.n_nodes(), " nodes"));
}

}  // namespace

const char* solver_name(SolverKind kind) {
  switch (kind) {
    case SolverKind::Mumps: return "mumps";
    case SolverKind::Cholmod: return "cholmod";
    case SolverKind::Auto: break;
  }
  return "auto";
}

SolverKind parse_solver(const std::string& name) {
  if (name == "mumps") return SolverKind::Mumps;
  if (name == "cholmod") return SolverKind::Cholmod;
  if (name == "auto") return SolverKind::Auto;
  throw InvalidInput(cat("solver '", name, "' is unknown; use auto, mumps or cholmod"));
}

SolverKind resolved_solver(SolverKind kind, Kinematics kinematics, bool tied) {
  if (kind != SolverKind::Auto) return kind;
  return kinematics == Kinematics::Finite && tied ? SolverKind::Cholmod : SolverKind::Mumps;
}

const char* kinematics_name(Kinematics kinematics) {
  return kinematics == Kinematics::Linear ? "small-strain" : "finite-strain";
}

Kinematics parse_kinematics(const std::string& name) {
  if (name == "small-strain") return Kinematics::Linear;
  if (name == "finite-strain") return Kinematics::Finite;
  throw InvalidInput(cat("kinematics '", name,
                         "' is unknown; use small-strain (the 1992 model) or finite-strain"));
}

bool parse_precision(const std::string& name) {
  if (name == "mixed") return true;
  if (name == "double") return false;
  throw InvalidInput(cat("precision '", name, "' is unknown; use mixed or double"));
}

SolveResult solve(const Mesh& mesh, const SolveOptions& options) {
  const auto t_start = Clock::now();
  std::optional<tbb::global_control> threads;
  if (options.threads > 0)
    threads.emplace(tbb::global_control::max_allowed_parallelism, options.threads);
  if (options.blas_threads < kAutoBlasThreads)
    throw InvalidInput(cat("blas_threads ", options.blas_threads,
                           " must be >= 0 (0 = as configured) or kAutoBlasThreads (-1)"));
  validate(mesh);
  if (!(options.prestretch >= 1.0 && options.prestretch <= 1.5))
    throw InvalidInput(cat("prestretch ", options.prestretch, " must be in 1..1.5 (skin in vivo: "
                           "about 1.1-1.2; 1 = none)"));
  if (options.prestretch != 1.0 && options.kinematics != Kinematics::Finite)
    throw InvalidInput(cat("prestretch ", options.prestretch, " needs the large-deformation model: "
                           "use the neo-hookean material (the linear model has no prestress)"));
  check_initial_displacement(mesh, options);
  check_materials(mesh, options);
  SolveResult res;
  const SolverKind solver_kind =
      resolved_solver(options.solver, options.kinematics, !mesh.ties.empty());
  res.solver = solver_name(solver_kind);
  auto t = Clock::now();
  const detail::DofMap map = detail::build_dof_map(mesh);
  res.timings.constraints_s = seconds_since(t);
  const Eigen::Index n_nodes = mesh.n_nodes();
  res.n_dofs = 3 * n_nodes;
  res.n_equations = map.n_eq;
  if (map.n_eq == 0) throw InvalidInput("every degree of freedom is fixed; nothing to solve");
  const detail::BlasThreads blas(options.blas_threads != kAutoBlasThreads ? options.blas_threads
                                 : map.n_eq >= kTwoBlasThreadsFromEquations ? 2
                                                                             : 1);
  res.kinematics = kinematics_name(options.kinematics);
  res.prestretch = options.prestretch;
  if (options.kinematics == Kinematics::Finite) {
    detail::solve_finite(mesh, options, map, res);
    res.timings.total_s = seconds_since(t_start);
    res.peak_memory_mb = peak_rss_mb();
    return res;
  }

  // The analysis needs only K's structure: it runs on its own thread while the element
  // stiffnesses are computed and assembled (the two take about as long on this problem size).
  t = Clock::now();
  detail::Assembly sys = detail::assemble_structure(mesh, map);
  res.n_nonzeros = sys.K.nonZeros();
  Eigen::VectorXd q;
  {
    // Ties' penalties leave single precision too few digits (docs/fem.md, "Ties and sliding on
    // the bone"): a tied mesh is factored in double precision from the start.
    auto solver = detail::make_direct_solver(solver_kind, options.mumps_ordering,
                                             options.mixed_precision && mesh.ties.empty());
    try {
      auto analysis = std::async(options.threads == 1 ? std::launch::deferred : std::launch::async,
                                 [&] {
                                   const auto t0 = Clock::now();
                                   solver->analyze(sys.K, map.block_start);
                                   return seconds_since(t0);
                                 });
      // One core for the analysis, the others for the values.
      tbb::task_arena arena(std::max(1, tbb::this_task_arena::max_concurrency() - 1));
      arena.execute([&] { detail::assemble_values(mesh, map, sys); });
      detail::add_sliding_supports(mesh, map, map.g, {}, false, true, sys);
      detail::add_ties(mesh, map, map.g, {}, true, sys);
      res.timings.assembly_s = seconds_since(t);
      res.timings.analysis_s = analysis.get();
      t = Clock::now();
      solver->factorize(sys.K);
      res.factorizations = 1;
      res.timings.factorization_s = seconds_since(t);
      t = Clock::now();
      q = solver->solve(sys.f);
      res.timings.solve_s = seconds_since(t);
    } catch (const detail::SingularMatrix& e) {
      // The solver knows the equation; the message and SolverError::element name the mesh.
      const int dof = e.equation >= 0 ? detail::equation_dof(map, e.equation) : -1;
      throw SolverError(
          cat("the stiffness matrix is singular (", e.what(),
              e.equation >= 0 ? cat(", near ", detail::describe_equation(map, e.equation)) : "",
              "): the mesh is under-constrained, a part can still move or rotate freely (a "
              "mechanism, such as elements joined only along an edge); fix at least three "
              "non-collinear nodes of every connected part (e.g. the bottom layer on bone)"),
          first_element_using(mesh, dof >= 0 ? dof / 3 : -1));
    }
    res.factor_nonzeros = solver->factor_nonzeros();
    const detail::SolverReport report = solver->report();
    res.precision = report.precision;
    res.refinement_iterations = report.iterations;
    res.fell_back_to_double = report.fell_back_to_double;
  }
  if (!q.allFinite())
    throw SolverError(cat(res.solver, ": the solution contains NaN or Inf"));
  const Eigen::VectorXd r = sys.K.selfadjointView<Eigen::Upper>() * q - sys.f;
  const double fn = sys.f.norm();
  res.relative_residual = fn > 0 ? r.norm() / fn : r.norm();
  if (!(res.relative_residual < 1e-6))
    throw InvalidInput(cat("the solve is inaccurate (relative residual ", res.relative_residual,
                           "): the stiffness is nearly singular; check for under-constrained "
                           "parts, extreme material contrasts or badly shaped elements"));

  t = Clock::now();
  res.displacement_mm.resize(n_nodes, 3);
  for (Eigen::Index i = 0; i < n_nodes; ++i)
    for (int c = 0; c < 3; ++c) {
      const std::size_t d = 3 * static_cast<std::size_t>(i) + c;
      res.displacement_mm(i, c) = (map.eq[d] >= 0 ? q[map.eq[d]] : 0.0) + map.g[d];
    }

  // Recovery: Gauss stresses, nodal stresses (evaluated at the element's nodes and averaged),
  // strain energy and internal forces (for the reactions), all from the same stresses.
  detail::recover(mesh, map, [&](int e, detail::ElementRecovery& out) {
    const Element& el = mesh.elements[e];
    const int nn = el.n_nodes();
    const IsotropicElastic& mat = detail::small_strain_material(mesh, el.layer);
    const double lam = mat.lambda_mpa(), mu = mat.mu_mpa();
    const Eigen::MatrixX3d X = element_coordinates(mesh, e);
    Eigen::VectorXd ue(3 * nn);
    for (int a = 0; a < nn; ++a) ue.segment<3>(3 * a) = res.displacement_mm.row(el.nodes[a]).transpose();
    const auto& tab = detail::shape_table(el.type, mesh.wedge_rule);
    Eigen::MatrixX3d G(nn, 3), F = Eigen::MatrixX3d::Zero(nn, 3);
    out.gauss_stress.resize(static_cast<Eigen::Index>(tab.w.size()), 6);
    double vm = 0, w_sum = 0, en = 0;
    for (std::size_t g = 0; g < tab.w.size(); ++g) {
      const double det = detail::gradients(tab.dN[g], X, G, e, static_cast<int>(g));
      const Eigen::Matrix3d eps = detail::strain_tensor(G, ue);
      const Vector6d s = detail::stress_from_strain(eps, lam, mu);
      out.gauss_stress.row(static_cast<Eigen::Index>(g)) = s.transpose();
      Eigen::Matrix3d S;
      S << s[0], s[3], s[5], s[3], s[1], s[4], s[5], s[4], s[2];
      const double w = tab.w[g] * det;
      F += w * G * S;
      en += 0.5 * w * (S.array() * eps.array()).sum();
      vm += w * von_mises(s);
      w_sum += w;
    }
    out.von_mises_mean = vm / w_sum;
    out.energy_mj = en;
    out.f_int = F;
  }, res);
  res.timings.recovery_s = seconds_since(t);
  res.timings.total_s = seconds_since(t_start);
  res.peak_memory_mb = peak_rss_mb();
  return res;
}

namespace detail {

double seconds_since(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

double peak_rss_mb() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return static_cast<double>(u.ru_maxrss) / 1024.0;  // ru_maxrss is in KiB on Linux
}

void recover(const Mesh& mesh, const DofMap& map, const ElementRecoveryFn& element_recovery,
             SolveResult& res) {
  const Eigen::Index n_nodes = mesh.n_nodes();
  const int n_el = static_cast<int>(mesh.elements.size());
  res.gauss_offset.resize(n_el + 1);
  res.gauss_offset[0] = 0;
  for (int e = 0; e < n_el; ++e)
    res.gauss_offset[e + 1] = res.gauss_offset[e] +
        static_cast<int>(quadrature(mesh.elements[e].type, mesh.wedge_rule).size());
  res.gauss_stress_mpa.resize(res.gauss_offset[n_el], 6);
  res.element_von_mises_mpa.resize(n_el);
  Eigen::MatrixXd nodal_sum = Eigen::MatrixXd::Zero(n_nodes, 6);
  std::vector<int> nodal_count(n_nodes, 0);
  Eigen::MatrixX3d f_int = Eigen::MatrixX3d::Zero(n_nodes, 3);
  std::vector<double> energy(n_el, 0.0);
  std::vector<Eigen::MatrixXd> elem_nodal(n_el);
  // The nodes whose reactions are reported: constrained, sliding and tied (slave) nodes.
  std::vector<char> held(map.constrained);
  for (const SlidingNode& s : mesh.sliding) held[s.node] = 1;
  for (const TiedNode& t : mesh.ties) held[t.node] = 1;
  tbb::parallel_for(tbb::blocked_range<int>(0, n_el, 32), [&](const tbb::blocked_range<int>& rr) {
    ElementRecovery out;
    for (int e = rr.begin(); e < rr.end(); ++e) {
      const Element& el = mesh.elements[e];
      element_recovery(e, out);
      res.gauss_stress_mpa.middleRows(res.gauss_offset[e], out.gauss_stress.rows()) = out.gauss_stress;
      res.element_von_mises_mpa[e] = out.von_mises_mean;
      energy[e] = out.energy_mj;
      elem_nodal[e] = gauss_to_nodes(el.type, mesh.wedge_rule) * out.gauss_stress;
      for (int a = 0; a < el.n_nodes(); ++a)
        if (held[el.nodes[a]])
          for (int c = 0; c < 3; ++c)
            std::atomic_ref<double>(f_int(el.nodes[a], c)).fetch_add(out.f_int(a, c), std::memory_order_relaxed);
    }
  });
  for (int e = 0; e < n_el; ++e) {
    const Element& el = mesh.elements[e];
    for (int a = 0; a < el.n_nodes(); ++a) {
      nodal_sum.row(el.nodes[a]) += elem_nodal[e].row(a);
      ++nodal_count[el.nodes[a]];
    }
    res.strain_energy_mj += energy[e];
  }
  res.nodal_stress_mpa = Eigen::MatrixXd::Zero(n_nodes, 6);
  res.von_mises_mpa = Eigen::VectorXd::Zero(n_nodes);
  res.max_principal_mpa = Eigen::VectorXd::Zero(n_nodes);
  for (Eigen::Index i = 0; i < n_nodes; ++i) {
    if (!nodal_count[i]) continue;
    res.nodal_stress_mpa.row(i) = nodal_sum.row(i) / nodal_count[i];
    const Vector6d s = res.nodal_stress_mpa.row(i).transpose();
    res.von_mises_mpa[i] = von_mises(s);
    res.max_principal_mpa[i] = max_principal(s);
  }
  // Reactions: R = f_int - f_ext on constrained, sliding and tied nodes (the force the
  // supports, sutures and ties apply; a sliding support's is along its normal).
  res.reaction_n = Eigen::MatrixX3d::Zero(n_nodes, 3);
  for (Eigen::Index i = 0; i < n_nodes; ++i)
    if (held[i]) res.reaction_n.row(i) = f_int.row(i);
  for (const NodalLoad& l : mesh.loads)
    if (held[l.node]) res.reaction_n.row(l.node) -= l.force_n.transpose();
  res.suture_forces.resize(mesh.sutures.size());
  std::vector<std::vector<int>> group_pairs(map.groups.size());
  for (std::size_t k = 0; k < mesh.sutures.size(); ++k) {
    res.suture_forces[k].a = mesh.sutures[k].a;
    res.suture_forces[k].b = mesh.sutures[k].b;
    group_pairs[map.group[mesh.sutures[k].a]].push_back(static_cast<int>(k));
  }
  for (std::size_t gi = 0; gi < map.groups.size(); ++gi)
    group_pair_forces(mesh, map.groups[gi], group_pairs[gi], res.reaction_n, res.suture_forces);
  for (const SutureForce& s : res.suture_forces) {
    const Eigen::Vector3d d = (mesh.nodes.row(s.b) - mesh.nodes.row(s.a)).transpose();
    res.total_suture_force_n += d.norm() > 0 ? s.force_on_a_n.dot(d.normalized()) : s.magnitude_n;
    res.sum_suture_magnitudes_n += s.magnitude_n;
  }
  // The force the ties apply on the slave side, from the penalty itself: a tie's force on its
  // nodes is -k c_a gap (c = 1 on the slave, -w on the others), which sums to zero over them;
  // on the slave side (the slave and, in a mortar row, its face neighbours, which are slaves
  // too) it is the opposite of that on the master nodes, -k gap sum of the master weights.
  res.tie_force_n.setZero();
  res.tie_gap_max_mm = 0;
  std::vector<char> slave(static_cast<std::size_t>(n_nodes), 0);
  for (const TiedNode& t : mesh.ties) slave[t.node] = 1;
  for (std::size_t i = 0; i < mesh.ties.size(); ++i) {
    const TiedNode& t = mesh.ties[i];
    Eigen::Vector3d gap = res.displacement_mm.row(t.node).transpose();
    double master_weight = 0;
    for (std::size_t a = 0; a < t.masters.size(); ++a) {
      gap -= t.weights[a] * res.displacement_mm.row(t.masters[a]).transpose();
      if (!slave[t.masters[a]]) master_weight += t.weights[a];
    }
    res.tie_force_n -= map.tie_stiffness[i] * master_weight * gap;
    res.tie_gap_max_mm = std::max(res.tie_gap_max_mm, gap.norm());
  }
}

}  // namespace detail

}  // namespace caps::fem
