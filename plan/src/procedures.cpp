#include "caps/plan/procedures.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <nlohmann/json.hpp>
#include <numeric>

#include "caps/core/data_dir.hpp"
#include "caps/core/error.hpp"
#include "caps/core/json_file.hpp"
#include "caps/core/units.hpp"
#include "caps/plan/skin_walk.hpp"
#include "suture_json.hpp"

namespace caps::plan {

namespace {

using V2 = Eigen::Vector2d;

SuturePair sp(int a, int b, int c, int d) { return {{a, b}, {c, d}}; }

// Ellipse and W-plasty: one path from apex to apex, every interior point moved off its twin,
// each edge sewn to its twin edge; the apices are corners (CAPS 1992, Figure 1).
std::vector<SuturePair> twin_sutures(int n_path) {
  const int n_loop = 2 * n_path - 2;
  auto twin = [&](int k) { return (k == 0 || k == n_path - 1) ? k : n_loop - k; };
  std::vector<SuturePair> s;
  for (int k = 0; k + 1 < n_path; ++k) s.push_back(sp(k, k + 1, twin(k), twin(k + 1)));
  return s;
}

LocalProcedure ellipse(std::map<std::string, double>& p) {
  const double L = p["length"];
  double W = p["width"];
  if (p.count("apex_angle")) W = L * std::tan(deg_to_rad(p["apex_angle"]) / 2);
  const double apex = rad_to_deg(2 * std::atan(W / L));
  if (!(apex >= 15 && apex <= 90))
    throw InvalidInput(cat("ellipse: length ", L, " mm and width ", W, " mm give an apex angle of ",
                           apex, " deg; keep it between 15 and 90 deg (about 30 deg avoids "
                           "dog-ears: length about 3.5 x width)"));
  p["width"] = W;
  p["apex_angle"] = apex;
  // The surgeon's points 0..3 along the axis; 1, 2 and their twins 5, 4 moved to the sides of
  // the fusiform: four points cannot hold a curved outline whose width and apex angle both
  // mean what they say (a lens through points at L/6 is 0.9 W wide with a 48 deg apex at
  // 3:1), so the outline is the rhombus of the given length, width and apex angle, with 1 at
  // its widest point (the centre) and 2 halfway along the side to the apex 3.
  LocalProcedure out;
  out.points_mm = {V2(-L / 2, 0), V2(0, 0), V2(L / 4, 0), V2(L / 2, 0)};
  out.paths = {{0, 1, 2, 3}};
  out.excisions = {{1, V2(0, W / 2)}, {2, V2(0, W / 4)}, {4, V2(0, -W / 4)}, {5, V2(0, -W / 2)}};
  out.sutures = {sp(0, 1, 0, 5), sp(1, 2, 5, 4), sp(2, 3, 4, 3)};  // the paper's list
  out.notes = "Elliptical (fusiform) excision, CAPS 1992 Figure 1: surgeon points 0..3 along the "
              "axis (1 at the centre, 2 halfway to the apex 3); 4 and 5 start on 2 and 1 and are "
              "moved (with 1 and 2) to enclose the fusiform of the given length, width and apex "
              "angle.";
  return out;
}

LocalProcedure z_plasty(std::map<std::string, double>& p) {
  const double L = p["length"], a = deg_to_rad(p["angle"]);
  const V2 limb = L * V2(std::cos(a), std::sin(a));
  LocalProcedure out;
  const V2 p1(-L / 2, 0), p2(L / 2, 0);
  out.points_mm = {p1 + limb, p1, p2, p2 - limb};
  out.paths = {{0, 1, 2, 3}};
  out.sutures = {sp(5, 0, 5, 4), sp(2, 1, 2, 3), sp(0, 1, 3, 4)};  // the paper's list
  out.flaps = {{0, 1, 2}, {3, 2, 1}};  // the two triangles, tips at 1 and 2
  out.notes = "Z-plasty, CAPS 1992 Figure 2: path 0,1,2,3 (central limb 1-2 along the "
              "orientation); loop 0..5 with 4 on 2 and 5 on 1. Flap tips at 1 and 4 transpose: "
              "0 meets 4, 1 meets 3; 2 and 5 are closed corners.";
  return out;
}

LocalProcedure multiple_z(std::map<std::string, double>& p) {
  const int n = static_cast<int>(std::lround(p["segments"]));
  p["segments"] = n;
  const double seg = p["length"] / n, a = deg_to_rad(p["angle"]);
  const V2 limb = seg * V2(std::cos(a), std::sin(a));
  LocalProcedure out;
  // Central points c_0..c_n are 0..n; limb ends p_i = c_i + limb (i < n), q_i = c_i - limb (i > 0).
  for (int i = 0; i <= n; ++i) out.points_mm.push_back(V2(-p["length"] / 2 + i * seg, 0));
  std::vector<int> pi(n), qi(n + 1, -1);
  for (int i = 0; i < n; ++i) {
    pi[i] = static_cast<int>(out.points_mm.size());
    out.points_mm.push_back(out.points_mm[i] + limb);
  }
  for (int i = 1; i <= n; ++i) {
    qi[i] = static_cast<int>(out.points_mm.size());
    out.points_mm.push_back(out.points_mm[i] - limb);
  }
  out.paths.push_back({pi[0], 0});
  for (int i = 0; i < n; ++i) out.paths.back().push_back(i + 1);
  out.paths.back().push_back(qi[n]);
  for (int i = 1; i < n; ++i) out.paths.push_back({qi[i], i, pi[i]});
  // Each Z (p_i, c_i, c_i+1, q_i+1) is sutured like the paper's: with E(u,v) the loop edge
  // running from u to v, {E(b,a), E(c,b)}, {E(b,c), E(c,d)}, {E(a,b), E(d,c)}.
  const std::vector<int> loop = walk_around_cut(out.points_mm, out.paths);
  const int nl = static_cast<int>(loop.size());
  auto E = [&](int u, int v) {
    for (int i = 0; i < nl; ++i)
      if (loop[i] == u && loop[(i + 1) % nl] == v) return BorderRun{i, (i + 1) % nl};
    throw Error("multiple-z-plasty: internal error, a segment missing from the loop");
  };
  for (int i = 0; i < n; ++i) {
    const int a = pi[i], b = i, c = i + 1, d = qi[i + 1];
    out.sutures.push_back({E(b, a), E(c, b)});
    out.sutures.push_back({E(b, c), E(c, d)});
    out.sutures.push_back({E(a, b), E(d, c)});
    out.flaps.push_back({a, b, c});
    out.flaps.push_back({d, c, b});
  }
  out.notes = cat(n, " Z-plasties in series sharing one central line; at each inner point the "
                  "limbs of two neighbouring Zs form one straight cut. Each Z is sutured like the "
                  "paper's Z-plasty.");
  return out;
}

LocalProcedure w_plasty(std::map<std::string, double>& p) {
  const double L = p["length"], h = p["width"] / 2, limb = p["limb"], a = deg_to_rad(p["angle"]);
  const double pitch = limb * std::sin(a / 2), amp = limb * std::cos(a / 2) / 2;
  const int m = std::max(1, static_cast<int>(std::lround(L / pitch)) - 1);
  const double dx = L / (m + 1);
  LocalProcedure out;
  out.points_mm.push_back(V2(-L / 2, 0));
  for (int k = 1; k <= m; ++k) out.points_mm.push_back(V2(-L / 2 + k * dx, (k % 2 ? amp : -amp)));
  out.points_mm.push_back(V2(L / 2, 0));
  const int np = m + 2, n_loop = 2 * np - 2;
  out.paths.push_back({});
  for (int k = 0; k < np; ++k) out.paths[0].push_back(k);
  for (int k = 1; k <= m; ++k) {
    out.excisions.push_back({k, V2(0, h)});
    out.excisions.push_back({n_loop - k, V2(0, -h)});
  }
  std::sort(out.excisions.begin(), out.excisions.end(),
            [](const ExcisionOffset& x, const ExcisionOffset& y) { return x.loop_index < y.loop_index; });
  out.sutures = twin_sutures(np);
  p["teeth"] = m;
  out.notes = "W-plasty: the surgeon's zigzag along the scar, both sides moved apart by the width; "
              "the two zigzags are translates of each other and interdigitate when closed.";
  return out;
}

LocalProcedure rhomboid(std::map<std::string, double>& p) {
  const double L = p["side"], s3 = std::sqrt(3.0);
  LocalProcedure out;
  // Rhombus A B C D (60 deg at A and C, long diagonal C->A along the orientation), flap cut
  // D -> E (the short diagonal extended) -> F (parallel to D->C). Path F, E, D, C, B.
  const V2 A(s3 / 2 * L, 0), C(-s3 / 2 * L, 0), E(0, -1.5 * L), F(-s3 / 2 * L, -L);
  const V2 D(0, -0.5 * L), B(0, 0.5 * L);
  out.points_mm = {F, E, D, C, B};
  out.paths = {{0, 1, 2, 3, 4}};
  // The rhombus's corners walked from its centre along the diagonals, the flap's E from D and F
  // from E; A (C's twin, moved) is put at the side's length from B and from D.
  out.laid_from = {1, 2, -1, -1, -1};
  out.excisions = {{5, A - C}};  // the twin of C becomes the rhombus corner A
  out.sutures = {sp(1, 2, 5, 4), sp(3, 2, 3, 4), sp(0, 1, 6, 5), sp(7, 0, 7, 6)};
  out.flaps = {{2, 1, 0, 3}};  // D E F C
  out.notes = "Rhomboid (Limberg) flap: loop F0 E1 D2 C3 B4 A5 D'6 E'7. The flap D-E-F-C turns "
              "60 deg about C into the defect: E meets A, D meets B, F meets D'; C and E' are "
              "closed corners.";
  return out;
}

// Rotation flap. Arc centre O (the apex of the triangular defect), defect O F S with the angle
// delta at O and legs R; the arc S = A_0, A_1 .. A_m = P (the pivot) runs on the circle of radius R
// through alpha, away from the defect. Path F, O, S, A_1 .. A_m (, B: the back-cut from P towards
// O). Nodes on the left of the path are the tissue beyond the far edge F-O, the flap's leading
// edge O-S and the flap's side of the arc; the twins are the outer side of the arc and the defect
// side of O-S. The twin of O is moved to the middle M of the base F-S to open the defect.
// Sutures (E(u,v): the loop edge from u to v): the leading edge to the far edge, corner O (S meets
// F); the flap's arc E(A_k, A_k+1) (then E(P, B)) to the outer side two edges further round,
// E(O,F), E(S,O), E(A_1,S), ..., so that A_k meets the outer node two places back; the two outer
// edges left at the pivot are closed as a corner (the standing cone / Burow's triangle).
LocalProcedure rotation_flap(std::map<std::string, double>& p) {
  const double R = p["radius"], delta = deg_to_rad(p["defect_angle"]);
  const double alpha = deg_to_rad(p["arc_angle"]), back_mm = p["back_cut"];
  const double side = p["arc_side"];
  if (side != 1 && side != -1)
    throw InvalidInput(cat("rotation-flap: arc_side = ", side, "; give 1 (the arc sweeps to the left "
                           "of the orientation) or -1 (to the right)"));
  if (back_mm > R / 2)
    throw InvalidInput(cat("rotation-flap: back_cut = ", back_mm, " mm is more than half the radius (",
                           R, " mm); a longer back-cut narrows the flap's pedicle too far"));
  const bool mirror = side < 0;
  // Arc segments about as long as half the defect's base: the two base halves are sewn to the
  // first two arc segments.
  const double half_base = R * std::sin(delta / 2);
  const int m = std::clamp(
      static_cast<int>(std::lround(alpha / (2 * std::asin(half_base / (2 * R))))), 4, 8);
  p["segments"] = m;
  auto at = [&](double phi) { return V2(R * std::cos(phi), (mirror ? -1 : 1) * R * std::sin(phi)); };
  LocalProcedure out;
  const int iF = 0, iO = 1, iS = 2;  // then A_k = 2 + k, k = 1..m (A_m = P), then B
  out.points_mm = {at(-delta), V2(0, 0), at(0)};
  for (int k = 1; k <= m; ++k) out.points_mm.push_back(at(k * alpha / m));
  auto A = [&](int k) { return k == 0 ? iS : 2 + k; };
  const int iP = A(m);
  const bool back = back_mm > 0;
  const int iB = static_cast<int>(out.points_mm.size());
  if (back) out.points_mm.push_back(out.points_mm[iP] * (1 - back_mm / R));
  std::vector<int> path = {iF, iO, iS};
  for (int k = 1; k <= m; ++k) path.push_back(A(k));
  if (back) path.push_back(iB);
  // Mirrored, the path is reversed so that the same side stays on the left.
  if (mirror) std::reverse(path.begin(), path.end());
  out.paths = {path};
  // Every point walked from O (the centre): the radius and the angles at O hold on the skin.
  out.laid_from.assign(out.points_mm.size(), -1);
  // The flap: the sector O, S, the arc to P (and the back-cut's end B).
  out.flaps = {{iO, iS}};
  for (int k = 1; k <= m; ++k) out.flaps[0].push_back(A(k));
  if (back) out.flaps[0].push_back(iB);
  const std::vector<int> loop = walk_around_cut(out.points_mm, out.paths);
  const int nl = static_cast<int>(loop.size());
  auto E = [&](int u, int v) {
    if (mirror) std::swap(u, v);
    for (int i = 0; i < nl; ++i)
      if (loop[i] == u && loop[(i + 1) % nl] == v) return BorderRun{i, (i + 1) % nl};
    throw Error("rotation-flap: internal error, a segment missing from the loop");
  };
  // The twin of O (between E(S,O) and E(O,F)) moves to the middle of the base.
  const BorderRun so = E(iS, iO);
  const int twin_O = mirror ? so[0] : so[1];
  out.excisions = {{twin_O, (out.points_mm[iF] + out.points_mm[iS]) / 2}};
  out.sutures.push_back({E(iF, iO), E(iO, iS)});
  std::vector<BorderRun> flap, outer = {E(iO, iF), E(iS, iO)};
  for (int k = 0; k < m; ++k) flap.push_back(E(A(k), A(k + 1)));
  if (back) flap.push_back(E(iP, iB));
  for (int k = 0; outer.size() < flap.size(); ++k) outer.push_back(E(A(k + 1), A(k)));
  for (std::size_t k = 0; k < flap.size(); ++k) out.sutures.push_back({flap[k], outer[k]});
  if (back)
    out.sutures.push_back({E(iB, iP), E(iP, A(m - 1))});
  else
    out.sutures.push_back({E(iP, A(m - 1)), E(A(m - 1), A(m - 2))});
  out.notes = cat("Rotation flap: triangular defect F-O-S (apex O at the arc's centre), arc of ", m,
                  " segments from S to the pivot P", back ? " and a back-cut P-B" : "",
                  ". The flap turns into the defect: S meets F (corner O); the flap's arc is sewn "
                  "to the outer arc shifted by the defect's base; the outer arc's excess at the "
                  "pivot closes as a corner (the standing cone, or Burow's triangle).");
  return out;
}

// V-Y advancement. The V's apex P at the origin, its arms to A (left, y > 0) and B (right) at
// half the apex angle either side of +x: the V opens along the orientation, which is the
// direction the flap advances. Path A, J_A, P, J_B, B, with J_A and J_B on the arms at the
// advance s from P. The path's left side is the flap (inside the V): loop 0 A, 1 J_A, 2 P,
// 3 J_B, 4 B; the twins 5 J_B', 6 P', 7 J_A' are the outer side. Closure: the outer arms are
// sewn together from the apex to J' (the stem of the Y, corner P'), and each side of the flap,
// P..A, is sewn by arc length to the outer arm left beyond the stem, J'..A (a run sewn to a
// shorter run): the flap's tip P meets J_A' and J_B' at the junction of the Y, A and B are
// closed corners. The flap thus moves s along the orientation.
LocalProcedure v_y(std::map<std::string, double>& p) {
  const double L = p["length"], half = deg_to_rad(p["angle"]) / 2, s = p["advance"];
  if (!(s <= L / 2))
    throw InvalidInput(cat("v-y-advancement: advance = ", s, " mm is more than half the arm (",
                           L, " mm); the stem of the Y would leave too little arm to sew the "
                           "flap's sides to (keep advance <= length / 2; about length / 3 is usual)"));
  const V2 arm_a(std::cos(half), std::sin(half)), arm_b(std::cos(half), -std::sin(half));
  LocalProcedure out;
  out.points_mm = {L * arm_a, s * arm_a, V2(0, 0), s * arm_b, L * arm_b};
  out.paths = {{0, 1, 2, 3, 4}};
  out.sutures = {{{5, 6}, {6, 7}},      // the stem: outer arms from P' to J'
                 {{0, 1, 2}, {0, 7}},   // flap side P..A to the outer J_A'..A
                 {{2, 3, 4}, {5, 4}}};  // flap side P..B to the outer J_B'..B
  out.flaps = {{0, 2, 4}};  // the V: A, P, B
  out.notes = cat("V-Y advancement: path A0 J1 P2 J3 B4 (the V's apex P, its arms ", L,
                  " mm at ", p["angle"], " deg), loop twins J5 P6 J7 on the outer side. The outer "
                  "arms close from the apex to J (the stem of the Y, ", s, " mm); each side of the "
                  "flap is sewn by arc length to the outer arm beyond J, so the flap's tip P moves ",
                  s, " mm along the orientation to the junction of the Y. Sides of ", L, " and ",
                  L - s, " mm are sewn together: the flap's edges are gathered slightly.");
  return out;
}

// Bilobed flap (Zitelli 1989), laid out as three teardrops fanned about the pivot P: the defect
// (a circle of radius r and the Burow's triangle from it to P), the first lobe (the same teardrop
// turned by the lobe angle beta) and the second lobe (a circle of radius k r whose centre is on
// the same arc, turned by 2 beta, drawn out to a tip). P is at d = r / sin(beta / 2) from the
// defect's centre, so that the defect's teardrop spans exactly beta at P: the first lobe turned
// back by beta lies on the defect (Esser's and Zitelli's geometry made exact; d = 2 r at 60 deg
// is Zitelli's "one radius from the defect's edge", 2.61 r at 45 deg the 2024 ePlasty design's
// 2.6 r). Local frame: the defect's centre at the origin, x from P through it.
// Path P, k1..k4 (on the defect's side towards the lobes, P-t+), t+ (where the defect and the
// first lobe touch), the first lobe's cap a1, T1, a2 to u+ (its other tangent point), v- (the
// second lobe's tangent point), b1, T2 (its tip), b2, w+, then Q down the second lobe's outer side
// (the pedicle is Q-P, uncut). The twins of k1..k4 are moved onto the defect's outline t-, c1,
// F, c2 (the far edge F on the axis), opening the teardrop. Sutures: the flap's border P..t+ to
// the defect's other side t-..P (corner P: the Burow's triangle closed), the first lobe's cap to
// the defect's cap (T1 meets F), the second lobe by arc length to the first lobe's donor site
// (T2 meets T1'), and the second lobe's donor closed primarily (corners T2' and Q).
LocalProcedure bilobed(std::map<std::string, double>& p) {
  const double r = p["radius"], beta = deg_to_rad(p["lobe_angle"]), k = p["second_lobe"];
  const double side = p["lobe_side"];
  if (side != 1 && side != -1)
    throw InvalidInput(cat("bilobed: lobe_side = ", side,
                           "; give 1 (the lobes to the left of the orientation) or -1 (right)"));
  const bool mirror = side < 0;
  const double d = r / std::sin(beta / 2), r2 = k * r;
  const V2 P(-d, 0);
  auto polar = [&](double rho, double phi) {
    return V2(P + rho * V2(std::cos(phi), std::sin(phi)));
  };
  auto turn = [&](const V2& x, double a) {
    const V2 u = x - P;
    return V2(P + V2(std::cos(a) * u.x() - std::sin(a) * u.y(),
                     std::sin(a) * u.x() + std::cos(a) * u.y()));
  };
  // The defect's cap from t- round the far side to t+: 180 deg + beta of the circle in 4 chords,
  // F on the axis. The end chords span 70 deg, so that the first lobe's border turns by 35 deg
  // at t+ (from the straight side P-t+): the surface mesher's stage 1 fills the flap only from
  // corners sharper than its t1 = 30 deg (docs/mesher.md), and at 4 equal chords (28 deg) the
  // flap was left to stage 2's layers, which overlapped inside it.
  const double end_step = deg_to_rad(70.0), mid_step = (kPi + beta) / 2 - end_step;
  const std::array<double, 5> cap_angle = {-(kPi / 2 + beta / 2), -mid_step, 0.0, mid_step,
                                           kPi / 2 + beta / 2};
  std::vector<V2> cap(5);
  for (int i = 0; i <= 4; ++i) cap[i] = r * V2(std::cos(cap_angle[i]), std::sin(cap_angle[i]));
  const V2 t_plus = cap[4];
  // The second lobe: centre on the arc of radius d at 2 beta, tangent half-angle h2 at P; its
  // cap from v- (the tangent point towards the first lobe) through b1, the tip T2 (drawn out to
  // 2 r2 from its centre: a 60 deg tip, so that its donor site closes primarily), b2 to w+.
  const double h2 = std::asin(r2 / d);
  const V2 c2 = polar(d, 2 * beta), ax(std::cos(2 * beta), std::sin(2 * beta)), nx(-ax.y(), ax.x());
  auto on2 = [&](double a) { return V2(c2 + r2 * (std::cos(a) * ax + std::sin(a) * nx)); };
  const double tangent = kPi / 2 + h2, widest = tangent / 2;
  std::vector<V2> pts = {P};
  for (int i = 1; i <= 4; ++i) pts.push_back(P + (t_plus - P) * (i / 5.0));
  pts.push_back(t_plus);                                           // 5 t+
  for (int i = 1; i <= 4; ++i) pts.push_back(turn(cap[i], beta));  // 6 a1, 7 T1, 8 a2, 9 u+
  pts.push_back(on2(-tangent));                                    // 10 v-
  pts.push_back(on2(-widest));                                     // 11 b1
  pts.push_back(c2 + 2 * r2 * ax);                                 // 12 T2
  pts.push_back(on2(widest));                                      // 13 b2
  pts.push_back(on2(tangent));                                     // 14 w+
  pts.push_back(polar(d - r, 2 * beta + h2));                      // 15 Q
  if ((pts[10] - pts[9]).norm() < 0.05 * r)
    throw InvalidInput(
        cat("bilobed: second_lobe = ", k, " leaves no notch between the lobes; keep it below 0.9"));
  p["pivot_distance"] = d;
  p["total_angle"] = rad_to_deg(2 * beta);
  LocalProcedure out;
  for (V2& x : pts) out.points_mm.push_back(mirror ? V2(x.x(), -x.y()) : x);
  std::vector<int> path(pts.size());
  std::iota(path.begin(), path.end(), 0);
  if (mirror) std::reverse(path.begin(), path.end());
  out.paths = {path};
  // The fan about P: every point laid from P (the angles at P and the distances from it hold).
  out.laid_from.assign(pts.size(), 0);
  out.laid_from[0] = -1;
  out.flaps = {{0, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15}};
  const std::vector<int> loop = walk_around_cut(out.points_mm, out.paths);
  const int nl = static_cast<int>(loop.size());
  // A run of the loop through the given points in that order (mirrored: the loop runs the other
  // way, so the same stretch of border is the reversed run).
  auto R = [&](std::vector<int> q) {
    if (mirror) std::reverse(q.begin(), q.end());
    for (int i = 0; i < nl; ++i) {
      bool match = true;
      for (std::size_t j = 0; j < q.size() && match; ++j) match = loop[(i + j) % nl] == q[j];
      if (match) {
        BorderRun run;
        for (std::size_t j = 0; j < q.size(); ++j) run.push_back(static_cast<int>((i + j) % nl));
        return run;
      }
    }
    throw Error("bilobed: internal error, a run missing from the loop");
  };
  // The skin-side copies of k1..k4 (k_i: point i) moved onto t-, c1, F, c2.
  for (int i = 1; i <= 4; ++i) {
    const BorderRun e = R({i + 1, i});
    const V2 to = mirror ? V2(cap[i - 1].x(), -cap[i - 1].y()) : cap[i - 1];
    out.excisions.push_back({mirror ? e[0] : e[1], to - out.points_mm[i]});
  }
  // The flap's side P..t+ to t-..P (corner P: the Burow's triangle closed); the first lobe's cap
  // to the defect's (t+ meets t-, T1 meets F); the second lobe by arc length to the first's
  // donor site (T2 meets T1'); the second's donor site closed primarily (corners T2' and Q).
  out.sutures = {{R({0, 1, 2, 3, 4, 5}), R({1, 0})},
                 {R({5, 6}), R({2, 1})},
                 {R({6, 7}), R({3, 2})},
                 {R({7, 8}), R({4, 3})},
                 {R({8, 9}), R({5, 4})},
                 {R({9, 10, 11, 12}), R({7, 6, 5})},
                 {R({12, 13, 14}), R({10, 9, 8, 7})},
                 {R({13, 12}), R({12, 11})},
                 {R({14, 13}), R({11, 10})},
                 {R({14, 15}), R({15, 14})}};
  out.notes =
      cat("Bilobed flap (Zitelli): defect of radius ", r, " mm with its Burow's triangle ",
          "to the pivot P at ", d, " mm from its centre; first lobe at ", p["lobe_angle"],
          " deg, second (", k, " of the first) at ", 2 * p["lobe_angle"], " deg. The ",
          "flap turns back by the lobe angle: the first lobe into the defect (T1 meets F), ",
          "the second into the first's donor site (T2 meets T1'); the second's donor site ",
          "and the Burow's triangle close primarily.");
  return out;
}

using Layout = LocalProcedure (*)(std::map<std::string, double>&);

struct Template {
  ProcedureInfo info;
  Layout layout;
};

// The layouts in code, by the library's names (data/procedures/library.json holds each one's
// summary and parameters).
const std::map<std::string, Layout>& layouts() {
  static const std::map<std::string, Layout> m = {
      {"ellipse", ellipse},          {"z-plasty", z_plasty}, {"multiple-z-plasty", multiple_z},
      {"w-plasty", w_plasty},        {"rhomboid", rhomboid}, {"rotation-flap", rotation_flap},
      {"v-y-advancement", v_y},      {"bilobed", bilobed}};
  return m;
}

const std::vector<Template>& templates() {
  static const std::vector<Template> t = [] {
    std::vector<Template> v;
    for (auto& info : read_procedure_library(data_file("procedures/library.json")))
      v.push_back({info, layouts().at(info.name)});
    return v;
  }();
  return t;
}

// Where the excised nodes go on the skin (loop index -> theta deg, z mm), given the points laid
// with their carried frames `at`. Each is walked from its point by its offset, in the frame
// carried there, or from the point its point is laid from when that is another point (the
// bilobed flap's fan about its pivot). A node moved away from both its loop neighbours, which
// stay on their points, and not in line with them (the rhomboid's corner A) is then put at its
// distances from both (the two sides of the rhombus keep their length). The ellipse: the widest
// points 1 and 5 are walked W/2 to either side of the centre, and 2 and 4 are walked from the
// apex 3 in the apex's directions, so that the length, the width and the apex angle at 3 hold
// on the skin; the apex angle at 0 follows from length and width (docs/plan.md).
std::map<int, V2> lay_excisions(const LocalProcedure& proc, const PatientModel& model,
                                const std::vector<int>& loop, const std::vector<SkinFrame>& at) {
  std::map<int, V2> to;
  const int n = static_cast<int>(loop.size());
  if (n == 0) return to;
  std::vector<V2> xy(n);
  std::vector<char> moved(n, 0);
  for (int i = 0; i < n; ++i) xy[i] = proc.points_mm[loop[i]];
  std::map<int, V2> offset;
  for (const auto& e : proc.excisions) {
    if (e.loop_index < 0 || e.loop_index >= n || !e.offset_mm.allFinite() || moved[e.loop_index])
      continue;  // refused by check_plan() with the entry named
    xy[e.loop_index] += e.offset_mm;
    moved[e.loop_index] = 1;
    offset[e.loop_index] = e.offset_mm;
  }
  for (const auto& [i, off] : offset) {
    // Laid from the point its point is laid from: its distance from there and the angle there
    // hold like the points' (the bilobed flap's defect outline, from the pivot).
    const int p = loop[i];
    const int from = p < static_cast<int>(proc.laid_from.size()) ? proc.laid_from[p] : -1;
    if (from >= 0 && from < static_cast<int>(at.size()))
      to[i] = walk_on_skin(model, at[from], xy[i] - proc.points_mm[from]).theta_z;
    else
      to[i] = walk_on_skin(model, at[p], off).theta_z;
  }
  auto flat_angle = [&](int v, int a, int b) {
    const V2 u = xy[a] - xy[v], w = xy[b] - xy[v];
    return std::atan2(std::abs(u.x() * w.y() - u.y() * w.x()), u.dot(w));
  };
  const bool ellipse = proc.name == "ellipse" && proc.points_mm.size() == 4 && n == 6 &&
                       moved[1] && moved[2] && moved[4] && moved[5] && !moved[0] && !moved[3];
  if (ellipse) {
    // The widest points stay walked W/2 from the centre (the width); 2 and 4 from the apex 3.
    to[2] = walk_on_skin(model, at[3], xy[2] - proc.points_mm[3]).theta_z;
    to[4] = walk_on_skin(model, at[3], xy[4] - proc.points_mm[3]).theta_z;
    return to;
  }
  for (auto& [i, u] : to) {
    const int a = (i + n - 1) % n, b = (i + 1) % n;
    const double da = (xy[i] - xy[a]).norm(), db = (xy[i] - xy[b]).norm();
    if (moved[a] || moved[b] || !(da > 1e-6) || !(db > 1e-6) ||
        flat_angle(i, a, b) > deg_to_rad(170.0))
      continue;
    V2 solved;
    if (point_at_skin_distances(model, at[loop[a]].theta_z, da, at[loop[b]].theta_z, db, u, solved))
      u = solved;
  }
  return to;
}

}  // namespace

const std::vector<ProcedureInfo>& procedure_library() {
  static const std::vector<ProcedureInfo> lib = [] {
    std::vector<ProcedureInfo> v;
    for (const auto& t : templates()) v.push_back(t.info);
    return v;
  }();
  return lib;
}

LocalProcedure layout_procedure(const std::string& name,
                                const std::map<std::string, double>& given) {
  auto it = std::find_if(templates().begin(), templates().end(),
                         [&](const Template& t) { return t.info.name == name; });
  if (it == templates().end()) {
    std::string names;
    for (const auto& t : templates()) names += (names.empty() ? "" : ", ") + t.info.name;
    throw InvalidInput(cat("unknown procedure '", name, "'; the library has: ", names,
                           " (or give a procedure file, *.json)"));
  }
  std::map<std::string, double> p;
  for (const auto& info : it->info.parameters)
    if (info.alternative_to.empty()) p[info.name] = info.default_value;
  for (const auto& [k, v] : given) {
    const std::string& key = k;  // clang 14 cannot capture a structured binding
    auto pi = std::find_if(it->info.parameters.begin(), it->info.parameters.end(),
                           [&](const ParameterInfo& x) { return x.name == key; });
    if (pi == it->info.parameters.end()) {
      std::string names;
      for (const auto& x : it->info.parameters)
        names += (names.empty() ? "{" : ", {") + x.name + "}";
      throw InvalidParameter(cat(name, ": no parameter '{", k, "}'; it takes ", names));
    }
    if (!pi->alternative_to.empty() && given.count(pi->alternative_to))
      throw InvalidParameter(cat(name, ": give {", pi->alternative_to, "} or {", k,
                                 "}, not both (the one sets the other)"));
    if (!(v >= pi->min && v <= pi->max))
      throw InvalidParameter(cat(name, ": {", k, "} = ", v, " ", pi->unit,
                                 " is outside its clinical range [", pi->min, ", ", pi->max, "] ",
                                 pi->unit));
    p[k] = v;
  }
  LocalProcedure out = it->layout(p);
  out.name = name;
  out.parameters = p;
  return out;
}

Plan place_procedure(const LocalProcedure& proc, const PatientModel& model, double theta_deg,
                     double z_mm, double orientation_deg) {
  Plan plan;
  plan.procedure = proc.name.empty() ? "custom" : proc.name;
  plan.parameters = proc.parameters;
  plan.frame = make_frame(model, theta_deg, z_mm, orientation_deg);
  // Each point is walked to along the skin from its neighbour on the cut, in the direction and
  // over the length the template draws, with the frame carried along: the cut's segments keep
  // their lengths and the angles between them on the skin (a linear map of the template would
  // stretch and turn it where the skin curves). The walks start from the point nearest the
  // centre; a point on no path is walked to from the centre.
  const std::size_t np = proc.points_mm.size();
  const SkinFrame centre = skin_frame(model, theta_deg, z_mm, orientation_deg);
  std::vector<std::vector<int>> nb(np);
  for (const auto& path : proc.paths)
    for (std::size_t i = 1; i < path.size(); ++i) {
      const int a = path[i - 1], b = path[i];
      if (a < 0 || b < 0 || a >= static_cast<int>(np) || b >= static_cast<int>(np)) continue;
      nb[a].push_back(b);
      nb[b].push_back(a);
    }
  std::vector<SkinFrame> at(np);
  std::vector<char> placed(np, 0);
  if (!proc.laid_from.empty()) {
    // Each point walked from the one it is laid from (-1: the centre), in index order of need.
    if (proc.laid_from.size() != np)
      throw InvalidInput(cat(plan.procedure, ": laid_from has ", proc.laid_from.size(),
                             " entries for ", np, " points"));
    std::vector<char> busy(np, 0);
    auto lay = [&](auto&& self, int i) -> void {
      if (placed[i]) return;
      if (busy[i]) throw InvalidInput(cat(plan.procedure, ": laid_from has a cycle through point ", i));
      busy[i] = 1;
      const int from = proc.laid_from[i];
      if (from < -1 || from >= static_cast<int>(np))
        throw InvalidInput(cat(plan.procedure, ": laid_from names point ", from, " for point ", i));
      if (from < 0) {
        at[i] = walk_on_skin(model, centre, proc.points_mm[i]);
      } else {
        self(self, from);
        at[i] = walk_on_skin(model, at[from], proc.points_mm[i] - proc.points_mm[from]);
      }
      placed[i] = 1;
    };
    for (std::size_t i = 0; i < np; ++i) lay(lay, static_cast<int>(i));
  }
  for (;;) {
    int root = -1;
    for (std::size_t i = 0; i < np; ++i)
      if (!placed[i] && (root < 0 || proc.points_mm[i].norm() < proc.points_mm[root].norm()))
        root = static_cast<int>(i);
    if (root < 0) break;
    at[root] = walk_on_skin(model, centre, proc.points_mm[root]);
    placed[root] = 1;
    std::vector<int> queue{root};
    for (std::size_t q = 0; q < queue.size(); ++q) {
      const int u = queue[q];
      for (int v : nb[u]) {
        if (placed[v]) continue;
        at[v] = walk_on_skin(model, at[u], proc.points_mm[v] - proc.points_mm[u]);
        placed[v] = 1;
        queue.push_back(v);
      }
    }
  }
  for (const auto& f : at) {
    const double theta = std::remainder(f.theta_z[0], 360.0);
    const double t = theta >= 180.0 ? theta - 360.0 : theta;
    plan.points.push_back({t, f.theta_z[1], model.skin_point(t, f.theta_z[1])});
  }
  plan.paths = proc.paths;
  plan.excisions = proc.excisions;
  // Excised nodes on the skin (lay_excisions()), their offsets rewritten in the plan's linear
  // frame so that border_loop() puts each exactly where it was laid: the linear frame at the
  // centre would stretch and turn the offsets where the skin curves.
  if (!plan.excisions.empty() && !proc.paths.empty()) {
    std::vector<int> loop;
    try {
      loop = walk_around_cut(proc.points_mm, proc.paths);
    } catch (const InvalidInput&) {
      // Not a tree: check_plan() says why; the offsets stay as given.
    }
    const std::map<int, V2> to = lay_excisions(proc, model, loop, at);
    for (auto& e : plan.excisions) {
      auto it = to.find(e.loop_index);
      if (it == to.end()) continue;
      const int p = loop[e.loop_index];
      e.offset_mm = plan.frame.to_local(it->second[0], it->second[1]) -
                    plan.frame.to_local(plan.points[p].theta_deg, plan.points[p].z_mm);
    }
  }
  plan.sutures = proc.sutures;
  plan.flaps = proc.flaps;
  plan.notes = proc.notes;
  return plan;
}

namespace {

using nlohmann::json;

json sutures_json(const std::vector<SuturePair>& s) {
  json a = json::array();
  for (const auto& x : s) a.push_back(detail::suture_to_json(x));
  return a;
}

}  // namespace

std::string procedure_to_json(const LocalProcedure& p) {
  json j;
  j["format"] = "caps-procedure";
  j["format_version"] = 1;
  j["name"] = p.name;
  j["units"] = {{"length", "mm"}};
  j["frame"] = "local tangent plane: x along the orientation, y to its left (seen from outside)";
  j["points_mm"] = json::array();
  for (const auto& x : p.points_mm) j["points_mm"].push_back({x.x(), x.y()});
  j["paths"] = p.paths;
  j["excisions"] = json::array();
  for (const auto& e : p.excisions)
    j["excisions"].push_back({{"loop_index", e.loop_index}, {"offset_mm", {e.offset_mm.x(), e.offset_mm.y()}}});
  j["sutures"] = sutures_json(p.sutures);
  if (!p.flaps.empty()) j["flaps"] = p.flaps;
  if (!p.laid_from.empty()) j["laid_from"] = p.laid_from;
  j["notes"] = p.notes;
  return j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace);
}

LocalProcedure parse_procedure_json(const std::string& text, const std::string& source) {
  const json j = parse_json<json>(text, source);
  try {
    if (j.value("format", "") != "caps-procedure")
      throw InvalidInput(cat(source, ": \"format\" must be \"caps-procedure\""));
    if (j.value("format_version", 0.0) != 1.0)
      throw InvalidInput(cat(source, ": format_version ", j.value("format_version", 0.0),
                             " is not supported (this caps reads version 1)"));
    LocalProcedure p;
    p.name = j.value("name", "custom");
    for (const auto& x : j.at("points_mm")) p.points_mm.push_back(V2(x.at(0).get<double>(), x.at(1).get<double>()));
    p.paths = detail::index_lists(j.at("paths"), cat(source, ": paths"));
    if (j.contains("excisions"))
      for (const auto& e : j["excisions"])
        p.excisions.push_back({to_int(e.at("loop_index").get<double>(), cat(source, ": excisions: loop_index")),
                               V2(e.at("offset_mm").at(0).get<double>(), e.at("offset_mm").at(1).get<double>())});
    for (const auto& s : j.at("sutures")) p.sutures.push_back(detail::suture_from_json(s, source));
    if (j.contains("flaps")) p.flaps = detail::index_lists(j["flaps"], cat(source, ": flaps"));
    if (j.contains("laid_from")) {
      // Indices, or -1 for the centre (index_list() takes whole numbers of any sign).
      p.laid_from = detail::index_list(j["laid_from"], cat(source, ": laid_from"));
      if (p.laid_from.size() != p.points_mm.size())
        throw InvalidInput(cat(source, ": laid_from has ", p.laid_from.size(), " entries for ",
                               p.points_mm.size(), " points (one per point: the point it is laid "
                               "from, or -1 for the centre)"));
    }
    p.notes = j.value("notes", "");
    return p;
  } catch (const json::exception& e) {
    throw InvalidInput(cat(source, ": ", e.what(), "; see docs/plan-format.md (procedure files)"));
  }
}

LocalProcedure procedure_from_plan(const Plan& plan) {
  LocalProcedure p;
  p.name = plan.procedure;
  p.parameters = plan.parameters;
  for (const auto& x : plan.points) p.points_mm.push_back(plan.frame.to_local(x.theta_deg, x.z_mm));
  p.paths = plan.paths;
  p.excisions = plan.excisions;
  p.sutures = plan.sutures;
  p.flaps = plan.flaps;
  p.notes = plan.notes;
  return p;
}

std::vector<ProcedureInfo> read_procedure_library(const std::filesystem::path& file) {
  const std::string source = file.string();
  const json j = read_json_file<json>(file, "the procedure library is data/procedures/library.json",
                                      std::size_t(1) << 20);
  std::vector<ProcedureInfo> lib;
  try {
    if (j.value("format", "") != "caps-procedure-library" || !j.contains("version") ||
        !j.at("version").is_number_integer() || j.at("version").get<long long>() != 1)
      throw InvalidInput(cat(source, ": not a caps procedure library (\"format\": "
                             "\"caps-procedure-library\", \"version\": 1)"));
    for (const auto& e : j.at("procedures")) {
      ProcedureInfo info;
      info.name = e.at("name").get<std::string>();
      info.summary = e.at("summary").get<std::string>();
      if (!layouts().count(info.name))
        throw InvalidInput(cat(source, ": the procedure '", info.name, "' has no layout in caps "
                               "(a new template needs its geometry in plan/src/procedures.cpp)"));
      for (const auto& q : e.at("parameters")) {
        ParameterInfo pi;
        pi.name = q.at("name").get<std::string>();
        pi.unit = q.at("unit").get<std::string>();
        pi.default_value = q.at("default").get<double>();
        pi.min = q.at("min").get<double>();
        pi.max = q.at("max").get<double>();
        pi.meaning = q.at("help").get<std::string>();
        pi.alternative_to = q.value("alternative_to", "");
        if (!(pi.min <= pi.default_value && pi.default_value <= pi.max))
          throw InvalidInput(cat(source, ": ", info.name, ": the default ", pi.default_value, " ",
                                 pi.unit, " of '", pi.name, "' is outside its range [", pi.min,
                                 ", ", pi.max, "]"));
        info.parameters.push_back(pi);
      }
      for (const auto& x : lib)
        if (x.name == info.name)
          throw InvalidInput(cat(source, ": the procedure '", info.name, "' is listed twice"));
      lib.push_back(info);
    }
  } catch (const json::exception& e) {
    throw InvalidInput(cat(source, ": ", e.what(), " (the procedure library: docs/plan.md, The library)"));
  }
  for (const auto& entry : layouts()) {
    const std::string& name = entry.first;  // clang 14 cannot capture a structured binding
    if (std::none_of(lib.begin(), lib.end(), [&](const ProcedureInfo& x) { return x.name == name; }))
      throw InvalidInput(cat(source, ": the procedure '", name, "' is missing (caps lays it out; "
                             "its parameters must be declared here)"));
  }
  return lib;
}

}  // namespace caps::plan
