#pragma once
/// @brief The closure in the patient's whole face: the 1992 wound patch (Hex20/Wedge15, meshed
/// on the cylindrical image and extruded to the measured bone) joined by a tie to the patient's
/// volumetric soft-tissue model (quadratic tetrahedra from the CT, mesher/tissue_model.hpp)
/// instead of clamped at its rim (docs/fem.md, "The whole face").
///
/// The tissue model is kept within FaceDomainOptions::radius_mm of the wound; its tetrahedra
/// under the patch's footprint (skin to bone) are left out, and the patch's rim nodes are tied
/// to the tetrahedra they lie in or next to (fem::TiedNode: the master element's shape functions
/// at the slave's place, as CalculiX's *TIE). The tissue is attached where it lies on the bone,
/// held where the region or the CT's field of view ends, and free on the skin (the eyelid
/// margins, the lips and the nostrils are free surfaces as the CT shows them). Undermined tissue
/// of the patch slides along its start normal, as in the patch (sliding on the bone's level set,
/// fem::ImplicitSurface, is not yet used here: docs/fem.md, "The whole face").

#include <Eigen/Core>
#include <array>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "caps/fem/mesh.hpp"
#include "caps/fem/solve.hpp"
#include "caps/fem/tie.hpp"
#include "caps/mesher/continuum_mesher.hpp"
#include "caps/mesher/tissue_model.hpp"
#include "caps/surface/feature_lines.hpp"

namespace caps {
class PatientModel;
}

namespace caps::closure {

/// Where the closure is solved: Face, the patch tied into the whole-face model (the default);
/// Patch, the 1992 patch clamped at its rim.
enum class Domain { Face, Patch };
const char* domain_name(Domain domain);
/// "face" or "patch"; InvalidInput naming the value otherwise.
Domain parse_domain(const std::string& name);

struct FaceDomainOptions {
  /// The tissue model is kept within this distance (mm) of the wound's centre and held beyond;
  /// 0: automatic, kRadiusBeyondPatchMm beyond the patch's rim, at least kMinRadiusMm.
  double radius_mm = 0;
  /// A rim node farther than this (mm) from every tetrahedron is left untied (a warning counts
  /// them); 0: 3 x the tissue model's facet size on the face or its label voxel, the larger.
  double tie_tolerance_mm = 0;
  /// How the patch's rim is tied to the tissue: a mortar row (passes the patch test; the
  /// default) or node to surface (each rim node follows the tetrahedron it lies in: CalculiX's
  /// *TIE, and an .inp deck CalculiX reads in seconds where the mortar rows' chains of
  /// *EQUATIONs take it many minutes to resolve).
  fem::TieMethod tie = fem::TieMethod::Mortar;
  /// Not owned, may be null: the tie's search stops (Cancelled) when it cancels.
  Reporter* reporter = nullptr;
};

/// The automatic region: at least this radius (mm)...
inline constexpr double kMinRadiusMm = 40.0;
/// ...and this far (mm) beyond the patch's rim (its farthest node from the wound's centre).
/// On Cranium, neo-Hookean, the closing force moves by at most 0.1 % when the region grows from
/// there to twice the radius, and by at most 0.05 % against 10 mm (until 6 December 2026), with
/// 15-30 % fewer equations (docs/fem.md, "The whole face").
inline constexpr double kRadiusBeyondPatchMm = 5.0;

/// The joined mesh and what the join did.
struct FaceDomain {
  /// The patch's nodes and elements first, in the patch's numbering (so the patch's node ids,
  /// sutures and flaps stay valid), then the tissue's nodes and Tet10 elements.
  fem::Mesh mesh;
  int n_patch_nodes = 0, n_patch_elements = 0;
  /// Joined-mesh ids of the tissue's nodes on the skin (corner and mid-edge nodes; also the
  /// mesh's node set kFaceSkinNodes).
  std::vector<int> skin_nodes;
  Eigen::Vector3d centre_lps = Eigen::Vector3d::Zero();  ///< the wound's centre on the skin
  double radius_mm = 0;               ///< the region kept
  int tets = 0;                       ///< tetrahedra in the joined mesh
  int tets_under_patch = 0;           ///< left out under the patch's footprint
  int tets_detached = 0;              ///< pieces of the region with no support, left out
  int tied_nodes = 0, untied_nodes = 0;
  double max_tie_distance_mm = 0;     ///< the farthest a tied rim node lies from its master
  int attached_nodes = 0;             ///< tissue nodes on the bone, fixed
  /// Tissue nodes on the bone within the undermining distance of the wound's border
  /// (ContinuumMeshOptions::undermine_mm): freed from it, sliding on it (or free).
  int undermined_nodes = 0;
  int held_nodes = 0;                 ///< tissue nodes where the region or the CT ends, fixed
  /// The layer ids of the tissue's elements (>= kFirstTissueLayer) and their mixture.
  std::vector<std::string> notes;
};

/// Element layer ids of the tissue's materials start here (the patch's are 0..2).
inline constexpr int kFirstTissueLayer = 10;

/// Joins the patch `wound` (meshed with RimCondition::Tied) to `tissue`. Materials: each
/// tetrahedron's mixture of the measured layers (TissueModel::layer_fraction, in fifths) gets
/// the volume-weighted mean of `layers`'s dermis, fat and deep E and nu (for in-plane loading of
/// layered tissue, the exact stiffness of the layers side by side), neo-Hookean under finite
/// strain, linear under small strain. Throws InvalidInput when the tissue model does not reach
/// the wound (another patient's, or a wound off its extent).
FaceDomain join_face_domain(const mesher::WoundMesh& wound, const PatientModel& model,
                            const mesher::TissueModel& tissue,
                            const mesher::ContinuumMeshOptions& layers, fem::Kinematics kinematics,
                            const FaceDomainOptions& options = {});

/// The patch's part of a solve of the joined mesh: the rows of its first `n_nodes` nodes and
/// first `n_elements` elements; the totals (suture forces, energy, counts, timings) as they are.
fem::SolveResult patch_part(const fem::SolveResult& joined, int n_nodes, int n_elements);

/// The closure's displacement on the skin, anywhere on the face: displacement_from_samples
/// (inverse-distance-squared weights within `reach_mm`) over the mesh's node set kFaceSkinNodes
/// and the nodes `extra` with their rows of `u`; nothing farther from every one (outside the
/// modelled region, where the face does not move). The renderer moves the skin outside the
/// patch with it; feature lines are measured on it.
DisplacementAt skin_displacement(const fem::Mesh& mesh, const Eigen::MatrixX3d& u,
                                          const std::vector<int>& extra = {}, double reach_mm = 6.0);

/// A nodal scalar of the closure (the maximum principal stress, MPa) on the skin, anywhere on the
/// face: as skin_displacement(), from the node set kFaceSkinNodes, so that a map of it goes on
/// across the patch's rim into the tissue around it instead of stopping there; nothing farther
/// than `reach_mm` from every one of those nodes (outside the modelled region), nor on a mesh
/// without them (a patch-only closure). Throws InvalidInput if `nodal` is not one value a node.
std::function<std::optional<double>(const Eigen::Vector3d&)> skin_scalar(
    const fem::Mesh& mesh, const Eigen::VectorXd& nodal, double reach_mm = 6.0);

/// The joined mesh's node set of the tissue's skin nodes (fem::Mesh::node_sets, mesh.json).
inline constexpr const char* kFaceSkinNodes = "face_skin";


}  // namespace caps::closure
