#pragma once
// Internal: the path along which the finite-strain solve closes the sutures (load factor 0 -> 1).

#include <Eigen/Core>
#include <vector>

#include "caps/fem/mesh.hpp"
#include "constraints.hpp"

namespace caps::fem::detail {

/// The prescribed values and suture offsets at a load factor lambda in [0, 1].
///
/// Straight closure moves every suture's two nodes towards each other along the line between
/// them: u = lambda g. A transposed or rotated flap does not travel that way: a surgeon swings
/// it about its pivot, so its tip follows an arc. Along the straight chord the tip passes closer
/// to the pivot than the flap is long and the flap is pushed into its own base half-way
/// (by 1 - cos(phi/2) of its length for a rotation phi: 13 % at 60 deg), which folds the
/// elements at the base corner. For every flap of Mesh::flaps the rigid motion that lays its
/// sutured nodes onto their partners outside the flap is fitted (Kabsch), and the flap's
/// offsets follow that screw motion's rotation a fraction lambda of the way, plus the linear
/// remainder: a node's path is X + w ([R(lambda phi) - I](X - c) - lambda [R(phi) - I](X - c))
/// + lambda (target - X), which starts at X, ends at the target, and is a rigid rotation about
/// the axis through c when the flap fits rigidly; w (0 at the flap's base, 1 at its tip) is the
/// node's distance from the base relative to the tip's, since the base stays attached. The remainder term cancels between the
/// members of a suture group, so only the arcs enter the offsets. At lambda = 1 the values are
/// exactly g; without flaps (or flaps turned by less than kMinRotationDeg) the path is u = lambda g.
class ClosingPath {
 public:
  /// Flaps whose fitted rotation is below this keep the straight path (deg).
  static constexpr double kMinRotationDeg = 3.0;

  ClosingPath(const Mesh& mesh, const DofMap& map);

  /// The full prescribed-value vector u_p(lambda) (3N, mm): u = T q + u_p.
  Eigen::VectorXd at(double lambda) const;

  /// Whether u_p is lambda g (no flap turns).
  bool straight() const { return moved_.empty(); }

  /// Each flap's fitted rotation (deg), in Mesh::flaps order; 0 for a flap that cannot be fitted.
  const std::vector<double>& rotations_deg() const { return rotations_deg_; }

 private:
  struct Motion {
    Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();  // unit
    Eigen::Vector3d centre = Eigen::Vector3d::Zero();  // a point on the axis (mm)
    double angle = 0;                                  // rad
  };
  // D(lambda) of node `n` on a flap with motion m.
  Eigen::Vector3d arc(const Motion& m, int n, double lambda) const;

  const Mesh& mesh_;   // not owned
  const DofMap& map_;  // not owned
  std::vector<Motion> motions_;      // per flap
  std::vector<int> node_flap_;       // node -> flap it lies wholly inside, -1 otherwise
  std::vector<double> swing_;        // node -> its distance from its flap's base / the tip's, 0..1
  // The sutured dofs whose path has an arc, each with the node its offset is relative to: the
  // group's master for a free group, -1 (the ground) for a group whose position is prescribed.
  std::vector<std::pair<int, int>> moved_;
  std::vector<double> rotations_deg_;
};

}  // namespace caps::fem::detail
