#pragma once
// Internal: sparse symmetric positive definite direct solvers behind one interface.

#include <Eigen/Sparse>
#include <memory>
#include <stdexcept>

#include "caps/fem/solve.hpp"

namespace caps::fem::detail {

/// Thrown by a solver when the matrix is singular or not positive definite; `equation` is a
/// reduced equation where it showed (-1 if unknown).
struct SingularMatrix : std::runtime_error {
  SingularMatrix(const std::string& what, int equation)
      : std::runtime_error(what), equation(equation) {}
  int equation;
};

class DirectSolver {
 public:
  virtual ~DirectSolver() = default;
  /// Symbolic analysis (ordering) of the upper triangle K (column-major). K must stay alive
  /// and unchanged in structure until the solver is destroyed.
  virtual void analyze(const Eigen::SparseMatrix<double>& K) = 0;
  virtual void factorize(const Eigen::SparseMatrix<double>& K) = 0;
  virtual Eigen::VectorXd solve(const Eigen::VectorXd& b) = 0;
  virtual long factor_nonzeros() const = 0;
};

std::unique_ptr<DirectSolver> make_direct_solver(SolverKind kind, int mumps_ordering);

}  // namespace caps::fem::detail
