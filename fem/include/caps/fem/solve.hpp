#pragma once
/// @brief Static solve with fixed dofs and suture constraints, and its results: the linear
/// (small-strain, the 1992 paper's) model, or finite strain (total-Lagrangian, neo-Hookean by
/// default) with the prescribed values and suture gaps closed in load steps by Newton-Raphson.
///
/// Sutures are eliminated (master-slave): every group of nodes joined by sutures shares one
/// final position, so u_n = u_m + (x_m - x_n) for each member n of master m's group. The reduced
/// system is symmetric positive definite and is solved by MUMPS (default) or CHOLMOD.

#include <Eigen/Core>
#include <string>
#include <vector>

#include "caps/core/reporter.hpp"
#include "caps/fem/mesh.hpp"

namespace caps::fem {

/// The direct solver. Auto (the default): MUMPS, except for the finite-strain solve of a mesh
/// with ties (the whole face), which CHOLMOD factors. Such a mesh is factored in double
/// precision (the ties' penalties), its Newton tangents are often indefinite where flaps buckle,
/// and CHOLMOD's supernodal Cholesky stops at the first non-positive pivot where MUMPS completes
/// the factorization: the Cranium page's default Z-plasty took 29.7 s of factorizations instead
/// of 43.3 s, a positive definite tangent as long with either (docs/fem.md, "Inexact Newton").
enum class SolverKind { Mumps, Cholmod, Auto };

/// "mumps" / "cholmod" / "auto".
const char* solver_name(SolverKind kind);
/// Parses "mumps" / "cholmod" / "auto"; throws InvalidInput otherwise.
SolverKind parse_solver(const std::string& name);

/// Parses a precision name: "mixed" -> true, "double" -> false (SolveOptions::mixed_precision);
/// throws InvalidInput otherwise.
bool parse_precision(const std::string& name);

/// Kinematics of the solve, apart from the materials (Mesh::materials, one per layer).
enum class Kinematics {
  Linear,  ///< small strain (the 1992 model): each material's small_strain() constants; one linear solve
  Finite   ///< finite strain: each layer's hyperelastic material (linear is refused)
};
/// The solver `kind` stands for in a solve (Auto resolved as described there).
SolverKind resolved_solver(SolverKind kind, Kinematics kinematics, bool tied);

/// "small-strain" / "finite-strain".
const char* kinematics_name(Kinematics kinematics);
/// Parses "small-strain" -> Linear, "finite-strain" -> Finite; throws InvalidInput otherwise.
Kinematics parse_kinematics(const std::string& name);

/// Load stepping and Newton-Raphson controls of the finite-strain solve. The load factor
/// lambda goes 0 -> 1; at lambda the prescribed displacements are lambda × their value, the
/// suture gaps lambda × x_b - x_a closed, the nodal loads lambda × f.
///
/// Steps: the first is 1/n_steps (the nominal step). A step that converged in at most
/// `grow_iterations` Newton solves doubles the next one (up to what remains of lambda), so an
/// easy closure takes fewer than n_steps steps; a step that fails is retried with half its size
/// (cut-back), and after the first cut-back of a solve the steps grow back only up to the nominal
/// size (after a step of at most 4 solves). Without cut-backs a solve takes at most n_steps steps.
///
/// Convergence of a step (Abaqus's and CalculiX's estimate of the next correction): the residual
/// ||r|| <= residual_tolerance ||r_0||, and the correction ||dq|| or, after a full Newton step,
/// the correction it predicts for the next iteration, ||dq|| ||r|| / ||r_prev||, at most
/// displacement_tolerance ||q - q_step_start||; r_0 and the step's increment are scaled to the
/// nominal step. Steps before the last (lambda < 1) only start the next one and stop at
/// intermediate_tolerance for both (docs/fem.md, "Finite strain").
struct NewtonOptions {
  int n_steps = 10;                     ///< nominal load steps: the first step is 1/n_steps
  /// A step converged in at most this many Newton solves doubles the next (beyond the nominal
  /// size until the first cut-back); 0 = steps never grow beyond 1/n_steps.
  int grow_iterations = 3;
  int max_iterations = 25;              ///< per step, before the step is cut back
  /// A step that has not converged after max_iterations but is snapping through (its tangent
  /// was indefinite in those solves, so the state it started from is unstable, and the energy
  /// still falls) goes on, max_iterations more at a time, up to this many solves: a cut-back
  /// cannot help there (the stable branch ends; a smaller step only meets the end again), the
  /// iteration has to reach the state the skin snaps to. The solves beyond max_iterations are
  /// limited to this many over the whole solve as well, so snaps that fail and are cut back
  /// are not repeated without end.
  int snap_iterations = 200;
  int max_cutbacks = 10;                ///< halvings of a step before giving up (SolverError)
  /// The closure's budget: Newton solves over the whole solve (every step, attempt and warm
  /// start), and load steps. Past either the solve stops with a SolverError that says how far
  /// the closure came and offers the small-strain answer: a closure Newton can only crawl
  /// through (steps cut back and grown again thousands of times, each converging) would
  /// otherwise run for minutes. The demo's plans take 9-15 solves in 4-5 steps, the hardest
  /// measured face closures (Z-plasties turned 90 deg) 40-50 in 11 (docs/fem.md).
  int max_solves = 400;
  int max_steps = 200;  ///< (at least twice n_steps)
  double residual_tolerance = 1e-6;     ///< ||r|| / ||r_0|| of the step (r_0: predictor load)
  /// ||dq|| (or the next correction it predicts) / ||q - q_step_start||
  double displacement_tolerance = 1e-5;
  /// Both tolerances for the steps before lambda = 1 (never tighter than the two above).
  double intermediate_tolerance = 1e-4;
  /// A step still short of the tolerances after max_iterations is accepted (marked `stagnated`)
  /// when both its residual and its last correction are below this, in the same relative terms:
  /// near a buckling point Newton slows to linear convergence (5 % a solve at 1e-6 of the load
  /// on the forehead 45 deg Z-plasty), and cutting the step back there only repeats that.
  /// 1e-6 of the load is a micronewton on a closure of newtons. Set it to residual_tolerance to
  /// never accept less.
  double stagnation_tolerance = 1e-6;
  /// A new tangent is first solved by conjugate gradients preconditioned with the last
  /// factorization (of an earlier tangent; any solver and precision), which is kept if that
  /// converges within this many iterations (to the accuracy an inexact Newton step needs, a
  /// relative residual of 1e-2 ||r|| / ||r_0||, at most `max_forcing`); otherwise the tangent
  /// is factorized. 0 = factorize every tangent. The default is the faster of those measured
  /// (docs/benchmarks.md, "factor reuse").
  int reuse_iterations = 16;
  /// The loosest relative residual a Newton correction is solved to (the inexact Newton step's
  /// forcing term is min(max_forcing, 1e-2 ||r|| / ||r_0||)): the first corrections of a step,
  /// where ||r|| is still near ||r_0||. 1e-3 until 6 December 2026; where flaps turn (a
  /// Z-plasty's closing path) a correction solved only to 1e-3 left each step about 1e-3 short
  /// and Newton converged linearly from there: the Cranium demo Z-plasty took 15 solves instead
  /// of 7, the page's default one 49 instead of 24 (docs/fem.md, "Finite strain").
  double max_forcing = 1e-5;
  /// A load step after the first starts from the last step's increment scaled to it (the
  /// secant predictor) when that is closer to equilibrium than the tangent predictor's load.
  bool secant_predictor = true;
};

/// SolveOptions::blas_threads: chosen by the system's size (see there).
inline constexpr int kAutoBlasThreads = -1;
/// The smallest system (equations) solved with two BLAS threads under kAutoBlasThreads.
inline constexpr long kTwoBlasThreadsFromEquations = 30000;

struct SolveOptions {
  /// Linear (default) or Finite; the finite-strain controls are in `newton`.
  Kinematics kinematics = Kinematics::Linear;
  NewtonOptions newton;
  SolverKind solver = SolverKind::Auto;
  /// MUMPS ICNTL(7) ordering: 0 AMD, 2 AMF, 3 SCOTCH (if built), 4 PORD, 5 METIS (if built),
  /// 6 QAMD, 7 automatic. The default is the fastest measured (docs/benchmarks.md).
  int mumps_ordering = 4;
  /// MUMPS only: factor in single precision and refine with conjugate gradients on the
  /// double-precision system to a relative residual of 1e-12 (faster: docs/benchmarks.md);
  /// falls back to a double-precision factorization by itself when that does not converge.
  /// false = factor in double precision. A mesh with ties (Mesh::ties) is always factored in
  /// double precision (their penalties leave single precision too few digits).
  bool mixed_precision = true;
  /// Threads for assembly and stress recovery (0 = all).
  int threads = 0;
  /// Threads of the BLAS inside the sparse factorization and solves (OpenBLAS; another BLAS is
  /// left alone) during the solve, restored afterwards; 0 = as the BLAS is configured
  /// (OPENBLAS_NUM_THREADS); kAutoBlasThreads (the default) = two for a system of at least
  /// kTwoBlasThreadsFromEquations equations, one below. With OpenBLAS on the CPU's own kernels
  /// (fem/blas.hpp) two threads take 8-23 % off the finite-strain closures on the whole face
  /// (37-96k equations), the same answers to 1e-12, and are no slower with a second closure
  /// beside them; on small systems their idle threads' spinning costs a third more CPU for the
  /// same wall time alone and 15 % more wall time beside another solve (docs/benchmarks.md,
  /// "BLAS threads").
  int blas_threads = kAutoBlasThreads;
  /// In-vivo prestretch of the skin (layer 0, the element layer under the surface), in its
  /// plane, 1 = none, valid 1..1.5 (skin in vivo: about 1.1-1.2; docs/fem.md). The stress-free
  /// skin is its reference shrunk by this factor in the plane and thickened along the normal
  /// (isochoric; FEBio's prestrain). Finite strain only; it grows with the load factor together
  /// with the closure, so the closed state and its forces include it.
  double prestretch = 1.0;
  /// Finite strain only: a warm start. Empty (the default): the load steps start from the
  /// reference state. Otherwise the #N×3 displacement (mm) of a state near the solution (a
  /// converged closure of this problem, or of a nearby one mapped to this mesh's nodes): the
  /// whole closure is then one load step whose Newton iteration starts at that state, with the
  /// tolerances of a one-step solve from the reference state (docs/fem.md, "The Newton solver's
  /// steps"), so a converged state converges in one solve. If that step fails, the solve starts
  /// afresh from the reference state in load steps (the failed attempt's solves are counted).
  /// Only the free and suture-group dofs are read: the prescribed values are the problem's.
  Eigen::MatrixX3d initial_displacement_mm;
  /// Finite strain only: wall-clock seconds the Newton solve may take (0 = no limit). Past it
  /// the solve stops at its next iteration with a SolverError saying how far the closure came
  /// and offering the small-strain answer (a closure that would run for minutes says so).
  double time_limit_s = 0;
  /// Not owned, may be null: a finite-strain solve reports the load factor reached after every
  /// load step as progress of "closing the wound", and stops there (Cancelled) when asked to.
  Reporter* reporter = nullptr;
};

/// Wall-clock seconds of each phase. The analysis runs on its own thread while the values are
/// assembled (assembly_s includes the structure); solve_s includes any refinement.
struct SolveTimings {
  double constraints_s = 0, assembly_s = 0, analysis_s = 0, factorization_s = 0, solve_s = 0,
         recovery_s = 0, total_s = 0;
};

/// One converged load step of a finite-strain solve.
struct NewtonStep {
  int step = 0;                        ///< 1-based, in order of convergence
  double lambda = 0;                   ///< load factor reached (0..1]
  int iterations = 0;                  ///< Newton iterations (solves) of the converged attempt
  int cutbacks = 0;                    ///< failed attempts of this step before it converged
  int factorizations = 0;              ///< numerical factorizations of all its attempts
  /// ||r|| after each solve relative to the step's predictor load ||r_0|| (first entry 1).
  std::vector<double> residual_norms;
  std::vector<double> line_search;     ///< accepted step length alpha of each iteration
  /// Per iteration, the shift mu that made the tangent positive definite (K + mu diag(K)), 0
  /// where the tangent itself was: non-zero past a buckling point (the tissue puckers).
  std::vector<double> shifts;
  /// Per iteration, the largest move of a dof by its correction (mm, alpha |dq|_inf): what the
  /// displacement tolerance weighs, in the unit a surgeon reads.
  std::vector<double> corrections_mm;
  /// Accepted at NewtonOptions::stagnation_tolerance after max_iterations, not at the tolerances.
  bool stagnated = false;
};

/// The force one suture carries.
struct SutureForce {
  int a = 0, b = 0;
  Eigen::Vector3d force_on_a_n = Eigen::Vector3d::Zero();  ///< N; the force on b is opposite
  double magnitude_n = 0;
};

struct SolveResult {
  Eigen::MatrixX3d displacement_mm;          ///< #N×3
  Eigen::MatrixXd gauss_stress_mpa;          ///< #GP×6 Voigt, element by element in rule order
  std::vector<int> gauss_offset;             ///< first row of element e in gauss_stress_mpa
  Eigen::MatrixXd nodal_stress_mpa;          ///< #N×6 Voigt, averaged over adjacent elements
  Eigen::VectorXd von_mises_mpa;             ///< #N
  Eigen::VectorXd max_principal_mpa;         ///< #N
  Eigen::VectorXd element_von_mises_mpa;     ///< #E mean over the element's Gauss points
  Eigen::MatrixX3d reaction_n;               ///< #N×3 reactions: fixed, sutured, sliding, tied slaves
  std::vector<SutureForce> suture_forces;    ///< one per mesh.sutures entry
  /// The closing tension: sum over pairs of the force on a along the unit vector from x_a to
  /// x_b (N). Single pairs of quadratic elements may carry negative (pushing) consistent forces;
  /// this signed sum is the net force across the wound.
  double total_suture_force_n = 0;
  double sum_suture_magnitudes_n = 0;        ///< sum of |force| over pairs (N)
  /// The force the ties (Mesh::ties) apply on their slaves, summed (N): what the tied part
  /// (the patch) receives from the part it is tied to.
  Eigen::Vector3d tie_force_n = Eigen::Vector3d::Zero();
  /// The largest tie gap |u_s - sum w u_m| (mm): how far the penalty gives way.
  double tie_gap_max_mm = 0;
  double strain_energy_mj = 0;               ///< N·mm = mJ
  double relative_residual = 0;              ///< ||K q - f|| / ||f|| of the reduced system
  long n_dofs = 0;                           ///< 3 × nodes
  long n_equations = 0;                      ///< after elimination
  long n_nonzeros = 0;                       ///< upper triangle of the reduced matrix
  long factor_nonzeros = 0;                  ///< entries of the factor (solver's report)
  double peak_memory_mb = 0;                 ///< process peak RSS after the solve
  std::string solver;
  std::string precision = "double";          ///< "mixed" or "double" (see SolveOptions)
  int refinement_iterations = 0;             ///< CG iterations of a mixed-precision solve
  bool fell_back_to_double = false;          ///< mixed precision was tried and not enough
  SolveTimings timings;
  std::string kinematics = "small-strain";   ///< kinematics_name() of the solve
  double prestretch = 1.0;                   ///< SolveOptions::prestretch of the solve
  std::vector<NewtonStep> newton_steps;      ///< finite strain: the converged load steps
  int secant_predictions = 0;                ///< finite strain: steps begun by the secant predictor
  int newton_iterations = 0;                 ///< finite strain: total, including cut-back attempts
  /// finite strain: evaluations of the element forces and tangent (predictors, line-search
  /// trials), including cut-back attempts; each costs about what a CG solve on a reused factor does
  int assemblies = 0;
  int factorizations = 0;                    ///< numerical factorizations (1 for a linear solve)
  /// Of those, the ones that found the (finite-strain, shifted or not) tangent not positive
  /// definite: the snap-through's cost (their time is in SolveTimings::factorization_s).
  int indefinite_factorizations = 0;
  /// finite strain: each flap's rotation along its closing path (deg, Mesh::flaps order; a flap
  /// turned by less than 3 deg closes straight)
  std::vector<double> flap_rotations_deg;
};

/// Solves the static problem (options.kinematics). Throws InvalidInput for bad input and for
/// parts without support against a translation or rotation (the message says what to fix);
/// SolverError naming the element (SolverError::element) for an inverted element (with its Gauss
/// point) or a singular stiffness the support checks cannot see (a mechanism, such as elements
/// joined only along an edge), SolverError for any other failure of the factorization and, in
/// finite strain, if a step does not converge within max_cutbacks halvings (naming the step and
/// iteration). Stresses are Cauchy stresses in the deformed state (finite) or the small-strain
/// stresses (linear); reactions and suture forces are nodal forces (N).
SolveResult solve(const Mesh& mesh, const SolveOptions& options = {});

}  // namespace caps::fem
