#include "caps/render/render.hpp"

#include "caps/core/atomic_output.hpp"
#include "caps/core/error.hpp"
#include "caps/core/units.hpp"
#include "caps/image/image_io.hpp"
#include "caps/render/animation.hpp"
#include "caps/surface/patient_model.hpp"
#include "embree_scene.hpp"

#include <embree3/rtcore.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>

namespace caps::render {
namespace {

// Twice the radius of the sphere about `centre` that holds every vertex, plus 1 mm (mm): a point
// this far from the centre is outside the mesh.
double outside_distance_mm(const TriMesh& m, const Eigen::Vector3d& centre) {
  return 2.0 * (m.V.rowwise() - centre.transpose()).rowwise().norm().maxCoeff() + 1.0;
}

// The Embree scene of one mesh seen by one camera, and the camera's rays in it. Embree works in
// float: the scene is shifted to the camera's target to keep precision.
struct Tracer {
  const Camera& camera;  // not owned; outlives the tracer
  CameraFrame frame;
  bool perspective = false;
  double back = 0;  // orthographic rays start this far before the target
  std::unique_ptr<detail::EmbreeScene> embree;

  Tracer(const TriMesh& mesh, const Camera& cam) : camera(cam) {
    if (mesh.V.rows() == 0 || mesh.F.rows() == 0) throw InvalidInput("render: the mesh is empty");
    try {
      camera.validate();
    } catch (const InvalidInput& e) {
      throw InvalidInput(cat("render: ", e.what()));
    }
    frame = camera.frame();
    perspective = camera.projection == Projection::Perspective;
    const Eigen::Vector3d& origin = camera.target;
    // no triangle is behind an orthographic ray's origin
    back = outside_distance_mm(mesh, origin);
    embree = std::make_unique<detail::EmbreeScene>(mesh, origin);
  }

  // The first hit of the ray through pixel (x, y) (Camera::ray, relative to the target).
  RTCRayHit trace(RTCIntersectContext& ctx, double x, double y) const {
    Eigen::Vector3d org, dir;
    ray(x, y, org, dir);
    RTCRayHit rh = detail::make_ray(org, dir);
    rtcIntersect1(embree->scene.get(), &ctx, &rh);
    return rh;
  }

  // The ray through pixel (x, y) in double, relative to the target.
  void ray(double x, double y, Eigen::Vector3d& org, Eigen::Vector3d& dir) const {
    const Eigen::Vector2d q = camera.image_plane(x, y);
    if (perspective) {
      org = -camera.distance_mm * frame.forward;
      dir = (frame.forward + q.x() * frame.right + q.y() * frame.up).normalized();
    } else {
      org = q.x() * frame.right + q.y() * frame.up - back * frame.forward;
      dir = frame.forward;
    }
  }
};

}  // namespace

const char* view_name(View view) {
  switch (view) {
    case View::Front: return "front";
    case View::Oblique: return "oblique";
    case View::Side: return "side";
    case View::Plan: return "plan";
  }
  return "?";
}

View parse_view(const std::string& name) {
  for (View v : {View::Front, View::Oblique, View::Side, View::Plan})
    if (name == view_name(v)) return v;
  throw InvalidInput(cat("view '", name, "': expected front, oblique, side or plan"));
}

Camera standard_camera(View view, const PatientModel& model, const SkinSurfaces& skin, int width_px,
                       int height_px) {
  if (width_px < 1 || height_px < 1)
    throw InvalidInput(cat("render: image size ", width_px, "x", height_px, " must be positive"));
  if (skin.pre.V.rows() == 0) throw InvalidInput("render: the skin to frame is empty");
  const double aspect = double(width_px) / height_px;
  const CylinderAxis& ax = model.axis();
  Camera cam;
  cam.projection = Projection::Orthographic;
  cam.width_px = width_px;
  cam.height_px = height_px;
  cam.up = ax.direction;
  // The eye outside the skin, so that a picking ray from it meets the skin first.
  const auto eye_outside = [&](Camera& c) {
    c.distance_mm = outside_distance_mm(skin.pre, c.target);
  };
  if (view == View::Plan) {
    const CylindricalPoint c = model.to_cylindrical(skin.mesh_centre_lps);
    const Eigen::Vector3d n = model.skin_normal(c.theta_deg, c.z_mm);
    cam.forward = -n;
    if (std::abs(n.dot(cam.up)) > 0.95) cam.up = ax.front;
    cam.target = model.skin_point(c.theta_deg, c.z_mm);
    cam.width_mm = std::max(1.6 * 2.0 * skin.mesh_radius_mm, 10.0) * std::max(1.0, aspect);
    eye_outside(cam);
    return cam;
  }
  const double theta_deg = view == View::Front ? 0.0 : view == View::Oblique ? 45.0 : 90.0;
  cam.forward = -ax.ray(deg_to_rad(theta_deg));
  // frame the whole skin: its extent across and up the image
  const Eigen::Vector3d up = (cam.up - cam.up.dot(cam.forward) * cam.forward).normalized();
  const Eigen::Vector3d right = cam.forward.cross(up);
  Eigen::Vector2d lo(1e300, 1e300), hi(-1e300, -1e300);
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (Eigen::Index v = 0; v < skin.pre.V.rows(); ++v) {
    const Eigen::Vector3d p = skin.pre.V.row(v);
    const Eigen::Vector2d q(p.dot(right), p.dot(up));
    lo = lo.cwiseMin(q);
    hi = hi.cwiseMax(q);
    mean += p;
  }
  mean /= static_cast<double>(skin.pre.V.rows());
  const Eigen::Vector2d mid = 0.5 * (lo + hi);
  cam.target = mean + (mid.x() - mean.dot(right)) * right + (mid.y() - mean.dot(up)) * up;
  cam.width_mm = 1.08 * std::max(hi.x() - lo.x(), (hi.y() - lo.y()) * aspect);
  eye_outside(cam);
  return cam;
}

RgbImage render_image(const TriMesh& mesh, const Eigen::MatrixX3d& color, const Camera& camera,
                      const RenderOptions& o) {
  return render_image(mesh, color, vertex_normals(mesh), camera, o);
}

RgbImage render_image(const TriMesh& mesh, const Eigen::MatrixX3d& color,
                      const Eigen::MatrixX3d& N, const Camera& camera, const RenderOptions& o) {
  if (color.rows() != mesh.V.rows())
    throw InvalidInput(cat("render: ", color.rows(), " colours for ", mesh.V.rows(), " vertices"));
  if (N.rows() != mesh.V.rows())
    throw InvalidInput(cat("render: ", N.rows(), " normals for ", mesh.V.rows(), " vertices"));
  if (o.samples_per_side < 1 || o.samples_per_side > 8)
    throw InvalidInput(
        cat("render: ", o.samples_per_side, " samples per side out of range (1..8)"));
  const Tracer tracer(mesh, camera);
  const CameraFrame& fr = tracer.frame;
  // a head light (from the viewer) and a key light from the upper left of the image
  const Eigen::Vector3d head = -fr.forward;
  const Eigen::Vector3d key = (-fr.forward + 0.6 * fr.up - 0.5 * fr.right).normalized();
  const int s = o.samples_per_side;
  const int W = camera.width_px, H = camera.height_px;

  RgbImage img;
  img.width = W;
  img.height = H;
  img.rgb.assign(static_cast<std::size_t>(W) * H * 3, 0);
  tbb::parallel_for(tbb::blocked_range<int>(0, H), [&](const tbb::blocked_range<int>& rows) {
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    for (int y = rows.begin(); y < rows.end(); ++y)
      for (int x = 0; x < W; ++x) {
        Eigen::Vector3d sum = Eigen::Vector3d::Zero();
        for (int sy = 0; sy < s; ++sy)
          for (int sx = 0; sx < s; ++sx) {
            RTCRayHit rh = tracer.trace(ctx, x + (sx + 0.5) / s, y + (sy + 0.5) / s);
            if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) {
              sum += o.background;
              continue;
            }
            const auto f = static_cast<Eigen::Index>(rh.hit.primID);
            const double b1 = rh.hit.u, b2 = rh.hit.v, b0 = 1.0 - b1 - b2;
            const int i0 = mesh.F(f, 0), i1 = mesh.F(f, 1), i2 = mesh.F(f, 2);
            Eigen::Vector3d n = b0 * N.row(i0) + b1 * N.row(i1) + b2 * N.row(i2);
            if (!(n.norm() > 0)) n = Eigen::Vector3d(rh.hit.Ng_x, rh.hit.Ng_y, rh.hit.Ng_z);
            n.normalize();
            // two-sided: turned towards the viewer (orthographic: the ray's direction is forward)
            const Eigen::Vector3d d(rh.ray.dir_x, rh.ray.dir_y, rh.ray.dir_z);
            if (n.dot(tracer.perspective ? d : fr.forward) > 0) n = -n;
            const Eigen::Vector3d albedo =
                b0 * color.row(i0) + b1 * color.row(i1) + b2 * color.row(i2);
            const double light =
                o.ambient + 0.55 * std::max(0.0, n.dot(head)) + 0.35 * std::max(0.0, n.dot(key));
            sum += albedo * light;
          }
        sum /= double(s * s);
        for (int c = 0; c < 3; ++c)
          img.rgb[(static_cast<std::size_t>(y) * W + x) * 3 + c] =
              static_cast<std::uint8_t>(std::lround(std::clamp(sum[c], 0.0, 1.0) * 255.0));
      }
  });
  return img;
}

PixelHits pixel_hits(const TriMesh& mesh, const Camera& camera) {
  const Tracer tracer(mesh, camera);
  const int W = camera.width_px, H = camera.height_px;
  PixelHits out;
  out.width = W;
  out.height = H;
  out.face.assign(static_cast<std::size_t>(W) * H, -1);
  out.depth_mm.assign(out.face.size(), std::numeric_limits<double>::infinity());
  tbb::parallel_for(tbb::blocked_range<int>(0, H), [&](const tbb::blocked_range<int>& rows) {
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    for (int y = rows.begin(); y < rows.end(); ++y)
      for (int x = 0; x < W; ++x) {
        const RTCRayHit rh = tracer.trace(ctx, x + 0.5, y + 0.5);
        if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) continue;
        const std::size_t i = static_cast<std::size_t>(y) * W + x;
        out.face[i] = static_cast<int>(rh.hit.primID);
        // the hit relative to the target; the eye's plane is distance_mm before it. The ray's
        // parameter is recomputed in double on the triangle's plane: Embree's float t (its
        // watertight test in particular) is good to a few 1e-3 mm at 300 mm only.
        Eigen::Vector3d org, dir;
        tracer.ray(x + 0.5, y + 0.5, org, dir);
        const Eigen::Index f = rh.hit.primID;
        const Eigen::Vector3d a = mesh.V.row(mesh.F(f, 0)).transpose() - camera.target;
        const Eigen::Vector3d n = (mesh.V.row(mesh.F(f, 1)) - mesh.V.row(mesh.F(f, 0)))
                                      .cross(mesh.V.row(mesh.F(f, 2)) - mesh.V.row(mesh.F(f, 0)))
                                      .transpose();
        const double dn = dir.dot(n);
        const double t = std::abs(dn) > 1e-12 * n.norm() ? (a - org).dot(n) / dn : double(rh.ray.tfar);
        out.depth_mm[i] = (org + t * dir).dot(tracer.frame.forward) + camera.distance_mm;
      }
  });
  return out;
}

RgbImage render_skin(const SkinSurfaces& skin, double t, const Eigen::MatrixX3d& color,
                     const Camera& camera, const RenderOptions& options) {
  return render_image(blend_skin(skin, t), color, shading_normals(skin, t), camera, options);
}

std::vector<std::filesystem::path> render_views(const PatientModel& model,
                                                const SkinSurfaces& skin,
                                                const std::vector<View>& views,
                                                const RenderOptions& options,
                                                const std::filesystem::path& dir) {
  std::vector<std::filesystem::path> written;
  for (View v : views) {
    const Camera cam = standard_camera(v, model, skin, options.width, options.height);
    for (const bool post : {false, true}) {
      const auto path = dir / cat(post ? "post_" : "pre_", view_name(v), ".png");
      write_png(path, render_skin(skin, post ? 1.0 : 0.0, skin.color, cam, options));
      written.push_back(path);
    }
  }
  return written;
}

}  // namespace caps::render
