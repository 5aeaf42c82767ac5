// Overlays: projection into the image, the displacement colour map and bar, the plan's lines.
// The tension map is tested in test_render_tension.cpp.
#include <gtest/gtest.h>

#include <cmath>

#include "caps/core/error.hpp"
#include "caps/render/overlay.hpp"
#include "caps/image/colormap.hpp"
#include "caps/image/image_io.hpp"

using namespace caps;
using namespace caps::render;

TEST(Overlay, ProjectionMatchesTheOrthographicCamera) {
  Camera cam;
  cam.target = {10, 20, 30};
  cam.forward = {0, 1, 0};  // looking posterior: the patient's face
  cam.up = {0, 0, 1};
  cam.width_mm = 200;
  cam.width_px = 400;
  cam.height_px = 300;
  const Eigen::Vector2d c = cam.project(cam.target);
  EXPECT_NEAR(c.x(), 200, 1e-9);
  EXPECT_NEAR(c.y(), 150, 1e-9);
  // 50 mm up is 100 pixels up; right = forward x up = +y x +z = +x (the patient's left).
  const Eigen::Vector2d up = cam.project(cam.target + Eigen::Vector3d(0, 0, 50));
  EXPECT_NEAR(up.y(), 50, 1e-9);
  const Eigen::Vector2d right = cam.project(cam.target + Eigen::Vector3d(25, 0, 0));
  EXPECT_NEAR(right.x(), 250, 1e-9);
  // Depth does not move a point in an orthographic view.
  const Eigen::Vector2d deep = cam.project(cam.target + Eigen::Vector3d(0, 80, 0));
  EXPECT_NEAR(deep.x(), 200, 1e-9);
}

TEST(Overlay, DisplacementColoursSpanTheScale) {
  SkinSurfaces s;
  s.pre.V = Eigen::MatrixX3d::Zero(3, 3);
  s.post.V = s.pre.V;
  s.post.V(1, 0) = 2.0;  // 2 mm
  s.post.V(2, 2) = 4.0;  // 4 mm, the largest
  const ScalarMap m = displacement_map(s);
  EXPECT_EQ(m.name, "displacement");
  EXPECT_EQ(m.unit, "mm");
  EXPECT_DOUBLE_EQ(m.max_value, 4.0);
  EXPECT_DOUBLE_EQ(m.value[1], 2.0);
  const Eigen::MatrixX3d c = scalar_colors(m.value, m.max_value);
  EXPECT_TRUE(c.row(0).isApprox(viridis(0.0).transpose()));
  EXPECT_TRUE(c.row(1).isApprox(viridis(0.5).transpose()));
  EXPECT_TRUE(c.row(2).isApprox(viridis(1.0).transpose()));
  EXPECT_DOUBLE_EQ(displacement_map(s, 8.0).max_value, 8.0);
  // No displacement at all: a 0 .. 1 mm scale, every vertex the bottom colour.
  s.post.V = s.pre.V;
  EXPECT_DOUBLE_EQ(displacement_map(s).max_value, 1.0);
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
  // A title of two lines too wide for the panel and a note: the text is moved left to stay whole
  // (pixels change left of the bar's usual panel but not in the left third), the note is drawn
  // under the bar, and nothing is drawn under the bar without one.
  RgbImage noted = blank, plain = blank;
  draw_color_bar(noted, 37.0, "kPa", "max principal stress\n(skin tension), kPa", "\u2264 0 = compression");
  draw_color_bar(plain, 37.0, "kPa", "max principal stress\n(skin tension), kPa");
  const int panel_x = static_cast<int>(300 - std::max(12.0, 0.025 * 300) - 0.12 * 300 - 0.4 * 12);
  int moved = 0, far = 0, note = 0, no_note = 0;
  const int bar_bottom = static_cast<int>(0.5 * (200 - 0.55 * 200) + 0.55 * 200);
  for (int y = 0; y < 200; ++y)
    for (int x = 0; x < 300; ++x) {
      const bool changed = noted.rgb[(std::size_t(y) * 300 + x) * 3] != 30;
      if (x < panel_x - 20 && y < 50 && changed) ++moved;
      if (x < 100 && changed) ++far;
      if (y > bar_bottom + 6 && x > 150 && noted.rgb[(std::size_t(y) * 300 + x) * 3] < 100 &&
          noted.rgb[(std::size_t(y) * 300 + x) * 3] != 30)
        ++note;
      if (y > bar_bottom + 6 && x > 150 && plain.rgb[(std::size_t(y) * 300 + x) * 3] < 100 &&
          plain.rgb[(std::size_t(y) * 300 + x) * 3] != 30)
        ++no_note;
    }
  EXPECT_GT(moved, 20);
  EXPECT_EQ(far, 0);
  EXPECT_GT(note, 20);  // dark text on the white panel
  EXPECT_EQ(no_note, 0);
  // A line across the middle of the image changes pixels on it and none far from it.
  Camera cam;
  cam.forward = {0, 1, 0};
  cam.up = {0, 0, 1};
  cam.width_mm = 300;
  cam.width_px = 300;
  cam.height_px = 200;
  RgbImage lined = blank;
  draw_polylines(lined, cam, {{Eigen::Vector3d(-100, 0, 0), Eigen::Vector3d(100, 0, 0)}});
  int changed_on = 0, changed_off = 0;
  for (int x = 60; x < 240; ++x) changed_on += lined.rgb[(std::size_t(100) * 300 + x) * 3] != 30;
  for (int x = 0; x < 300; ++x) changed_off += lined.rgb[(std::size_t(20) * 300 + x) * 3] != 30;
  EXPECT_GT(changed_on, 60);  // dashed: most, not all
  EXPECT_EQ(changed_off, 0);
}
