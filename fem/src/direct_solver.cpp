#include "direct_solver.hpp"

#include <cholmod.h>
#include <dmumps_c.h>

#include <string>
#include <vector>

#include "caps/core/error.hpp"

namespace caps::fem::detail {
namespace {

// MUMPS 5.5 users' guide, sec. 5-6: SYM = 1 (symmetric positive definite), sequential host.
class MumpsSolver final : public DirectSolver {
 public:
  explicit MumpsSolver(int ordering) : ordering_(ordering) {
    id_.comm_fortran = -987654;  // USE_COMM_WORLD; the sequential library ignores it
    id_.par = 1;
    id_.sym = 1;
    id_.job = -1;
    dmumps_c(&id_);
    check("initialization");
    id_.icntl[0] = -1;  // no error/diagnostic/global output
    id_.icntl[1] = -1;
    id_.icntl[2] = -1;
    id_.icntl[3] = 0;
    id_.icntl[6] = ordering_;  // ICNTL(7)
    id_.icntl[13] = 50;        // ICNTL(14): +50 % workspace over the estimate
    id_.icntl[23] = 1;         // ICNTL(24): detect null pivots (rigid-body modes)
    id_.cntl[2] = 1e-12;       // CNTL(3): |pivot| <= 1e-12 ||A|| counts as null
  }
  ~MumpsSolver() override {
    id_.job = -2;
    dmumps_c(&id_);
  }
  void analyze(const Eigen::SparseMatrix<double>& K) override {
    const int n = static_cast<int>(K.rows());
    irn_.resize(K.nonZeros());
    jcn_.resize(K.nonZeros());
    for (int j = 0; j < n; ++j)
      for (int k = K.outerIndexPtr()[j]; k < K.outerIndexPtr()[j + 1]; ++k) {
        irn_[k] = K.innerIndexPtr()[k] + 1;
        jcn_[k] = j + 1;
      }
    id_.n = n;
    id_.nnz = K.nonZeros();
    id_.irn = irn_.data();
    id_.jcn = jcn_.data();
    id_.a = const_cast<double*>(K.valuePtr());
    id_.job = 1;
    dmumps_c(&id_);
    check("analysis");
  }
  void factorize(const Eigen::SparseMatrix<double>& K) override {
    id_.a = const_cast<double*>(K.valuePtr());
    for (int attempt = 0;; ++attempt) {
      id_.job = 2;
      dmumps_c(&id_);
      // -8/-9: workspace too small for the numerical pivots; grow and retry (users' guide 8).
      if ((id_.infog[0] == -8 || id_.infog[0] == -9) && attempt < 3) {
        id_.icntl[13] *= 2;
        continue;
      }
      break;
    }
    if (id_.infog[0] == -10)
      throw SingularMatrix("MUMPS: the matrix is numerically singular (INFOG(1) = -10)", -1);
    check("factorization");
    if (id_.infog[27] > 0)  // INFOG(28): null pivots
      throw SingularMatrix(cat("MUMPS found ", id_.infog[27], " null pivot(s)"),
                           id_.pivnul_list ? id_.pivnul_list[0] - 1 : -1);
    if (id_.infog[11] > 0)  // INFOG(12): negative pivots, impossible for a valid stiffness
      throw SingularMatrix(cat("MUMPS found ", id_.infog[11], " negative pivot(s)"), -1);
  }
  Eigen::VectorXd solve(const Eigen::VectorXd& b) override {
    Eigen::VectorXd x = b;
    id_.rhs = x.data();
    id_.nrhs = 1;
    id_.lrhs = id_.n;
    id_.job = 3;
    dmumps_c(&id_);
    check("solve");
    return x;
  }
  long factor_nonzeros() const override {
    // INFOG(29): effective entries in the factors (negative = millions).
    const long v = id_.infog[28];
    return v >= 0 ? v : -v * 1000000L;
  }

 private:
  void check(const char* phase) {
    if (id_.infog[0] < 0)
      throw SolverError(cat("MUMPS ", phase, " failed: INFOG(1) = ", id_.infog[0],
                            ", INFOG(2) = ", id_.infog[1],
                            " (see the MUMPS users' guide, section 8)"));
  }
  int ordering_;
  DMUMPS_STRUC_C id_{};
  std::vector<MUMPS_INT> irn_, jcn_;
};

// CHOLMOD (SuiteSparse 5): supernodal Cholesky with its default AMD/METIS ordering choice.
class CholmodSolver final : public DirectSolver {
 public:
  CholmodSolver() {
    cholmod_start(&c_);
    c_.print = 0;
  }
  ~CholmodSolver() override {
    if (L_) cholmod_free_factor(&L_, &c_);
    cholmod_finish(&c_);
  }
  void analyze(const Eigen::SparseMatrix<double>& K) override {
    cholmod_sparse A = view(K);
    L_ = cholmod_analyze(&A, &c_);
    if (!L_ || c_.status < 0)
      throw SolverError(cat("CHOLMOD analysis failed, status ", c_.status));
  }
  void factorize(const Eigen::SparseMatrix<double>& K) override {
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
      throw SingularMatrix(cat("CHOLMOD: reciprocal condition estimate ", rc), -1);
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
  cholmod_common c_{};
  cholmod_factor* L_ = nullptr;
};

}  // namespace

std::unique_ptr<DirectSolver> make_direct_solver(SolverKind kind, int mumps_ordering) {
  if (kind == SolverKind::Cholmod) return std::make_unique<CholmodSolver>();
  return std::make_unique<MumpsSolver>(mumps_ordering);
}

}  // namespace caps::fem::detail
