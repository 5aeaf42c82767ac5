#pragma once
// Internal: assembly of the reduced stiffness (upper triangle) and load vector, in two steps so
// that the solver's symbolic analysis, which needs only the structure, can run while the values
// are computed.

#include <Eigen/Sparse>
#include <map>
#include <vector>

#include "caps/fem/mesh.hpp"
#include "constraints.hpp"

namespace caps::fem::detail {

struct Assembly {
  Eigen::SparseMatrix<double> K;  ///< n_eq × n_eq, column-major, upper triangle (row <= col)
  Eigen::VectorXd f;              ///< T^T (f_ext - K g)

  // Block structure (DofMap blocks): for block column B, the blocks B' <= B it couples to,
  // sorted (B itself last), and how many rows of each column of B come before block B'.
  std::vector<int> nbr_start, nbr, nbr_row;
  // Elements grouped by colour: no two elements of one colour share a block, so a colour is
  // assembled in parallel without atomics and the sums do not depend on the thread count.
  std::vector<int> colour_start, colour_elements;
};

/// The structure of K (values zero), f = 0 and the scatter tables. TBB-parallel.
Assembly assemble_structure(const Mesh& mesh, const DofMap& map);

/// Element stiffnesses into K's values and the loads and lifting (-K g) into f, colour by
/// colour in parallel over elements.
void assemble_values(const Mesh& mesh, const DofMap& map, Assembly& sys);

/// The sliding supports' penalty springs (Mesh::sliding) at the full displacement u (3N, mm),
/// with the predictor's lifting term for `lift` (3N mm, or empty): each entry's -T^T k r n
/// into f, minus T^T k n (n . lift), and T^T k n n^T T into K's values (with_tangent); with
/// `unit_lift`, also -T^T k n (n . g) for the offsets g = map.g. Along a fixed normal (and for
/// every entry in the small-strain solve, `finite_strain` false, with n = start_normal()) r =
/// n . u; an entry on Mesh::sliding_surface in the finite-strain solve has r = phi(X + u) -
/// phi(X) and n = grad phi(X + u). Returns their energy 1/2 k r^2 (mJ) at u.
/// The linear solve passes u = g (the lifting term), the finite-strain one its state.
double add_sliding_supports(const Mesh& mesh, const DofMap& map, const Eigen::VectorXd& u,
                            const Eigen::VectorXd& lift, bool finite_strain, bool with_tangent,
                            Assembly& sys, Eigen::VectorXd* unit_lift = nullptr);

/// The ties' penalties (Mesh::ties, k = map.tie_stiffness) at the full displacement u (3N, mm):
/// energy k/2 |gap|^2 with gap = u_s - sum w_i u_m_i; -T^T k c gap into f (c = (1, -w)), with
/// the lifting term of `lift` (3N mm, or empty) as add_sliding_supports(), T^T k (c c^T ⊗ I) T
/// into K's values (with_tangent; assemble_structure() has their pattern), and with `unit_lift`
/// -T^T k c gap(g). Returns their energy (mJ) at u.
double add_ties(const Mesh& mesh, const DofMap& map, const Eigen::VectorXd& u,
                const Eigen::VectorXd& lift, bool with_tangent, Assembly& sys,
                Eigen::VectorXd* unit_lift = nullptr);

/// f += scale × T^T f_ext (the nodal loads, N).
void add_loads(const Mesh& mesh, const DofMap& map, double scale, Eigen::VectorXd& f);

/// Layer id -> the material of the finite-strain solve (not owned; must outlive the assembly).
using FiniteMaterials = std::map<int, const Material*>;

/// The small-strain constants of the layer's material (Material::small_strain()); InvalidInput
/// naming the layer and the material if it has none (solve() checks every layer first).
const IsotropicElastic& small_strain_material(const Mesh& mesh, int layer);

/// The in-plane prestretch of one element layer (detail::prestretch_tensor); stretch 1: none.
struct LayerPrestretch {
  int layer = 0;
  double stretch = 1.0;
};

/// What assemble_finite() found: the strain energy, or the first inverted element.
struct FiniteAssembly {
  double energy_mj = 0;
  int inverted_element = -1;      ///< lowest element id with det F <= 0 at a Gauss point
  int inverted_gauss_point = -1;
  double det_F = 1;
};

/// Finite strain, at the full displacement u (3N, mm): the consistent tangent T^T K_T T into
/// K's values (overwritten; skipped when `with_tangent` is false) and the out-of-balance force
///   f = T^T (load_factor f_ext - f_int(u)) - T^T K_T lift     (lift: 3N mm, or empty)
/// (the lifting term gives the predictor of a load step whose prescribed values grow by lift).
/// With `unit_lift` (and the tangent), also -T^T K_T g for the full offsets g = map.g, so that
/// the next load step's predictor needs no assembly of its own. The elements of
/// `prestretch.layer` are prestretched by `prestretch.stretch`. Same colours and scatter as
/// assemble_values(). An inverted element is reported, not thrown (K and f are then incomplete).
FiniteAssembly assemble_finite(const Mesh& mesh, const DofMap& map,
                               const FiniteMaterials& materials, const Eigen::VectorXd& u,
                               double load_factor, const Eigen::VectorXd& lift, bool with_tangent,
                               Assembly& sys, Eigen::VectorXd* unit_lift = nullptr,
                               const LayerPrestretch& prestretch = {});

}  // namespace caps::fem::detail
