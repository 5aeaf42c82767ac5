// Overlays: projection into the image, the displacement colour map and bar, the plan's lines.
#include <gtest/gtest.h>

#include <cmath>

#include "caps/core/error.hpp"
#include "caps/render/overlay.hpp"
#include "caps/volume/image_io.hpp"

using namespace caps;
using namespace caps::render;

TEST(Overlay, ProjectionMatchesTheOrthographicCamera) {
  Camera cam;
  cam.centre = {10, 20, 30};
  cam.forward = {0, 1, 0};  // looking posterior: the patient's face
  cam.up = {0, 0, 1};
  cam.width_mm = 200;
  RenderOptions o;
  o.width = 400;
  o.height = 300;
  const Eigen::Vector2d c = project(cam, o, cam.centre);
  EXPECT_NEAR(c.x(), 200, 1e-9);
  EXPECT_NEAR(c.y(), 150, 1e-9);
  // 50 mm up is 100 pixels up; right = forward x up = +y x +z = +x (the patient's left).
  const Eigen::Vector2d up = project(cam, o, cam.centre + Eigen::Vector3d(0, 0, 50));
  EXPECT_NEAR(up.y(), 50, 1e-9);
  const Eigen::Vector2d right = project(cam, o, cam.centre + Eigen::Vector3d(25, 0, 0));
  EXPECT_NEAR(right.x(), 250, 1e-9);
  // Depth does not move a point in an orthographic view.
  const Eigen::Vector2d deep = project(cam, o, cam.centre + Eigen::Vector3d(0, 80, 0));
  EXPECT_NEAR(deep.x(), 200, 1e-9);
}

TEST(Overlay, DisplacementColoursSpanTheScale) {
  SkinSurfaces s;
  s.pre.V = Eigen::MatrixX3d::Zero(3, 3);
  s.post.V = s.pre.V;
  s.post.V(1, 0) = 2.0;  // 2 mm
  s.post.V(2, 2) = 4.0;  // 4 mm, the largest
  double top = 0;
  const Eigen::MatrixX3d c = displacement_colors(s, 0, top);
  EXPECT_DOUBLE_EQ(top, 4.0);
  EXPECT_TRUE(c.row(0).isApprox(viridis(0.0).transpose()));
  EXPECT_TRUE(c.row(1).isApprox(viridis(0.5).transpose()));
  EXPECT_TRUE(c.row(2).isApprox(viridis(1.0).transpose()));
  displacement_colors(s, 8.0, top);
  EXPECT_DOUBLE_EQ(top, 8.0);
}

TEST(Overlay, ColourBarAndLinesDrawOnlyWhereTheyShould) {
  RgbImage img;
  img.width = 300;
  img.height = 200;
  img.rgb.assign(std::size_t(300) * 200 * 3, 30);
  const RgbImage blank = img;
  draw_color_bar(img, 5.0, "mm", "displacement");
  // The left half is untouched; the bar's column has viridis colours, yellow on top.
  for (int y = 0; y < 200; ++y)
    for (int x = 0; x < 100; ++x)
      ASSERT_EQ(img.rgb[(std::size_t(y) * 300 + x) * 3], blank.rgb[(std::size_t(y) * 300 + x) * 3]);
  const int bar_x = static_cast<int>(300 - std::max(12.0, 0.025 * 300) - 0.12 * 300 + 3);
  const int top_y = static_cast<int>(0.5 * (200 - 0.55 * 200)) + 1;
  const std::uint8_t* top = &img.rgb[(std::size_t(top_y) * 300 + bar_x) * 3];
  EXPECT_GT(top[0], 200);  // viridis(1) is yellow: (253, 231, 37)
  EXPECT_GT(top[1], 200);
  EXPECT_LT(top[2], 90);
  EXPECT_THROW(draw_color_bar(img, 0.0, "mm", "x"), InvalidInput);
  // A line across the middle of the image changes pixels on it and none far from it.
  Camera cam;
  cam.forward = {0, 1, 0};
  cam.up = {0, 0, 1};
  cam.width_mm = 300;
  RenderOptions o;
  o.width = 300;
  o.height = 200;
  RgbImage lined = blank;
  draw_polylines(lined, cam, o, {{Eigen::Vector3d(-100, 0, 0), Eigen::Vector3d(100, 0, 0)}});
  int changed_on = 0, changed_off = 0;
  for (int x = 60; x < 240; ++x) changed_on += lined.rgb[(std::size_t(100) * 300 + x) * 3] != 30;
  for (int x = 0; x < 300; ++x) changed_off += lined.rgb[(std::size_t(20) * 300 + x) * 3] != 30;
  EXPECT_GT(changed_on, 60);  // dashed: most, not all
  EXPECT_EQ(changed_off, 0);
}
