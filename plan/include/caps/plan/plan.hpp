#pragma once
/// @brief A surgical plan (CAPS 1992, section 5): points on the skin, the cutting path(s), the
/// border loop of the hole they make, excision offsets and the suture pairs of border edges.
///
/// Frames and units. Points on the skin are (theta deg, z mm) of the patient model, with their
/// LPS position kept for reading. Procedures are laid out in the local tangent plane of the skin
/// at the plan's centre (PlanFrame), in mm: x along the plan's orientation, y to the left of x as
/// seen from outside the patient. The orientation is measured in degrees from the model's +z
/// (superior) direction towards +theta (the patient's left), so 0 points superior and 90 points
/// to the patient's left. Geometry is done in these unwrapped local coordinates, so a plan may
/// straddle the seam at theta = +-180.
///
/// Border loop (Figure 2 of the paper). A single cutting path 0..n-1 becomes the loop
/// 0..n-1, n-2..1: the copies of n-2..1 are the points on the other side of the cut, coincident
/// with their originals. Paths that share points (a branching cut, e.g. multiple Z-plasty) form a
/// tree; its loop is the walk around the tree, which for a single path is exactly the rule above.
/// The loop keeps the tissue on its left as seen from outside (clockwise in a picture with theta
/// across and superior up): loop nodes 0..n-1 lie on the left side of the cutting direction.
///
/// Sutures. A suture pair ((a,b),(c,d)) names two border edges (pairs of loop-consecutive
/// nodes) to be sewn together. Which nodes meet does not depend on the order in which the pair
/// is written: sewing two border edges of an oriented surface always joins them with opposite
/// directions along the loop, so for loop edges i->i+1 and j->j+1, i meets j+1 and i+1 meets j.
/// This reproduces both of the paper's examples (its Z-plasty pair ((0,1),(3,4)) means 0 meets 4
/// and 1 meets 3). A node that both edges share is a corner being closed and is not sutured.
/// oriented_suture() rewrites a pair so that a meets c and b meets d.
///
/// Runs (an extension of the paper). A side of a suture pair may also be a run of several
/// consecutive border nodes [a, ..., b], sewn to a run with a different number of edges; the two
/// meet by arc length (the mesher puts matching nodes on both). This is what an advancement
/// needs: in the V-Y flap each side of the flap is sewn to the shorter stretch of the outer arm
/// left beyond the stem of the Y (docs/plan.md). The same rule orients runs: the first traversed
/// along the loop meets the second traversed against it.

#include <Eigen/Core>
#include <array>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "caps/surface/patient_model.hpp"

namespace caps::plan {

inline constexpr int kPlanFormatVersion = 1;

/// A point on the skin.
struct SkinPoint {
  double theta_deg = 0;            ///< [-180, 180)
  double z_mm = 0;
  Eigen::Vector3d lps{0, 0, 0};    ///< for reading; recomputed from (theta, z) on load
};

/// A border edge: two loop indices, consecutive along the loop (either order).
struct BorderEdge {
  int a = 0, b = 0;
  bool operator==(const BorderEdge&) const = default;
};

/// A run of border nodes: loop indices [a, ..., b], each next to the one before on the loop,
/// all in one direction; two nodes are one border edge.
using BorderRun = std::vector<int>;

/// A suture pair ((a,b),(c,d)) as written by the user or the procedure (the paper's form), or
/// with runs ((a,...,b),(c,...,d)).
struct SuturePair {
  BorderRun first, second;
  bool operator==(const SuturePair&) const = default;
};

/// "((0,1),(0,5))" — a pair as written, for messages and figures.
std::string suture_text(const SuturePair& s);

/// An excision offset: a loop node moved away from its twin by `offset_mm` in the local
/// tangent frame (x along the orientation, y to its left), mm.
struct ExcisionOffset {
  int loop_index = 0;
  Eigen::Vector2d offset_mm{0, 0};
};

/// The local tangent frame at the plan's centre: a linear map between local mm (x, y) and
/// (dtheta deg, dz mm), exact to first order at the centre (from the skin's metric there).
struct PlanFrame {
  double theta_deg = 0, z_mm = 0;     ///< the centre
  double orientation_deg = 0;         ///< x axis: from +z (superior) towards +theta
  Eigen::Matrix2d local_to_theta_z = Eigen::Matrix2d::Identity();  ///< (x,y) mm -> (dtheta deg, dz mm)

  /// (theta deg, z mm) of a local point (x, y) mm; theta wrapped into [-180, 180).
  Eigen::Vector2d to_theta_z(const Eigen::Vector2d& xy_mm) const;
  /// Local (x, y) mm of (theta deg, z mm); theta unwrapped about the centre (seam-safe).
  Eigen::Vector2d to_local(double theta_deg, double z_mm) const;
};

/// The local tangent frame of `model`'s skin at (theta, z) with the given orientation.
/// Throws InvalidInput if the skin there is degenerate (on the axis) or the values are not finite.
PlanFrame make_frame(const PatientModel& model, double theta_deg, double z_mm,
                     double orientation_deg);

/// Where a plan was placed relative to an anatomical landmark (surface/landmarks.hpp): its centre
/// is `left_mm` towards the patient's left and `up_mm` up along the skin from the landmark
/// (plan/placement.hpp). Plan files record it as "at" (docs/plan-format.md).
struct LandmarkPlacement {
  std::string landmark;  ///< a name of landmark_names(), e.g. "glabella"
  double left_mm = 0, up_mm = 0;
};

/// A surgical plan. Stored as JSON (docs/plan-format.md).
struct Plan {
  /// The patient model directory: as given when the plan was made; read_plan() resolves it
  /// relative to the plan file where the file records it so (a copied plan and model folder
  /// stay together).
  std::string model;
  /// The model's content identity (model.json "content_hash") when the plan was made; empty
  /// for plans made before it existed. check_plan() refuses a model with another one.
  std::string model_hash;
  std::string procedure = "custom";         ///< a template name, or "custom"
  std::map<std::string, double> parameters; ///< the procedure's parameters (mm, deg, counts)
  PlanFrame frame;
  /// Set when the plan was placed relative to a landmark (its frame's centre is where that
  /// placement resolved on the model); empty for a plan placed at (theta, z) or an LPS point.
  std::optional<LandmarkPlacement> placement;
  std::vector<SkinPoint> points;            ///< the surgeon's points
  std::vector<std::vector<int>> paths;      ///< cutting paths, as indices into `points`
  std::vector<ExcisionOffset> excisions;
  std::vector<SuturePair> sutures;
  /// The flaps a surgeon raises (transposed, rotated or advanced tissue): each a polygon of
  /// indices into `points`, the flap's outline through its cut sides and its uncut base. The
  /// mesher frees the deep tissue under their whole area (docs/fem.md).
  std::vector<std::vector<int>> flaps;
  std::string notes;
  /// The file the plan was read from (read_plan(), parse_plan_json()'s `source`); empty for a
  /// plan made in memory. Not written to plan files. The checks' errors start with it, and name
  /// the offending entry by its JSON pointer in the file (`/paths/0/3`).
  std::string source;
};

/// The paper's Figure 2 rule for one path of n >= 2 points: 0..n-1 then n-2..1.
std::vector<int> incision_to_loop(int n_points);

/// The walk around the cut formed by `paths` (indices into `xy_mm`, local mm), starting at the
/// first point of the first path, with the tissue on the left: the loop as point indices. For
/// one path of n points this is incision_to_loop(n). Throws InvalidInput when the paths are not a
/// tree (a cycle, disconnected, an index out of range, a repeated point or segment) or the first
/// point is not an end of the cut.
std::vector<int> walk_around_cut(const std::vector<Eigen::Vector2d>& xy_mm,
                                 const std::vector<std::vector<int>>& paths);

/// The border loop of a plan: for each loop node, the point it was copied from, and its
/// position with the excision offsets applied.
struct BorderLoop {
  std::vector<int> point;                         ///< loop index -> index into Plan::points
  std::vector<Eigen::Vector2d> local_mm;          ///< loop positions, local frame, mm
  std::vector<Eigen::Vector2d> theta_z;           ///< the same as (theta deg, z mm)
  int size() const { return static_cast<int>(point.size()); }
};

/// The border loop of the plan's cutting paths (the walk around their tree, starting at the
/// first point of the first path, which must be an end of the cut). Throws InvalidInput when
/// the paths are not a tree (a cycle, disconnected, an index out of range, a repeated point)
/// or an excision names a node that is not on the loop.
BorderLoop border_loop(const Plan& plan);

/// Whether (a, b) is a border edge of a loop of `loop_size` nodes.
bool is_border_edge(const BorderEdge& e, int loop_size);

/// A suture pair rewritten as (a, b, c, d): the run from a forward along the loop to b meets the
/// run from c backward to d, a meeting c and b meeting d; for edges b = a + 1 and d = c - 1 (see
/// @brief). Throws InvalidInput if a side is not a run of border nodes.
std::array<int, 4> oriented_suture(const SuturePair& s, int loop_size);

/// The border edges of the run from `a` forward along the loop to `b`, each by its first node
/// (edge i joins i and i+1 mod loop_size); at least one.
std::vector<int> forward_edges(int a, int b, int loop_size);

/// Both runs of an oriented suture (a, b, c, d) as edge lists: the first's edges a .. b-1, the
/// second's d .. c-1.
std::array<std::vector<int>, 2> suture_edges(const std::array<int, 4>& q, int loop_size);

/// What the mesher needs: the border loop with excision offsets applied, as (theta deg, z mm),
/// and the suture pairs as quadruples (a, b, c, d) into that loop (oriented_suture()): the run
/// from a forward to b meets the run from c backward to d, a meeting c and b meeting d; a == c
/// or b == d is a corner being closed (no suture for that node).
struct WoundBorder {
  std::vector<Eigen::Vector2d> loop_theta_z;
  std::vector<std::array<int, 4>> sutures;
  /// The plan's flaps as polygons of (theta deg, z mm), theta unwrapped about the loop's first
  /// point: the areas whose deep tissue is freed (dissected off the bone) before closing.
  std::vector<std::vector<Eigen::Vector2d>> flaps_theta_z;
};

/// The wound border of a plan (structure checked, see border_loop() and oriented_suture()).
/// Throws InvalidInput when a flap names a point the plan does not have or has fewer than 3.
WoundBorder wound_border(const Plan& plan);

}  // namespace caps::plan
