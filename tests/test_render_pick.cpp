// Picking on a rendered view: the camera of a standard view projects a known skin point to its
// pixel, and the ray of that pixel, cast by picking (SkinPicker on the model, MeshRayCaster on
// the rendered mesh), meets the point again; at every pixel centre the renderer's own hit
// (pixel_hits, Embree) is the triangle picking (CGAL) meets there, at the same depth.
#include <gtest/gtest.h>

#include "synthetic_model.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include "caps/core/error.hpp"
#include "caps/core/units.hpp"
#include "caps/closure/simulate.hpp"
#include "caps/plan/procedures.hpp"
#include "caps/render/render.hpp"
#include "caps/render/skin_surface.hpp"
#include "caps/surface/camera.hpp"
#include "caps/surface/patient_model.hpp"
#include "caps/surface/picking.hpp"

using namespace caps;
using namespace caps::render;

namespace {

// A bumpy cylinder about the LPS z axis (as in test_render.cpp): theta every degree from -180,
// z = -100 .. 100 mm every mm, skin radius 70 + 2 sin(3 theta) cos(z / 15) mm.
const PatientModel& bumpy() {
  static const PatientModel m(caps_test::synthetic_maps(
      caps_test::grid(360, 201, -100, 1),
      [](double theta, double z) {
        return 70.0 + 2.0 * std::sin(deg_to_rad(3 * theta)) * std::cos(z / 15.0);
      },
      [](double, double) { return 5.0; }));
  return m;
}

// An ellipse excision at theta 10 deg, z 5 mm, closed by the solver: post differs from pre.
const SkinSurfaces& skin() {
  static const SkinSurfaces s = [] {
    const plan::Plan p =
        plan::place_procedure(plan::layout_procedure("ellipse", {{"length", 20.0}, {"width", 6.0}}),
                              bumpy(), 10.0, 5.0, 90.0);
    closure::SimulateOptions o;
    o.surface.size_mm = 3.0;
    const closure::Simulation sim = closure::simulate(bumpy(), p, o);
    return displaced_skin(bumpy(), sim.wound.continuum.mesh, &sim.result, 4);
  }();
  return s;
}

// The lateral offset of b from a in the image plane, in mm along (right, up).
Eigen::Vector2d lateral(const Camera& cam, const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  const CameraFrame f = cam.frame();
  return {(b - a).dot(f.right), (b - a).dot(f.up)};
}

// The distance from p to the edges of triangle f of m (mm).
double distance_to_boundary(const TriMesh& m, Eigen::Index f, const Eigen::Vector3d& p) {
  double best = std::numeric_limits<double>::infinity();
  for (int k = 0; k < 3; ++k) {
    const Eigen::Vector3d u = m.V.row(m.F(f, k)), v = m.V.row(m.F(f, (k + 1) % 3));
    const double t = std::clamp((p - u).dot(v - u) / (v - u).squaredNorm(), 0.0, 1.0);
    best = std::min(best, (p - u - t * (v - u)).norm());
  }
  return best;
}

// The distance from p to triangle f of m (mm): to its plane if p projects inside it, else to
// its edges.
double distance_to_face(const TriMesh& m, Eigen::Index f, const Eigen::Vector3d& p) {
  const Eigen::Vector3d a = m.V.row(m.F(f, 0)), b = m.V.row(m.F(f, 1)), c = m.V.row(m.F(f, 2));
  double best = distance_to_boundary(m, f, p);
  const Eigen::Vector3d n = (b - a).cross(c - a).normalized();
  const Eigen::Vector3d q = p - (p - a).dot(n) * n;
  const double s1 = (b - a).cross(q - a).dot(n), s2 = (c - b).cross(q - b).dot(n),
               s3 = (a - c).cross(q - c).dot(n);
  if ((s1 >= 0 && s2 >= 0 && s3 >= 0) || (s1 <= 0 && s2 <= 0 && s3 <= 0))
    best = std::min(best, std::abs((p - a).dot(n)));
  return best;
}

constexpr int kW = 240, kH = 200;

}  // namespace

TEST(RenderPick, AModelSkinPointComesBackThroughItsPixel) {
  const SkinPicker picker(bumpy());
  const CylindricalPoint centre = bumpy().to_cylindrical(skin().mesh_centre_lps);
  // front: a sample away from the wound; plan: the sample nearest the wound's centre. Both are
  // vertices of the model's range mesh, which picking meets.
  const std::vector<std::pair<View, Eigen::Vector2d>> cases{
      {View::Front, {-30.0, 40.0}},
      {View::Plan, {std::round(centre.theta_deg), std::round(centre.z_mm)}}};
  for (const auto& [view, theta_z] : cases) {
    const Camera cam = standard_camera(view, bumpy(), skin(), kW, kH);
    const Eigen::Vector3d p = bumpy().skin_point(theta_z.x(), theta_z.y());
    const Eigen::Vector2d px = cam.project(p);
    ASSERT_TRUE(px.x() > 0 && px.x() < kW && px.y() > 0 && px.y() < kH) << view_name(view);
    // through the point's own (fractional) pixel position: the point itself
    const SkinHit exact = picker.pick(cam.ray(px.x(), px.y()));
    ASSERT_TRUE(exact.hit) << view_name(view);
    EXPECT_LT((exact.lps - p).norm(), 1e-6) << view_name(view);
    EXPECT_NEAR(std::remainder(exact.theta_deg - theta_z.x(), 360.0), 0.0, 1e-6);
    EXPECT_NEAR(exact.z_mm, theta_z.y(), 1e-6);
    // through the centre of the pixel holding it (the click): within half a pixel's footprint
    // across and up the image
    const Eigen::Vector2d click = px.array().floor() + 0.5;
    const SkinHit hit = picker.pick(cam.ray(click.x(), click.y()));
    ASSERT_TRUE(hit.hit) << view_name(view);
    const double half_px_mm = cam.width_mm / cam.width_px / 2;
    const Eigen::Vector2d off = lateral(cam, p, hit.lps);
    EXPECT_LE(off.cwiseAbs().maxCoeff(), half_px_mm + 1e-9)
        << view_name(view) << " " << off.transpose();
    // and its pixel is the clicked one
    EXPECT_TRUE((cam.project(hit.lps) - click).isZero(1e-9)) << view_name(view);
  }
}

TEST(RenderPick, ARenderedSkinPointComesBackThroughItsPixel) {
  // The post-operative skin of the plan view: the centroid of the micropolygon nearest the
  // closed wound's centre, which the solver moved, is a point of the rendered mesh.
  const TriMesh& post = skin().post;
  const MeshRayCaster caster(post);
  const Camera cam = standard_camera(View::Plan, bumpy(), skin(), kW, kH);
  const auto centroid = [](const TriMesh& m, Eigen::Index f) -> Eigen::Vector3d {
    return (m.V.row(m.F(f, 0)) + m.V.row(m.F(f, 1)) + m.V.row(m.F(f, 2))).transpose() / 3.0;
  };
  Eigen::Index best = -1;
  for (Eigen::Index f = 0; f < post.F.rows(); ++f)
    if (skin().face_part[f] == SkinPart::Micropolygon &&
        (best < 0 || (centroid(post, f) - skin().mesh_centre_lps).norm() <
                         (centroid(post, best) - skin().mesh_centre_lps).norm()))
      best = f;
  ASSERT_GE(best, 0);
  const Eigen::Vector3d p = centroid(post, best);
  ASSERT_GT((p - centroid(skin().pre, best)).norm(), 0.1) << "the wound's skin moved";
  const Eigen::Vector2d px = cam.project(p);
  const auto exact = caster.first_hit(cam.ray(px.x(), px.y()));
  ASSERT_TRUE(exact);
  EXPECT_EQ(exact->face, best);
  EXPECT_LT((exact->point - p).norm(), 1e-6);
  const Eigen::Vector2d click = px.array().floor() + 0.5;
  const auto hit = caster.first_hit(cam.ray(click.x(), click.y()));
  ASSERT_TRUE(hit);
  const Eigen::Vector2d off = lateral(cam, p, hit->point);
  EXPECT_LE(off.cwiseAbs().maxCoeff(), cam.width_mm / cam.width_px / 2 + 1e-9) << off.transpose();
  // The renderer shaded the same triangle at that pixel, at the same depth.
  const PixelHits hits = pixel_hits(post, cam);
  const std::size_t i = static_cast<std::size_t>(std::floor(px.y())) * kW + std::floor(px.x());
  ASSERT_GE(hits.face[i], 0);
  EXPECT_LT(distance_to_face(post, hits.face[i], hit->point), 1e-3);
  EXPECT_NEAR(hits.depth_mm[i], cam.depth_mm(hit->point), 1e-3);
}

TEST(RenderPick, TheRendererAndPickingMeetTheSameTriangleAtEveryPixel) {
  RenderOptions one;
  one.samples_per_side = 1;  // the one sample of each pixel is its centre
  const TriMesh& post = skin().post;
  const MeshRayCaster caster(post);
  const std::vector<Camera> cams{
      standard_camera(View::Front, bumpy(), skin(), kW, kH),
      standard_camera(View::Plan, bumpy(), skin(), kW, kH),
      Camera::look_at({250, -250, 60}, {0, 0, 10}, {0, 0, 1}, 40, kW, kH)};
  for (const Camera& cam : cams) {
    const std::string what = cam.projection == Projection::Perspective
                                 ? "perspective"
                                 : cat("orthographic along ", cam.forward.transpose());
    const PixelHits hits = pixel_hits(post, cam);
    ASSERT_EQ(hits.width, kW);
    ASSERT_EQ(hits.height, kH);
    const RgbImage img = render_image(post, skin().color, cam, one);
    const std::array<int, 3> bg{31, 31, 36};  // RenderOptions::background × 255, rounded
    int both = 0, neighbour = 0, through_edge = 0, one_missed = 0, wrong_background = 0;
    double worst_depth = 0;
    for (int y = 0; y < kH; ++y)
      for (int x = 0; x < kW; ++x) {
        const std::size_t i = static_cast<std::size_t>(y) * kW + x;
        const int face = hits.face[i];
        // the image shows the background exactly where the renderer's ray met nothing
        const bool is_bg =
            img.rgb[3 * i] == bg[0] && img.rgb[3 * i + 1] == bg[1] && img.rgb[3 * i + 2] == bg[2];
        wrong_background += is_bg != (face < 0);
        const auto h = caster.first_hit(cam.ray(x + 0.5, y + 0.5));
        if (!h || face < 0) {
          one_missed += bool(h) != (face >= 0);
          continue;
        }
        ++both;
        if (h->face == face || distance_to_face(post, face, h->point) < 1e-3) {
          // the same triangle, or a neighbour across the edge or vertex the ray passes through
          neighbour += h->face != face;
          worst_depth = std::max(worst_depth, std::abs(hits.depth_mm[i] - cam.depth_mm(h->point)));
          continue;
        }
        // Otherwise Embree's single-precision test let a ray through an edge of the triangle
        // picking met, on to a farther one (rare since the scene is built in robust mode).
        ++through_edge;
        EXPECT_LT(distance_to_boundary(post, h->face, h->point), 1e-4)
            << what << " pixel " << x << "," << y;
        EXPECT_GT(hits.depth_mm[i], cam.depth_mm(h->point)) << what << " pixel " << x << "," << y;
      }
    EXPECT_GT(both, kW * kH / 3) << what;
    EXPECT_EQ(wrong_background, 0) << what;
    EXPECT_EQ(one_missed, 0) << what;
    // measured: one pixel in the three views of 48 000 pixels each (the perspective one)
    EXPECT_LE(through_edge, 2) << what;
    EXPECT_LE(neighbour, 2) << what;
    EXPECT_LT(worst_depth, 1e-3) << what;
  }
}
