#pragma once
// An Embree 3 scene of one triangle mesh (internal to caps::render). Embree works in float: the
// vertices are stored relative to `origin` (LPS mm) to keep precision near it.

#include <embree3/rtcore.h>

#include <memory>

#include "caps/core/mesh.hpp"

namespace caps::render::detail {

struct DeviceDeleter {
  void operator()(RTCDeviceTy* d) const { rtcReleaseDevice(d); }
};
struct SceneDeleter {
  void operator()(RTCSceneTy* s) const { rtcReleaseScene(s); }
};

/// The committed scene of `mesh` (V #V×3 LPS mm, F #F×3), vertices shifted by -origin.
struct EmbreeScene {
  std::unique_ptr<RTCDeviceTy, DeviceDeleter> device;
  std::unique_ptr<RTCSceneTy, SceneDeleter> scene;
  EmbreeScene(const TriMesh& mesh, const Eigen::Vector3d& origin);
};

/// A ray from `org` along `dir` (both relative to the scene's origin), tnear 0, tfar +inf.
RTCRayHit make_ray(const Eigen::Vector3d& org, const Eigen::Vector3d& dir);

}  // namespace caps::render::detail
