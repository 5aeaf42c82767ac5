#pragma once
/// @brief Abaqus / CalculiX input deck (.inp) of a caps mesh, so that an independent code
/// (Debian calculix-ccx) solves the same problem.
///
/// Node ids are caps ids + 1. Elements: C3D20 (caps Hex20 order, identity) and C3D15 (caps
/// Wedge15 order, identity: CalculiX's wedge has nodes 1-3 at zeta = -1 with the right-hand
/// normal of 1-2-3 towards 4-6, like caps; checked by running ccx, docs/mesher.md) and C3D10
/// (caps Tet10 order, identity: corners, then edges 1-2, 2-3, 3-1, 1-4, 2-4, 3-4), one ELSET and
/// material per layer. Fixed nodes: NSET FIXED with *BOUNDARY 1-3. Sutures: the pairs are grouped
/// (union-find) and each group member n other than its root m gets, per component i,
///   *EQUATION  u_n,i - u_m,i - u_h,i = 0
/// with a helper node h (unattached, ids after the mesh's) whose displacement is prescribed to
/// x_m - x_n: the same "all members meet" condition that solve() imposes, without redundant
/// equations. A component of a group with a prescribed member (fixed node or fixed dof) gets no
/// equations; its other members are prescribed to meet it, as solve() does. One *STATIC linear
/// step (or, with InpOptions::finite_strain, one *STEP, NLGEOM with *HYPERELASTIC, NEO HOOKE
/// materials, C10 = mu/2 and D1 = 2/K of each layer's finite-strain material, and the prescribed
/// values and suture gaps ramped over the step from an initial increment 1/increments, as
/// caps's load steps do); *NODE PRINT writes U to the .dat file and *NODE FILE U to the .frd file. Units: mm, N,
/// MPa (consistent).
///
/// CalculiX integrates C3D20 like caps (27 points) but C3D15 with 9 points where caps uses 21
/// (Mesh::wedge_rule Full, the default), so on meshes with Wedge15 the two codes solve slightly
/// different discrete problems (0.1-0.3 % of the largest displacement on closures); a mesh with
/// WedgeRule::CalculiX is integrated as ccx does, and the deck says which in a comment.
/// C3D10 is integrated alike (4 points; tests/test_fem_tet10.cpp runs ccx on Tet10 meshes).

#include <filesystem>
#include <string>

#include "caps/fem/mesh.hpp"

namespace caps::fem {

/// What kind of analysis the deck asks for.
struct InpOptions {
  /// false: *ELASTIC (each layer's Material::small_strain() constants) and a linear *STATIC
  /// step. true: *HYPERELASTIC, NEO HOOKE (every layer's material must be neo-hookean) and
  /// *STEP, NLGEOM. A comment line before each *MATERIAL names the layer's material and its
  /// parameters (material_json()); a material without a CalculiX form is InvalidInput.
  bool finite_strain = false;
  int increments = 10;  ///< initial increment 1/increments of the NLGEOM step
  /// true: CalculiX may grow its increments up to the whole step (its automatic incrementation,
  /// as caps's load steps grow: NewtonOptions::grow_iterations); false: the largest increment
  /// is the initial one (fixed increments).
  bool grow_increments = true;
};

/// Writes `mesh` as an .inp deck to `path` (atomically). Throws IoError if it cannot be written,
/// InvalidInput if the mesh is not valid or a finite-strain material has no CalculiX form.
void write_inp(const Mesh& mesh, const std::filesystem::path& path, const InpOptions& options = {});

/// The deck as a string (what write_inp writes).
std::string inp_text(const Mesh& mesh, const InpOptions& options = {});

}  // namespace caps::fem
