#include "embree_scene.hpp"

#include "caps/core/error.hpp"

#include <limits>

namespace caps::render::detail {

EmbreeScene::EmbreeScene(const TriMesh& mesh, const Eigen::Vector3d& origin) {
  device.reset(rtcNewDevice(nullptr));
  if (!device) throw Error("render: Embree could not create a device");
  scene.reset(rtcNewScene(device.get()));
  // watertight intersection: a ray through an edge shared by two triangles meets one of them
  // rather than slipping through to a farther surface (a speckle of the back of the head)
  rtcSetSceneFlags(scene.get(), RTC_SCENE_FLAG_ROBUST);
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
}

RTCRayHit make_ray(const Eigen::Vector3d& org, const Eigen::Vector3d& dir) {
  RTCRayHit rh;
  rh.ray.org_x = static_cast<float>(org.x());
  rh.ray.org_y = static_cast<float>(org.y());
  rh.ray.org_z = static_cast<float>(org.z());
  rh.ray.dir_x = static_cast<float>(dir.x());
  rh.ray.dir_y = static_cast<float>(dir.y());
  rh.ray.dir_z = static_cast<float>(dir.z());
  rh.ray.tnear = 0.0f;
  rh.ray.tfar = std::numeric_limits<float>::infinity();
  rh.ray.mask = 0xFFFFFFFFu;
  rh.ray.flags = 0;
  rh.ray.time = 0.0f;
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  return rh;
}

}  // namespace caps::render::detail
