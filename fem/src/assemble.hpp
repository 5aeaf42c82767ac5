#pragma once
// Internal: parallel assembly of the reduced stiffness (upper triangle) and load vector.

#include <Eigen/Sparse>

#include "caps/fem/mesh.hpp"
#include "constraints.hpp"

namespace caps::fem::detail {

struct Assembly {
  Eigen::SparseMatrix<double> K;  ///< n_eq × n_eq, column-major, upper triangle (row <= col)
  Eigen::VectorXd f;              ///< T^T (f_ext - K g)
};

/// Assembles with TBB over elements (atomic scatter into a precomputed pattern).
Assembly assemble(const Mesh& mesh, const DofMap& map);

}  // namespace caps::fem::detail
