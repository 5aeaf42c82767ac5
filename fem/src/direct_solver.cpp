#include "direct_solver.hpp"

#include <cholmod.h>
#include <dlfcn.h>
#include <dmumps_c.h>
#include <smumps_c.h>

#include <algorithm>
#include <cmath>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "caps/core/error.hpp"

namespace caps::fem::detail {
namespace {

// How a factorization ended: `ok`, or the error it stands for. A null or negative pivot is a
// singular matrix (SingularMatrix, with the reduced equation where it showed, -1 if not known;
// `factored`: the factor exists all the same); anything else is a failure of the solver
// (SolverError).
struct FactorStatus {
  bool ok = true;
  bool singular = false;
  bool factored = true;
  std::string message;
  int equation = -1;

  static FactorStatus failed(std::string message) {
    return {false, false, false, std::move(message), -1};
  }
  static FactorStatus singular_at(std::string message, int equation, bool factored) {
    return {false, true, factored, std::move(message), equation};
  }
  void throw_if_failed() const {
    if (ok) return;
    if (singular) throw SingularMatrix(message, equation);
    throw SolverError(message);
  }
};

// Where a singular K's null space shows: the largest entry of x = K^-1 b, solved with the
// factor that has the round-off (or negative) pivot, for a b with no special structure. That
// pivot's direction dominates x, so the entry is an equation of the part that can move. -1 if
// x is zero; the first non-finite entry if there is one.
template <class Solve>
int dominant_equation(Eigen::Index n, Solve&& solve) {
  Eigen::VectorXd b(n);
  for (Eigen::Index i = 0; i < n; ++i) b[i] = 1.0 + 0.5 * std::sin(1.0 + static_cast<double>(i));
  const Eigen::VectorXd x = solve(b);
  int best = -1;
  double largest = 0;
  for (Eigen::Index i = 0; i < x.size(); ++i) {
    if (!std::isfinite(x[i])) return static_cast<int>(i);
    if (std::abs(x[i]) > largest) {
      largest = std::abs(x[i]);
      best = static_cast<int>(i);
    }
  }
  return best;
}

// Every call into MUMPS, by any instance in any thread, holds this. The sequential library keeps
// state in Fortran module variables (the analysis's static mapping among them), so two instances
// working at once in two threads corrupt each other: `caps plan suggest`'s sweep closes two
// designs at once, each with CHOLMOD ordered by MUMPS's analysis, and one of them died of an
// integer division by zero in mumps_init_arch_parameters (SIGFPE, 1 run in 3 of test_app_suggest
// on 7 December 2026; most likely also the SIGFPE of its goh sweep in a loaded full run before),
// and once, probably the same race, glibc found the heap corrupt at a thread's end. One call
// after another, as a single thread makes them, is what the library supports.
std::mutex& mumps_mutex() {
  static std::mutex m;
  return m;
}

// One MUMPS instance in double (DMUMPS) or single (SMUMPS) precision. MUMPS 5.5 users' guide,
// sec. 5-6: SYM = 1 (symmetric positive definite), sequential host, assembled centralized input.
template <class Struc, class Real, void (*MumpsCall)(Struc*)>
class Mumps {
  static void Call(Struc* id) {
    const std::lock_guard<std::mutex> lock(mumps_mutex());
    MumpsCall(id);
  }

 public:
  Mumps(int ordering, Real null_pivot) {
    id_.comm_fortran = -987654;  // USE_COMM_WORLD; the sequential library ignores it
    id_.par = 1;
    id_.sym = 1;
    id_.job = -1;
    Call(&id_);
    check("initialization");
    id_.icntl[0] = -1;  // no error/diagnostic/global output
    id_.icntl[1] = -1;
    id_.icntl[2] = -1;
    id_.icntl[3] = 0;
    ordering_ = ordering;     // ICNTL(7), set by analyze()
    id_.icntl[7] = 0;         // ICNTL(8): no scaling; an SPD stiffness is factored unpivoted
    id_.icntl[13] = 50;       // ICNTL(14): +50 % workspace over the estimate
    id_.icntl[23] = 1;        // ICNTL(24): detect null pivots (rigid-body modes)
    id_.cntl[2] = null_pivot; // CNTL(3): |pivot| <= this * ||A|| counts as null
  }
  ~Mumps() {
    id_.job = -2;
    Call(&id_);
  }
  Mumps(const Mumps&) = delete;
  Mumps& operator=(const Mumps&) = delete;

  /// Structure only (1-based coordinates, `blkptr` 1-based block starts or empty); the arrays
  /// must outlive the instance.
  void analyze(int n, std::vector<MUMPS_INT>& irn, std::vector<MUMPS_INT>& jcn,
               std::vector<MUMPS_INT>& blkptr) {
    id_.n = n;
    id_.nnz = static_cast<MUMPS_INT8>(irn.size());
    id_.irn = irn.data();
    id_.jcn = jcn.data();
    // ICNTL(15) = 1: the graph is compressed by the caller's blocks (one per node) before the
    // ordering, which is both faster and a slightly better ordering (docs/benchmarks.md).
    id_.icntl[14] = blkptr.size() > 1 ? 1 : 0;
    id_.nblk = static_cast<MUMPS_INT>(blkptr.size()) - 1;
    id_.blkptr = blkptr.size() > 1 ? blkptr.data() : nullptr;
    id_.blkvar = nullptr;  // blocks are runs of consecutive equations
    id_.a = nullptr;       // no values are needed before the factorization
    // PORD ends the process (quit()) when the graph compresses to one vertex: a single clique
    // (one element, every equation coupled to every other). Any order suits a dense matrix, so
    // it gets AMD.
    const long long n_upper = static_cast<long long>(n) * (n + 1) / 2;
    id_.icntl[6] = static_cast<long long>(irn.size()) >= n_upper ? 0 : ordering_;  // ICNTL(7)
    id_.job = 1;
    Call(&id_);
    check("analysis");
  }
  /// After analyze(): the pivot order, 0-based (order[k] = the variable eliminated k-th).
  std::vector<int> pivot_order() const {
    std::vector<int> order(static_cast<std::size_t>(id_.n), -1);
    if (!id_.sym_perm) throw SolverError("MUMPS analysis returned no ordering");
    for (int i = 0; i < id_.n; ++i) {
      const int k = id_.sym_perm[i] - 1;  // SYM_PERM(i): the position of variable i
      if (k < 0 || k >= id_.n || order[k] >= 0)
        throw SolverError("MUMPS analysis returned an ordering that is not a permutation");
      order[k] = i;
    }
    return order;
  }
  /// The numerical factorization of the values `a` (which must outlive the instance); reports
  /// null or negative pivots and other failures rather than throwing them, so that a caller
  /// can try another precision.
  FactorStatus factorize(Real* a) {
    id_.a = a;
    for (int attempt = 0;; ++attempt) {
      provide_workspace();
      id_.job = 2;
      Call(&id_);
      // -8/-9: workspace too small for the numerical pivots; grow and retry (users' guide 8).
      if ((id_.infog[0] == -8 || id_.infog[0] == -9) && attempt < 3) {
        id_.icntl[13] *= 2;
        continue;
      }
      break;
    }
    if (id_.infog[0] == -10)
      return FactorStatus::singular_at(
          "MUMPS: the matrix is numerically singular (INFOG(1) = -10)", -1, false);
    if (id_.infog[0] < 0) return FactorStatus::failed(failure("factorization"));
    if (id_.infog[27] > 0)  // INFOG(28): null pivots
      return FactorStatus::singular_at(cat("MUMPS found ", id_.infog[27], " null pivot(s)"),
                                       id_.pivnul_list ? id_.pivnul_list[0] - 1 : -1, true);
    if (id_.infog[11] > 0)  // INFOG(12): negative pivots, impossible for a valid stiffness
      return FactorStatus::singular_at(cat("MUMPS found ", id_.infog[11], " negative pivot(s)"),
                                       -1, true);
    return {};
  }
  /// Overwrites x (the right-hand side) with the solution; `iteration` is the refinement
  /// iteration it serves (-1: none), named if the solve fails.
  void solve(Real* x, int iteration = -1) {
    id_.rhs = x;
    id_.nrhs = 1;
    id_.lrhs = id_.n;
    id_.job = 3;
    Call(&id_);
    check("solve", iteration);
  }
  /// The status of a factorization, with the equation of a singular K located by
  /// dominant_equation() when MUMPS did not name it (negative pivots). Double precision only.
  FactorStatus located(FactorStatus status) {
    if (status.singular && status.equation < 0 && status.factored)
      status.equation = dominant_equation(id_.n, [&](const Eigen::VectorXd& b) {
        Eigen::VectorXd x = b;
        solve(x.data());
        return x;
      });
    return status;
  }
  long factor_nonzeros() const {
    // INFOG(29): effective entries in the factors (negative = millions).
    const long v = id_.infog[28];
    return v >= 0 ? v : -v * 1000000L;
  }

 private:
  std::string failure(const char* phase) const {
    return cat("MUMPS ", phase, " failed: INFOG(1) = ", id_.infog[0], ", INFOG(2) = ", id_.infog[1],
               " (see the MUMPS users' guide, section 8)");
  }
  void check(const char* phase, int iteration = -1) const {
    if (id_.infog[0] < 0) throw SolverError(failure(phase), -1, -1, iteration);
  }
  // The factorization's main workspace S (fronts, then the factors) as WK_USER, kept from one
  // factorization to the next (MUMPS 5.5 users' guide, LWK_USER): MUMPS would allocate and free
  // it each time, and zeroing it and faulting in its fresh pages took about a fifth of a Newton
  // solve's time (perf, Cranium Z-plasty). INFO(8), after the analysis, is its size in core
  // (entries; negative: millions), to which ICNTL(14)'s margin is added.
  void provide_workspace() {
    const long long estimate = id_.info[7] >= 0 ? id_.info[7] : -1000000LL * id_.info[7];
    const long long wanted = estimate + estimate * std::max(0, id_.icntl[13]) / 100;
    if (wanted <= 0) return;
    if (static_cast<long long>(workspace_.size()) < wanted)
      workspace_.resize(static_cast<std::size_t>(wanted));
    id_.wk_user = workspace_.data();
    const long long n = static_cast<long long>(workspace_.size());
    // LWK_USER > 0: entries; < 0: millions of entries (a MUMPS_INT holds up to 2^31 - 1).
    id_.lwk_user = n < 2000000000LL ? static_cast<MUMPS_INT>(n)
                                    : -static_cast<MUMPS_INT>(n / 1000000LL);
  }
  Struc id_{};
  int ordering_;
  std::vector<Real> workspace_;
};
using MumpsDouble = Mumps<DMUMPS_STRUC_C, double, dmumps_c>;
using MumpsSingle = Mumps<SMUMPS_STRUC_C, float, smumps_c>;

// Preconditioned CG (Saad 2003, alg. 9.1) on K (its upper triangle) until the recursive residual
// is below tolerance ||b|| (1e-12 for a solve as accurate as a direct one) and then the true
// one, b - K x, below 10 tolerance ||b|| (the recursive residual of an ill-conditioned system can
// drop below what is achievable); empty if that does not happen in max_iterations (the
// preconditioner, a factor of an earlier K or in single precision, is then too poor) or K is not
// positive definite in working precision. `iterations` receives the count;
// precondition(r, iteration) applies the factor.
constexpr double kCgTolerance = 1e-12;
template <class Precondition>
std::optional<Eigen::VectorXd> conjugate_gradients(const Eigen::SparseMatrix<double>& Kupper,
                                                   const Eigen::VectorXd& b, int max_iterations,
                                                   double tolerance, Precondition&& precondition,
                                                   int& iterations,
                                                   bool* negative_curvature = nullptr) {
  const double true_tolerance = 10 * tolerance;
  const auto K = Kupper.selfadjointView<Eigen::Upper>();
  const double bn = b.norm();
  Eigen::VectorXd x = Eigen::VectorXd::Zero(b.size());
  iterations = 0;
  if (bn == 0) return x;
  Eigen::VectorXd r = b, z = precondition(r, 0), p = z, Kp(b.size());
  double rz = r.dot(z);
  for (iterations = 1; iterations <= max_iterations; ++iterations) {
    Kp.noalias() = K * p;
    const double pKp = p.dot(Kp);
    if (!(pKp > 0) || !(rz > 0)) {  // not SPD in working precision
      // p^T K p <= 0 proves K is not positive definite (a factorization of it would fail).
      if (negative_curvature && !(pKp > 0)) *negative_curvature = true;
      return std::nullopt;
    }
    const double alpha = rz / pKp;
    x += alpha * p;
    r -= alpha * Kp;
    if (r.norm() <= tolerance * bn) {
      Kp.noalias() = K * x;
      if ((b - Kp).norm() <= true_tolerance * bn) return x;
      return std::nullopt;
    }
    z = precondition(r, iterations);
    const double rz_next = r.dot(z);
    p = z + (rz_next / rz) * p;
    rz = rz_next;
  }
  return std::nullopt;
}

// CG on K preconditioned with the last factor of a double-precision `solver` (its solve()).
std::optional<Eigen::VectorXd> reuse_factor(DirectSolver& solver,
                                            const Eigen::SparseMatrix<double>& K,
                                            const Eigen::VectorXd& b, int max_iterations,
                                            double tolerance, bool* negative_curvature) {
  int iterations = 0;
  return conjugate_gradients(
      K, b, max_iterations, std::max(tolerance, kCgTolerance),
      [&](const Eigen::VectorXd& r, int) { return solver.solve(r); }, iterations,
      negative_curvature);
}

// The assembled upper triangle as MUMPS coordinates, and the block starts, both 1-based.
struct MumpsInput {
  std::vector<MUMPS_INT> irn, jcn, blkptr;
  MumpsInput(const Eigen::SparseMatrix<double>& K, const std::vector<int>& block_start)
      : irn(K.nonZeros()), jcn(K.nonZeros()), blkptr(block_start.begin(), block_start.end()) {
    for (int j = 0; j < K.cols(); ++j)
      for (int k = K.outerIndexPtr()[j]; k < K.outerIndexPtr()[j + 1]; ++k) {
        irn[k] = K.innerIndexPtr()[k] + 1;
        jcn[k] = j + 1;
      }
    for (MUMPS_INT& b : blkptr) ++b;
  }
};

class MumpsSolver final : public DirectSolver {
 public:
  explicit MumpsSolver(int ordering) : mumps_(ordering, 1e-12) {}
  void analyze(const Eigen::SparseMatrix<double>& K, const std::vector<int>& block_start) override {
    in_.emplace(K, block_start);
    mumps_.analyze(static_cast<int>(K.rows()), in_->irn, in_->jcn, in_->blkptr);
  }
  void factorize(const Eigen::SparseMatrix<double>& K) override {
    factored_ = false;
    mumps_.located(mumps_.factorize(const_cast<double*>(K.valuePtr()))).throw_if_failed();
    factored_ = true;
  }
  Eigen::VectorXd solve(const Eigen::VectorXd& b) override {
    Eigen::VectorXd x = b;
    mumps_.solve(x.data());
    return x;
  }
  std::optional<Eigen::VectorXd> solve_reusing_factor(const Eigen::SparseMatrix<double>& K,
                                                      const Eigen::VectorXd& b, int max_iterations,
                                                      double tolerance,
                                                      bool* negative_curvature) override {
    return factored_ ? reuse_factor(*this, K, b, max_iterations, tolerance, negative_curvature)
                     : std::nullopt;
  }
  long factor_nonzeros() const override { return mumps_.factor_nonzeros(); }

 private:
  std::optional<MumpsInput> in_;
  MumpsDouble mumps_;
  bool factored_ = false;
};

// Mixed precision: the factorization in single precision (SMUMPS, about 1.7× faster here: half
// the memory traffic and twice the SIMD width), used as the preconditioner of conjugate
// gradients on the double-precision K until the relative residual is below 1e-12 (two
// iterations on the skin meshes; a double-precision factorization gets about 1e-15). When the
// single-precision factor is not good enough (null or negative pivots in single precision,
// or CG not converging: an ill-conditioned or singular K) the system is analysed and factored
// again in double precision, so the answer and the error messages are those of MumpsSolver.
class MixedMumpsSolver final : public DirectSolver {
 public:
  explicit MixedMumpsSolver(int ordering) : ordering_(ordering), single_(ordering, 1e-5f) {}
  void analyze(const Eigen::SparseMatrix<double>& K, const std::vector<int>& block_start) override {
    in_.emplace(K, block_start);
    single_.analyze(static_cast<int>(K.rows()), in_->irn, in_->jcn, in_->blkptr);
  }
  void factorize(const Eigen::SparseMatrix<double>& K) override {
    K_ = &K;
    if (double_) {  // a later factorization (Newton) after a fall-back stays in double precision
      // and checked as MumpsSolver checks it: a singular tangent is reported, never solved
      double_->located(double_->factorize(const_cast<double*>(K.valuePtr()))).throw_if_failed();
      double_factored_ = true;
      return;
    }
    a_ = K.coeffs().cast<float>();
    // A K beyond single precision's range, or a single-precision factor that fails in any way,
    // is factored again in double precision.
    if (!a_.allFinite() || !single_.factorize(a_.data()).ok) fall_back();
  }
  std::optional<Eigen::VectorXd> solve_reusing_factor(const Eigen::SparseMatrix<double>& K,
                                                      const Eigen::VectorXd& b, int max_iterations,
                                                      double tolerance,
                                                      bool* negative_curvature) override {
    if (!K_ || (double_ && !double_factored_)) return std::nullopt;
    K_ = &K;
    return cg(b, max_iterations, std::max(tolerance, kCgTolerance), negative_curvature);
  }
  Eigen::VectorXd solve(const Eigen::VectorXd& b) override {
    if (!double_) {
      if (std::optional<Eigen::VectorXd> x = cg(b, kMaxIterations, kCgTolerance)) return *x;
      fall_back();
    }
    Eigen::VectorXd x = b;
    double_->solve(x.data());
    return x;
  }
  long factor_nonzeros() const override {
    return double_ ? double_->factor_nonzeros() : single_.factor_nonzeros();
  }
  SolverReport report() const override {
    return {double_ ? "double" : "mixed", iterations_, static_cast<bool>(double_)};
  }

 private:
  void fall_back() {
    double_.emplace(ordering_, 1e-12);
    double_factored_ = false;
    double_->analyze(static_cast<int>(K_->rows()), in_->irn, in_->jcn, in_->blkptr);
    double_->located(double_->factorize(const_cast<double*>(K_->valuePtr()))).throw_if_failed();
    double_factored_ = true;
  }
  // The last factor applied to r: the single-precision one, or the double-precision one after a
  // fall-back (then reused for later tangents as well).
  Eigen::VectorXd precondition(const Eigen::VectorXd& r, int iteration) {
    if (double_) {
      Eigen::VectorXd z = r;
      double_->solve(z.data(), iteration);
      return z;
    }
    Eigen::VectorXf z = r.cast<float>();
    single_.solve(z.data(), iteration);
    return z.cast<double>();
  }
  std::optional<Eigen::VectorXd> cg(const Eigen::VectorXd& b, int max_iterations, double tolerance,
                                    bool* negative_curvature = nullptr) {
    return conjugate_gradients(
        *K_, b, max_iterations, tolerance,
        [&](const Eigen::VectorXd& r, int iteration) { return precondition(r, iteration); },
        iterations_, negative_curvature);
  }
  static constexpr int kMaxIterations = 40;

  int ordering_;
  std::optional<MumpsInput> in_;
  MumpsSingle single_;
  std::optional<MumpsDouble> double_;
  bool double_factored_ = false;  // the double-precision factor exists (after a fall-back)
  const Eigen::SparseMatrix<double>* K_ = nullptr;
  Eigen::VectorXf a_;
  int iterations_ = 0;
};

// CHOLMOD (SuiteSparse 5): supernodal Cholesky, on the fill-reducing ordering of a MUMPS
// analysis (PORD, the MUMPS default here). CHOLMOD's own choice would be METIS's nested
// dissection, and METIS 5 (GKlib) replaces the process's SIGTERM handler with one that
// longjmps to a thread-local buffer for as long as it runs: a SIGTERM then (caps serve being
// stopped) lands on another thread and crashes the process. On the whole face PORD's factor
// has 1.4 % more entries than CHOLMOD's choice (METIS-based nested dissection) and 8 % fewer
// flops; AMD alone costs 1.6x the flops (docs/fem.md).
class CholmodSolver final : public DirectSolver {
 public:
  explicit CholmodSolver(int mumps_ordering) : mumps_ordering_(mumps_ordering) {
    cholmod_start(&c_);
    c_.print = 0;
    c_.nmethods = 1;
    c_.method[0].ordering = CHOLMOD_GIVEN;
    c_.postorder = 1;
    // Always the supernodal LL^T, which stops at a pivot that is not positive. On a small matrix
    // CHOLMOD would otherwise choose its simplicial LDL^T, which factors an indefinite matrix
    // without a word (a 50-equation tangent with a negative eigenvalue was factored): the
    // finite-strain solve would then take an indefinite tangent's direction for Newton's.
    c_.supernodal = CHOLMOD_SUPERNODAL;
  }
  ~CholmodSolver() override {
    if (L_) cholmod_free_factor(&L_, &c_);
    cholmod_finish(&c_);
  }
  void analyze(const Eigen::SparseMatrix<double>& K, const std::vector<int>& block_start) override {
    std::vector<int> order;
    {
      MumpsInput in(K, block_start);
      MumpsDouble ordering(mumps_ordering_, 1e-12);
      ordering.analyze(static_cast<int>(K.rows()), in.irn, in.jcn, in.blkptr);
      order = ordering.pivot_order();
    }
    cholmod_sparse A = view(K);
    A.xtype = CHOLMOD_PATTERN;  // the values may still be being assembled
    A.x = nullptr;
    if (L_) cholmod_free_factor(&L_, &c_);
    L_ = cholmod_analyze_p(&A, order.data(), nullptr, 0, &c_);
    if (!L_ || c_.status < 0)
      throw SolverError(cat("CHOLMOD analysis failed, status ", c_.status));
  }
  void factorize(const Eigen::SparseMatrix<double>& K) override {
    factored_ = false;
    cholmod_sparse A = view(K);
    cholmod_factorize(&A, L_, &c_);
    if (c_.status == CHOLMOD_NOT_POSDEF) {
      const int minor = static_cast<int>(L_->minor);
      const int* perm = static_cast<const int*>(L_->Perm);
      throw SingularMatrix("CHOLMOD: the matrix is not positive definite",
                           perm && minor < static_cast<int>(K.rows()) ? perm[minor] : -1);
    }
    if (c_.status < 0) throw SolverError(cat("CHOLMOD factorization failed, status ", c_.status));
    // A rigid-body mode gives a pivot at round-off level rather than a negative one.
    const double rc = cholmod_rcond(L_, &c_);
    if (!(rc > 1e-14))
      throw SingularMatrix(
          cat("CHOLMOD: reciprocal condition estimate ", rc),
          dominant_equation(K.rows(), [&](const Eigen::VectorXd& b) { return solve(b); }));
    factored_ = true;
  }
  std::optional<Eigen::VectorXd> solve_reusing_factor(const Eigen::SparseMatrix<double>& K,
                                                      const Eigen::VectorXd& b, int max_iterations,
                                                      double tolerance,
                                                      bool* negative_curvature) override {
    return factored_ ? reuse_factor(*this, K, b, max_iterations, tolerance, negative_curvature)
                     : std::nullopt;
  }
  Eigen::VectorXd solve(const Eigen::VectorXd& b) override {
    cholmod_dense B{};
    B.nrow = B.d = static_cast<size_t>(b.size());
    B.ncol = 1;
    B.nzmax = B.nrow;
    B.x = const_cast<double*>(b.data());
    B.xtype = CHOLMOD_REAL;
    B.dtype = CHOLMOD_DOUBLE;
    cholmod_dense* X = cholmod_solve(CHOLMOD_A, L_, &B, &c_);
    if (!X) throw SolverError(cat("CHOLMOD solve failed, status ", c_.status));
    Eigen::VectorXd x = Eigen::Map<Eigen::VectorXd>(static_cast<double*>(X->x), b.size());
    cholmod_free_dense(&X, &c_);
    return x;
  }
  long factor_nonzeros() const override { return static_cast<long>(c_.lnz); }

 private:
  static cholmod_sparse view(const Eigen::SparseMatrix<double>& K) {
    cholmod_sparse A{};
    A.nrow = A.ncol = static_cast<size_t>(K.rows());
    A.nzmax = static_cast<size_t>(K.nonZeros());
    A.p = const_cast<int*>(K.outerIndexPtr());
    A.i = const_cast<int*>(K.innerIndexPtr());
    A.x = const_cast<double*>(K.valuePtr());
    A.stype = 1;  // upper triangle stored
    A.itype = CHOLMOD_INT;
    A.xtype = CHOLMOD_REAL;
    A.dtype = CHOLMOD_DOUBLE;
    A.sorted = 1;
    A.packed = 1;
    return A;
  }
  int mumps_ordering_;
  cholmod_common c_{};
  cholmod_factor* L_ = nullptr;
  bool factored_ = false;
};

// OpenBLAS's thread controls, looked up in the process (MUMPS and CHOLMOD link the system's
// libblas.so.3, which Debian's alternatives may point at OpenBLAS or at the reference BLAS).
struct OpenBlas {
  void (*set)(int) = nullptr;
  int (*get)() = nullptr;
};

const OpenBlas& openblas() {
  static const OpenBlas blas = [] {
    OpenBlas b;
    b.set = reinterpret_cast<void (*)(int)>(dlsym(RTLD_DEFAULT, "openblas_set_num_threads"));
    b.get = reinterpret_cast<int (*)()>(dlsym(RTLD_DEFAULT, "openblas_get_num_threads"));
    if (!b.set || !b.get) b = {};
    return b;
  }();
  return blas;
}

std::mutex blas_mutex;
int blas_guards = 0;        // BlasThreads alive that changed the count
int blas_kept_threads = 0;  // the count before the first of them

}  // namespace

}  // namespace caps::fem::detail

namespace caps::fem {

using detail::blas_guards;
using detail::blas_kept_threads;
using detail::blas_mutex;
using detail::OpenBlas;
using detail::openblas;

BlasThreads::BlasThreads(int threads) {
  const OpenBlas& blas = openblas();
  if (threads <= 0 || !blas.set) return;
  const std::lock_guard lock(blas_mutex);
  if (blas_guards++ == 0) {
    blas_kept_threads = blas.get();
    if (blas_kept_threads != threads) blas.set(threads);
  }
  active_ = true;
}

BlasThreads::~BlasThreads() {
  if (!active_) return;
  const std::lock_guard lock(blas_mutex);
  if (--blas_guards == 0 && openblas().get() != blas_kept_threads) openblas().set(blas_kept_threads);
}

}  // namespace caps::fem

namespace caps::fem::detail {

bool gemv_forwarding_linked();  // blas_gemv_forward.cpp

std::unique_ptr<DirectSolver> make_direct_solver(SolverKind kind, int mumps_ordering,
                                                 bool mixed_precision) {
  [[maybe_unused]] static const bool gemv_forwarding = gemv_forwarding_linked();
  // (SolverKind::Auto is resolved by the caller: resolved_solver().)
  if (kind == SolverKind::Cholmod) return std::make_unique<CholmodSolver>(mumps_ordering);
  if (mixed_precision) return std::make_unique<MixedMumpsSolver>(mumps_ordering);
  return std::make_unique<MumpsSolver>(mumps_ordering);
}

}  // namespace caps::fem::detail
