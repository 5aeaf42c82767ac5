#include "caps/plan/plan.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <set>

#include "caps/core/error.hpp"
#include "caps/core/units.hpp"
#include "caps/plan/skin_walk.hpp"
#include "plan_source.hpp"

namespace caps::plan {

namespace {

double wrap_theta(double theta_deg) {
  double t = std::fmod(theta_deg + 180.0, 360.0);
  if (t < 0) t += 360.0;
  return t - 180.0;
}

}  // namespace

Eigen::Vector2d PlanFrame::to_theta_z(const Eigen::Vector2d& xy_mm) const {
  const Eigen::Vector2d d = local_to_theta_z * xy_mm;
  return {wrap_theta(theta_deg + d[0]), z_mm + d[1]};
}

Eigen::Vector2d PlanFrame::to_local(double theta, double z) const {
  const Eigen::Vector2d d(std::remainder(theta - theta_deg, 360.0), z - z_mm);
  return local_to_theta_z.inverse() * d;
}

PlanFrame make_frame(const PatientModel& model, double theta_deg, double z_mm,
                     double orientation_deg) {
  if (!std::isfinite(theta_deg) || !std::isfinite(z_mm) || !std::isfinite(orientation_deg))
    throw InvalidInput(cat("plan centre (theta ", theta_deg, " deg, z ", z_mm, " mm, orientation ",
                           orientation_deg, " deg) must be finite numbers"));
  const SkinTangent t = skin_tangent(model, theta_deg, z_mm);
  const SkinFrame axes = skin_frame(model, theta_deg, z_mm, orientation_deg);
  Eigen::Matrix<double, 3, 2> J, E;
  J << t.d_theta, t.d_z;
  E << axes.ex, axes.ey;
  PlanFrame f;
  f.theta_deg = wrap_theta(theta_deg);
  f.z_mm = z_mm;
  f.orientation_deg = orientation_deg;
  // Least squares: the (dtheta, dz) whose skin displacement is the local vector.
  f.local_to_theta_z = (J.transpose() * J).ldlt().solve(J.transpose() * E);
  return f;
}

std::vector<int> incision_to_loop(int n) {
  if (n < 2) throw InvalidInput(cat("a cutting path needs at least 2 points, got ", n));
  std::vector<int> loop;
  for (int i = 0; i < n; ++i) loop.push_back(i);
  for (int i = n - 2; i >= 1; --i) loop.push_back(i);
  return loop;
}

std::vector<int> walk_around_cut(const std::vector<Eigen::Vector2d>& xy,
                                 const std::vector<std::vector<int>>& paths) {
  const int np = static_cast<int>(xy.size());
  if (paths.empty()) throw InvalidInput("the plan has no cutting path");
  std::vector<std::vector<int>> nb(np);
  std::set<std::pair<int, int>> edges;
  for (std::size_t p = 0; p < paths.size(); ++p) {
    const auto& path = paths[p];
    if (path.size() < 2)
      throw InvalidInput(cat("path ", p, " (/paths/", p, ") has ", path.size(), " point(s); a cut needs at least 2"));
    for (std::size_t i = 0; i < path.size(); ++i) {
      if (path[i] < 0 || path[i] >= np)
        throw InvalidInput(cat("path ", p, " (/paths/", p, "/", i, ") names point ", path[i], ", but the plan has ", np,
                               " points (0..", np - 1, ")"));
      if (i == 0) continue;
      const int a = path[i - 1], b = path[i];
      if (a == b)
        throw InvalidInput(cat("path ", p, " (/paths/", p, "/", i, ") repeats point ", a, " (segment ", i - 1, "-", i, ")"));
      const auto key = std::minmax(a, b);
      if (!edges.insert({key.first, key.second}).second)
        throw InvalidInput(cat("path ", p, " (/paths/", p, "/", i, "): segment (", a, ",", b,
                               ") is cut twice (the paths overlap there)"));
      nb[a].push_back(b);
      nb[b].push_back(a);
    }
  }
  for (int i = 0; i < np; ++i)
    if (nb[i].empty())
      throw InvalidInput(cat("point ", i, " is on no cutting path (/points/", i, " is in no entry of /paths)"));
  const int start = paths[0][0];
  if (nb[start].size() != 1)
    throw InvalidInput(cat("the first path (/paths/0/0) must start at an end of the cut, but point ", start,
                           " joins ", nb[start].size(), " segments"));
  // A tree has one segment fewer than points; more closes a loop, fewer leaves it in pieces
  // (found by the walk below).
  if (static_cast<int>(edges.size()) > np - 1)
    throw InvalidInput(cat("the cutting paths close a loop (", edges.size(), " segments over ", np,
                           " points): a closed cut would free an island of skin; describe removed "
                           "tissue with excision offsets instead"));
  std::vector<int> loop{start};
  // Walk around the tree with the tissue on the left: at each point, leave by the first segment
  // clockwise from the one we came in by.
  int prev = start, cur = nb[start][0];
  const std::size_t n_loop = 2 * edges.size();
  while (loop.size() < n_loop) {
    loop.push_back(cur);
    const Eigen::Vector2d back = xy[prev] - xy[cur];
    const double a_back = std::atan2(back.y(), back.x());
    int best = -1;
    double best_cw = 0;
    for (int q : nb[cur]) {
      const Eigen::Vector2d d = xy[q] - xy[cur];
      double cw = std::fmod(a_back - std::atan2(d.y(), d.x()) + 4 * kPi, 2 * kPi);
      if (q == prev) cw = 2 * kPi;
      else if (cw < 1e-9 || cw > 2 * kPi - 1e-9)
        throw InvalidInput(cat("the cut overlaps itself: segments (", prev, ",", cur, ") and (", cur,
                               ",", q, ") leave point ", cur, " in the same direction"));
      if (best < 0 || cw < best_cw) best = q, best_cw = cw;
    }
    prev = cur;
    cur = best;
  }
  std::vector<char> seen(np, 0);
  for (int p : loop) seen[p] = 1;
  for (int i = 0; i < np; ++i)
    if (!seen[i])
      throw InvalidInput(cat("point ", i, " (/points/", i, ") is on a cut not connected to the first path; a plan "
                             "describes one wound (make a plan per wound)"));
  return loop;
}

BorderLoop border_loop(const Plan& plan) {
  return detail::naming_plan_file(plan, [&] {
  const int np = static_cast<int>(plan.points.size());
  std::vector<Eigen::Vector2d> xy(np);
  for (int i = 0; i < np; ++i) xy[i] = plan.frame.to_local(plan.points[i].theta_deg, plan.points[i].z_mm);
  BorderLoop loop;
  loop.point = walk_around_cut(xy, plan.paths);
  const int n = loop.size();
  loop.local_mm.resize(n);
  for (int i = 0; i < n; ++i) loop.local_mm[i] = xy[loop.point[i]];
  std::vector<char> moved(n, 0);
  for (std::size_t e = 0; e < plan.excisions.size(); ++e) {
    const auto& x = plan.excisions[e];
    if (x.loop_index < 0 || x.loop_index >= n)
      throw InvalidInput(cat("excision ", e, " (/excisions/", e, "/loop_index) moves loop node ", x.loop_index,
                             ", but the border loop has nodes 0..", n - 1));
    if (!x.offset_mm.allFinite())
      throw InvalidInput(cat("excision ", e, " (/excisions/", e, "/offset_mm, loop node ",
                             x.loop_index, "): the offset must be finite"));
    if (moved[x.loop_index]++)
      throw InvalidInput(cat("excision ", e, " (/excisions/", e, "/loop_index): loop node ", x.loop_index, " is moved twice"));
    loop.local_mm[x.loop_index] += x.offset_mm;
  }
  loop.theta_z.resize(n);
  for (int i = 0; i < n; ++i) loop.theta_z[i] = plan.frame.to_theta_z(loop.local_mm[i]);
  return loop;
  });
}

bool is_border_edge(const BorderEdge& e, int n) {
  if (e.a < 0 || e.b < 0 || e.a >= n || e.b >= n) return false;
  return e.b == (e.a + 1) % n || e.a == (e.b + 1) % n;
}

std::string suture_text(const SuturePair& s) {
  auto run = [](const BorderRun& r) {
    std::string t = "(";
    for (std::size_t i = 0; i < r.size(); ++i) t += cat(i ? "," : "", r[i]);
    return t + ")";
  };
  return "(" + run(s.first) + "," + run(s.second) + ")";
}

std::array<int, 4> oriented_suture(const SuturePair& s, int n) {
  // +1 if the run goes along the loop, -1 against it; for one edge both may hold (n = 2), and
  // an edge is taken as written in whichever direction fits.
  auto direction = [&](const BorderRun& r, const char* which) {
    auto fail = [&](const std::string& why) -> int {
      throw InvalidInput(cat("suture ", suture_text(s), ": its ", which, " side ", why,
                             "; a side is a border edge (two consecutive nodes of the loop 0..",
                             n - 1, ", or ", n - 1, " and 0) or a run of them"));
    };
    if (r.size() < 2) fail("has fewer than two nodes");
    for (int v : r)
      if (v < 0 || v >= n) fail(cat("names node ", v, ", which is not on the loop"));
    if (static_cast<int>(r.size()) > n) fail("is longer than the loop");
    int dir = 0;
    for (std::size_t i = 0; i + 1 < r.size(); ++i) {
      const bool fwd = r[i + 1] == (r[i] + 1) % n, bwd = r[i] == (r[i + 1] + 1) % n;
      if (!fwd && !bwd) fail(cat("(", r[i], ",", r[i + 1], ") is not a border edge"));
      const int d = fwd ? 1 : -1;
      if (r.size() > 2 && dir != 0 && d != dir) fail("turns back on itself");
      dir = d;
    }
    return dir;
  };
  BorderRun first = s.first, second = s.second;
  if (direction(first, "first") < 0) std::reverse(first.begin(), first.end());
  const int d2 = direction(second, "second");
  if (second.size() == 2) {
    // An edge as the second side is read against the loop: (i+1, i).
    if (second[0] != (second[1] + 1) % n) std::swap(second[0], second[1]);
  } else if (d2 > 0) {
    std::reverse(second.begin(), second.end());
  }
  return {first.front(), first.back(), second.front(), second.back()};
}

std::vector<int> forward_edges(int a, int b, int n) {
  std::vector<int> e;
  for (int i = a; e.empty() || i != b; i = (i + 1) % n) e.push_back(i);
  return e;
}

std::array<std::vector<int>, 2> suture_edges(const std::array<int, 4>& q, int n) {
  return {forward_edges(q[0], q[1], n), forward_edges(q[3], q[2], n)};
}

WoundBorder wound_border(const Plan& plan) {
  return detail::naming_plan_file(plan, [&] {
  const BorderLoop loop = border_loop(plan);
  WoundBorder w;
  w.loop_theta_z = loop.theta_z;
  for (std::size_t k = 0; k < plan.sutures.size(); ++k) {
    try {
      w.sutures.push_back(oriented_suture(plan.sutures[k], loop.size()));
    } catch (const InvalidInput& e) {
      throw InvalidInput(cat("/sutures/", k, ": ", e.what()));
    }
  }
  const double t0 = loop.theta_z.empty() ? 0.0 : loop.theta_z[0][0];
  for (std::size_t f = 0; f < plan.flaps.size(); ++f) {
    const auto& flap = plan.flaps[f];
    if (flap.size() < 3)
      throw InvalidInput(cat("flap ", f, " (/flaps/", f, ") has ", flap.size(), " point(s); a flap's outline needs "
                             "at least 3"));
    std::vector<Eigen::Vector2d> poly;
    for (int i : flap) {
      if (i < 0 || i >= static_cast<int>(plan.points.size()))
        throw InvalidInput(cat("flap ", f, " (/flaps/", f, ") names point ", i, ", but the plan has ",
                               plan.points.size(), " points"));
      const auto& p = plan.points[i];
      poly.push_back({t0 + std::remainder(p.theta_deg - t0, 360.0), p.z_mm});
    }
    w.flaps_theta_z.push_back(std::move(poly));
  }
  return w;
  });
}

}  // namespace caps::plan
