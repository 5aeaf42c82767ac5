#pragma once
/// @brief The result directory of a solve: result.vtu (VTK XML UnstructuredGrid, ascii; point
/// data displacement, stresses, reactions) and result.json (summary, timings, sizes, suture
/// forces), written by `caps solve` and `caps simulate` and read back by `caps render`.

#include <Eigen/Core>
#include <filesystem>

#include "caps/fem/mesh.hpp"
#include "caps/fem/solve.hpp"
#include "caps/fem/suture_report.hpp"

namespace caps::fem {

/// Writes result.vtu (deformed-ready: displacement, stresses, reactions) and result.json
/// (summary, timings, sizes, suture forces; with `sutures` also "sutures_at_spacing": the force
/// per suture at that spacing, the largest, the force per mm of wound) into an existing
/// directory.
void write_result_dir(const Mesh& mesh, const SolveResult& result,
                      const std::filesystem::path& dir, const SutureSpacing* sutures = nullptr);

/// Reads the nodal displacement (#N×3, mm) from `dir`/result.vtu and checks it has `n_nodes`
/// finite rows. Throws IoError (missing file) or InvalidInput (wrong size, missing array).
Eigen::MatrixX3d read_result_displacement(const std::filesystem::path& dir, Eigen::Index n_nodes);

/// Reads the nodal maximum principal stress (#N, MPa; SolveResult::max_principal_mpa) from
/// `dir`/result.vtu and checks it has `n_nodes` finite entries. Throws as
/// read_result_displacement().
Eigen::VectorXd read_result_max_principal(const std::filesystem::path& dir, Eigen::Index n_nodes);

}  // namespace caps::fem
