// Finite-strain solve: total-Lagrangian elements, the prescribed values and suture gaps applied
// in load steps (lambda 0 -> 1), Newton-Raphson with a line search and automatic cut-back.

#include <Eigen/Dense>
#include <algorithm>
#include <array>
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
// The shifts tried, a ladder of rungs: rung -1 is the tangent itself, rung k >= 0 the shift
// kFirstShift 10^k, up to kTopRung (100 |diag K|).
constexpr int kTopRung = 8;
constexpr int kNoRung = -2;
constexpr std::array<double, kTopRung + 1> kRungShifts{1e-6, 1e-5, 1e-4, 1e-3, 1e-2,
                                                       1e-1, 1.0,  1e1,  1e2};
double rung_shift(int k) { return k < 0 ? 0.0 : kRungShifts[static_cast<std::size_t>(k)]; }
// The rung of a shift (the nearest: shifts are products of rungs and powers of ten).
int shift_rung(double mu) {
  if (mu <= 0) return -1;
  return std::clamp(static_cast<int>(std::lround(std::log10(mu / kFirstShift))), 0, kTopRung);
}
// Levenberg-Marquardt memory: a line search that had to cut the step below kPoorStep of its
// start raises the next solve's shift tenfold; a full step lowers it tenfold.
constexpr double kPoorStep = 0.25;
// The forcing term of the inexact Newton iteration: each correction is solved to a relative
// residual eta = kForcing r_k (r_k: the Newton residual relative to the step's load), at most
// NewtonOptions::max_forcing. Full Newton takes r_k to about c r_k^2 (measured on the slab: 1,
// 0.02, 2e-5, 3e-10, so c = 0.02-1); the linear solve adds about eta r_k = kForcing r_k^2, below
// that.
constexpr double kForcing = 1e-2;
// CG iterations on a tangent with its own new factor (single precision: about two digits an
// iteration) before its direct solve is used instead.
constexpr int kMaxFreshIterations = 20;
// A residual this many times the step's load means the iteration diverges: cut back.
constexpr double kDivergence = 1e8;
// The layer SolveOptions::prestretch acts on: the one under the skin surface.
constexpr int kSkinLayer = 0;
// A sliding node farther than this off its curved surface after a Newton correction is put back
// on it (FiniteProblem::project_on_surface); the penalty's give is orders of magnitude less.
constexpr double kSurfaceProjectionMm = 1e-4;

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
      const double sliding = add_sliding_supports(mesh_, map_, u, lift, true, true, sys, unit_lift);
      const double tied = add_ties(mesh_, map_, u, lift, true, sys, unit_lift);
      if (energy) *energy = a.energy_mj + sliding + tied;
    }
    if (a.inverted_element >= 0)
      return Failure{inverted_message(a.inverted_element, a.inverted_gauss_point, a.det_F),
                     a.inverted_element, a.inverted_gauss_point};
    if (!sys.f.allFinite()) return Failure{"the out-of-balance force is not finite"};
    return std::nullopt;
  }

  // Second-order correction for sliding on a curved surface: each sliding node of `q` (at
  // load factor lambda) that a correction has left more than kSurfaceProjectionMm off its level
  // set is moved back onto it along grad phi, within its free dofs (two Newton steps of the
  // scalar equation phi(X + u) = phi(X)). A straight Newton correction leaves the curved surface
  // by d^2 / 2R, and the stiff penalty then stops the line search at a fraction of the step
  // (the Maratos effect; Nocedal & Wright 2006, sec. 15.5-15.6); the nodes' positions within
  // the penalty's give are left to Newton. Returns whether q changed.
  bool project_on_surface(Eigen::VectorXd& q, double lambda) const {
    if (!mesh_.sliding_surface) return false;
    bool changed = false;
    for (int pass = 0; pass < 2; ++pass) {
      const Eigen::VectorXd u = expand(q, lambda);
      for (const SlidingNode& s : mesh_.sliding) {
        if (!s.on_surface) continue;
        const Eigen::Index base = 3 * static_cast<Eigen::Index>(s.node);
        const Eigen::Vector3d X = mesh_.nodes.row(s.node).transpose(), x = X + u.segment<3>(base);
        const double r = mesh_.sliding_surface->distance(x) - mesh_.sliding_surface->distance(X);
        if (!(std::abs(r) > kSurfaceProjectionMm)) continue;
        Eigen::Vector3d g = mesh_.sliding_surface->gradient(x);
        for (int c = 0; c < 3; ++c)
          if (map_.eq[base + c] < 0) g[c] = 0;
        if (!(g.squaredNorm() > 1e-12)) continue;
        const Eigen::Vector3d du = -r * g / g.squaredNorm();
        for (int c = 0; c < 3; ++c)
          if (map_.eq[base + c] >= 0) q[map_.eq[base + c]] += du[c];
        changed = true;
      }
    }
    return changed;
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
  if (!(o.max_solves >= 1 && o.max_steps >= 1))
    throw InvalidInput(cat("newton: max_solves = ", o.max_solves, " and max_steps = ", o.max_steps,
                           " must be >= 1"));
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
  if (!(o.max_forcing >= 1e-12 && o.max_forcing < 1))
    throw InvalidInput(cat("newton: max_forcing = ", o.max_forcing, " must be in [1e-12, 1)"));
  if (!(o.stagnation_tolerance >= o.residual_tolerance && o.stagnation_tolerance < 1))
    throw InvalidInput(cat("newton: stagnation_tolerance = ", o.stagnation_tolerance,
                           " must be in [residual_tolerance, 1)"));
}

const NewtonOptions& checked(const NewtonOptions& o) {
  check_options(o);
  return o;
}

// One attempt at a load step: its target, the state it started from and how far its Newton
// iteration has come.
struct StepAttempt {
  double lambda_new = 0, dl = 0;
  Eigen::VectorXd q_start;  // the state the step started from: a cut-back returns to it
  NewtonStep record;
  std::optional<Failure> failure;
  double r0 = 0;     // the step's predictor load ||r_0||
  double scale = 1;  // the tolerances' scale: the nominal step over this one, at least 1
  double r_ref = 0;  // scale r0
  // The potential energy of the current iterate at lambda_new; unknown for the predictor,
  // whose direction also moves the prescribed values (its step is judged by the slope alone).
  double energy = NAN;
  double r_prev = 0;  // the residual before the current correction
  // The first solve is the tangent predictor's: the tangent of the converged state the step
  // starts from (no secant trial taken), the same in every attempt at this step.
  bool tangent_predictor = false;
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
  int limit = 0;  // the solves this attempt may take (max_iterations, more while it snaps)
};

// What one Newton iteration of a step came to.
enum class IterationOutcome { Continue, Converged, Failed };

// The load-stepping Newton-Raphson solve of one finite-strain problem (MFEM's NewtonSolver,
// deal.II step-44's setup / assemble / solve in short named steps): construction sets up the
// tangent's structure and its analysis, run() steps the load factor from 0 to 1 (or starts
// from a given state, a warm start) and recovers the stresses and forces. Each step is a
// predictor and Newton iterations (a shifted solve of the tangent, a line search, the
// convergence test, snap-through handling); a step that fails is cut back, one that converged
// easily lets the next grow.
class FiniteStrainSolver {
 public:
  FiniteStrainSolver(const Mesh& mesh, const SolveOptions& options, const DofMap& map,
                     SolveResult& res);

  /// Solves, from SolveOptions::initial_displacement_mm when given (a warm start), and fills
  /// the result.
  void run();

 private:
  // Warm start: the whole closure as one step from the given state; false if it failed (the
  // solve then starts afresh from the reference state).
  bool warm_start();
  // The next step's target (lambda_new, at most what remains) from the converged state.
  StepAttempt begin_step();
  // The predictor's out-of-balance force in sys_, its norm r0 and the tolerances' scale;
  // s.failure if the predictor state inverts an element.
  void predictor(StepAttempt& s);
  // The secant predictor, when it starts the step closer to equilibrium (see the definition).
  void extrapolate(StepAttempt& s);
  // Newton iterations until the step converges or fails (s.converged, s.failure).
  void iterate(StepAttempt& s);
  IterationOutcome newton_iteration(StepAttempt& s, int it);
  // The step length along dq the line search accepts (its state assembled in sys_), or a failure.
  std::optional<Failure> line_search(StepAttempt& s, const Eigen::VectorXd& dq, double& alpha,
                                     double& energy_at);
  // problem_.evaluate, timed and counted (SolveResult::assemblies).
  std::optional<Failure> assemble(const Eigen::VectorXd& q, double lambda, double load_lambda,
                                  const Eigen::VectorXd& dpath, Eigen::VectorXd* unit_lift = nullptr,
                                  double* energy = nullptr);
  // Whether the state the step's first solve started from, at lambda_new, inverts `element`.
  bool lift_inverts(StepAttempt& s, int element);
  // Convergence of the iteration that moved q by du (alpha dq) to residual rn.
  bool converged(const StepAttempt& s, double rn, double du, double du_next,
                 double step_norm) const;
  // A step still falling through unstable states after `limit` solves is given more.
  void extend_for_snap(StepAttempt& s);
  void accept_step(const StepAttempt& s);
  // SolverError when the closure has used its budget (NewtonOptions::max_solves, max_steps,
  // SolveOptions::time_limit_s) before the next solve of s.
  void check_budget(const StepAttempt& s) const;
  void grow_step(const NewtonStep& record);
  void cut_back_step(StepAttempt& s);
  // One solve of the tangent, shifted where it is not positive definite.
  std::optional<Failure> solve_shifted(Eigen::VectorXd& dq, double& shift, double tolerance,
                                       double damping, bool factor_is_shifted_tangent = false,
                                       double guess = 0);
  void factorize_and_solve(Eigen::VectorXd& dq, double tolerance);
  // K dq = f by conjugate gradients preconditioned with the solver's last factor, in at most
  // max_iterations (timed as a solve); false, dq untouched, if they did not get there.
  // `negative_curvature` (optional): set when CG met a direction of non-positive curvature (the
  // tangent is then not positive definite).
  bool solve_with_last_factor(Eigen::VectorXd& dq, int max_iterations, double tolerance,
                              bool* negative_curvature = nullptr);
  void finish_report();
  void recover_result();
  void recover_element(const Eigen::VectorXd& u, int e, ElementRecovery& out) const;

  const Mesh& mesh_;
  const SolveOptions& options_;
  const NewtonOptions& no_;
  const DofMap& map_;
  SolveResult& res_;
  FiniteProblem problem_;
  Assembly sys_;
  std::unique_ptr<DirectSolver> solver_;
  const Eigen::VectorXd no_lift_;
  Eigen::VectorXd f_ext_, unit_lift_;
  Eigen::VectorXd q_trial_;  // the line search's state (q + alpha dq, put back on the surfaces)
  bool projected_ = false;   // q_trial_ was put back on the surfaces
  // The diagonal of K's stored upper triangle (the last entry of each column), for the shift.
  std::vector<Eigen::Index> diagonal_;
  Eigen::VectorXd kept_diagonal_;
  // The shift the last step's first solve needed: the next step's first solve guesses it.
  double first_shift_ = 0;

  // sys_ holds the tangent and out-of-balance force of the last converged state, and unit_lift_
  // its -T^T K g: the next predictor is then f + dl (f_ext + unit_lift), without an assembly.
  bool at_converged_state_ = false;
  Eigen::VectorXd q_;
  double nominal_ = 1, lambda_ = 0, dlambda_ = 1;
  // The largest step a step grows back to after a cut-back: the nominal step, halved by each
  // cut-back of this solve down to a quarter of it (grow_step()); below the nominal step once a
  // step of this solve has been cut back.
  double growth_cap_ = 1;
  int step_ = 0, cutbacks_ = 0;
  int step_factorizations_from_ = 0;  // res_.factorizations when the current step began
  // The solves snapping steps may take beyond max_iterations, over the whole solve: a closure
  // whose snaps fail and are cut back does not repeat them without end.
  int snap_solves_left_ = 0;
  std::optional<Failure> inverted_in_step_;  // the first inversion among the attempts of a step
  Clock::time_point started_ = Clock::now();
  // The last accepted step's start and size, for the secant predictor (0: none yet).
  Eigen::VectorXd q_last_start_;
  double last_dl_ = 0;
  Eigen::VectorXd predicted_f_, predicted_values_;  // the tangent predictor's f and K (extrapolate())
  // The shift the tangent of the converged state needed in a step's first solve, after step_
  // accepted steps, and res_.factorizations after it. A step cut back starts again from that
  // tangent: its first solve starts at that shift instead of climbing the ladder again, and
  // reuses the factor while it is the solver's last (Cranium, the page's default Z-plasty on
  // the forehead: the same indefinite tangent was factorized five times, shifts 0 to 1e-3, in
  // each of four attempts at one step; docs/fem.md, "Inexact Newton").
  struct StartTangent {
    int step = -1;
    double shift = 0;
    int factorizations = -1;
  } start_tangent_;
};

FiniteStrainSolver::FiniteStrainSolver(const Mesh& mesh, const SolveOptions& options,
                                       const DofMap& map, SolveResult& res)
    : mesh_(mesh), options_(options), no_(checked(options.newton)), map_(map), res_(res),
      problem_(mesh, map, options.prestretch) {
  res_.flap_rotations_deg = problem_.path().rotations_deg();
  auto t = Clock::now();
  sys_ = assemble_structure(mesh, map);
  res_.n_nonzeros = sys_.K.nonZeros();
  res_.timings.assembly_s += seconds_since(t);
  // A tied mesh in double precision from the start (as the linear solve, solve.cpp).
  solver_ = make_direct_solver(
      resolved_solver(options.solver, Kinematics::Finite, !mesh.ties.empty()),
      options.mumps_ordering, options.mixed_precision && mesh.ties.empty());
  t = Clock::now();
  solver_->analyze(sys_.K, map.block_start);  // once: every tangent has this structure
  res_.timings.analysis_s = seconds_since(t);

  f_ext_ = Eigen::VectorXd::Zero(map.n_eq);
  add_loads(mesh, map, 1.0, f_ext_);
  q_ = Eigen::VectorXd::Zero(map.n_eq);
  nominal_ = 1.0 / no_.n_steps;
  dlambda_ = nominal_;
  growth_cap_ = nominal_;
  snap_solves_left_ = no_.snap_iterations;

  diagonal_.resize(static_cast<std::size_t>(sys_.K.cols()));
  for (Eigen::Index j = 0; j < sys_.K.cols(); ++j) diagonal_[j] = sys_.K.outerIndexPtr()[j + 1] - 1;
  kept_diagonal_.resize(sys_.K.cols());
}

void FiniteStrainSolver::run() {
  if (options_.initial_displacement_mm.size() == 0 || !warm_start()) {
    while (lambda_ < 1.0) {
      StepAttempt s = begin_step();
      predictor(s);
      iterate(s);
      if (s.converged)
        accept_step(s);
      else
        cut_back_step(s);
    }
  }
  finish_report();
  recover_result();
}

// A warm start (SolveOptions::initial_displacement_mm: a converged closure of a nearby problem,
// or of this one): the whole closure is one step, lambda 0 -> 1, whose Newton iteration starts
// at the given state instead of the predictor. Its tolerances are those of a one-step solve
// from the reference state (the predictor load of the whole closure, the displacement from the
// reference), so a given state that is already the solution converges in one solve. If the step
// fails, the solve starts afresh from the reference state and steps the load as without it.
bool FiniteStrainSolver::warm_start() {
  const Eigen::MatrixX3d& u0 = options_.initial_displacement_mm;
  StepAttempt s;
  s.lambda_new = 1.0;
  s.dl = 1.0;
  s.q_start = Eigen::VectorXd::Zero(map_.n_eq);  // the reference state, for the tolerances
  s.record.step = 1;
  s.record.lambda = 1.0;
  s.limit = no_.max_iterations;
  // The reference load: the predictor load of the whole closure from the reference state.
  s.failure = assemble(s.q_start, 0.0, 1.0, problem_.path().at(1.0) - problem_.path().at(0.0));
  s.r0 = s.failure ? 0.0 : sys_.f.norm();
  // The given state's unknowns: u = T q + u_p(1).
  const Eigen::VectorXd u_p = problem_.path().at(1.0);
  Eigen::VectorXd q0 = Eigen::VectorXd::Zero(map_.n_eq);
  for (std::size_t d = 0; d < map_.eq.size(); ++d)
    if (map_.eq[d] >= 0)
      q0[map_.eq[d]] = u0(static_cast<Eigen::Index>(d / 3), static_cast<Eigen::Index>(d % 3)) -
                       u_p[static_cast<Eigen::Index>(d)];
  if (s.r0 > 0) s.failure = assemble(q0, 1.0, 1.0, no_lift_, &unit_lift_, &s.energy);
  if (s.r0 > 0 && !s.failure) {
    s.scale = std::max(1.0, nominal_ / s.dl);
    s.r_ref = s.scale * s.r0;
    s.r_prev = sys_.f.norm();
    q_ = q0;
    iterate(s);
    if (s.converged) {
      accept_step(s);
      return true;
    }
  }
  // Afresh from the reference state, as without a warm start (the failed attempt's solves stay
  // counted).
  q_.setZero();
  lambda_ = 0;
  dlambda_ = growth_cap_ = nominal_;
  step_ = cutbacks_ = 0;
  snap_solves_left_ = no_.snap_iterations;
  inverted_in_step_.reset();
  at_converged_state_ = false;
  return false;
}

StepAttempt FiniteStrainSolver::begin_step() {
  StepAttempt s;
  s.lambda_new = 1.0 - lambda_ <= 1.0001 * dlambda_ ? 1.0 : lambda_ + dlambda_;
  s.dl = s.lambda_new - lambda_;
  s.q_start = q_;
  s.record.step = step_ + 1;
  s.record.lambda = s.lambda_new;
  s.record.cutbacks = cutbacks_;
  s.limit = no_.max_iterations;
  return s;
}

// Predictor: the tangent at the converged state with the increment of the prescribed values
// lifted, K dq = lambda_new f_ext - f_int - K (dl g).
void FiniteStrainSolver::predictor(StepAttempt& s) {
  if (at_converged_state_ && problem_.path().straight() && !problem_.prestretched()) {
    sys_.f += s.dl * (f_ext_ + unit_lift_);
  } else {
    s.failure = assemble(q_, lambda_, s.lambda_new,
                         problem_.path().at(s.lambda_new) - problem_.path().at(lambda_));
  }
  at_converged_state_ = false;
  s.r0 = s.failure ? 0.0 : sys_.f.norm();
  // The tolerances are relative to the nominal step: a step cut back k times has a first
  // residual and an increment 2^k times smaller, while the round-off in the element forces
  // that cancel in the residual does not shrink with it (measured on the Cranium Z-plasty:
  // halved steps stalled at 1e-8 of their own first residual against 1e-10).
  s.scale = std::max(1.0, nominal_ / s.dl);
  s.r_ref = s.scale * s.r0;
  s.r_prev = s.r0;
  if (!s.failure && s.r0 > 0) extrapolate(s);
}

// The secant predictor (issue 35: a predictor that follows the last step's solution): the
// step starts at the last step's increment scaled to this one, q + dl / dl_last (q - q_last),
// at lambda_new, when its out-of-balance force is smaller than the tangent predictor's load;
// its Newton iteration then starts there instead of with the tangent predictor's solve. Else
// the tangent predictor, as without it. r0 stays the tangent predictor's load (the tolerances'
// reference).
void FiniteStrainSolver::extrapolate(StepAttempt& s) {
  s.tangent_predictor = true;
  if (!no_.secant_predictor || last_dl_ <= 0) return;
  q_trial_ = q_ + (s.dl / last_dl_) * (q_ - q_last_start_);
  problem_.project_on_surface(q_trial_, s.lambda_new);
  // The tangent predictor's system, put back if the trial is no nearer (no second assembly).
  predicted_f_ = sys_.f;
  predicted_values_ = Eigen::Map<const Eigen::VectorXd>(sys_.K.valuePtr(), sys_.K.nonZeros());
  double energy = NAN;
  const std::optional<Failure> inverted =
      assemble(q_trial_, s.lambda_new, s.lambda_new, no_lift_, &unit_lift_, &energy);
  const double rn = inverted ? INFINITY : sys_.f.norm();
  if (std::isfinite(rn) && rn < s.r0) {
    s.tangent_predictor = false;
    q_ = q_trial_;
    s.energy = energy;
    s.r_prev = rn;
    ++res_.secant_predictions;
    return;
  }
  // Back to the tangent predictor.
  sys_.f = predicted_f_;
  Eigen::Map<Eigen::VectorXd>(sys_.K.valuePtr(), sys_.K.nonZeros()) = predicted_values_;
}

void FiniteStrainSolver::iterate(StepAttempt& s) {
  for (int it = 1; !s.failure && it <= s.limit; ++it) {
    const IterationOutcome outcome = newton_iteration(s, it);
    if (outcome == IterationOutcome::Converged) s.converged = true;
    if (outcome != IterationOutcome::Continue) break;
  }
}

// One Newton iteration: a (shifted) solve of the tangent, a line search along its direction,
// the convergence test and, after the step's last allowed solve, the snap-through test.
IterationOutcome FiniteStrainSolver::newton_iteration(StepAttempt& s, int it) {
  if (options_.reporter) options_.reporter->check_cancelled();
  check_budget(s);
  ++res_.newton_iterations;
  NewtonStep& record = s.record;
  record.iterations = it;
  if (s.r0 == 0) return IterationOutcome::Converged;  // nothing to do in this step
  Eigen::VectorXd dq;
  double shift = 0;
  // Inexact Newton (Dembo, Eisenstat & Steihaug 1982): a correction solved to a relative
  // residual eta_k = kForcing ||r_k|| / ||r_ref|| (at most max_forcing) converges as fast as
  // an exact one (quadratically), and a reused factor gets there in fewer CG iterations.
  const double eta = std::min(no_.max_forcing, kForcing * s.r_prev / s.r_ref);
  const bool start_tangent = it == 1 && s.tangent_predictor;
  const bool known_start = start_tangent && start_tangent_.step == step_;
  if (known_start) s.damping = start_tangent_.shift;
  const bool reuse_start = known_start && start_tangent_.shift > 0 && no_.reuse_iterations > 0 &&
                           start_tangent_.factorizations == res_.factorizations;
  const double guess = it == 1 && !known_start ? first_shift_ : 0.0;
  if ((s.failure = solve_shifted(dq, shift, eta, s.damping, reuse_start, guess))) {
    s.failure->iteration = it;
    return IterationOutcome::Failed;
  }
  if (it == 1) first_shift_ = shift;
  if (start_tangent) start_tangent_ = {step_, shift, res_.factorizations};
  // A shifted direction is long along the soft (buckling) mode: it is first cut to move no
  // dof by more than kShiftedStepMm.
  const double dq_max = dq.lpNorm<Eigen::Infinity>();
  const double alpha_start = shift > 0 && dq_max > kShiftedStepMm ? kShiftedStepMm / dq_max : 1.0;
  double alpha = alpha_start, energy_at = 0;
  if ((s.failure = line_search(s, dq, alpha, energy_at))) {
    s.failure->iteration = it;
    return IterationOutcome::Failed;
  }
  s.energy = energy_at;
  // alpha |dq|, or the move including the projection onto the surface
  const double du = projected_ ? (q_trial_ - q_).norm() : alpha * dq.norm();
  const double du_max = projected_ ? (q_trial_ - q_).lpNorm<Eigen::Infinity>() : alpha * dq_max;
  q_ = q_trial_;
  const double rn = sys_.f.norm();
  if (alpha < kPoorStep * alpha_start)
    s.damping = std::max(kFirstShift, 10 * shift);
  else if (alpha == alpha_start)
    s.damping = rung_shift(shift_rung(shift) - 1);
  else
    s.damping = shift;
  record.line_search.push_back(alpha);
  record.shifts.push_back(shift);
  record.corrections_mm.push_back(du_max);
  record.residual_norms.push_back(rn / s.r0);
  if (!std::isfinite(rn) || rn > kDivergence * s.r0) {
    s.failure = Failure{cat("the Newton iteration diverges (residual ", rn / s.r0,
                            " times the step's load)"), -1, -1, it};
    return IterationOutcome::Failed;
  }
  const double step_norm = std::max(s.scale * (q_ - s.q_start).norm(), 1e-300);
  // The correction the next iteration would make, estimated from this one and the residual's
  // fall (Abaqus's and CalculiX's test: c_next = c rn / r_prev, an overestimate once Newton
  // converges faster than linearly). Only after a full step along the tangent's own direction: a
  // shortened or shifted step says nothing about the next one. This spares the solve that
  // would take the residual from 1e-10 to round-off.
  const double du_next = alpha == 1.0 && shift == 0 && rn < s.r_prev ? du * rn / s.r_prev : du;
  s.r_prev = rn;
  if (converged(s, rn, du, du_next, step_norm)) return IterationOutcome::Converged;
  if (it == s.limit && rn <= no_.stagnation_tolerance * s.r_ref &&
      du <= no_.stagnation_tolerance * step_norm) {
    record.stagnated = true;
    return IterationOutcome::Converged;
  }
  s.potentials.push_back(s.energy - s.lambda_new * f_ext_.dot(q_));
  s.shifted_solve.push_back(shift > 0);
  if (it == s.limit) extend_for_snap(s);
  return IterationOutcome::Continue;
}

// Line search (see kSlopeRatio): from alpha (its start), the step along dq whose state lowers
// the potential and the slope; its state's out-of-balance force and tangent are left in sys_.
std::optional<Failure> FiniteStrainSolver::line_search(StepAttempt& s, const Eigen::VectorXd& dq,
                                                       double& alpha, double& energy_at) {
  const double s0 = dq.dot(sys_.f);  // slope of the energy along dq at alpha = 0 (negated)
  // The potential at alpha = 0 (external loads do work lambda f_ext . q).
  const double pi0 = s.energy - s.lambda_new * f_ext_.dot(q_);
  std::optional<Failure> inverted, first_inverted;
  for (int ls = 0; ls < kMaxLineSearch; ++ls) {
    if (options_.reporter) options_.reporter->check_cancelled();
    const auto t = Clock::now();
    q_trial_ = q_ + alpha * dq;
    projected_ = problem_.project_on_surface(q_trial_, s.lambda_new);
    res_.timings.assembly_s += seconds_since(t);
    inverted = assemble(q_trial_, s.lambda_new, s.lambda_new, no_lift_, &unit_lift_, &energy_at);
    if (inverted) {
      if (!first_inverted) {
        first_inverted = inverted;
        if (lift_inverts(s, inverted->element)) return first_inverted;
      }
      alpha *= 0.5;
      continue;
    }
    const double slope = dq.dot(sys_.f);
    const double pi = energy_at - s.lambda_new * f_ext_.dot(q_trial_);
    const double drop = pi0 - pi;  // > 0: the energy fell
    const bool energy_ok = std::isnan(pi0) || drop >= kArmijo * alpha * s0 ||
                           std::abs(drop) <= 1e-12 * std::max(std::abs(pi0), std::abs(pi));
    if (energy_ok && (std::abs(slope) <= kSlopeRatio * std::abs(s0) || s0 * slope > 0))
      return std::nullopt;
    if (energy_ok) {
      // Past the minimum along dq (the slope changed sign): its root by linear interpolation.
      alpha *= std::clamp(s0 / (s0 - slope), 0.1, 1.0);
    } else {
      // The energy rose: the minimum of the quadratic with pi(0), slope -s0 and pi(alpha).
      const double a_min = s0 * alpha * alpha / (2 * (s0 * alpha - drop));
      alpha = std::clamp(a_min, 0.1 * alpha, 0.5 * alpha);
    }
  }
  return first_inverted ? *first_inverted
                        : Failure{"the line search found no step that lowers the energy"};
}

// The tangent predictor's first solve starts from the converged state q with the prescribed
// values still at the last step's lambda: at lambda_new the sutures' helper nodes and the flaps'
// arcs move (the lift) with every other dof held. Where a trial of the line search inverts an
// element and that state, alpha = 0, inverts the same element, the halvings only close in on an
// inverted state (det F at a Gauss point is a cubic in alpha, negative at both ends; it could
// turn positive in between, which was not seen): the attempt fails now and is cut back, instead
// of after kMaxLineSearch assemblies (Cranium, the page's default Z-plasty on the forehead: four
// attempts at its snap-through, each 12 inverted trials, 1.6 s, the last det F -0.08 to -4.3).
// Any later solve starts from a state the line search accepted, which inverts nothing.
bool FiniteStrainSolver::lift_inverts(StepAttempt& s, int element) {
  if (!(s.tangent_predictor && s.record.iterations == 1)) return false;
  q_trial_ = q_;
  projected_ = problem_.project_on_surface(q_trial_, s.lambda_new);
  const std::optional<Failure> inverted = assemble(q_trial_, s.lambda_new, s.lambda_new, no_lift_);
  return inverted && inverted->element == element;
}

std::optional<Failure> FiniteStrainSolver::assemble(const Eigen::VectorXd& q, double lambda,
                                                    double load_lambda, const Eigen::VectorXd& dpath,
                                                    Eigen::VectorXd* unit_lift, double* energy) {
  const auto t = Clock::now();
  ++res_.assemblies;
  std::optional<Failure> failure = problem_.evaluate(q, lambda, load_lambda, dpath, sys_, unit_lift, energy);
  res_.timings.assembly_s += seconds_since(t);
  return failure;
}

// Converged; or at the round-off floor: a correction a thousand times below the tolerance
// while the residual is within a hundred times of it (a residual cannot drop below the
// rounding of the element forces that cancel in it). A step before the last only has to
// be a good start for the next one (its left-over residual is carried into the next
// predictor): it stops at intermediate_tolerance.
bool FiniteStrainSolver::converged(const StepAttempt& s, double rn, double du, double du_next,
                                   double step_norm) const {
  const bool last = s.lambda_new == 1.0;
  const double r_tol =
      last ? no_.residual_tolerance : std::max(no_.residual_tolerance, no_.intermediate_tolerance);
  const double d_tol =
      last ? no_.displacement_tolerance : std::max(no_.displacement_tolerance, no_.intermediate_tolerance);
  return (rn <= r_tol * s.r_ref && du_next <= d_tol * step_norm) ||
         (rn <= 1e2 * r_tol * s.r_ref && du <= 1e-3 * d_tol * step_norm);
}

// Snapping: the tangent was shifted (indefinite, or its Newton steps far too long) in the last
// max_iterations solves and the potential fell over them by more than round-off: the step
// goes on, max_iterations more solves at a time.
void FiniteStrainSolver::extend_for_snap(StepAttempt& s) {
  if (!(s.limit < no_.snap_iterations && snap_solves_left_ > 0)) return;
  const std::size_t from = s.potentials.size() - static_cast<std::size_t>(no_.max_iterations);
  const double fall = s.potentials[from] - s.potentials.back();
  const bool shifted =
      std::find(s.shifted_solve.begin() + static_cast<std::ptrdiff_t>(from), s.shifted_solve.end(),
                true) != s.shifted_solve.end();
  if (shifted && fall > 1e-9 * std::abs(s.potentials.back())) {
    const int more = std::min({no_.max_iterations, no_.snap_iterations - s.limit, snap_solves_left_});
    s.limit += more;
    snap_solves_left_ -= more;
  }
}

void FiniteStrainSolver::check_budget(const StepAttempt& s) const {
  const double elapsed = seconds_since(started_);
  std::string spent;
  if (res_.newton_iterations >= no_.max_solves)
    spent = cat(no_.max_solves, " Newton solves, its budget");
  else if (step_ >= std::max(no_.max_steps, 2 * no_.n_steps))
    spent = cat(step_, " load steps, its budget");
  else if (options_.time_limit_s > 0 && elapsed > options_.time_limit_s)
    spent = cat("its time limit of ", options_.time_limit_s, " s (--time-limit)");
  if (spent.empty()) return;
  throw SolverError(cat("the finite-strain closure stopped after ", spent, ": it had come ",
                        std::round(1000 * lambda_) / 10, " % of the way in ", step_,
                        " load steps (", res_.newton_iterations, " solves, ", res_.factorizations,
                        " factorizations, ", std::round(10 * elapsed) / 10,
                        " s) and was working towards ", std::round(1000 * s.lambda_new) / 10,
                        " %; Newton cannot follow this closure within its budget (tissue "
                        "buckling or nearly inverted under it). The small-strain answer "
                        "(--material linear) takes one solve; or undermine more, or refine the mesh"),
                    -1, -1, s.record.iterations);
}

void FiniteStrainSolver::accept_step(const StepAttempt& s) {
  q_last_start_ = s.q_start;
  last_dl_ = s.dl;
  NewtonStep record = s.record;
  record.residual_norms.insert(record.residual_norms.begin(), 1.0);
  record.factorizations = res_.factorizations - step_factorizations_from_;
  step_factorizations_from_ = res_.factorizations;
  res_.newton_steps.push_back(record);
  ++step_;
  lambda_ = s.lambda_new;
  cutbacks_ = 0;
  inverted_in_step_.reset();
  at_converged_state_ = record.iterations > 0 && s.r0 > 0;
  if (options_.reporter) {
    options_.reporter->progress("closing the wound", lambda_);
    options_.reporter->check_cancelled();
  }
  grow_step(record);
}

// An easy step doubles the next: beyond the nominal size (up to what remains) until a step
// of this solve has been cut back, then only back up to growth_cap_, the nominal size halved by
// each cut-back (at least a quarter of it). A step of the nominal size that failed where the
// flaps buckle would otherwise be tried again at that size after every cut-back, and fail
// again (Cranium, the page's default Z-plasty at 30,110 on the clamped patch: 5 cut-backs,
// 81 solves and 101 factorizations; with the cap 3, 59 and 41; docs/fem.md, "Load steps").
void FiniteStrainSolver::grow_step(const NewtonStep& record) {
  const bool cut_back = growth_cap_ < nominal_;  // a step of this solve was cut back
  if (!cut_back && record.iterations <= no_.grow_iterations)
    dlambda_ = 2 * dlambda_;
  else if (record.iterations <= 4)
    dlambda_ = std::max(dlambda_, std::min(2 * dlambda_, growth_cap_));
}

// A failed attempt: back to the step's start with half the step; SolverError after
// max_cutbacks halvings.
void FiniteStrainSolver::cut_back_step(StepAttempt& s) {
  std::optional<Failure>& failure = s.failure;
  if (!failure)
    failure = Failure{cat("Newton did not converge in ", s.record.iterations,
                          " iterations (last relative residual ",
                          s.record.residual_norms.empty() ? NAN : s.record.residual_norms.back(), ")"),
                      -1, -1, s.record.iterations};
  failure->lambda = s.lambda_new;
  // An inverted element is the cause worth reporting: smaller steps after it often fail
  // differently (a stiffening, ill-conditioned tangent near det F = 0).
  if (failure->element >= 0 && !inverted_in_step_) inverted_in_step_ = failure;
  if (inverted_in_step_) failure = inverted_in_step_;
  q_ = s.q_start;
  growth_cap_ = std::max(0.5 * growth_cap_, 0.25 * nominal_);
  dlambda_ = 0.5 * s.dl;  // half the step that failed (it may have been clipped to what remained)
  if (++cutbacks_ > no_.max_cutbacks) {
    throw SolverError(
        cat("finite-strain solve failed at load step ", step_ + 1, " (from lambda ", lambda_,
            " towards ", failure->lambda, "; ", no_.max_cutbacks, " halvings), Newton iteration ",
            failure->iteration, ": ", failure->what, "; the closure is too large for this mesh or material: refine the mesh, undermine "
            "more, or close the wound in more steps (n_steps)"),
        failure->element, failure->gauss_point, failure->iteration);
  }
}

// A new factor of K solved to the inexact Newton step's tolerance: with the mixed-precision
// solver, CG on K preconditioned by the new single-precision factor stops there instead of at
// a direct solve's 1e-12 (half its iterations on the Cranium Z-plasty).
void FiniteStrainSolver::factorize_and_solve(Eigen::VectorXd& dq, double tolerance) {
  auto t0 = Clock::now();
  ++res_.factorizations;
  // A factorization that finds the tangent not positive definite (it throws) took its time too.
  struct Timed {
    double& total;
    Clock::time_point from;
    ~Timed() { total += seconds_since(from); }
  };
  {
    const Timed timed{res_.timings.factorization_s, t0};
    solver_->factorize(sys_.K);
  }
  if (solve_with_last_factor(dq, kMaxFreshIterations, tolerance)) return;
  t0 = Clock::now();
  dq = solver_->solve(sys_.f);
  res_.timings.solve_s += seconds_since(t0);
}

bool FiniteStrainSolver::solve_with_last_factor(Eigen::VectorXd& dq, int max_iterations,
                                                double tolerance, bool* negative_curvature) {
  const auto t0 = Clock::now();
  std::optional<Eigen::VectorXd> x =
      solver_->solve_reusing_factor(sys_.K, sys_.f, max_iterations, tolerance, negative_curvature);
  res_.timings.solve_s += seconds_since(t0);
  if (x) dq = std::move(*x);
  return x.has_value();
}

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
// Newton loop's Levenberg-Marquardt memory, StepAttempt::damping). `factor_is_shifted_tangent`:
// the solver's factor is of this tangent shifted by `damping` (a step cut back, start_tangent_),
// so conjugate gradients preconditioned by it solve the shifted tangent in an iteration or two
// instead of a new factorization.
std::optional<Failure> FiniteStrainSolver::solve_shifted(Eigen::VectorXd& dq, double& shift,
                                                         double tolerance, double damping,
                                                         bool factor_is_shifted_tangent,
                                                         double guess) {
  shift = 0;
  const auto finite = [&]() -> std::optional<Failure> {
    if (dq.allFinite()) return std::nullopt;
    return Failure{"the Newton correction is not finite"};
  };
  // The tangent itself first, by conjugate gradients on the last factor: no factorization. A
  // direction of negative curvature met on the way proves the tangent indefinite: its own
  // factorization, which would fail, is not tried.
  bool indefinite = false;
  if (damping == 0 && no_.reuse_iterations > 0 &&
      solve_with_last_factor(dq, no_.reuse_iterations, tolerance, &indefinite))
    return finite();
  std::string unshifted;  // why the tangent itself could not be factorized
  if (indefinite) unshifted = "conjugate gradients met a direction of negative curvature";
  double* values = sys_.K.valuePtr();
  for (Eigen::Index j = 0; j < sys_.K.cols(); ++j) kept_diagonal_[j] = values[diagonal_[j]];
  const int lowest = damping == 0 ? (indefinite ? 0 : -1) : shift_rung(damping);
  // One rung: the tangent shifted by it solved, or false (not positive definite).
  int factored = kNoRung;  // the rung whose factor the solver holds, if any
  const auto attempt = [&](int k) {
    if (options_.reporter) options_.reporter->check_cancelled();
    const double mu = rung_shift(k);
    for (Eigen::Index j = 0; j < sys_.K.cols(); ++j)
      values[diagonal_[j]] = kept_diagonal_[j] + mu * std::abs(kept_diagonal_[j]);
    if (k >= 0 && factor_is_shifted_tangent && k == lowest &&
        solve_with_last_factor(dq, kMaxFreshIterations, tolerance))
      return true;
    try {
      factorize_and_solve(dq, tolerance);
      factored = k;
      return true;
    } catch (const SingularMatrix& e) {
      ++res_.indefinite_factorizations;
      factored = kNoRung;
      if (unshifted.empty()) unshifted = e.what();
      return false;
    }
  };
  // The smallest rung from `lowest` up whose shifted tangent is positive definite (definiteness
  // only grows with the shift). Climbed rung by rung from `lowest`, unless `guess` (the shift
  // the last step's first solve needed) is two or more rungs above it: then from the rung below
  // the guess, and, if that rung holds, down by bisection to the smallest that does (the 45 deg
  // Z-plasty planner_e2e saves on the phantom, closed with finite strain, climbed seven rungs,
  // 0 to 1, at the first solve of each of four steps). Either way the chosen shift is the same;
  // only the factorizations tried on the way differ.
  int found = kNoRung;
  const int remembered = guess > 0 ? shift_rung(guess) : kNoRung;
  const bool guessed = remembered != kNoRung && remembered - 1 > lowest;
  if (guessed && attempt(remembered - 1)) {
    int hi = remembered - 1, lo = lowest;  // hi holds; lo is not yet known
    if (attempt(lo)) {
      hi = lo;
    } else {
      while (hi - lo > 1) {  // lo fails, hi holds
        const int mid = (lo + hi) / 2;
        (attempt(mid) ? hi : lo) = mid;
      }
      if (factored != hi && !attempt(hi)) hi = kNoRung;  // the solver holds another factor now
    }
    found = hi;
  } else {
    for (int k = guessed ? remembered : lowest; k <= kTopRung; ++k)
      if (attempt(k)) {
        found = k;
        break;
      }
  }
  for (Eigen::Index j = 0; j < sys_.K.cols(); ++j) values[diagonal_[j]] = kept_diagonal_[j];
  if (found == kNoRung)
    return Failure{cat("the tangent stiffness is not positive definite even shifted by 100 times "
                       "its diagonal (", unshifted, ")")};
  shift = rung_shift(found);
  return finite();
}

void FiniteStrainSolver::finish_report() {
  res_.factor_nonzeros = solver_->factor_nonzeros();
  const SolverReport report = solver_->report();
  res_.precision = report.precision;
  res_.refinement_iterations = report.iterations;
  res_.fell_back_to_double = report.fell_back_to_double;
  // The last step's final residual relative to its load (the linear solve's measure).
  res_.relative_residual = res_.newton_steps.back().residual_norms.back();
}

// Recovery: the displacement of the converged state, and every element's stresses and forces.
void FiniteStrainSolver::recover_result() {
  const auto t = Clock::now();
  const Eigen::VectorXd u = problem_.expand(q_, 1.0);
  const Eigen::Index n_nodes = mesh_.n_nodes();
  res_.displacement_mm.resize(n_nodes, 3);
  for (Eigen::Index i = 0; i < n_nodes; ++i)
    for (int c = 0; c < 3; ++c) res_.displacement_mm(i, c) = u[3 * i + c];
  recover(mesh_, map_, [&](int e, ElementRecovery& out) { recover_element(u, e, out); }, res_);
  res_.timings.recovery_s = seconds_since(t);
}

void FiniteStrainSolver::recover_element(const Eigen::VectorXd& u, int e,
                                         ElementRecovery& out) const {
  const FiniteMaterials& mats = problem_.materials();
  const Element& el = mesh_.elements[e];
  const int nn = el.n_nodes();
  const Material& mat = *mats.at(el.layer);
  const Eigen::MatrixX3d X = element_coordinates(mesh_, e);
  Eigen::VectorXd ue(3 * nn);
  for (int a = 0; a < nn; ++a) ue.segment<3>(3 * a) = u.segment<3>(3 * static_cast<Eigen::Index>(el.nodes[a]));
  Eigen::VectorXd fe;
  const double stretch = el.layer == kSkinLayer ? options_.prestretch : 1.0;
  const FiniteKernelResult k =
      finite_kernel(el.type, X, mat, ue, e, fe, nullptr, stretch, mesh_.wedge_rule);
  if (k.inverted_at >= 0)  // not after a converged step, which evaluated this very state
    throw SolverError(inverted_message(e, k.inverted_at, k.det_F), e, k.inverted_at);
  out.energy_mj = k.energy_mj;
  out.f_int.resize(nn, 3);
  for (int a = 0; a < nn; ++a) out.f_int.row(a) = fe.segment<3>(3 * a).transpose();
  const auto& tab = shape_table(el.type, mesh_.wedge_rule);
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
}

}  // namespace

void solve_finite(const Mesh& mesh, const SolveOptions& options, const DofMap& map,
                  SolveResult& res) {
  FiniteStrainSolver(mesh, options, map, res).run();
}

}  // namespace caps::fem::detail
