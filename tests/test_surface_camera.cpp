// The one camera (surface/camera.hpp): the pixel convention (pixel (0, 0) is the top-left
// corner, centres at half-integers) worked by hand for an orthographic and a perspective camera,
// project(ray(pixel)) == pixel for both, and the checks on a bad camera.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>

#include "caps/core/error.hpp"
#include "caps/core/units.hpp"
#include "caps/surface/camera.hpp"

using namespace caps;

namespace {

// Looking posterior at the face from 600 mm: right = forward x up = +y x +z = +x.
Camera frontal_orthographic() {
  Camera c;
  c.target = {10, 20, 30};
  c.forward = {0, 1, 0};
  c.up = {0, 0, 1};
  c.width_mm = 200;
  c.width_px = 400;
  c.height_px = 300;
  return c;
}

// An oblique view with an up vector that is not orthogonal to forward, a non-square image.
Camera oblique(Projection projection) {
  Camera c;
  c.projection = projection;
  c.target = {12.5, -40, 75};
  c.forward = Eigen::Vector3d(0.6, 1.0, -0.3);
  c.up = Eigen::Vector3d(0.1, 0.2, 1.0);
  c.distance_mm = 450;
  c.width_mm = 180;
  c.fov_y_deg = 35;
  c.width_px = 300;
  c.height_px = 170;
  return c;
}

}  // namespace

TEST(Camera, OrthographicPixelConventionByHand) {
  const Camera c = frontal_orthographic();  // 0.5 mm per pixel
  EXPECT_DOUBLE_EQ(c.pixel_scale(), 0.5);
  const CameraFrame f = c.frame();
  EXPECT_TRUE(f.right.isApprox(Eigen::Vector3d(1, 0, 0)));
  // The target is at the image's centre, (W/2, H/2): the corner shared by the four middle pixels.
  EXPECT_TRUE(c.project(c.target).isApprox(Eigen::Vector2d(200, 150)));
  // 50 mm up is 100 pixels up (y grows downwards); 25 mm to the patient's left 50 pixels right.
  EXPECT_NEAR(c.project(c.target + Eigen::Vector3d(0, 0, 50)).y(), 50, 1e-9);
  EXPECT_NEAR(c.project(c.target + Eigen::Vector3d(25, 0, 0)).x(), 250, 1e-9);
  // Depth does not move a point.
  EXPECT_TRUE(c.project(c.target + Eigen::Vector3d(0, 80, 0)).isApprox(Eigen::Vector2d(200, 150)));
  // Pixel (0, 0)'s top-left corner is 100 mm left of and 75 mm above the target; its centre is
  // (0.5, 0.5), a quarter millimetre further in; the rays start 600 mm before the target.
  const Ray corner = c.ray(0, 0);
  EXPECT_TRUE(corner.origin.isApprox(Eigen::Vector3d(10 - 100, 20 - 600, 30 + 75)));
  EXPECT_TRUE(corner.direction.isApprox(Eigen::Vector3d(0, 1, 0)));
  EXPECT_TRUE(c.ray(0.5, 0.5).origin.isApprox(Eigen::Vector3d(10 - 99.75, 20 - 600, 30 + 74.75)));
  // The bottom-right corner of the last pixel is (W, H).
  EXPECT_TRUE(c.ray(400, 300).origin.isApprox(Eigen::Vector3d(10 + 100, 20 - 600, 30 - 75)));
  EXPECT_TRUE(c.eye().isApprox(Eigen::Vector3d(10, 20 - 600, 30)));
  EXPECT_DOUBLE_EQ(c.depth_mm(c.target), 600);
  EXPECT_DOUBLE_EQ(c.depth_mm(Eigen::Vector3d(0, 0, 0)), 580);
}

TEST(Camera, PerspectivePixelConventionByHand) {
  // 90 degrees vertically over 100 pixels: the focal length is 50 pixels.
  const Camera c = Camera::look_at({0, -600, 0}, {0, 0, 0}, {0, 0, 1}, 90, 200, 100);
  EXPECT_EQ(c.projection, Projection::Perspective);
  EXPECT_NEAR(c.pixel_scale(), 50, 1e-12);
  EXPECT_DOUBLE_EQ(c.distance_mm, 600);
  EXPECT_TRUE(c.eye().isApprox(Eigen::Vector3d(0, -600, 0)));
  EXPECT_TRUE(c.project({0, 0, 0}).isApprox(Eigen::Vector2d(100, 50)));
  // 30 mm to the left at 600 mm depth: 50 * 30 / 600 = 2.5 pixels right; half as far at twice
  // the depth.
  EXPECT_NEAR(c.project({30, 0, 0}).x(), 102.5, 1e-9);
  EXPECT_NEAR(c.project({30, 600, 0}).x(), 101.25, 1e-9);
  // 45 degrees up is the top edge, y = 0; the ray through (100, 0) goes up at 45 degrees.
  EXPECT_NEAR(c.project({0, 0, 600}).y(), 0, 1e-9);
  const Ray top = c.ray(100, 0);
  EXPECT_TRUE(top.origin.isApprox(Eigen::Vector3d(0, -600, 0)));
  EXPECT_TRUE(top.direction.isApprox(Eigen::Vector3d(0, 1, 1).normalized()));
  // The pinhole formula of the old picking camera: slope (2x/W - 1) tan(fov/2) W/H across,
  // (1 - 2y/H) tan(fov/2) up.
  for (const Eigen::Vector2d px :
       {Eigen::Vector2d(0, 0), Eigen::Vector2d(37.5, 80.25), Eigen::Vector2d(200, 100)}) {
    const double t = std::tan(deg_to_rad(45.0));
    const Eigen::Vector3d d =
        Eigen::Vector3d((2 * px.x() / 200 - 1) * t * 2.0, 1.0, (1 - 2 * px.y() / 100) * t)
            .normalized();
    EXPECT_LT((c.ray(px.x(), px.y()).direction - d).norm(), 1e-12) << px.transpose();
  }
  // Behind the eye there is no pixel.
  EXPECT_THROW(c.project({0, -700, 0}), InvalidInput);
}

TEST(Camera, ProjectOfRayIsThePixelForBothProjections) {
  for (const Projection p : {Projection::Orthographic, Projection::Perspective}) {
    const Camera c = oblique(p);
    double worst = 0;
    for (double y = 0; y <= 170; y += 8.5)
      for (double x = 0; x <= 300; x += 12.25) {
        const Ray r = c.ray(x, y);
        EXPECT_NEAR(r.direction.norm(), 1.0, 1e-12);
        // every point of the ray in front of the eye projects to the pixel
        for (const double t : {1.0, 250.0, 450.0, 900.0})
          worst = std::max(worst,
                           (c.project(r.origin + t * r.direction) - Eigen::Vector2d(x, y)).norm());
      }
    EXPECT_LT(worst, 1e-9) << (p == Projection::Orthographic ? "orthographic" : "perspective");
    // and the other way: the ray through a point's pixel passes through the point
    const Eigen::Vector3d q(30, 10, 60);
    const Eigen::Vector2d px = c.project(q);
    const Ray r = c.ray(px.x(), px.y());
    const Eigen::Vector3d d = r.direction.normalized();
    const Eigen::Vector3d off = (q - r.origin) - (q - r.origin).dot(d) * d;
    EXPECT_LT(off.norm(), 1e-9);
    EXPECT_GT((q - r.origin).dot(d), 0) << "the point lies in front of the ray's origin";
    // the depth of the ray's origin: the eye's plane
    EXPECT_NEAR(c.depth_mm(r.origin), 0, 1e-9);
  }
}

TEST(Camera, TheImagePlaneAndTheFrameAreOrthonormalAndUpright) {
  for (const Projection p : {Projection::Orthographic, Projection::Perspective}) {
    const Camera c = oblique(p);
    const CameraFrame f = c.frame();
    EXPECT_NEAR(f.right.norm(), 1, 1e-12);
    EXPECT_NEAR(f.up.norm(), 1, 1e-12);
    EXPECT_NEAR(f.right.dot(f.up), 0, 1e-12);
    EXPECT_NEAR(f.up.dot(f.forward), 0, 1e-12);
    EXPECT_TRUE(f.forward.cross(f.up).isApprox(f.right));  // right-handed with -forward
    EXPECT_TRUE(f.right.cross(f.up).isApprox(-f.forward));
    EXPECT_GT(f.up.dot(c.up), 0);
    // a point above the target is higher in the image (smaller y), one to the right larger x
    const Eigen::Vector2d mid = c.project(c.target);
    EXPECT_TRUE(mid.isApprox(Eigen::Vector2d(150, 85)));
    EXPECT_LT(c.project(c.target + 10 * f.up).y(), mid.y());
    EXPECT_GT(c.project(c.target + 10 * f.right).x(), mid.x());
  }
}

TEST(Camera, BadCamerasThrow) {
  Camera c;
  EXPECT_NO_THROW(c.validate());
  c.forward = Eigen::Vector3d::Zero();
  EXPECT_THROW(c.ray(0, 0), InvalidInput);
  c = Camera();
  c.up = Eigen::Vector3d(0, -2, 0);  // parallel to forward
  EXPECT_THROW(c.project(Eigen::Vector3d::Zero()), InvalidInput);
  c = Camera();
  c.width_mm = 0;
  EXPECT_THROW(c.validate(), InvalidInput);
  c.projection = Projection::Perspective;  // width_mm does not matter then
  EXPECT_NO_THROW(c.validate());
  c.fov_y_deg = 180;
  EXPECT_THROW(c.validate(), InvalidInput);
  c = Camera();
  c.height_px = 0;
  EXPECT_THROW(c.validate(), InvalidInput);
  c = Camera();
  c.distance_mm = -1;
  EXPECT_THROW(c.validate(), InvalidInput);
  c = Camera();
  c.target.x() = std::nan("");
  EXPECT_THROW(c.validate(), InvalidInput);
  EXPECT_THROW(Camera::look_at({1, 2, 3}, {1, 2, 3}, {0, 0, 1}, 30, 64, 64), InvalidInput);
}
