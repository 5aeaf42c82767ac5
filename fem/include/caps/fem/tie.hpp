#pragma once
/// @brief Ties between non-matching meshes (Abaqus's and CalculiX's *TIE): each slave node is
/// given the master element it lies in (or the nearest one within a tolerance) and that
/// element's shape functions at its position, the weights of Mesh::ties.

#include <Eigen/Core>
#include <vector>

#include "caps/fem/mesh.hpp"

namespace caps::fem {

/// How tie_nodes() ties a slave that lies on a face of slave nodes.
enum class TieMethod {
  /// The mortar condition int N_s (u_slave - u_master) dA = 0 over the slave's faces (a row
  /// coupling the slave to its face neighbours and to the master nodes under those faces):
  /// passes the patch test (a uniform stress crosses the interface exactly).
  Mortar,
  /// The slave's own displacement equals the master's at its position (CalculiX's *TIE for
  /// quadratic elements): does not pass the patch test on non-matching quadratic faces.
  NodeToSurface
};

/// What tie_nodes() found.
struct TieSearchResult {
  std::vector<TiedNode> ties;           ///< one per slave that found a master, in input order
  std::vector<int> master_element;      ///< per tie: the element it is tied to
  std::vector<Eigen::Vector3d> natural; ///< per tie: the natural coordinates of its master point
  std::vector<double> distance_mm;      ///< per tie: slave to its master point (0 inside)
  std::vector<int> unmatched;           ///< slaves with no master element within the tolerance
  /// per unmatched slave: its distance to the nearest master element (mm; infinity if none)
  std::vector<double> unmatched_distance_mm;
  int n_mortar = 0;  ///< ties that are mortar rows (the others are node-to-surface)
};

/// Ties `slaves` to `master_elements` of `mesh` (any element type, through its shape functions):
/// a slave inside a master element (found by inverting the element's map with Newton in natural
/// coordinates) gets N_a(xi) of that element; one outside every master element gets those of
/// its nearest point on the nearest element (the closest point, projected Gauss-Newton on the
/// element's reference domain) if that is within `tolerance_mm`, and is listed as unmatched
/// with its distance otherwise. Weights below 1e-12 are dropped (the rest renormalised to sum
/// to 1). The result's ties go into Mesh::ties; the caller decides what an unmatched slave means.
/// @param slaves           node ids (no repeats)
/// @param master_elements  element ids; an element the slave is a node of is not its master
/// @param tolerance_mm     >= 0: how far outside the master elements a slave may be
/// Throws InvalidInput for ids out of range, repeated slaves or a negative tolerance.
TieSearchResult tie_nodes(const Mesh& mesh, const std::vector<int>& slaves,
                          const std::vector<int>& master_elements, double tolerance_mm,
                          TieMethod method = TieMethod::Mortar);

}  // namespace caps::fem
