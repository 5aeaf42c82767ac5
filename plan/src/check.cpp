#include "caps/plan/check.hpp"

#include <algorithm>
#include <cmath>
#include <map>
#include <set>

#include "caps/core/error.hpp"
#include "caps/core/plane_geometry.hpp"
#include "caps/plan/procedures.hpp"
#include "caps/volume/cylindrical_map.hpp"
#include "plan_source.hpp"

namespace caps::plan {

namespace {

// Plan points beyond these are damage, not surgery (a head is well under a metre tall); they are
// refused before any geometry, which would overflow or lose all precision with them.
constexpr double kMaxAbsThetaDeg = 720.0;
constexpr double kMaxAbsZMm = 1000.0;

double cross2(const Eigen::Vector2d& a, const Eigen::Vector2d& b) { return a.x() * b.y() - a.y() * b.x(); }

// Whether segments pq and rs meet (touching or overlapping counts), in mm.
bool segments_meet(const Eigen::Vector2d& p, const Eigen::Vector2d& q, const Eigen::Vector2d& r,
                   const Eigen::Vector2d& s, double tol) {
  auto dist_point_seg = [](const Eigen::Vector2d& x, const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
    const Eigen::Vector2d ab = b - a;
    const double t = std::clamp((x - a).dot(ab) / std::max(ab.squaredNorm(), 1e-30), 0.0, 1.0);
    return (a + t * ab - x).norm();
  };
  const double d1 = cross2(q - p, r - p), d2 = cross2(q - p, s - p);
  const double d3 = cross2(s - r, p - r), d4 = cross2(s - r, q - r);
  if (((d1 > 0 && d2 < 0) || (d1 < 0 && d2 > 0)) && ((d3 > 0 && d4 < 0) || (d3 < 0 && d4 > 0)))
    return true;
  return dist_point_seg(p, r, s) < tol || dist_point_seg(q, r, s) < tol ||
         dist_point_seg(r, p, q) < tol || dist_point_seg(s, p, q) < tol;
}

// Whether segments cross properly: each one's interior strictly separates the other's ends.
bool segments_cross(const Eigen::Vector2d& p, const Eigen::Vector2d& q, const Eigen::Vector2d& r,
                    const Eigen::Vector2d& s, double tol) {
  const double lpq = (q - p).norm(), lrs = (s - r).norm();
  if (lpq < tol || lrs < tol) return false;
  const double d1 = cross2(q - p, r - p) / lpq, d2 = cross2(q - p, s - p) / lpq;
  const double d3 = cross2(s - r, p - r) / lrs, d4 = cross2(s - r, q - r) / lrs;
  return ((d1 > tol && d2 < -tol) || (d1 < -tol && d2 > tol)) &&
         ((d3 > tol && d4 < -tol) || (d3 < -tol && d4 > tol));
}

std::string at(const Plan& plan, const Eigen::Vector2d& local) {
  const Eigen::Vector2d tz = plan.frame.to_theta_z(local);
  char buf[96];
  std::snprintf(buf, sizeof buf, "(theta %.2f deg, z %.2f mm)", tz[0], tz[1]);
  return buf;
}

constexpr double kMinSegmentMm = 0.1;   // shorter cuts cannot be told apart from a point
constexpr double kTouchMm = 0.05;       // cuts closer than this touch
constexpr double kSampleMm = 0.25;      // edge sampling on the model

}  // namespace

double SutureLength::ratio() const {
  const double lo = std::min(first_mm, second_mm), hi = std::max(first_mm, second_mm);
  return lo > 0 ? hi / lo : INFINITY;
}

namespace {

/// check_plan_structure() without the plan's file in front of its errors.
PlanReport structure(const Plan& plan) {
  if (plan.points.empty()) throw InvalidInput("the plan has no points");
  for (std::size_t i = 0; i < plan.points.size(); ++i)
    if (!std::isfinite(plan.points[i].theta_deg) || !std::isfinite(plan.points[i].z_mm))
      throw InvalidInput(cat("point ", i, " (/points/", i, "): theta and z must be finite numbers"));
    else if (std::abs(plan.points[i].theta_deg) > kMaxAbsThetaDeg ||
             std::abs(plan.points[i].z_mm) > kMaxAbsZMm)
      throw InvalidInput(cat("point ", i, " (/points/", i, "): theta ", plan.points[i].theta_deg, " deg, z ",
                             plan.points[i].z_mm, " mm is outside any head (|theta| <= ",
                             kMaxAbsThetaDeg, " deg, |z| <= ", kMaxAbsZMm, " mm)"));
  if (!plan.frame.local_to_theta_z.allFinite() ||
      std::abs(plan.frame.local_to_theta_z.determinant()) < 1e-12)
    throw InvalidInput("the plan's frame (/frame/local_to_theta_z) is singular or not finite");
  // Parameters of a library procedure stay in their clinical range.
  for (const auto& info : procedure_library()) {
    if (info.name != plan.procedure) continue;
    for (const auto& [k, v] : plan.parameters) {
      const std::string& key = k;  // clang 14 cannot capture a structured binding
      auto it = std::find_if(info.parameters.begin(), info.parameters.end(),
                             [&](const ParameterInfo& p) { return p.name == key; });
      if (it == info.parameters.end()) continue;
      if (!(v >= it->min && v <= it->max))
        throw InvalidInput(cat(plan.procedure, ": parameter ", k, " = ", v, " ", it->unit,
                               " is outside its clinical range [", it->min, ", ", it->max,
                               "] (/procedure/parameters/", k, ")"));
    }
  }
  const BorderLoop loop = border_loop(plan);
  const int n = loop.size();
  PlanReport report;
  report.n_points = static_cast<int>(plan.points.size());
  report.n_loop = n;
  report.n_sutures = static_cast<int>(plan.sutures.size());

  // The cut: segments of positive length that meet only at shared points, without folding back.
  struct Seg { int a, b; std::size_t path; };
  std::vector<Seg> segs;
  for (std::size_t p = 0; p < plan.paths.size(); ++p)
    for (std::size_t i = 1; i < plan.paths[p].size(); ++i)
      segs.push_back({plan.paths[p][i - 1], plan.paths[p][i], p});
  std::vector<Eigen::Vector2d> xy(plan.points.size());
  for (std::size_t i = 0; i < xy.size(); ++i)
    xy[i] = plan.frame.to_local(plan.points[i].theta_deg, plan.points[i].z_mm);
  for (const auto& s : segs)
    if ((xy[s.a] - xy[s.b]).norm() < kMinSegmentMm)
      throw InvalidInput(cat("path ", s.path, " (/paths/", s.path, "): segment (", s.a, ",", s.b, ") is ",
                             (xy[s.a] - xy[s.b]).norm(), " mm long at ", at(plan, xy[s.a]),
                             "; points of a cut must be at least ", kMinSegmentMm, " mm apart"));
  for (std::size_t i = 0; i < segs.size(); ++i)
    for (std::size_t j = i + 1; j < segs.size(); ++j) {
      const Seg &s = segs[i], &t = segs[j];
      int shared = -1;
      if (s.a == t.a || s.a == t.b) shared = s.a;
      if (s.b == t.a || s.b == t.b) shared = s.b;
      if (shared < 0) {
        if (segments_meet(xy[s.a], xy[s.b], xy[t.a], xy[t.b], kTouchMm))
          throw InvalidInput(cat("the cut crosses itself: segments (", s.a, ",", s.b, ") and (",
                                 t.a, ",", t.b, ") meet near ", at(plan, xy[s.a])));
        continue;
      }
      const int so = s.a == shared ? s.b : s.a, to = t.a == shared ? t.b : t.a;
      const Eigen::Vector2d u = (xy[so] - xy[shared]).normalized(), v = (xy[to] - xy[shared]).normalized();
      if (std::abs(cross2(u, v)) < 1e-3 && u.dot(v) > 0)
        throw InvalidInput(cat("the cut overlaps itself: segments (", s.a, ",", s.b, ") and (", t.a,
                               ",", t.b, ") leave point ", shared, " in the same direction"));
    }
  // Excisions must not make the border cross itself.
  for (int i = 0; i < n; ++i)
    for (int j = i + 2; j < n; ++j) {
      if ((j + 1) % n == i) continue;
      const auto &p = loop.local_mm[i], &q = loop.local_mm[(i + 1) % n];
      const auto &r = loop.local_mm[j], &s = loop.local_mm[(j + 1) % n];
      if (segments_cross(p, q, r, s, 1e-6))
        throw InvalidInput(cat("the border crosses itself: loop edges (", i, ",", (i + 1) % n,
                               ") and (", j, ",", (j + 1) % n, ") cross near ", at(plan, p),
                               "; check the excision offsets"));
    }
  // The tissue lies left of the loop: an excision that swaps a node and its twin across the cut
  // turns the border inside out (a counterclockwise loop).
  if (2 * signed_area(loop.local_mm) > 1e-6) {
    int worst = 0;
    for (const auto& x : plan.excisions) worst = x.loop_index;
    for (const auto& x : plan.excisions) {
      // The first moved node whose offset points to the right of its outgoing edge.
      const auto d = loop.local_mm[(x.loop_index + 1) % n] - loop.local_mm[x.loop_index];
      if (cross2(d, x.offset_mm) < 0) { worst = x.loop_index; break; }
    }
    throw InvalidInput(cat("the excision offsets turn the border inside out (it must keep the "
                           "tissue on its left, running clockwise with superior up); check loop "
                           "node ", worst, " and its twin: nodes 0..n-1 of a path lie on its left"));
  }
  // A flap's outline is a simple polygon: a bow-tie (two of its sides crossing or touching, or a
  // side folding back over the one before) frees no well-defined area.
  for (std::size_t f = 0; f < plan.flaps.size(); ++f) {
    const auto& flap = plan.flaps[f];
    const std::size_t m = flap.size();
    if (m < 3)
      throw InvalidInput(cat("flap ", f, " (/flaps/", f, ") has ", m, " point(s); a flap's outline needs at least 3"));
    for (int i : flap)
      if (i < 0 || i >= static_cast<int>(xy.size()))
        throw InvalidInput(cat("flap ", f, " (/flaps/", f, ") names point ", i, ", but the plan has ", xy.size(),
                               " points"));
    const auto corner = [&](std::size_t k) { return xy[static_cast<std::size_t>(flap[k % m])]; };
    for (std::size_t i = 0; i < m; ++i) {
      const Eigen::Vector2d u = corner(i + 1) - corner(i), v = corner(i + 2) - corner(i + 1);
      if (m > 2 && u.norm() > 0 && v.norm() > 0 && std::abs(cross2(u, v)) < 1e-3 * u.norm() * v.norm() &&
          u.dot(v) < 0)
        throw InvalidInput(cat("flap ", f, " (/flaps/", f, "): its outline folds back at point ", flap[(i + 1) % m],
                               " (sides (", flap[i], ",", flap[(i + 1) % m], ") and (",
                               flap[(i + 1) % m], ",", flap[(i + 2) % m], ") overlap); list the "
                               "flap's points in order around it"));
      for (std::size_t j = i + 2; j < m; ++j) {
        if ((j + 1) % m == i) continue;
        if (segments_meet(corner(i), corner(i + 1), corner(j), corner(j + 1), kTouchMm))
          throw InvalidInput(cat("flap ", f, " (/flaps/", f, "): its outline crosses itself (a bow-tie): sides (",
                                 flap[i], ",", flap[(i + 1) % m], ") and (", flap[j], ",",
                                 flap[(j + 1) % m], ") meet near ", at(plan, corner(i)),
                                 "; list the flap's points in order around it"));
      }
    }
  }
  // Sutures: border edges (or runs of them), each edge sewn once, never to itself.
  std::map<std::pair<int, int>, int> used;
  for (std::size_t k = 0; k < plan.sutures.size(); ++k) {
    const auto& s = plan.sutures[k];
    for (const BorderRun* r : {&s.first, &s.second})
      for (std::size_t i = 0; i + 1 < r->size(); ++i)
        if (!is_border_edge({(*r)[i], (*r)[i + 1]}, n))
          throw InvalidInput(cat("suture ", k, " (/sutures/", k, ") ", suture_text(s), ": edge (", (*r)[i], ",",
                                 (*r)[i + 1], ") is not on the border; border edges join "
                                 "consecutive nodes of the loop 0..", n - 1));
    std::array<int, 4> q;
    try {
      q = oriented_suture(s, n);
    } catch (const InvalidInput& e) {
      throw InvalidInput(cat("/sutures/", k, ": ", e.what()));
    }
    const auto edges = suture_edges(q, n);
    for (int e : edges[0])
      if (std::find(edges[1].begin(), edges[1].end(), e) != edges[1].end())
        throw InvalidInput(cat("suture ", k, " (/sutures/", k, ") ", suture_text(s), ": edge (", e, ",", (e + 1) % n,
                               ") is sewn to itself"));
    for (const auto& side : edges)
      for (int e : side) {
        auto [it, fresh] = used.insert({{e, (e + 1) % n}, static_cast<int>(k)});
        if (!fresh)
          throw InvalidInput(cat("border edge (", e, ",", (e + 1) % n, ") is used by sutures ",
                                 it->second, " and ", k, " (/sutures/", it->second, ", /sutures/", k, ")", "; each edge can be sewn once"));
      }
  }
  std::string open;
  for (int i = 0; i < n; ++i)
    if (!used.count({i, (i + 1) % n})) open += cat(open.empty() ? "" : ", ", "(", i, ",", (i + 1) % n, ")");
  if (!open.empty())
    report.warnings.push_back(cat("border edges not sutured (the wound stays open there): ", open));
  return report;
}

/// check_plan() without the plan's file in front of its errors.
PlanReport on_model(const Plan& plan, const PatientModel& model) {
  PlanReport report = structure(plan);
  if (!plan.model_hash.empty() && plan.model_hash != model.content_hash())
    throw InvalidInput(cat("the plan was made on another model (", plan.model.empty() ? "" : plan.model + ", ",
                           "content ", plan.model_hash, ") than the one given (content ",
                           model.content_hash(), "): its points would land elsewhere on this "
                           "patient; place the procedure again with caps plan new on this model"));
  const BorderLoop loop = border_loop(plan);
  const int n = loop.size();
  const auto& g = model.grid();
  const double z_lo = g.z0_mm, z_hi = g.z_mm(g.n_z - 1);
  auto check_at = [&](const Eigen::Vector2d& tz, const std::string& what) {
    if (!model.has_z(tz[1]))
      throw InvalidInput(cat(what, " at (theta ", tz[0], " deg, z ", tz[1],
                             " mm) is outside the model (z from ", z_lo, " to ", z_hi, " mm)"));
    const auto f = model.flags_at(tz[0], tz[1]);
    if (flags_valid(f)) return;
    // Where the model cannot represent the skin, the chart to make, for this plan's centre.
    const std::string message = cat(what, " at (theta ", tz[0], " deg, z ", tz[1], " mm) ",
                                    invalid_flags_advice(f));
    if (flags_chart_would_hold(f))
      throw SkinNotHeld(cat(message, " (here: caps model chart ",
                            plan.model.empty() ? "MODEL" : plan.model, " --at ",
                            std::round(plan.frame.theta_deg * 10) / 10, ",",
                            std::round(plan.frame.z_mm * 10) / 10, " -o CHART)"));
    throw InvalidInput(message);
  };
  for (int i = 0; i < n; ++i)
    check_at(loop.theta_z[i], cat("loop node ", i, " (point ", loop.point[i], "), /points/", loop.point[i]));
  // Edge lengths on the skin, sampled densely in the local frame.
  std::vector<double> len(n, 0.0);
  for (int i = 0; i < n; ++i) {
    const auto &p = loop.local_mm[i], &q = loop.local_mm[(i + 1) % n];
    const int steps = std::max(1, static_cast<int>(std::ceil((q - p).norm() / kSampleMm)));
    Eigen::Vector3d last = model.skin_point(loop.theta_z[i][0], loop.theta_z[i][1]);
    for (int s = 1; s <= steps; ++s) {
      const Eigen::Vector2d tz = plan.frame.to_theta_z(p + (q - p) * (double(s) / steps));
      if (s < steps) check_at(tz, cat("loop edge (", i, ",", (i + 1) % n, ")"));
      const Eigen::Vector3d x = model.skin_point(tz[0], tz[1]);
      len[i] += (x - last).norm();
      last = x;
    }
  }
  // Each cut segment is traversed twice by the loop.
  for (double l : len) report.cut_length_mm += 0.5 * l;
  for (std::size_t k = 0; k < plan.sutures.size(); ++k) {
    const auto edges = suture_edges(oriented_suture(plan.sutures[k], n), n);
    SutureLength sl{static_cast<int>(k), 0, 0};
    for (int e : edges[0]) sl.first_mm += len[e];
    for (int e : edges[1]) sl.second_mm += len[e];
    report.suture_lengths.push_back(sl);
    if (sl.ratio() > kSutureRatioWarning) {
      char buf[64];
      std::snprintf(buf, sizeof buf, "%.1f and %.1f mm, ratio %.2f", sl.first_mm, sl.second_mm,
                    sl.ratio());
      report.warnings.push_back(cat("suture ", k, " ", suture_text(plan.sutures[k]), ": sides of ",
                                    buf, "; expect puckering (a dog-ear) or tension"));
    }
  }
  return report;
}

}  // namespace

PlanReport check_plan_structure(const Plan& plan) {
  return detail::naming_plan_file(plan, [&] { return structure(plan); });
}

PlanReport check_plan(const Plan& plan, const PatientModel& model) {
  return detail::naming_plan_file(plan, [&] { return on_model(plan, model); });
}

}  // namespace caps::plan
