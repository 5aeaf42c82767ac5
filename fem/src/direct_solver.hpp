#pragma once
// Internal: sparse symmetric positive definite direct solvers behind one interface.

#include "caps/fem/blas.hpp"
#include <Eigen/Sparse>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "caps/core/error.hpp"
#include "caps/fem/solve.hpp"

namespace caps::fem::detail {

/// Thrown by a solver when the matrix is singular or not positive definite; `equation` is a
/// reduced equation where it showed (-1 if unknown). solve() names the element from it.
struct SingularMatrix : SolverError {
  SingularMatrix(const std::string& what, int equation) : SolverError(what), equation(equation) {}
  int equation;
};

/// How a solve was done: "double", or "mixed" (single-precision factor, refined to double
/// accuracy by conjugate gradients), with its iteration count and whether it fell back.
struct SolverReport {
  std::string precision = "double";
  int iterations = 0;
  bool fell_back_to_double = false;
};

class DirectSolver {
 public:
  virtual ~DirectSolver() = default;
  /// Symbolic analysis (ordering) of the structure of the upper triangle K (column-major); K's
  /// values are not read, so they may be assembled meanwhile. `block_start` (optional) groups
  /// consecutive equations that share their structure (a node's x, y, z): block b is
  /// block_start[b] .. block_start[b+1]-1. K must stay alive and unchanged in structure until
  /// the solver is destroyed.
  virtual void analyze(const Eigen::SparseMatrix<double>& K, const std::vector<int>& block_start) = 0;
  /// Numerical factorization of K's values; may be called again with new values of the same
  /// structure (Newton iterations, load steps): the analysis is reused.
  virtual void factorize(const Eigen::SparseMatrix<double>& K) = 0;
  virtual Eigen::VectorXd solve(const Eigen::VectorXd& b) = 0;
  /// Solves K x = b for K's current values by conjugate gradients preconditioned with the last
  /// factorization (of earlier values of the same structure: a previous Newton tangent), to a
  /// relative residual ||b - K x|| <= tolerance ||b|| (1e-12 and below: the accuracy of solve();
  /// an inexact Newton iteration asks for less). Empty when there is no factorization to reuse,
  /// or CG needs more than `max_iterations` (then factorize() the new values). The base class
  /// never reuses (always empty). `negative_curvature` (optional) is set to true when CG met a
  /// direction p with p^T K p <= 0: K is then not positive definite, and factorizing it would fail.
  virtual std::optional<Eigen::VectorXd> solve_reusing_factor(const Eigen::SparseMatrix<double>& K,
                                                              const Eigen::VectorXd& b,
                                                              int max_iterations,
                                                              double tolerance = 1e-12,
                                                              bool* negative_curvature = nullptr) {
    (void)K, (void)b, (void)max_iterations, (void)tolerance, (void)negative_curvature;
    return std::nullopt;
  }
  virtual long factor_nonzeros() const = 0;
  virtual SolverReport report() const { return {}; }
};

std::unique_ptr<DirectSolver> make_direct_solver(SolverKind kind, int mumps_ordering,
                                                 bool mixed_precision);

using caps::fem::BlasThreads;  // fem/blas.hpp

}  // namespace caps::fem::detail
