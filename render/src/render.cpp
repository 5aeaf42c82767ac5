#include "caps/render/render.hpp"

#include "caps/core/atomic_output.hpp"
#include "caps/core/error.hpp"
#include "caps/core/units.hpp"
#include "caps/image/image_io.hpp"
#include "caps/surface/patient_model.hpp"

#include <embree3/rtcore.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>

namespace caps::render {
namespace {

struct DeviceDeleter {
  void operator()(RTCDeviceTy* d) const { rtcReleaseDevice(d); }
};
struct SceneDeleter {
  void operator()(RTCSceneTy* s) const { rtcReleaseScene(s); }
};

Eigen::MatrixX3d vertex_normals(const TriMesh& m) {
  Eigen::MatrixX3d N = Eigen::MatrixX3d::Zero(m.V.rows(), 3);
  for (Eigen::Index f = 0; f < m.F.rows(); ++f) {
    const Eigen::Vector3d a = m.V.row(m.F(f, 0)), b = m.V.row(m.F(f, 1)), c = m.V.row(m.F(f, 2));
    const Eigen::Vector3d n = (b - a).cross(c - a);  // area-weighted
    for (int k = 0; k < 3; ++k) N.row(m.F(f, k)) += n.transpose();
  }
  for (Eigen::Index v = 0; v < N.rows(); ++v) {
    const double l = N.row(v).norm();
    if (l > 0) N.row(v) /= l;
  }
  return N;
}

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

Camera standard_camera(View view, const PatientModel& model, const SkinSurfaces& skin,
                       double aspect) {
  const CylinderAxis& ax = model.axis();
  Camera cam;
  cam.up = ax.direction;
  if (view == View::Plan) {
    const CylindricalPoint c = model.to_cylindrical(skin.mesh_centre_lps);
    const Eigen::Vector3d n = model.skin_normal(c.theta_deg, c.z_mm);
    cam.forward = -n;
    if (std::abs(n.dot(cam.up)) > 0.95) cam.up = ax.front;
    cam.centre = model.skin_point(c.theta_deg, c.z_mm);
    cam.width_mm = std::max(1.6 * 2.0 * skin.mesh_radius_mm, 10.0) * std::max(1.0, aspect);
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
  cam.centre = mean + (mid.x() - mean.dot(right)) * right + (mid.y() - mean.dot(up)) * up;
  cam.width_mm = 1.08 * std::max(hi.x() - lo.x(), (hi.y() - lo.y()) * aspect);
  return cam;
}

RgbImage render_image(const TriMesh& mesh, const Eigen::MatrixX3d& color, const Camera& camera,
                      const RenderOptions& o) {
  if (mesh.V.rows() == 0 || mesh.F.rows() == 0)
    throw InvalidInput("render: the mesh is empty");
  if (color.rows() != mesh.V.rows())
    throw InvalidInput(cat("render: ", color.rows(), " colours for ", mesh.V.rows(), " vertices"));
  if (o.width < 1 || o.height < 1 || o.width > 16384 || o.height > 16384 ||
      o.samples_per_side < 1 || o.samples_per_side > 8)
    throw InvalidInput(cat("render: image size ", o.width, "x", o.height, " (1..16384) or ",
                           o.samples_per_side, " samples per side (1..8) out of range"));
  if (!(camera.width_mm > 0) || !(camera.forward.norm() > 0))
    throw InvalidInput("render: the camera needs a positive width and a viewing direction");

  // Embree works in float: shift the scene to the camera's centre to keep precision.
  const Eigen::Vector3d origin = camera.centre;
  std::unique_ptr<RTCDeviceTy, DeviceDeleter> device(rtcNewDevice(nullptr));
  if (!device) throw Error("render: Embree could not create a device");
  std::unique_ptr<RTCSceneTy, SceneDeleter> scene(rtcNewScene(device.get()));
  RTCGeometry geom = rtcNewGeometry(device.get(), RTC_GEOMETRY_TYPE_TRIANGLE);
  auto* vb = static_cast<float*>(rtcSetNewGeometryBuffer(
      geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), mesh.V.rows()));
  auto* ib = static_cast<unsigned*>(rtcSetNewGeometryBuffer(
      geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(unsigned), mesh.F.rows()));
  for (Eigen::Index v = 0; v < mesh.V.rows(); ++v)
    for (int c = 0; c < 3; ++c) vb[3 * v + c] = static_cast<float>(mesh.V(v, c) - origin[c]);
  for (Eigen::Index f = 0; f < mesh.F.rows(); ++f)
    for (int c = 0; c < 3; ++c) ib[3 * f + c] = static_cast<unsigned>(mesh.F(f, c));
  rtcCommitGeometry(geom);
  rtcAttachGeometry(scene.get(), geom);
  rtcReleaseGeometry(geom);
  rtcSetSceneBuildQuality(scene.get(), RTC_BUILD_QUALITY_HIGH);
  rtcCommitScene(scene.get());

  const Eigen::MatrixX3d N = vertex_normals(mesh);
  const Eigen::Vector3d fwd = camera.forward.normalized();
  const Eigen::Vector3d up = (camera.up - camera.up.dot(fwd) * fwd).normalized();
  const Eigen::Vector3d right = fwd.cross(up);
  const double px = camera.width_mm / o.width;
  const double back = 2.0 * (mesh.V.rowwise() - origin.transpose()).rowwise().norm().maxCoeff() + 1.0;
  // a head light (from the viewer) and a key light from the upper left of the image
  const Eigen::Vector3d head = -fwd;
  const Eigen::Vector3d key = (-fwd + 0.6 * up - 0.5 * right).normalized();
  const int s = o.samples_per_side;

  RgbImage img;
  img.width = o.width;
  img.height = o.height;
  img.rgb.assign(static_cast<std::size_t>(o.width) * o.height * 3, 0);
  tbb::parallel_for(tbb::blocked_range<int>(0, o.height), [&](const tbb::blocked_range<int>& rows) {
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    for (int y = rows.begin(); y < rows.end(); ++y)
      for (int x = 0; x < o.width; ++x) {
        Eigen::Vector3d sum = Eigen::Vector3d::Zero();
        for (int sy = 0; sy < s; ++sy)
          for (int sx = 0; sx < s; ++sx) {
            const double u = (x + (sx + 0.5) / s - 0.5 * o.width) * px;
            const double v = (0.5 * o.height - (y + (sy + 0.5) / s)) * px;
            const Eigen::Vector3d org = u * right + v * up - back * fwd;
            RTCRayHit rh;
            rh.ray.org_x = static_cast<float>(org.x());
            rh.ray.org_y = static_cast<float>(org.y());
            rh.ray.org_z = static_cast<float>(org.z());
            rh.ray.dir_x = static_cast<float>(fwd.x());
            rh.ray.dir_y = static_cast<float>(fwd.y());
            rh.ray.dir_z = static_cast<float>(fwd.z());
            rh.ray.tnear = 0.0f;
            rh.ray.tfar = std::numeric_limits<float>::infinity();
            rh.ray.mask = 0xFFFFFFFFu;
            rh.ray.flags = 0;
            rh.ray.time = 0.0f;
            rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
            rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
            rtcIntersect1(scene.get(), &ctx, &rh);
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
            if (n.dot(fwd) > 0) n = -n;  // two-sided
            const Eigen::Vector3d albedo = b0 * color.row(i0) + b1 * color.row(i1) + b2 * color.row(i2);
            const double light = o.ambient + 0.55 * std::max(0.0, n.dot(head)) +
                                 0.35 * std::max(0.0, n.dot(key));
            sum += albedo * light;
          }
        sum /= double(s * s);
        for (int c = 0; c < 3; ++c)
          img.rgb[(static_cast<std::size_t>(y) * o.width + x) * 3 + c] =
              static_cast<std::uint8_t>(std::lround(std::clamp(sum[c], 0.0, 1.0) * 255.0));
      }
  });
  return img;
}

std::vector<std::filesystem::path> render_views(const PatientModel& model,
                                                const SkinSurfaces& skin,
                                                const std::vector<View>& views,
                                                const RenderOptions& options,
                                                const std::filesystem::path& dir) {
  std::vector<std::filesystem::path> written;
  const double aspect = double(options.width) / options.height;
  for (View v : views) {
    const Camera cam = standard_camera(v, model, skin, aspect);
    for (const bool post : {false, true}) {
      const auto path = dir / cat(post ? "post_" : "pre_", view_name(v), ".png");
      write_png(path, render_image(post ? skin.post : skin.pre, skin.color, cam, options));
      written.push_back(path);
    }
  }
  return written;
}

}  // namespace caps::render
