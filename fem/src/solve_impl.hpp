#pragma once
// Internal: pieces shared by the linear solve (solve.cpp) and the finite-strain solve
// (solve_finite.cpp): timing, stress recovery, reactions and suture forces.

#include <Eigen/Core>
#include <chrono>
#include <functional>

#include "caps/fem/solve.hpp"
#include "constraints.hpp"

namespace caps::fem::detail {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t);
/// Process peak RSS (MB).
double peak_rss_mb();

/// What the recovery needs from one element.
struct ElementRecovery {
  Eigen::MatrixXd gauss_stress;  ///< #GP×6 Voigt (MPa), rule order
  Eigen::MatrixX3d f_int;        ///< #n×3 internal force (N)
  double energy_mj = 0;          ///< strain energy of the element
  double von_mises_mean = 0;     ///< volume mean of the Gauss von Mises stress (MPa)
};
using ElementRecoveryFn = std::function<void(int element, ElementRecovery& out)>;

/// Fills res's Gauss, nodal (gauss_to_nodes(), averaged over the elements at a node) and
/// element stresses, strain energy, reactions (f_int - f_ext on constrained nodes) and suture
/// forces from `element_recovery`, run in parallel over elements.
/// res.displacement_mm must be set.
void recover(const Mesh& mesh, const DofMap& map, const ElementRecoveryFn& element_recovery,
             SolveResult& res);

/// The finite-strain solve after validation and the dof map (res has the sizes set).
void solve_finite(const Mesh& mesh, const SolveOptions& options, const DofMap& map,
                  SolveResult& res);

}  // namespace caps::fem::detail
