#pragma once
/// @brief The sutures' report of a solve: the row of sutures a surgeon places along the closed
/// wound, each with the closing force of the nodal suture pairs it holds (caps::closure
/// gathers them on a patient's mesh; result_io writes them into result.json).

#include <Eigen/Core>
#include <vector>

#include "caps/fem/solve.hpp"

namespace caps::fem {

/// One suture of the row.
struct SutureStitch {
  Eigen::Vector3d position_mm{0, 0, 0};  ///< where it sits on the closed skin, LPS mm
  double force_n = 0;                    ///< its closing force, N
  int n_pairs = 0;                       ///< nodal suture pairs it holds (all depths)
};

/// The row of sutures and its summary.
struct SutureSpacing {
  double spacing_mm = 5;              ///< the spacing asked for
  double wound_length_mm = 0;         ///< the closed wound's length on the skin (all its lines)
  std::vector<SutureStitch> sutures;  ///< the tensile ones (force >= 0), along the wound
  /// The sutures whose pairs push in sum (force < 0): where the closure presses the lips
  /// together. Reported apart: in no total, maximum, mean or force per mm.
  std::vector<SutureStitch> compressive;
  double max_suture_force_n = 0;      ///< the largest single-suture force, N
  double mean_suture_force_n = 0;     ///< over the tensile sutures, N
  double force_per_mm_n = 0;          ///< total_force_n / wound length, N/mm
  double total_force_n = 0;           ///< the sum over the tensile sutures, N
  double compressive_force_n = 0;     ///< the sum over the compressive ones (<= 0), N
};

/// The largest force on one sutured node pair (N): max over result.suture_forces of magnitude_n.
double max_suture_pair_force_n(const SolveResult& result);

}  // namespace caps::fem
