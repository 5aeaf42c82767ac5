#pragma once
/// @brief The continuum mesh the solver reads: quadratic hexahedra, wedges and tetrahedra, layers,
/// fixed degrees of freedom, nodal loads and suture pairs. Units mm (LPS), N.
///
/// Local node numbering (paper Figure 5; docs/mesh-format.md has the drawings):
///
/// Hex20 (natural coordinates xi, eta, zeta in [-1,1]^3; zeta = -1 is face 0, the "top" face,
/// the skin side; zeta = +1 is face 1, the bottom, towards bone):
///   0-3   top_nodes       (-1,-1,-1) (1,-1,-1) (1,1,-1) (-1,1,-1)
///   4-7   bottom_nodes    same at zeta = +1
///   8-11  top_mid_nodes   edges 0-1, 1-2, 2-3, 3-0
///   12-15 bottom_mid      edges 4-5, 5-6, 6-7, 7-4
///   16-19 center_nodes    edges 0-4, 1-5, 2-6, 3-7
/// The right-hand normal of 0-1-2-3 must point into the element (towards 4-7); otherwise the
/// Jacobian is negative. This is exactly VTK_QUADRATIC_HEXAHEDRON (25): identity mapping.
///
/// Wedge15 (area coordinates r, s with L0 = 1-r-s, and zeta in [-1,1]):
///   0-2   top corners (r,s) = (0,0) (1,0) (0,1) at zeta = -1;   3-5 same at zeta = +1
///   6-8   top edges 0-1, 1-2, 2-0;  9-11 bottom edges 3-4, 4-5, 5-3;  12-14 edges 0-3, 1-4, 2-5
/// Same orientation rule as Hex20 (0-1-2 right-hand normal towards 3-5). It is the paper's
/// collapsed hexahedron with hex nodes 2=3=10, 18=19 and 6=7=14 merged (wedge_from_collapsed_hex).
/// VTK_QUADRATIC_WEDGE (26) orients 0-1-2 the other way, so VTK order = caps order permuted by
/// kWedge15ToVtk (an involution: the same table converts back).
///
/// Tet10 (volume coordinates L1 = xi, L2 = eta, L3 = zeta, L0 = 1-xi-eta-zeta):
///   0-3   corners (0,0,0) (1,0,0) (0,1,0) (0,0,1)
///   4-9   mid-edge nodes of edges 0-1, 1-2, 2-0, 0-3, 1-3, 2-3
///
///            3
///           /|\             the right-hand normal of 0-1-2 points towards 3:
///          7 | 9            det J > 0 when (x1-x0) x (x2-x0) . (x3-x0) > 0
///         /  8  \           (quadratic_tetrahedra() refuses a tet that is not)
///        0 -6-|- 2
///         \   |  /
///          4  | 5
///           \ |/
///             1
/// This is VTK_QUADRATIC_TETRA (24) and CalculiX C3D10 node for node: identity mapping. A
/// tetrahedron has no top face and no layer plane (the whole-face model, not the extruded patch).

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "caps/fem/implicit_surface.hpp"
#include "caps/fem/material.hpp"

namespace caps::fem {

enum class ElementType : std::uint8_t { Hex20, Wedge15, Tet10 };

/// How Wedge15 is integrated (the other types have one rule).
enum class WedgeRule {
  /// 21 points (a 7-point degree-5 triangle rule x 3 Gauss points): exact on affine wedges.
  Full,
  /// 9 points (a 3-point degree-2 triangle rule x 3 Gauss points): CalculiX's C3D15, so that
  /// caps and ccx solve the same discrete problem on meshes with wedges (caps simulate
  /// --wedge-rule calculix; docs/fem.md, "The whole face").
  CalculiX
};

/// "full" / "calculix".
const char* wedge_rule_name(WedgeRule rule);
/// Parses "full" / "calculix"; throws InvalidInput otherwise.
WedgeRule parse_wedge_rule(const std::string& name);

/// 20 for Hex20, 15 for Wedge15, 10 for Tet10.
int n_element_nodes(ElementType type);
/// "Hex20" / "Wedge15" / "Tet10".
const char* element_type_name(ElementType type);

/// vtk_node[k] = caps_node[kWedge15ToVtk[k]].
inline constexpr std::array<int, 15> kWedge15ToVtk{0, 2, 1, 3, 5, 4, 8, 7, 6, 11, 10, 9, 12, 14, 13};

/// One element: type, material layer id and node ids (first n_element_nodes(type) are used).
struct Element {
  ElementType type = ElementType::Hex20;
  int layer = 0;
  std::array<int, 20> nodes{};
  int n_nodes() const { return n_element_nodes(type); }
};

/// A prescribed displacement of one component (0 = x, 1 = y, 2 = z) of one node, in mm.
struct FixedDof {
  int node = 0;
  int component = 0;
  double value_mm = 0.0;
};

/// A point force on a node, N.
struct NodalLoad {
  int node = 0;
  Eigen::Vector3d force_n = Eigen::Vector3d::Zero();
};

/// A suture between nodes a and b: u_a - u_b = x_b - x_a, so the two meet after closure.
struct SuturePair {
  int a = 0;
  int b = 0;
};

/// A node that rests on the deep tissue but slides over it (undermined tissue lying back on the
/// fascia: frictionless contact that stays closed, linearized about the start): its
/// displacement along the unit `normal` is held at 0 by a penalty spring of
/// `stiffness_n_per_mm` (N/mm); along the surface it is free.
///
/// With `on_surface` (and Mesh::sliding_surface given) the node slides on that curved surface
/// instead: the finite-strain solve holds phi(X + u) = phi(X) by the penalty
/// k/2 (phi(X + u) - phi(X))^2, re-evaluated at every Newton iteration, so the node ends on the
/// level set it started on; the small-strain solve holds its linearisation, the displacement
/// along grad phi(X) / |grad phi(X)| (docs/fem.md, "Ties and sliding on the bone"). `normal` is
/// then the start normal (written to mesh.json and the CalculiX deck).
struct SlidingNode {
  int node = 0;
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
  double stiffness_n_per_mm = 0;
  bool on_surface = false;
};

/// A node tied to a non-matching mesh (Abaqus's and CalculiX's *TIE): u_node = sum_i
/// weights[i] u_masters[i], the weights summing to 1. fem::tie_nodes() makes the entries: a
/// mortar row (the masters are the master nodes under the slave's faces and its neighbours on
/// those faces, which are slaves too) or the master element's shape functions at the slave's
/// position. Held by a penalty in both solves and written as exact *EQUATIONs to CalculiX
/// (docs/fem.md, "Ties and sliding on the bone").
struct TiedNode {
  int node = 0;                  ///< the slave
  std::vector<int> masters;      ///< the other nodes of the row
  std::vector<double> weights;   ///< one per master, summing to 1 (mortar rows: some negative)
};

/// The solver's input mesh.
struct Mesh {
  Eigen::MatrixX3d nodes;                 ///< #N×3 positions, LPS mm
  std::vector<Element> elements;          ///< connectivity in the numbering above
  /// Layer id -> its material, one for both kinematics (SolveOptions::kinematics: the
  /// small-strain solve uses Material::small_strain(), the finite-strain one the material
  /// itself). mesh.json, result.json and the CalculiX deck name each one and its parameters.
  std::map<int, std::shared_ptr<const Material>> materials;
  std::vector<int> fixed_nodes;           ///< all three components fixed at 0
  std::vector<FixedDof> fixed_dofs;       ///< single prescribed components
  std::vector<NodalLoad> loads;           ///< nodal forces
  std::vector<SuturePair> sutures;        ///< suture constraints
  std::vector<SlidingNode> sliding;       ///< nodes held only along a normal (undermined base)
  /// What SlidingNode::on_surface entries slide on (shared, immutable; may be null). Not
  /// written to mesh.json, which keeps only its name and each entry's start normal: a mesh read
  /// back without it slides those entries along their start normals (a warning says so).
  std::shared_ptr<const ImplicitSurface> sliding_surface;
  std::string sliding_surface_name;       ///< e.g. "bone"; recorded in mesh.json
  std::vector<TiedNode> ties;             ///< slave nodes tied to master elements
  /// Named node sets (mesh.json "node_sets", CalculiX *NSET): e.g. the whole-face tissue
  /// model's skin nodes, which the renderer moves the skin around the patch with. Names are
  /// letters, digits and underscores.
  std::map<std::string, std::vector<int>> node_sets;
  /// The elements of each flap the plan raises (transposed, rotated or advanced tissue): the
  /// finite-strain solve swings each flap into place along an arc (docs/fem.md, "Closing path").
  std::vector<std::vector<int>> flaps;
  /// How the Wedge15 elements are integrated (mesh.json "wedge_rule": "full" or "calculix").
  WedgeRule wedge_rule = WedgeRule::Full;
  std::string model;                      ///< reference to the patient model, if known
  std::string plan;                       ///< reference to the surgical plan, if known
  std::vector<std::string> warnings;      ///< what the mesher had to give up (e.g. a limited extent)

  Eigen::Index n_nodes() const { return nodes.rows(); }
  std::size_t n_elements() const { return elements.size(); }
};

/// Checks ids in range, finite coordinates, known layers, no self-sutures, no duplicate
/// elements nodes, component in 0..2, ties (ids in range, one entry per slave, not tied to
/// itself, finite weights summing to 1 within 1e-6). Throws InvalidInput naming `where` and
/// the item.
void validate(const Mesh& mesh, const std::string& where = "mesh");

/// Builds a Wedge15 from a 20-entry collapsed hexahedron (paper section 6: hex nodes 2, 10, 3
/// share one node, 18 and 19 one, 6, 14, 7 one). Throws InvalidInput if the shared ids differ.
Element wedge_from_collapsed_hex(const std::array<int, 20>& hex, int layer);

}  // namespace caps::fem
