#pragma once
// Measures a placed plan on the skin in 3-D (LPS mm), independently of the code that lays it:
// only PatientModel::skin_point() / skin_normal() / axis() and the plan's border loop (the
// positions the mesher is handed, wound_border()) are used, never plan/skin_walk.hpp.
//
// Lengths are the 3-D polyline length of a segment as plans draw it (straight in (theta, z)
// between its ends, sampled every <= 0.05 mm). Angles are between the directions in which two
// segments leave a node, projected into the skin's tangent plane there (normal: skin_normal()).
// Orientation is the direction of a segment where it passes the plan's centre, in the tangent
// plane there, in degrees from "up" (the model's superior axis projected into the plane) towards
// "right" (up x normal: +theta, the patient's left): 90 = horizontal, perpendicular to the
// superior axis.
//
// What a template asks for is read off its flat layout (layout_procedure(): local mm, before
// placing): every border edge's length, every angle between consecutive border edges at a loop
// node, the distances across that a template names (the ellipse's width, the rotation flap's
// radius), and the direction of its axis. measure_plan() compares each with the placed plan.

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <string>
#include <vector>

#include "caps/core/error.hpp"
#include "caps/core/units.hpp"
#include "caps/plan/plan.hpp"
#include "caps/plan/procedures.hpp"

namespace caps_test {

using caps::PatientModel;
using Eigen::Vector2d;
using Eigen::Vector3d;

/// (theta, z) of b unwrapped next to a.
inline Vector2d unwrap_next_to(const Vector2d& a, Vector2d b) {
  b[0] = a[0] + std::remainder(b[0] - a[0], 360.0);
  return b;
}

/// The skin length (mm) of the segment a -> b drawn straight in (theta deg, z mm).
inline double skin_length(const PatientModel& m, const Vector2d& a, Vector2d b) {
  b = unwrap_next_to(a, b);
  // A first estimate of the length sets the sampling (<= 0.05 mm per step).
  const double rough = (m.skin_point(b[0], b[1]) - m.skin_point(a[0], a[1])).norm();
  const int n = std::max(400, static_cast<int>(std::ceil(rough * 1.5 / 0.05)));
  double len = 0;
  Vector3d last = m.skin_point(a[0], a[1]);
  for (int s = 1; s <= n; ++s) {
    const Vector2d t = a + (b - a) * (static_cast<double>(s) / n);
    const Vector3d x = m.skin_point(t[0], t[1]);
    len += (x - last).norm();
    last = x;
  }
  return len;
}

/// The unit tangent (LPS) in which the segment a -> b leaves a, on the skin, projected into the
/// tangent plane at a.
inline Vector3d skin_direction(const PatientModel& m, const Vector2d& a, Vector2d b) {
  b = unwrap_next_to(a, b);
  const double rough = (m.skin_point(b[0], b[1]) - m.skin_point(a[0], a[1])).norm();
  const double h = std::min(1e-3, 0.01 / std::max(rough, 1e-9));  // about 0.01 mm of skin
  const Vector2d t = a + (b - a) * h;
  const Vector3d n = m.skin_normal(a[0], a[1]);
  Vector3d d = m.skin_point(t[0], t[1]) - m.skin_point(a[0], a[1]);
  d -= d.dot(n) * n;
  return d.normalized();
}

/// The unsigned angle (deg, 0..180) at v between the segments v -> a and v -> b on the skin.
inline double skin_angle(const PatientModel& m, const Vector2d& v, const Vector2d& a,
                         const Vector2d& b) {
  const Vector3d u = skin_direction(m, v, a), w = skin_direction(m, v, b);
  return caps::rad_to_deg(std::atan2(u.cross(w).norm(), u.dot(w)));
}

/// The direction (deg from up towards right, see @brief) of the segment a -> b on the skin at
/// its point nearest (in theta, z) to `centre`.
inline double skin_heading(const PatientModel& m, const Vector2d& a, Vector2d b,
                           const Vector2d& centre) {
  b = unwrap_next_to(a, b);
  const Vector2d c = unwrap_next_to(a, centre);
  const double t = std::clamp((c - a).dot(b - a) / (b - a).squaredNorm(), 0.0, 1.0);
  const Vector2d p = a + t * (b - a);
  const double h = 1e-4;
  const Vector2d p0 = a + std::max(0.0, t - h) * (b - a), p1 = a + std::min(1.0, t + h) * (b - a);
  const Vector3d n = m.skin_normal(p[0], p[1]);
  Vector3d d = m.skin_point(p1[0], p1[1]) - m.skin_point(p0[0], p0[1]);
  Vector3d up = m.axis().direction;
  up = (up - up.dot(n) * n).normalized();
  const Vector3d right = up.cross(n);
  return caps::rad_to_deg(std::atan2(d.dot(right), d.dot(up)));
}

/// One requested quantity of a placed template: asked (from the flat layout) and measured.
struct Measured {
  std::string what;  ///< e.g. "edge 0-1", "angle at 3", "width 1-5", "orientation"
  char kind = 'L';   ///< 'L' length (mm), 'A' angle (deg), 'O' orientation (deg)
  double asked = 0, measured = 0;
  /// Whether a parameter of the template sets it (a limb, the width, an apex angle), or it
  /// follows from them in the flat layout (the ellipse's sides, the rotation flap's arc chords).
  bool requested = true;
  /// A requested quantity that closes a figure (the rhombus's corners B, A, D' and its sides
  /// from C; the turns of the W-plasty's moved sides): segments drawn straight in (theta, z)
  /// curve on skin inclined to the axis, so these hold only where the chart is not curved
  /// (docs/plan.md, "Accuracy").
  bool closure = false;
  /// Relative error for lengths, degrees (signed for 'O', absolute difference otherwise).
  double error() const {
    if (kind == 'L') return std::abs(measured - asked) / asked;
    if (kind == 'O') return std::remainder(measured - asked, 360.0);
    return std::abs(measured - asked);
  }
};

/// The flat layout's border loop: per loop node, its local position (mm) after the excisions.
inline std::vector<Vector2d> flat_loop(const caps::plan::LocalProcedure& proc) {
  const std::vector<int> loop = caps::plan::walk_around_cut(proc.points_mm, proc.paths);
  std::vector<Vector2d> xy;
  for (int p : loop) xy.push_back(proc.points_mm[p]);
  for (const auto& e : proc.excisions) xy[e.loop_index] += e.offset_mm;
  return xy;
}

inline double flat_angle_deg(const Vector2d& v, const Vector2d& a, const Vector2d& b) {
  const Vector2d u = a - v, w = b - v;
  return caps::rad_to_deg(std::atan2(std::abs(u.x() * w.y() - u.y() * w.x()), u.dot(w)));
}

/// Pairs of loop nodes a template names besides its border edges: distances across (length
/// asked = their distance in the flat layout) and the loop nodes of the segment that gives its
/// axis (orientation asked = the plan's orientation minus the segment's angle in the layout).
struct TemplateAxes {
  std::vector<std::pair<int, int>> across;
  std::vector<std::pair<int, int>> axis;
  std::vector<std::array<int, 3>>
      angles;  ///< extra angles (at, a, b) between non-consecutive nodes
  /// Border edges (by their first loop node) and loop-node angles no parameter sets.
  std::vector<int> derived_edges, derived_angles;
  bool across_derived = false;  ///< the distances across follow from the parameters
  std::vector<int> closure_edges, closure_angles;  ///< see Measured::closure
  bool extra_angles_closure = false;
  bool axis_closure = false;  ///< the axis is the chord of a chain of segments (the W-plasty)
};

/// What each library template names, as loop indices (docs/plan.md has the loops).
inline TemplateAxes template_axes(const caps::plan::LocalProcedure& proc) {
  TemplateAxes t;
  const int n = static_cast<int>(flat_loop(proc).size());
  const std::vector<int> loop = caps::plan::walk_around_cut(proc.points_mm, proc.paths);
  auto node_of_point = [&](int p) {
    for (int i = 0; i < n; ++i)
      if (loop[i] == p) return i;
    return -1;
  };
  if (proc.name == "ellipse") {
    t.across = {{1, 5}, {0, 3}};           // the width; apex to apex
    t.axis = {{0, 3}};                     // the apices (1 and 2 are moved to the sides)
    t.derived_edges = {0, 1, 2, 3, 4, 5};  // the sides follow from length and width
    t.derived_angles = {1, 2, 4, 5};       // only the apices (0, 3) are asked for
    t.closure_angles = {0};                // 3 is laid; 0 follows from the length and the width
  } else if (proc.name == "z-plasty") {
    t.axis = {{1, 2}};
  } else if (proc.name == "multiple-z-plasty") {
    const int segs = static_cast<int>(std::lround(proc.parameters.at("segments")));
    t.across = {{node_of_point(0), node_of_point(segs)}};               // the whole central line
    t.axis = {{node_of_point(segs / 2), node_of_point(segs / 2 + 1)}};  // through the centre
  } else if (proc.name == "w-plasty") {
    const int last = static_cast<int>(proc.points_mm.size()) - 1;
    t.across = {{0, last}};                                         // end to end along the scar
    for (int k = 1; k < last; ++k) t.across.push_back({k, n - k});  // the width at each tooth
    t.axis = {{0, last}};
    // The edges from the apices to the moved sides and the turns there follow from the width.
    t.derived_edges = {0, last - 1, last, n - 1};
    t.derived_angles = {0, 1, last - 1, last, last + 1, n - 1};
    for (int i = 0; i < n; ++i) t.closure_angles.push_back(i);  // every node is moved
    t.axis_closure = true;                                      // end to end over the whole zigzag
  } else if (proc.name == "rhomboid") {
    // Loop F0 E1 D2 C3 B4 A5 D'6 E'7: the long diagonal C-A and the short one D-B.
    t.across = {{3, 5}, {2, 4}};  // the diagonals follow from the side and the 60 deg
    t.across_derived = true;
    t.axis = {{2, 4}};
    t.angles = {{5, 4, 6}, {3, 2, 4}};  // the rhombus's 60 deg corners
    t.extra_angles_closure = true;
    t.closure_edges = {2, 3};            // D-C and C-B; B-A and A-D' are laid at their length
    t.closure_angles = {2, 3, 4, 5, 6};  // the corners; the flap's turn at E is walked
  } else if (proc.name == "rotation-flap") {
    // O (point 1) to S and every arc point: the radius; the angles at O.
    const int o = node_of_point(1);
    const int m = static_cast<int>(std::lround(proc.parameters.at("segments")));
    for (int k = 0; k <= m; ++k) t.across.push_back({o, node_of_point(2 + k)});
    t.axis = {{o, node_of_point(2)}};
    t.angles = {{o, node_of_point(0), node_of_point(2)},
                {o, node_of_point(2), node_of_point(2 + m)}};
    // Asked: the legs O-F, O-S, the back-cut and the angles at O; the arc's chords, the base's
    // halves and the turns along the arc follow from them.
    const std::vector<Vector2d> xy = flat_loop(proc);
    for (int i = 0; i < n; ++i) {
      const int a = loop[i], b = loop[(i + 1) % n];
      const bool at_o = xy[i].norm() < 1e-9 || xy[(i + 1) % n].norm() < 1e-9;  // O, not M
      const bool leg = at_o && (a == 1 || b == 1) && (a <= 2 && b <= 2);
      const bool back =
          proc.parameters.at("back_cut") > 0 && (a == static_cast<int>(proc.points_mm.size()) - 1 ||
                                                 b == static_cast<int>(proc.points_mm.size()) - 1);
      if (!leg && !back) t.derived_edges.push_back(i);
      if (loop[i] != 1 || (xy[i] - proc.points_mm[1]).norm() > 1e-9)  // O, not its moved twin
        t.derived_angles.push_back(i);
    }
  } else if (proc.name == "bilobed") {
    // Every point is laid from the pivot P (point 0), and so is the defect's outline (the twins
    // of k1..k4): their distances from P and the angles at P are asked (t+ at half the lobe
    // angle from the first lobe's tip T1, T1 at the lobe angle from the second's tip T2, the
    // defect's apex at P), and so are the straight sides P..t+, t-..P and w+-Q. The lobes' and
    // the defect's chords and turns follow.
    const int p0 = node_of_point(0);
    std::vector<char> moved(static_cast<std::size_t>(n), 0);
    for (const auto& e : proc.excisions) moved[static_cast<std::size_t>(e.loop_index)] = 1;
    for (int q = 1; q <= 15; ++q) t.across.push_back({p0, node_of_point(q)});
    for (const auto& e : proc.excisions) t.across.push_back({p0, e.loop_index});
    t.angles = {{p0, node_of_point(5), node_of_point(7)},
                {p0, node_of_point(7), node_of_point(12)}};
    t.axis = {{p0, node_of_point(7)}};
    t.axis_closure = true;  // P-T1 passes the centre only at a distance
    for (int i = 0; i < n; ++i) {
      const int j = (i + 1) % n, a = loop[i], b = loop[j];
      const bool lip = a <= 5 && b <= 5 && !moved[i] && !moved[j];
      if (!lip && a != 0 && b != 0 && !(std::min(a, b) == 14 && std::max(a, b) == 15))
        t.derived_edges.push_back(i);
      if (a > 4 || moved[i]) t.derived_angles.push_back(i);  // P and the straight side's k1..k4
    }
  } else if (proc.name == "v-y-advancement") {
    t.axis = {{2, 0}, {2, 4}};  // the arms from the apex: their bisector is the axis
    t.across = {{0, 4}};        // the V's mouth follows from the arms and the apex angle
    t.across_derived = true;
  }
  return t;
}

/// Every quantity of `plan` (placed from `proc` on `m`) that the flat layout asks for: border
/// edges (lengths), angles between consecutive border edges at each loop node (where both
/// neighbours are distinct points), the template's distances across, extra angles and axis.
inline std::vector<Measured> measure_plan(const caps::plan::LocalProcedure& proc,
                                          const caps::plan::Plan& plan, const PatientModel& m) {
  const std::vector<Vector2d> xy = flat_loop(proc);
  const std::vector<Vector2d> tz = caps::plan::wound_border(plan).loop_theta_z;
  const int n = static_cast<int>(xy.size());
  const TemplateAxes t = template_axes(proc);
  auto is_in = [](const std::vector<int>& v, int i) {
    return std::find(v.begin(), v.end(), i) != v.end();
  };
  std::vector<Measured> out;
  for (int i = 0; i < n; ++i) {
    const int j = (i + 1) % n;
    const double asked = (xy[j] - xy[i]).norm();
    if (asked < 1e-9) continue;
    out.push_back({caps::cat("edge ", i, "-", j), 'L', asked, skin_length(m, tz[i], tz[j])});
    out.back().requested = !is_in(t.derived_edges, i);
    out.back().closure = is_in(t.closure_edges, i);
  }
  for (int i = 0; i < n; ++i) {
    const int a = (i + n - 1) % n, b = (i + 1) % n;
    if ((xy[a] - xy[b]).norm() < 1e-9 || (xy[a] - xy[i]).norm() < 1e-9 ||
        (xy[b] - xy[i]).norm() < 1e-9)
      continue;
    out.push_back({caps::cat("angle at ", i), 'A', flat_angle_deg(xy[i], xy[a], xy[b]),
                   skin_angle(m, tz[i], tz[a], tz[b])});
    out.back().requested = !is_in(t.derived_angles, i);
    out.back().closure = is_in(t.closure_angles, i);
  }
  for (const auto& [a, b] : t.across)
    out.push_back({caps::cat("across ", a, "-", b), 'L', (xy[b] - xy[a]).norm(),
                   skin_length(m, tz[a], tz[b])});
  out.back().requested = !t.across_derived;
  for (const auto& [v, a, b] : t.angles) {
    out.push_back({caps::cat("angle ", a, "-", v, "-", b), 'A', flat_angle_deg(xy[v], xy[a], xy[b]),
                   skin_angle(m, tz[v], tz[a], tz[b])});
    out.back().closure = t.extra_angles_closure;
  }
  const Vector2d centre(plan.frame.theta_deg, plan.frame.z_mm);
  for (const auto& [a, b] : t.axis) {
    const Vector2d d = xy[b] - xy[a];
    const double asked = plan.frame.orientation_deg - caps::rad_to_deg(std::atan2(d.y(), d.x()));
    out.push_back(
        {caps::cat("orientation ", a, "-", b), 'O', asked, skin_heading(m, tz[a], tz[b], centre)});
    out.back().closure = t.axis_closure;
  }
  return out;
}

/// The worst errors of a measurement: lengths (relative), angles and orientation (deg).
struct WorstError {
  double length_rel = 0, angle_deg = 0, orientation_deg = 0;
  std::string length_what, angle_what;
};

/// Which quantities worst() looks at.
enum class Kind { kByConstruction, kClosure, kDerived };

inline Kind kind_of(const Measured& x) {
  return !x.requested ? Kind::kDerived : x.closure ? Kind::kClosure : Kind::kByConstruction;
}

/// The worst errors among the quantities of one kind.
inline WorstError worst(const std::vector<Measured>& v, Kind kind) {
  WorstError w;
  double o_sum = 0;
  int o_n = 0;
  for (const auto& x : v) {
    if (kind_of(x) != kind) continue;
    if (x.kind == 'L' && x.error() > w.length_rel) w.length_rel = x.error(), w.length_what = x.what;
    if (x.kind == 'A' && x.error() > w.angle_deg) w.angle_deg = x.error(), w.angle_what = x.what;
    if (x.kind == 'O') o_sum += x.error(), ++o_n;
  }
  // Several axis segments (the V's two arms) give the axis as their mean direction.
  if (o_n) w.orientation_deg = std::abs(o_sum / o_n);
  return w;
}

}  // namespace caps_test
