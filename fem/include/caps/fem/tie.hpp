#pragma once
/// @brief Ties between non-matching meshes (Abaqus's and CalculiX's *TIE): each slave node is
/// given the master element it lies in (or the nearest one within a tolerance), and the weights
/// of Mesh::ties: a mortar row over the slave's faces, or that element's shape functions at its
/// position.

#include <Eigen/Core>
#include <string>
#include <vector>

#include "caps/core/reporter.hpp"
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

/// "mortar" / "node-to-surface".
const char* tie_method_name(TieMethod method);
/// Parses "mortar" / "node-to-surface"; throws InvalidInput otherwise.
TieMethod parse_tie_method(const std::string& name);

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

/// Ties `slaves` to `master_elements` of `mesh` (any element type, through its shape functions
/// and the reference domain spanned by its natural nodes).
///
/// Every slave is first located: inside a master element (found by inverting the element's map
/// with Newton in natural coordinates) or, outside every one, at its nearest point on the nearest
/// element (projected Gauss-Newton on the element's reference domain) if that is within
/// `tolerance_mm`; a slave with no master point within the tolerance is listed as unmatched with
/// its distance (the caller decides what that means). Its tie is then:
///  - TieMethod::Mortar, for a slave on a slave face (a face of an element outside the masters
///    whose nodes are all slaves): the row int_G N_s (u_slave - u_master) dA = 0 over its slave
///    faces G, scaled to a unit coefficient on the slave: its masters are its face neighbours
///    (negative weights, -M_ss' / M_ss) and the master nodes under its faces (D_sm / M_ss), where
///    M_ss' = int N_s N_s' and D_sm = int N_s N_m (docs/fem.md, "Ties and sliding on the bone").
///    The integrals are taken on n x n sub-cells of each slave face (n = 4..16, from the face's
///    size against the master elements'), 3 x 3 Gauss points each, every point's master value at
///    its nearest master point; a face with a point beyond the tolerance is left out.
///  - TieMethod::NodeToSurface, and for a matched slave on no slave face: the master element's
///    shape functions at the slave's master point (CalculiX's *TIE for quadratic elements).
/// Weights below 1e-12 are dropped (the rest renormalised to sum to 1). The result's ties go
/// into Mesh::ties.
/// @param slaves           node ids (no repeats)
/// @param master_elements  element ids; an element the slave is a node of is not its master
/// @param tolerance_mm     >= 0: how far outside the master elements a slave may be
/// @param reporter         not owned, may be null: its cancellation is checked at every point
///                         located (Cancelled)
/// Throws InvalidInput for ids out of range, repeated slaves or a negative tolerance.
TieSearchResult tie_nodes(const Mesh& mesh, const std::vector<int>& slaves,
                          const std::vector<int>& master_elements, double tolerance_mm,
                          TieMethod method = TieMethod::Mortar, Reporter* reporter = nullptr);

}  // namespace caps::fem
