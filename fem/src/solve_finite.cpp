// Finite-strain solve: total-Lagrangian elements, the prescribed values and suture gaps applied
// in load steps (lambda 0 -> 1), Newton-Raphson with a line search and automatic cut-back.

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <memory>
#include <optional>

#include "caps/core/error.hpp"
#include "caps/fem/elements.hpp"
#include "assemble.hpp"
#include "closing_path.hpp"
#include "direct_solver.hpp"
#include "elements_impl.hpp"
#include "solve_impl.hpp"

namespace caps::fem::detail {
namespace {

// Line search (Bonet & Wood 2008, sec. 9.6; Nocedal & Wright 2006, sec. 3.1 and 3.5): along the
// Newton direction dq (a descent direction: the tangent is positive definite, shifted if need
// be) a step alpha is accepted when the potential energy has dropped (Armijo, kArmijo) and its
// slope s(alpha) = -dq . grad has fallen to kSlopeRatio |s(0)| or is still downhill; otherwise
// alpha is cut back to the minimum of the quadratic through the energy at 0 and alpha and the
// slope at 0, kept within [0.1, 0.5] alpha. An inverted element at alpha halves it. The energy
// test keeps the iteration from bouncing between states past a buckling point; near convergence
// the energy changes at round-off level and the slope test alone decides.
constexpr double kSlopeRatio = 0.8;
constexpr double kArmijo = 1e-4;
constexpr int kMaxLineSearch = 12;
constexpr double kShiftedStepMm = 1.0;
// The first shift of an indefinite tangent, in units of |diag K| (see solve_system).
constexpr double kFirstShift = 1e-6;
// Levenberg-Marquardt memory: a line search that had to cut the step below kPoorStep of its
// start raises the next solve's shift tenfold; a full step lowers it tenfold.
constexpr double kPoorStep = 0.25;
// The forcing term of the inexact Newton iteration: each correction is solved to a relative
// residual eta = kForcing r_k (r_k: the Newton residual relative to the step's load), at most
// kMaxForcing. Full Newton takes r_k to about c r_k^2 (measured on the slab: 1, 0.02, 2e-5,
// 3e-10, so c = 0.02-1); the linear solve adds about eta r_k = kForcing r_k^2, below that.
constexpr double kForcing = 1e-2, kMaxForcing = 1e-3;
// CG iterations on a tangent with its own new factor (single precision: about two digits an
// iteration) before its direct solve is used instead.
constexpr int kMaxFreshIterations = 20;
// A residual this many times the step's load means the iteration diverges: cut back.
constexpr double kDivergence = 1e8;
// The layer SolveOptions::prestretch acts on: the one under the skin surface.
constexpr int kSkinLayer = 0;

// Why an attempt at a load step failed: an inverted element, a singular tangent or no
// convergence.
struct Failure {
  std::string what;
  int element = -1, gauss_point = -1, iteration = -1;
  double lambda = 0;  // the load factor the attempt aimed at
};

class FiniteProblem {
 public:
  FiniteProblem(const Mesh& mesh, const DofMap& map, double prestretch)
      : mesh_(mesh), map_(map), path_(mesh, map), prestretch_(prestretch) {
    // solve() has checked that every layer's material is hyperelastic.
    for (const auto& [layer, material] : mesh.materials) materials_[layer] = material.get();
  }

  const FiniteMaterials& materials() const { return materials_; }
  const ClosingPath& path() const { return path_; }
  bool prestretched() const { return prestretch_ != 1.0; }
  /// The skin layer's prestretch at load factor lambda: it grows linearly from none.
  LayerPrestretch prestretch_at(double lambda) const {
    return {kSkinLayer, 1.0 + lambda * (prestretch_ - 1.0)};
  }

  // Full displacement u = T q + u_p(lambda) (3N, mm): u_p = lambda g on a straight path.
  Eigen::VectorXd expand(const Eigen::VectorXd& q, double lambda) const {
    Eigen::VectorXd u = path_.at(lambda);
    for (std::size_t d = 0; d < map_.eq.size(); ++d)
      if (map_.eq[d] >= 0) u[static_cast<Eigen::Index>(d)] += q[map_.eq[d]];
    return u;
  }

  // Out-of-balance force and tangent at (q, lambda); the `lift` term gives the predictor.
  // Returns a failure when an element inverts.
  // `energy` (optional) receives the strain energy (mJ).
  std::optional<Failure> evaluate(const Eigen::VectorXd& q, double lambda, double load_lambda,
                                  const Eigen::VectorXd& lift, Assembly& sys,
                                  Eigen::VectorXd* unit_lift = nullptr,
                                  double* energy = nullptr) const {
    const Eigen::VectorXd u = expand(q, lambda);
    const FiniteAssembly a = assemble_finite(mesh_, map_, materials_, u, load_lambda, lift, true,
                                             sys, unit_lift, prestretch_at(load_lambda));
    if (a.inverted_element < 0) {
      const double sliding = add_sliding_supports(mesh_, map_, lift.size() ? Eigen::VectorXd(u + lift) : u,
                                                  true, sys, unit_lift);
      if (energy) *energy = a.energy_mj + sliding;
    }
    if (a.inverted_element >= 0)
      return Failure{inverted_message(a.inverted_element, a.inverted_gauss_point, a.det_F),
                     a.inverted_element, a.inverted_gauss_point};
    if (!sys.f.allFinite()) return Failure{"the out-of-balance force is not finite"};
    return std::nullopt;
  }

 private:
  const Mesh& mesh_;   // not owned; outlives the problem
  const DofMap& map_;  // not owned; outlives the problem
  ClosingPath path_;
  double prestretch_;
  FiniteMaterials materials_;
};

void check_options(const NewtonOptions& o) {
  if (o.n_steps < 1 || o.n_steps > 100000)
    throw InvalidInput(cat("newton: n_steps = ", o.n_steps, " must be in 1..100000"));
  if (o.snap_iterations < o.max_iterations)
    throw InvalidInput(cat("newton: snap_iterations = ", o.snap_iterations,
                           " must be at least max_iterations = ", o.max_iterations));
  if (o.max_iterations < 1 || o.max_cutbacks < 0 || o.reuse_iterations < 0 || o.grow_iterations < 0)
    throw InvalidInput(cat("newton: max_iterations = ", o.max_iterations, " must be >= 1 and max_cutbacks = ",
                           o.max_cutbacks, ", reuse_iterations = ", o.reuse_iterations,
                           ", grow_iterations = ", o.grow_iterations, " >= 0"));
  if (!(o.residual_tolerance > 0 && o.residual_tolerance < 1) ||
      !(o.displacement_tolerance > 0 && o.displacement_tolerance < 1) ||
      !(o.intermediate_tolerance > 0 && o.intermediate_tolerance < 1))
    throw InvalidInput(cat("newton: tolerances (", o.residual_tolerance, ", ",
                           o.displacement_tolerance, ", ", o.intermediate_tolerance,
                           ") must be in (0, 1)"));
  if (!(o.stagnation_tolerance >= o.residual_tolerance && o.stagnation_tolerance < 1))
    throw InvalidInput(cat("newton: stagnation_tolerance = ", o.stagnation_tolerance,
                           " must be in [residual_tolerance, 1)"));
}

}  // namespace

void solve_finite(const Mesh& mesh, const SolveOptions& options, const DofMap& map,
                  SolveResult& res) {
  const NewtonOptions& no = options.newton;
  check_options(no);
  const FiniteProblem problem(mesh, map, options.prestretch);
  res.flap_rotations_deg = problem.path().rotations_deg();
  auto t = Clock::now();
  Assembly sys = assemble_structure(mesh, map);
  res.n_nonzeros = sys.K.nonZeros();
  res.timings.assembly_s += seconds_since(t);
  auto solver = make_direct_solver(options.solver, options.mumps_ordering, options.mixed_precision);
  t = Clock::now();
  solver->analyze(sys.K, map.block_start);  // once: every tangent has this structure
  res.timings.analysis_s = seconds_since(t);

  const Eigen::VectorXd no_lift;
  Eigen::VectorXd f_ext = Eigen::VectorXd::Zero(map.n_eq), unit_lift;
  add_loads(mesh, map, 1.0, f_ext);
  // sys holds the tangent and out-of-balance force of the last converged state, and unit_lift
  // its -T^T K g: the next predictor is then f + dl (f_ext + unit_lift), without an assembly.
  bool at_converged_state = false;
  Eigen::VectorXd q = Eigen::VectorXd::Zero(map.n_eq);
  const double nominal = 1.0 / no.n_steps;
  double lambda = 0, dlambda = nominal;
  int step = 0, cutbacks = 0;
  // The solves snapping steps may take beyond max_iterations, over the whole solve: a closure
  // whose snaps fail and are cut back does not repeat them without end.
  int snap_solves_left = no.snap_iterations;
  bool cut_back = false;  // a step of this solve was cut back: steps grow only to the nominal size
  std::optional<Failure> inverted_in_step;  // the first inversion among the attempts of a step

  // The diagonal of K's stored upper triangle (the last entry of each column), for the shift.
  std::vector<Eigen::Index> diagonal(static_cast<std::size_t>(sys.K.cols()));
  for (Eigen::Index j = 0; j < sys.K.cols(); ++j) diagonal[j] = sys.K.outerIndexPtr()[j + 1] - 1;
  Eigen::VectorXd kept_diagonal(sys.K.cols());

  // A new factor of K solved to the inexact Newton step's tolerance: with the mixed-precision
  // solver, CG on K preconditioned by the new single-precision factor stops there instead of at
  // a direct solve's 1e-12 (half its iterations on the Cranium Z-plasty).
  auto factorize_and_solve = [&](Eigen::VectorXd& dq, double tolerance) {
    auto t0 = Clock::now();
    ++res.factorizations;
    solver->factorize(sys.K);
    res.timings.factorization_s += seconds_since(t0);
    t0 = Clock::now();
    std::optional<Eigen::VectorXd> x =
        solver->solve_reusing_factor(sys.K, sys.f, kMaxFreshIterations, tolerance);
    dq = x ? std::move(*x) : solver->solve(sys.f);
    res.timings.solve_s += seconds_since(t0);
  };

  // One solve of K dq = f. Past a buckling point (the free flaps pucker under the closure's
  // compression) the tangent is indefinite and its Newton direction need not lower the energy:
  // the tangent is then shifted, K + mu |diag(K)| with mu = 1e-6, 1e-5, ... until it is positive
  // definite (Levenberg-Marquardt; Nocedal & Wright 2006, sec. 3.4 and 6.3), which gives a
  // descent direction and leads to a stable (minimum-energy) equilibrium rather than the
  // unstable one. `shift` returns the mu used, 0 for the tangent itself. The shift takes the
  // diagonal's magnitude: strongly compressed elements give negative diagonal entries (the
  // geometric stiffness), which a multiple of diag(K) itself would make more negative still.
  // The smallest shift first: near a buckling point a larger one shortens the correction along
  // the soft mode so much that Newton creeps away from the unstable state micrometres a solve
  // (docs/fem.md, the forehead 75 deg Z-plasty with measured layers: over 15 minutes at 1e-4,
  // 188 s at 1e-6). `damping` > 0 starts at that shift without trying the tangent itself (the
  // Newton loop's Levenberg-Marquardt memory, below).
  auto solve_system = [&](Eigen::VectorXd& dq, double& shift, double tolerance,
                          double damping) -> std::optional<Failure> {
    shift = 0;
    const auto finite = [&]() -> std::optional<Failure> {
      if (dq.allFinite()) return std::nullopt;
      return Failure{"the Newton correction is not finite"};
    };
    std::string unshifted;  // why the tangent itself could not be factorized
    if (damping == 0) {
      if (no.reuse_iterations > 0) {
        const auto t0 = Clock::now();
        std::optional<Eigen::VectorXd> x =
            solver->solve_reusing_factor(sys.K, sys.f, no.reuse_iterations, tolerance);
        res.timings.solve_s += seconds_since(t0);
        if (x) {
          dq = std::move(*x);
          return finite();
        }
      }
      try {
        factorize_and_solve(dq, tolerance);
        return finite();
      } catch (const SingularMatrix& e) {
        unshifted = e.what();
      }
    }
    double* values = sys.K.valuePtr();
    for (Eigen::Index j = 0; j < sys.K.cols(); ++j) kept_diagonal[j] = values[diagonal[j]];
    bool solved = false;
    for (double mu = std::max(damping, kFirstShift); mu <= 1.01e2 && !solved; mu *= 10) {
      for (Eigen::Index j = 0; j < sys.K.cols(); ++j)
        values[diagonal[j]] = kept_diagonal[j] + mu * std::abs(kept_diagonal[j]);
      try {
        factorize_and_solve(dq, tolerance);
        solved = true;
        shift = mu;
      } catch (const SingularMatrix& e) {
        if (unshifted.empty()) unshifted = e.what();
      }
    }
    for (Eigen::Index j = 0; j < sys.K.cols(); ++j) values[diagonal[j]] = kept_diagonal[j];
    if (!solved)
      return Failure{cat("the tangent stiffness is not positive definite even shifted by 100 times "
                         "its diagonal (", unshifted, ")")};
    return finite();
  };

  while (lambda < 1.0) {
    const double lambda_new = 1.0 - lambda <= 1.0001 * dlambda ? 1.0 : lambda + dlambda;
    const double dl = lambda_new - lambda;
    const Eigen::VectorXd q_start = q;
    NewtonStep record;
    record.step = step + 1;
    record.lambda = lambda_new;
    record.cutbacks = cutbacks;
    std::optional<Failure> failure;

    // Predictor: the tangent at the converged state with the increment of the prescribed values
    // lifted, K dq = lambda_new f_ext - f_int - K (dl g).
    if (at_converged_state && problem.path().straight() && !problem.prestretched()) {
      sys.f += dl * (f_ext + unit_lift);
    } else {
      t = Clock::now();
      failure = problem.evaluate(q, lambda, lambda_new,
                                 problem.path().at(lambda_new) - problem.path().at(lambda), sys);
      res.timings.assembly_s += seconds_since(t);
    }
    at_converged_state = false;
    const double r0 = failure ? 0.0 : sys.f.norm();
    // The tolerances are relative to the nominal step: a step cut back k times has a first
    // residual and an increment 2^k times smaller, while the round-off in the element forces
    // that cancel in the residual does not shrink with it (measured on the Cranium Z-plasty:
    // halved steps stalled at 1e-8 of their own first residual against 1e-10).
    const double scale = std::max(1.0, nominal / dl);
    const double r_ref = scale * r0;
    // The potential energy of the current iterate at lambda_new; unknown for the predictor,
    // whose direction also moves the prescribed values (its step is judged by the slope alone).
    double energy = NAN;
    double r_prev = r0;  // the residual before the current correction
    // The shift the next solve starts from (Levenberg-Marquardt with memory: Nocedal & Wright
    // 2006, sec. 10.3; Nielsen 1999). Where the tangent is positive definite but its Newton step
    // is far too long (near a limit point the soft mode's stiffness tends to zero: measured on
    // the forehead 90 deg Z-plasty with measured layers, corrections of 44 mm cut by the line
    // search to 0.3 %, and 25 solves that did not lower the residual) a shifted tangent gives a
    // shorter step in a better direction, which the line search then accepts whole; each full
    // step lowers the shift again, so the last solves are plain Newton and converge
    // quadratically.
    double damping = 0;
    bool converged = false;
    // The potential after each solve and whether its tangent was shifted: a step still falling
    // through unstable states after max_iterations is a snap, given more solves.
    std::vector<double> potentials;
    std::vector<bool> shifted_solve;
    int limit = no.max_iterations;
    for (int it = 1; !failure && it <= limit; ++it) {
      ++res.newton_iterations;
      record.iterations = it;
      if (r0 == 0) {  // nothing to do in this step
        converged = true;
        break;
      }
      Eigen::VectorXd dq;
      double shift = 0;
      // Inexact Newton (Dembo, Eisenstat & Steihaug 1982): a correction solved to a relative
      // residual eta_k = kForcing ||r_k|| / ||r_ref|| (at most kMaxForcing) converges as fast as
      // an exact one (quadratically), and a reused factor gets there in fewer CG iterations.
      const double eta = std::min(kMaxForcing, kForcing * r_prev / r_ref);
      if ((failure = solve_system(dq, shift, eta, damping))) {
        failure->iteration = it;
        break;
      }
      const double s0 = dq.dot(sys.f);  // slope of the energy along dq at alpha = 0 (negated)
      // The potential at alpha = 0 (external loads do work lambda f_ext . q).
      const double pi0 = energy - lambda_new * f_ext.dot(q);
      // A shifted direction is long along the soft (buckling) mode: it is first cut to move no
      // dof by more than kShiftedStepMm.
      const double dq_max = dq.lpNorm<Eigen::Infinity>();
      const double alpha_start = shift > 0 && dq_max > kShiftedStepMm ? kShiftedStepMm / dq_max : 1.0;
      double alpha = alpha_start;
      std::optional<Failure> inverted, first_inverted;
      bool accepted = false;
      double energy_at = 0;
      for (int ls = 0; ls < kMaxLineSearch; ++ls) {
        t = Clock::now();
        inverted = problem.evaluate(q + alpha * dq, lambda_new, lambda_new, no_lift, sys, &unit_lift,
                                    &energy_at);
        res.timings.assembly_s += seconds_since(t);
        if (inverted) {
          if (!first_inverted) first_inverted = inverted;
          alpha *= 0.5;
          continue;
        }
        const double s = dq.dot(sys.f);
        const double pi = energy_at - lambda_new * f_ext.dot(q + alpha * dq);
        const double drop = pi0 - pi;  // > 0: the energy fell
        const bool energy_ok = std::isnan(pi0) || drop >= kArmijo * alpha * s0 ||
                               std::abs(drop) <= 1e-12 * std::max(std::abs(pi0), std::abs(pi));
        if (energy_ok && (std::abs(s) <= kSlopeRatio * std::abs(s0) || s0 * s > 0)) {
          accepted = true;
          break;
        }
        if (energy_ok) {
          // Past the minimum along dq (the slope changed sign): its root by linear interpolation.
          alpha *= std::clamp(s0 / (s0 - s), 0.1, 1.0);
        } else {
          // The energy rose: the minimum of the quadratic with pi(0), slope -s0 and pi(alpha).
          const double a_min = s0 * alpha * alpha / (2 * (s0 * alpha - drop));
          alpha = std::clamp(a_min, 0.1 * alpha, 0.5 * alpha);
        }
      }
      if (!accepted) {
        failure = first_inverted ? *first_inverted
                                 : Failure{"the line search found no step that lowers the energy"};
        failure->iteration = it;
        break;
      }
      energy = energy_at;
      q += alpha * dq;
      if (alpha < kPoorStep * alpha_start)
        damping = std::max(kFirstShift, 10 * shift);
      else if (alpha == alpha_start)
        damping = shift >= 10 * kFirstShift ? 0.1 * shift : 0.0;
      else
        damping = shift;
      record.line_search.push_back(alpha);
      record.shifts.push_back(shift);
      const double rn = sys.f.norm();
      record.residual_norms.push_back(rn / r0);
      if (!std::isfinite(rn) || rn > kDivergence * r0) {
        failure = Failure{cat("the Newton iteration diverges (residual ", rn / r0,
                              " times the step's load)"), -1, -1, it};
        break;
      }
      const double du = alpha * dq.norm(),
                   step_norm = std::max(scale * (q - q_start).norm(), 1e-300);
      // The correction the next iteration would make, estimated from this one and the residual's
      // fall (Abaqus's and CalculiX's test: c_next = c rn / r_prev, an overestimate once Newton
      // converges faster than linearly). Only after a full step along the tangent's own direction: a
      // shortened or shifted step says nothing about the next one. This spares the solve that
      // would take the residual from 1e-10 to round-off.
      const double du_next = alpha == 1.0 && shift == 0 && rn < r_prev ? du * rn / r_prev : du;
      r_prev = rn;
      // Converged; or at the round-off floor: a correction a thousand times below the tolerance
      // while the residual is within a hundred times of it (a residual cannot drop below the
      // rounding of the element forces that cancel in it). A step before the last only has to
      // be a good start for the next one (its left-over residual is carried into the next
      // predictor): it stops at intermediate_tolerance.
      const bool last = lambda_new == 1.0;
      const double r_tol =
          last ? no.residual_tolerance : std::max(no.residual_tolerance, no.intermediate_tolerance);
      const double d_tol =
          last ? no.displacement_tolerance : std::max(no.displacement_tolerance, no.intermediate_tolerance);
      if ((rn <= r_tol * r_ref && du_next <= d_tol * step_norm) ||
          (rn <= 1e2 * r_tol * r_ref && du <= 1e-3 * d_tol * step_norm)) {
        converged = true;
        break;
      }
      if (it == limit && rn <= no.stagnation_tolerance * r_ref &&
          du <= no.stagnation_tolerance * step_norm) {
        record.stagnated = true;
        converged = true;
        break;
      }
      potentials.push_back(energy - lambda_new * f_ext.dot(q));
      shifted_solve.push_back(shift > 0);
      if (it == limit && limit < no.snap_iterations && snap_solves_left > 0) {
        // Snapping: the tangent was shifted (indefinite, or its Newton steps far too long) in
        // the last max_iterations solves and the potential fell over them by more than
        // round-off.
        const std::size_t from = potentials.size() - static_cast<std::size_t>(no.max_iterations);
        const double fall = potentials[from] - potentials.back();
        const bool shifted =
            std::find(shifted_solve.begin() + static_cast<std::ptrdiff_t>(from), shifted_solve.end(),
                      true) != shifted_solve.end();
        if (shifted && fall > 1e-9 * std::abs(potentials.back())) {
          const int more = std::min({no.max_iterations, no.snap_iterations - limit, snap_solves_left});
          limit += more;
          snap_solves_left -= more;
        }
      }
    }
    if (converged) {
      record.residual_norms.insert(record.residual_norms.begin(), 1.0);
      res.newton_steps.push_back(record);
      ++step;
      lambda = lambda_new;
      cutbacks = 0;
      inverted_in_step.reset();
      at_converged_state = record.iterations > 0 && r0 > 0;
      if (options.reporter) {
        options.reporter->progress("closing the wound", lambda);
        options.reporter->check_cancelled();
      }
      // An easy step doubles the next: beyond the nominal size (up to what remains) until a step
      // of this solve has been cut back, then only back up to the nominal size.
      if (!cut_back && record.iterations <= no.grow_iterations)
        dlambda = 2 * dlambda;
      else if (record.iterations <= 4)
        dlambda = std::max(dlambda, std::min(2 * dlambda, nominal));
      continue;
    }
    if (!failure)
      failure = Failure{cat("Newton did not converge in ", record.iterations,
                            " iterations (last relative residual ",
                            record.residual_norms.empty() ? NAN : record.residual_norms.back(), ")"),
                        -1, -1, record.iterations};
    failure->lambda = lambda_new;
    // An inverted element is the cause worth reporting: smaller steps after it often fail
    // differently (a stiffening, ill-conditioned tangent near det F = 0).
    if (failure->element >= 0 && !inverted_in_step) inverted_in_step = failure;
    if (inverted_in_step) failure = inverted_in_step;
    q = q_start;
    dlambda = 0.5 * dl;  // half the step that failed (it may have been clipped to what remained)
    cut_back = true;
    if (++cutbacks > no.max_cutbacks) {
      throw SolverError(
          cat("finite-strain solve failed at load step ", step + 1, " (from lambda ", lambda,
              " towards ", failure->lambda, "; ", no.max_cutbacks, " halvings), Newton iteration ",
              failure->iteration, ": ", failure->what, "; the closure is too large for this mesh or material: refine the mesh, undermine "
              "more, or close the wound in more steps (n_steps)"),
          failure->element, failure->gauss_point, failure->iteration);
    }
  }
  res.factor_nonzeros = solver->factor_nonzeros();
  const SolverReport report = solver->report();
  res.precision = report.precision;
  res.refinement_iterations = report.iterations;
  res.fell_back_to_double = report.fell_back_to_double;
  // The last step's final residual relative to its load (the linear solve's measure).
  res.relative_residual = res.newton_steps.back().residual_norms.back();

  t = Clock::now();
  const Eigen::VectorXd u = problem.expand(q, 1.0);
  const Eigen::Index n_nodes = mesh.n_nodes();
  res.displacement_mm.resize(n_nodes, 3);
  for (Eigen::Index i = 0; i < n_nodes; ++i)
    for (int c = 0; c < 3; ++c) res.displacement_mm(i, c) = u[3 * i + c];
  const FiniteMaterials& mats = problem.materials();
  recover(mesh, map, [&](int e, ElementRecovery& out) {
    const Element& el = mesh.elements[e];
    const int nn = el.n_nodes();
    const Material& mat = *mats.at(el.layer);
    const Eigen::MatrixX3d X = element_coordinates(mesh, e);
    Eigen::VectorXd ue(3 * nn);
    for (int a = 0; a < nn; ++a) ue.segment<3>(3 * a) = u.segment<3>(3 * static_cast<Eigen::Index>(el.nodes[a]));
    Eigen::VectorXd fe;
    const double stretch = el.layer == kSkinLayer ? options.prestretch : 1.0;
    const FiniteKernelResult k = finite_kernel(el.type, X, mat, ue, e, fe, nullptr, stretch);
    if (k.inverted_at >= 0)  // not after a converged step, which evaluated this very state
      throw SolverError(inverted_message(e, k.inverted_at, k.det_F), e, k.inverted_at);
    out.energy_mj = k.energy_mj;
    out.f_int.resize(nn, 3);
    for (int a = 0; a < nn; ++a) out.f_int.row(a) = fe.segment<3>(3 * a).transpose();
    const auto& tab = shape_table(el.type);
    Eigen::MatrixX3d G(nn, 3);
    out.gauss_stress.resize(static_cast<Eigen::Index>(tab.w.size()), 6);
    Vector6d S;
    Matrix6d C;
    double vm = 0, w_sum = 0;
    for (std::size_t g = 0; g < tab.w.size(); ++g) {
      const double w = tab.w[g] * gradients(tab.dN[g], X, G, e, static_cast<int>(g));
      const Eigen::Matrix3d H = displacement_gradient(G, ue);
      const Eigen::Vector3d n = layer_normal(tab.dN[g], X);
      material_response(mat, H, &n, stretch, S, C);
      const Vector6d sigma = cauchy_from_pk2(H + Eigen::Matrix3d::Identity(), S);
      out.gauss_stress.row(static_cast<Eigen::Index>(g)) = sigma.transpose();
      vm += w * von_mises(sigma);
      w_sum += w;
    }
    out.von_mises_mean = vm / w_sum;
    const Eigen::MatrixX3d P = natural_nodes(el.type);
    out.nodal_stress.resize(nn, 6);
    // At a node the quadratic element's deformation gradient may fold (det F <= 0 at a corner
    // squeezed by the closure) while every Gauss point, where equilibrium is solved and checked,
    // is sound: such a node takes the stress of its nearest Gauss point.
    const auto& rule = quadrature(el.type);
    for (int a = 0; a < nn; ++a) {
      const Eigen::Vector3d xi = P.row(a).transpose();
      try {
        out.nodal_stress.row(a) = finite_cauchy_stress(el.type, X, mat, ue, xi, e, stretch).transpose();
      } catch (const SolverError&) {
        std::size_t nearest = 0;
        for (std::size_t g = 1; g < rule.size(); ++g)
          if ((rule[g].xi - xi).squaredNorm() < (rule[nearest].xi - xi).squaredNorm()) nearest = g;
        out.nodal_stress.row(a) = out.gauss_stress.row(static_cast<Eigen::Index>(nearest));
      }
    }
  }, res);
  res.timings.recovery_s = seconds_since(t);
}

}  // namespace caps::fem::detail
