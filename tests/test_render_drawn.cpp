// caps::render's drawn skin on the analytic head phantom (volume/phantom.hpp) scanned with thick
// slices (2 x 2 x 4 mm voxels, so that the range image measured from the voxels steps once per
// slice): the skin drawn has no slice terraces (its normals vary across slices as smoothly as the
// analytic surface's), and where the skin did not move the pre- and post-operative images agree.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <set>

#include "caps/core/units.hpp"
#include "caps/closure/simulate.hpp"
#include "caps/plan/procedures.hpp"
#include "caps/core/error.hpp"
#include "caps/render/drawn_skin.hpp"
#include "caps/render/overlay.hpp"
#include "caps/render/render.hpp"
#include "caps/render/skin_surface.hpp"
#include "caps/surface/patient_model.hpp"
#include "caps/volume/model.hpp"
#include "caps/volume/phantom.hpp"

using namespace caps;
using namespace caps::render;

namespace {

constexpr double kSliceMm = 4.0;

struct PhantomCase {
  HeadPhantom head;
  PatientModel model;
  DrawnSkin drawn;
  PatientModel analytic;
  TriMesh iso;  // the volume model's skin isosurface
};

// The analytic skin's outermost crossing along each of the model's rays (bisection to 1e-6 mm).
PatientModel analytic_range(const HeadPhantom& head, const PatientModel& model) {
  CylindricalMaps maps = model.maps();
  const CylinderGrid& g = maps.grid;
  const Eigen::Vector3d a = head.axis_point();
  auto outside = [&](const Eigen::Vector3d& p) {
    const Eigen::Vector3d q = p - a;
    const double theta = std::atan2(q.x(), -q.y());
    return std::hypot(q.x(), q.y()) > head.skin_radius(theta, p.z());
  };
  for (int k = 0; k < g.n_z; ++k)
    for (int j = 0; j < g.n_theta; ++j) {
      const double th = g.theta_deg(j), z = g.z_mm(k);
      double lo = 0, hi = 250;  // hi outside
      for (double r = 250; r > 0; r -= 0.25)
        if (!outside(model.to_lps(th, z, r))) {
          lo = r;
          hi = r + 0.25;
          break;
        }
      if (lo == 0) continue;  // no skin on this ray: keep the model's value
      while (hi - lo > 1e-6) {
        const double mid = 0.5 * (lo + hi);
        (outside(model.to_lps(th, z, mid)) ? hi : lo) = mid;
      }
      maps.r_skin[g.index(j, k)] = static_cast<float>(0.5 * (lo + hi));
    }
  return PatientModel(std::move(maps));
}

const PhantomCase& phantom() {
  static const PhantomCase c = [] {
    PhantomOptions o;
    o.dims = {120, 120, 56};
    o.spacing_mm = {2.0, 2.0, kSliceMm};
    o.head_holder = false;
    ModelOptions mo;
    mo.maps.n_theta = 256;
    mo.maps.n_z = 128;
    const VolumeModel vm = build_volume_model(make_phantom(o), mo);
    HeadPhantom head;
    PatientModel model(vm.maps, {}, "volume");
    DrawnSkin drawn = drawn_skin(model, &vm.skin, {.slice_spacing_mm = kSliceMm});
    PatientModel analytic = analytic_range(head, model);
    return PhantomCase{head, std::move(model), std::move(drawn), std::move(analytic), vm.skin};
  }();
  return c;
}

}  // namespace

// Terraces: the measure is terrace_rms_deg(), the RMS over a region of the second difference along
// z of the surface's tilt atan(dr/dz), i.e. how much the row-to-row turn of the normal changes
// from one row to the next. On the top of the head the analytic head's is 0.014-0.033 deg, the
// range image measured from 4 mm slices steps and scores 1.9-4.8 deg, the drawn skin 0.19-0.40
// deg (the facets of the smoothed isosurface it is resampled from).
TEST(DrawnSkin, NoSliceTerracesOnTheAnalyticPhantom) {
  const PhantomCase& c = phantom();
  for (const auto& [z0, z1] : {std::pair{41.6, 61.6}, std::pair{61.6, 81.6}}) {
    const double measured = terrace_rms_deg(c.model, -40, 40, z0, z1);
    const double drawn = terrace_rms_deg(c.drawn.range, -40, 40, z0, z1);
    const double analytic = terrace_rms_deg(c.analytic, -40, 40, z0, z1);
    std::printf("terrace RMS, z %.1f..%.1f mm: measured %.3f, drawn %.3f, analytic %.3f deg\n", z0,
                z1, measured, drawn, analytic);
    EXPECT_LT(analytic, 0.05) << "z " << z0;
    EXPECT_GT(measured, 1.5) << "z " << z0;       // the terraces are there to remove
    EXPECT_LT(drawn, 0.5) << "z " << z0;          // and they are gone (8x down at least; what
    EXPECT_LT(drawn, 0.125 * measured) << "z " << z0;  // is left: the isosurface's facets)
  }
}

// Real detail is kept: the nose (about 20 mm long, z -40..0) keeps its curvature (its terrace
// measure, all real shape there, within 25 % of the analytic one) and its tip's height (within
// 0.8 mm: the isosurface's smoothing and the 4 mm box shave a 2 x 2 x 4 mm-voxel tip by 0.6 mm);
// over the front of the head the drawn normals are closer to the analytic ones than the measured
// range image's (measured: 0.61 deg RMS drawn, 1.03 deg measured).
TEST(DrawnSkin, KeepsTheNose) {
  const PhantomCase& c = phantom();
  const double drawn = terrace_rms_deg(c.drawn.range, -40, 40, -38.4, 1.6);
  const double analytic = terrace_rms_deg(c.analytic, -40, 40, -38.4, 1.6);
  EXPECT_NEAR(drawn, analytic, 0.25 * analytic);
  const double z = HeadPhantom::kNoseZ;
  std::printf("nose tip r: drawn %.3f, measured %.3f, analytic %.3f mm\n", c.drawn.range.r_skin(0.0, z),
              c.model.r_skin(0.0, z), c.analytic.r_skin(0.0, z));
  EXPECT_NEAR(c.drawn.range.r_skin(0.0, z), c.analytic.r_skin(0.0, z), 0.8);
  // and the drawn normals are close to the analytic ones over the whole front of the head
  const CylinderGrid& g = c.model.grid();
  Eigen::MatrixX2d tz(0, 2);
  std::vector<Eigen::Vector2d> pts;
  for (int k = 0; k < g.n_z; ++k)
    for (int j = 0; j < g.n_theta; ++j)
      if (std::abs(g.theta_deg(j)) <= 40 && g.z_mm(k) > -60 && g.z_mm(k) < 80)
        pts.emplace_back(g.theta_deg(j), g.z_mm(k));
  tz.resize(static_cast<Eigen::Index>(pts.size()), 2);
  for (std::size_t i = 0; i < pts.size(); ++i) tz.row(static_cast<Eigen::Index>(i)) = pts[i];
  const Eigen::MatrixX3d nd = skin_normal_field(c.drawn.range, tz), na = skin_normal_field(c.analytic, tz),
                         nm = skin_normal_field(c.model, tz);
  double err_d = 0, err_m = 0;
  for (Eigen::Index i = 0; i < tz.rows(); ++i) {
    err_d += std::pow(rad_to_deg(std::acos(std::clamp(nd.row(i).dot(na.row(i)), -1.0, 1.0))), 2);
    err_m += std::pow(rad_to_deg(std::acos(std::clamp(nm.row(i).dot(na.row(i)), -1.0, 1.0))), 2);
  }
  err_d = std::sqrt(err_d / tz.rows());
  err_m = std::sqrt(err_m / tz.rows());
  std::printf("normal error vs the analytic head: drawn %.2f deg RMS, measured %.2f deg RMS\n", err_d,
              err_m);
  EXPECT_LT(err_d, 0.75 * err_m);
  EXPECT_LT(err_d, 1.0);
}

namespace {

const closure::Simulation& phantom_ellipse() {
  static const closure::Simulation s = [] {
    const plan::Plan p = plan::place_procedure(
        plan::layout_procedure("ellipse", {{"length", 20.0}, {"width", 6.0}}), phantom().model,
        20.0, 40.0, 90.0);
    closure::SimulateOptions o;
    o.surface.size_mm = 3.0;
    return closure::simulate(phantom().model, p, o);
  }();
  return s;
}

// The displacement-mapped skin of phantom_ellipse() at full resolution, drawn on the drawn skin.
const SkinSurfaces& phantom_skin() {
  static const SkinSurfaces s = [] {
    const fem::Mesh& mesh = phantom_ellipse().wound.continuum.mesh;
    return displaced_skin(phantom().model, mesh, &phantom_ellipse().result,
                          full_resolution_subdivisions(phantom().model, mesh), &phantom().drawn);
  }();
  return s;
}

// 1 where a vertex and every vertex of its one-ring moved less than `mm`.
std::vector<char> still_vertices(const SkinSurfaces& s, double mm) {
  const Eigen::VectorXd moved = (s.post.V - s.pre.V).rowwise().norm();
  std::vector<char> still(static_cast<std::size_t>(moved.size()), 1);
  for (Eigen::Index f = 0; f < s.pre.F.rows(); ++f) {
    bool any = false;
    for (int k = 0; k < 3; ++k) any = any || moved[s.pre.F(f, k)] >= mm;
    if (any)
      for (int k = 0; k < 3; ++k) still[static_cast<std::size_t>(s.pre.F(f, k))] = 0;
  }
  return still;
}

}  // namespace

// Where the displacement is below 0.01 mm the pre- and post-operative images agree to 1 grey
// level. "Below 0.01 mm" at a pixel: the triangles the pixel and its 8 neighbours show, before and
// after, have every vertex and every vertex's one-ring moved less than 0.01 mm (a shading normal
// depends on its one-ring). Before the shared normal field the patch shaded differently from the
// skin around it and the seam strip folded: a lighter polygon with a jagged outline.
TEST(DrawnSkin, UnmovedSkinShadesTheSameBeforeAndAfter) {
  const PhantomCase& c = phantom();
  const SkinSurfaces& s = phantom_skin();
  ASSERT_GT((s.post.V - s.pre.V).rowwise().norm().maxCoeff(), 0.5);
  const std::vector<char> still = still_vertices(s, 0.01);
  for (View v : {View::Plan, View::Oblique, View::Front}) {
    const Camera cam = standard_camera(v, c.model, s, 300, 300);
    const RgbImage pre = render_skin(s, 0.0, s.color, cam), post = render_skin(s, 1.0, s.color, cam);
    const PixelHits hp = pixel_hits(s.pre, cam), hq = pixel_hits(s.post, cam);
    auto unmoved = [&](const PixelHits& h, int x, int y) {
      const int f = h.face[static_cast<std::size_t>(y) * h.width + x];
      if (f < 0) return false;
      for (int k = 0; k < 3; ++k)
        if (!still[static_cast<std::size_t>(s.pre.F(f, k))]) return false;
      return true;
    };
    int compared = 0, worst = 0, micropolygon_pixels = 0;
    for (int y = 1; y + 1 < cam.height_px; ++y)
      for (int x = 1; x + 1 < cam.width_px; ++x) {
        bool ok = true;
        for (int dy = -1; dy <= 1 && ok; ++dy)
          for (int dx = -1; dx <= 1 && ok; ++dx)
            ok = unmoved(hp, x + dx, y + dy) && unmoved(hq, x + dx, y + dy);
        if (!ok) continue;
        ++compared;
        const int f = hp.face[static_cast<std::size_t>(y) * hp.width + x];
        micropolygon_pixels += s.face_part[static_cast<std::size_t>(f)] != SkinPart::Range;
        const std::size_t i = (static_cast<std::size_t>(y) * cam.width_px + x) * 3;
        for (int ch = 0; ch < 3; ++ch)
          worst = std::max(worst, std::abs(int(pre.rgb[i + ch]) - int(post.rgb[i + ch])));
      }
    EXPECT_GT(compared, 1000) << view_name(v);
    if (v == View::Plan) EXPECT_GT(micropolygon_pixels, 500);  // the patch's unmoved parts count
    EXPECT_LE(worst, 1) << view_name(v);
  }
}

// No patch outline before the operation: the pre-operative image of the displacement-mapped skin
// (micropolygons, seam and range cells) matches the drawn range surface rendered alone (the range
// mesh with the same normal field) to 2 grey levels wherever both show skin away from silhouettes.
TEST(DrawnSkin, NoPatchOutlineBeforeTheOperation) {
  const PhantomCase& c = phantom();
  const SkinSurfaces& s = phantom_skin();
  // the drawn range surface alone: one vertex per sample, two triangles per cell
  const CylinderGrid& g = c.drawn.range.grid();
  TriMesh range;
  range.V.resize(static_cast<Eigen::Index>(g.size()), 3);
  Eigen::MatrixX2d tz(static_cast<Eigen::Index>(g.size()), 2);
  for (int k = 0; k < g.n_z; ++k)
    for (int j = 0; j < g.n_theta; ++j) {
      const auto i = static_cast<Eigen::Index>(g.index(j, k));
      range.V.row(i) = c.drawn.range.skin_point(g.theta_deg(j), g.z_mm(k)).transpose();
      tz.row(i) = Eigen::RowVector2d(g.theta_deg(j), g.z_mm(k));
    }
  range.F.resize(2 * static_cast<Eigen::Index>(g.n_theta) * (g.n_z - 1), 3);
  Eigen::Index f = 0;
  for (int k = 0; k + 1 < g.n_z; ++k)
    for (int j = 0; j < g.n_theta; ++j) {
      const int j1 = (j + 1) % g.n_theta;
      const int a = static_cast<int>(g.index(j, k)), b = static_cast<int>(g.index(j1, k)),
                cc = static_cast<int>(g.index(j1, k + 1)), d = static_cast<int>(g.index(j, k + 1));
      range.F.row(f++) = Eigen::RowVector3i(a, b, cc);
      range.F.row(f++) = Eigen::RowVector3i(a, cc, d);
    }
  const Eigen::MatrixX3d range_normals = skin_normal_field(c.drawn.range, tz);
  const Eigen::MatrixX3d white = Eigen::MatrixX3d::Constant(range.V.rows(), 3, 0.8);
  const Eigen::MatrixX3d skin_white = Eigen::MatrixX3d::Constant(s.pre.V.rows(), 3, 0.8);
  const Camera cam = standard_camera(View::Plan, c.model, s, 300, 300);
  const RgbImage alone = render_image(range, white, range_normals, cam);
  const RgbImage pre = render_skin(s, 0.0, skin_white, cam);
  const PixelHits ha = pixel_hits(range, cam), hp = pixel_hits(s.pre, cam);
  int compared = 0, worst = 0, patch = 0;
  for (int y = 1; y + 1 < 300; ++y)
    for (int x = 1; x + 1 < 300; ++x) {
      bool ok = true;
      for (int dy = -1; dy <= 1 && ok; ++dy)
        for (int dx = -1; dx <= 1 && ok; ++dx) {
          const std::size_t i = static_cast<std::size_t>(y + dy) * 300 + (x + dx);
          // the same surface (the range mesh alone has no caps at its ends), and not the
          // isosurface (drawn where the range image cannot show the skin, with its own normals:
          // a pixel beside it mixes its shade in)
          ok = ha.face[i] >= 0 && hp.face[i] >= 0 && std::abs(ha.depth_mm[i] - hp.depth_mm[i]) < 0.5 &&
               s.face_part[static_cast<std::size_t>(hp.face[i])] != SkinPart::Isosurface;
        }
      if (!ok) continue;
      const std::size_t i = static_cast<std::size_t>(y) * 300 + x;
      // the wound's fill is skin to be excised: drawn flat across the ellipse, not the range
      if (s.face_part[static_cast<std::size_t>(hp.face[i])] == SkinPart::WoundFill) continue;
      ++compared;
      patch += s.face_part[static_cast<std::size_t>(hp.face[i])] != SkinPart::Range;
      for (int ch = 0; ch < 3; ++ch)
        worst = std::max(worst, std::abs(int(alone.rgb[3 * i + ch]) - int(pre.rgb[3 * i + ch])));
    }
  std::printf("pre vs the range surface alone: %d pixels (%d on the patch and seam), worst %d levels\n",
              compared, patch, worst);
  EXPECT_GT(patch, 5000);
  EXPECT_LE(worst, 2);
}

// Where the range image's rays graze the skin (kGrazing: on the phantom the top of the head and the
// nose's flanks) it draws the skin as a staircase of streaks; the isosurface is drawn there
// instead, as in the undercuts (since 6 December: a local chart's band showed streaks across the
// eyes, the ear and the far cheek).
TEST(DrawnSkin, TheIsosurfaceIsDrawnWhereTheRaysGraze) {
  const PhantomCase& c = phantom();
  const CylinderGrid& g = c.model.grid();
  const auto& flags = c.model.maps().flags;
  int grazing = 0, drawn_by_isosurface = 0;
  for (int k = 0; k + 1 < g.n_z; ++k)
    for (int j = 0; j < g.n_theta; ++j)
      if (flags[g.index(j, k)] & kGrazing) {
        ++grazing;
        drawn_by_isosurface += !c.drawn.undercut_cells.empty() && c.drawn.undercut_cells[g.index(j, k)] != 0;
      }
  std::printf("grazing samples %d, their cells drawn by the isosurface %d; isosurface triangles %ld\n",
              grazing, drawn_by_isosurface, static_cast<long>(c.drawn.undercuts.F.rows()));
  ASSERT_GT(grazing, 100);
  EXPECT_EQ(drawn_by_isosurface, grazing);
  EXPECT_GT(c.drawn.undercuts.F.rows(), grazing);
}

// A patch beside undercuts (a local chart's on the side of the nose, where the chart's rays cross
// the nose twice): the seam joins the patch's rim to the range mesh, so around the footprint the
// range mesh is drawn and the isosurface keeps clear of it. Until 6 December the isosurface's
// triangles reached over the footprint's border cells there: the render showed a ring of shards
// around the patch (issue 34). Here every cell within 12 cells of the phantom ellipse's footprint
// is made an undercut cell, drawn by the isosurface's triangles as DrawnSkin draws undercuts.
TEST(DrawnSkin, APatchAmongUndercutsHasNoIsosurfaceOverItsSeam) {
  const PhantomCase& c = phantom();
  const CylinderGrid& g = c.model.grid();
  const fem::Mesh& mesh = phantom_ellipse().wound.continuum.mesh;
  // The footprint's box (the patch as drawn without undercuts), grown by 12 cells: all undercut.
  const SkinSurfaces plain =
      displaced_skin(c.model, mesh, &phantom_ellipse().result.displacement_mm, 2, &c.drawn);
  int j_lo = g.n_theta, j_hi = -1, k_lo = g.n_z, k_hi = -1;
  for (int q : plain.replaced_cells) {
    j_lo = std::min(j_lo, q % g.n_theta);
    j_hi = std::max(j_hi, q % g.n_theta);
    k_lo = std::min(k_lo, q / g.n_theta);
    k_hi = std::max(k_hi, q / g.n_theta);
  }
  ASSERT_LT(j_hi - j_lo, g.n_theta / 2);  // the patch does not wrap around theta's seam
  DrawnSkin drawn = c.drawn;
  drawn.undercut_cells.assign(g.size(), 0);
  for (int k = std::max(k_lo - 12, 0); k <= std::min(k_hi + 12, g.n_z - 2); ++k)
    for (int j = j_lo - 12; j <= j_hi + 12; ++j)
      drawn.undercut_cells[g.index((j + g.n_theta) % g.n_theta, k)] = 1;
  // The isosurface's triangles whose centroid lies in those cells (as drawn_skin() selects them).
  const auto cell_of = [&](const Eigen::Vector3d& p) {
    const CylindricalPoint cp = c.model.to_cylindrical(p);
    double u = (cp.theta_deg - g.theta0_deg) / g.dtheta_deg();
    u -= g.n_theta * std::floor(u / g.n_theta);
    const int j = std::min(static_cast<int>(std::floor(u)), g.n_theta - 1);
    const int k = static_cast<int>(std::floor((cp.z_mm - g.z0_mm) / g.dz_mm));
    return k < 0 || k + 1 >= g.n_z ? -1 : static_cast<int>(g.index(j, k));
  };
  std::vector<Eigen::Vector3i> faces;
  for (Eigen::Index f = 0; f < c.iso.F.rows(); ++f) {
    const int q = cell_of((c.iso.V.row(c.iso.F(f, 0)) + c.iso.V.row(c.iso.F(f, 1)) +
                           c.iso.V.row(c.iso.F(f, 2))).transpose() / 3.0);
    if (q >= 0 && drawn.undercut_cells[static_cast<std::size_t>(q)]) faces.push_back(c.iso.F.row(f));
  }
  ASSERT_GT(faces.size(), 1000u);
  drawn.undercuts.V = c.iso.V;
  drawn.undercuts.F.resize(static_cast<Eigen::Index>(faces.size()), 3);
  for (std::size_t f = 0; f < faces.size(); ++f)
    drawn.undercuts.F.row(static_cast<Eigen::Index>(f)) = faces[f].transpose();
  drawn.undercut_normals = Eigen::MatrixX3d::Zero(c.iso.V.rows(), 3);
  drawn.undercut_normals.col(2).setOnes();

  const SkinSurfaces s =
      displaced_skin(c.model, mesh, &phantom_ellipse().result.displacement_mm, 2, &drawn);
  const std::set<int> footprint(s.replaced_cells.begin(), s.replaced_cells.end());
  int iso_faces = 0, over_footprint = 0, range_faces = 0;
  for (Eigen::Index f = 0; f < s.pre.F.rows(); ++f) {
    const SkinPart part = s.face_part[static_cast<std::size_t>(f)];
    if (part == SkinPart::Isosurface) {
      ++iso_faces;
      bool over = false;
      for (int a = 0; a < 3; ++a) over = over || footprint.count(cell_of(s.pre.V.row(s.pre.F(f, a)).transpose()));
      over_footprint += over;
    }
    // range cells among the undercuts (the ring around the footprint)
    if (part == SkinPart::Range) {
      const int q = cell_of((s.pre.V.row(s.pre.F(f, 0)) + s.pre.V.row(s.pre.F(f, 1)) +
                             s.pre.V.row(s.pre.F(f, 2))).transpose() / 3.0);
      range_faces += q >= 0 && drawn.undercut_cells[static_cast<std::size_t>(q)];
    }
  }
  std::printf("isosurface faces %d, with a corner over the footprint %d; range faces among the "
              "undercuts %d\n", iso_faces, over_footprint, range_faces);
  EXPECT_GT(iso_faces, 1000);
  EXPECT_EQ(over_footprint, 0);
  EXPECT_GT(range_faces, 100);
}

// The suture line after the closure: one loop for the ellipse (its two lips), closed up: the area
// it encloses, seen along the skin's normal at the mesh's centre, is under 1 mm^2 (the 20 x 6 mm
// ellipse is about 94 mm^2).
TEST(Overlays, TheSutureLineOfAClosedEllipseIsOneClosedUpLoop) {
  const SkinSurfaces& s = phantom_skin();
  const auto lines = suture_lines(s);
  ASSERT_EQ(lines.size(), 1u);
  const CylindricalPoint c = phantom().model.to_cylindrical(s.mesh_centre_lps);
  const Eigen::Vector3d n = phantom().model.skin_normal(c.theta_deg, c.z_mm);
  const Eigen::Vector3d e1 = n.unitOrthogonal(), e2 = n.cross(e1);
  double area = 0, length = 0;
  for (std::size_t i = 0; i + 1 < lines[0].size(); ++i) {
    const Eigen::Vector3d& p = lines[0][i];
    const Eigen::Vector3d& q = lines[0][i + 1];
    area += p.dot(e1) * q.dot(e2) - q.dot(e1) * p.dot(e2);
    length += (q - p).norm();
  }
  EXPECT_LT(std::abs(0.5 * area), 1.0);
  EXPECT_GT(length, 2 * 18.0);  // both lips, each about as long as the ellipse
  EXPECT_EQ((lines[0].front() - lines[0].back()).norm(), 0.0);
}

// The scale bar: the largest 1-2-5 length up to a fifth of the image, drawn at the camera's scale.
TEST(Overlays, ScaleBar) {
  EXPECT_EQ(scale_bar_length_mm(100), 20);
  EXPECT_EQ(scale_bar_length_mm(250), 50);
  EXPECT_EQ(scale_bar_length_mm(60), 10);
  EXPECT_EQ(scale_bar_length_mm(9), 1);
  EXPECT_EQ(scale_bar_length_mm(0.4), 0.05);
  EXPECT_THROW(scale_bar_length_mm(0), InvalidInput);
  Camera cam;
  cam.width_px = 500;
  cam.height_px = 300;
  cam.width_mm = 100;  // 5 px per mm: a 20 mm bar is 100 px long
  RgbImage img;
  img.width = 500;
  img.height = 300;
  img.rgb.assign(500 * 300 * 3, 255);
  draw_scale_bar(img, cam);
  int longest = 0;
  for (int y = 0; y < 300; ++y) {
    int run = 0;
    for (int x = 0; x < 500; ++x) {
      run = img.rgb[(static_cast<std::size_t>(y) * 500 + x) * 3] < 40 ? run + 1 : 0;
      longest = std::max(longest, run);
    }
  }
  EXPECT_NEAR(longest, 100, 3);  // the bar (and its end ticks' width)
  cam.projection = Projection::Perspective;
  EXPECT_THROW(draw_scale_bar(img, cam), InvalidInput);
}

// Lines behind the head are not drawn: in the front view a line across the back of the head
// (theta 180) projects onto the one across the face (theta 0); with the hits only the front one
// shows.
TEST(Overlays, HiddenLinesAreLeftOut) {
  const PatientModel& m = phantom().model;
  const SkinSurfaces& s = phantom_skin();
  const Camera cam = standard_camera(View::Front, m, s, 200, 200);
  std::vector<Eigen::Vector3d> front, back;
  for (int i = 0; i <= 20; ++i) {
    front.push_back(m.skin_point(-10.0 + i, 40.0));
    back.push_back(m.skin_point(170.0 + i, 40.0));
  }
  const PixelHits hits = pixel_hits(s.pre, cam);
  RgbImage blank;
  blank.width = blank.height = 200;
  blank.rgb.assign(200 * 200 * 3, 255);
  RgbImage both = blank, only_front = blank, unhidden = blank;
  draw_polylines(both, cam, {front, back}, &hits);
  draw_polylines(only_front, cam, {front}, &hits);
  draw_polylines(unhidden, cam, {front, back});
  EXPECT_EQ(both.rgb, only_front.rgb);
  EXPECT_NE(unhidden.rgb, only_front.rgb);
  EXPECT_NE(only_front.rgb, blank.rgb);
}
