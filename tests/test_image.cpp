// The image module: PNG (RGB and 16-bit grey) round trips, reading by signature, the viridis map,
// and the Canvas drawing known pixels (pixel-aligned shapes are exact, so their colours are known).
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "caps/core/error.hpp"
#include "caps/image/canvas.hpp"
#include "caps/image/colormap.hpp"
#include "caps/image/image_io.hpp"

namespace fs = std::filesystem;
using namespace caps;

namespace {

// A fresh folder for one test, under GoogleTest's temporary directory.
fs::path temp_dir(const std::string& name) {
  const fs::path d = fs::path(::testing::TempDir()) / cat("caps_image_", name, "_", ::getpid());
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

void write_bytes(const fs::path& path, const std::string& bytes) {
  std::ofstream(path, std::ios::binary) << bytes;
}

// The pixel (x, y) as bytes.
std::array<int, 3> px(const RgbImage& im, int x, int y) {
  const std::uint8_t* p = &im.rgb[(std::size_t(y) * im.width + x) * 3];
  return {p[0], p[1], p[2]};
}

const std::array<int, 3> kWhite{255, 255, 255};

}  // namespace

TEST(RgbImage, SetRoundsToTheNearestByteAndClamps) {
  RgbImage im = make_image(2, 1, {0, 0, 0});
  im.set(1, 0, {0.5, 1.7, -0.2});  // 127.5 -> 128, clamped to 255 and 0
  EXPECT_EQ(px(im, 1, 0), (std::array<int, 3>{128, 255, 0}));
  EXPECT_EQ(px(im, 0, 0), (std::array<int, 3>{0, 0, 0}));
  EXPECT_NEAR(im.get(1, 0)[0], 128 / 255.0, 1e-15);
  EXPECT_THROW(make_image(0, 3), InvalidInput);
}

TEST(Png, RgbRoundTripIsExact) {
  const fs::path dir = temp_dir("rgb");
  RgbImage im = make_image(7, 5);
  for (int y = 0; y < 5; ++y)
    for (int x = 0; x < 7; ++x)
      for (int c = 0; c < 3; ++c) im.rgb[(std::size_t(y) * 7 + x) * 3 + c] = std::uint8_t(37 * x + 11 * y + 80 * c);
  write_png(dir / "a.png", im);
  const RgbImage back = read_png(dir / "a.png");
  EXPECT_EQ(back.width, 7);
  EXPECT_EQ(back.height, 5);
  EXPECT_EQ(back.rgb, im.rgb);
  EXPECT_EQ(read_image(dir / "a.png").rgb, im.rgb);  // told apart by its signature
  RgbImage bad = im;
  bad.rgb.pop_back();
  EXPECT_THROW(write_png(dir / "bad.png", bad), InvalidInput);
  EXPECT_FALSE(fs::exists(dir / "bad.png"));
  EXPECT_THROW(read_png(dir / "missing.png"), IoError);
  fs::remove_all(dir);
}

TEST(Png, Grey16RoundTripKeepsEveryBit) {
  const fs::path dir = temp_dir("grey");
  GreyImage g{3, 2, {0, 1, 255, 256, 40000, 65535}};
  write_grey16_png(dir / "g.png", g);
  const GreyImage back = read_grey_png(dir / "g.png");
  EXPECT_EQ(back.width, 3);
  EXPECT_EQ(back.height, 2);
  EXPECT_EQ(back.value, g.value);
  // A colour PNG is not a grey image; a truncated one is damaged; a text file is not a PNG.
  write_png(dir / "rgb.png", make_image(2, 2));
  EXPECT_THROW(read_grey_png(dir / "rgb.png"), InvalidInput);
  std::ifstream in(dir / "g.png", std::ios::binary);
  const std::string png((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  write_bytes(dir / "cut.png", png.substr(0, png.size() / 2));
  write_bytes(dir / "text.png", "not a picture");
  EXPECT_THROW(read_grey_png(dir / "cut.png"), IoError);
  EXPECT_THROW(read_grey_png(dir / "text.png"), InvalidInput);
  EXPECT_THROW(read_grey_png(dir / "missing.png"), IoError);
  fs::remove_all(dir);
}

TEST(ReadImage, RefusesWhatIsNeitherJpegNorPng) {
  const fs::path dir = temp_dir("sig");
  write_bytes(dir / "broken.jpg", "\xff\xd8\xff this is not really a JPEG");
  write_bytes(dir / "notes.txt", "hello");
  for (const char* f : {"broken.jpg", "notes.txt", "missing.jpg"})
    EXPECT_THROW(read_image(dir / f), IoError) << f;
  fs::remove_all(dir);
}

TEST(Colormap, ViridisEndsAndStops) {
  // viridis' first colour is (68, 1, 84), its last (253, 231, 37); the middle is stop 5.
  EXPECT_NEAR(viridis(0.0)[0] * 255, 68, 1e-9);
  EXPECT_NEAR(viridis(0.0)[1] * 255, 1, 1e-9);
  EXPECT_NEAR(viridis(1.0)[0] * 255, 253, 1e-9);
  EXPECT_NEAR(viridis(1.0)[2] * 255, 37, 1e-9);
  EXPECT_LT((viridis(0.5) * 255 - Eigen::Vector3d(33, 145, 140)).norm(), 1e-9);
  // Halfway between stops 0 and 1 is their mean; outside [0, 1] is clamped.
  EXPECT_LT((viridis(0.05) * 255 - Eigen::Vector3d(70, 18.5, 100.5)).norm(), 1e-9);
  EXPECT_EQ(viridis(-3.0), viridis(0.0));
  EXPECT_EQ(viridis(7.0), viridis(1.0));
}

TEST(Canvas, FilledSquareAndPolygonCoverExactlyTheirPixels) {
  Canvas cv(40, 30);
  cv.fill_rect(10, 5, 8, 6, {1, 0, 0});                       // pixels x 10..17, y 5..10
  cv.fill_polygon({{20, 20}, {30, 20}, {30, 25}, {20, 25}}, {0, 0, 1});  // x 20..29, y 20..24
  const RgbImage im = cv.image();
  ASSERT_EQ(im.width, 40);
  ASSERT_EQ(im.height, 30);
  int red = 0, blue = 0;
  for (int y = 0; y < 30; ++y)
    for (int x = 0; x < 40; ++x) {
      const bool in_square = x >= 10 && x < 18 && y >= 5 && y < 11;
      const bool in_polygon = x >= 20 && x < 30 && y >= 20 && y < 25;
      const auto p = px(im, x, y);
      if (in_square) red += p == std::array<int, 3>{255, 0, 0};
      else if (in_polygon) blue += p == std::array<int, 3>{0, 0, 255};
      else ASSERT_EQ(p, kWhite) << x << ", " << y;
    }
  EXPECT_EQ(red, 8 * 6);
  EXPECT_EQ(blue, 10 * 5);
  // Half opacity over white: 255 * 0.5 + 0 * 0.5.
  Canvas half(4, 4);
  half.fill_rect(0, 0, 4, 4, {0, 0, 0}, 0.5);
  const auto grey = px(half.image(), 2, 2);
  EXPECT_NEAR(grey[0], 127.5, 1.0);
  EXPECT_THROW(Canvas(0, 10), InvalidInput);
}

TEST(Canvas, LineHasItsColourOnItsRowOnly) {
  Canvas cv(30, 20);
  cv.line({2, 10.5}, {28, 10.5}, {.colour = {0, 0.5, 1}, .width_px = 1.0});  // covers row 10
  const RgbImage im = cv.image();
  for (int x = 2; x < 28; ++x) EXPECT_EQ(px(im, x, 10), (std::array<int, 3>{0, 128, 255})) << x;
  for (int x = 0; x < 30; ++x) {
    EXPECT_EQ(px(im, x, 9), kWhite);
    EXPECT_EQ(px(im, x, 11), kWhite);
  }
  EXPECT_EQ(px(im, 0, 10), kWhite);
  EXPECT_EQ(px(im, 29, 10), kWhite);
  // Dashed 4 on, 4 off from x = 0: pixels 0..3 drawn, 4..7 not, 8..11 drawn.
  Canvas dashed(16, 4);
  dashed.line({0, 1.5}, {16, 1.5}, {.colour = {0, 0, 0}, .dash_px = {4.0, 4.0}});
  const RgbImage d = dashed.image();
  for (int x : {0, 3, 8, 11}) EXPECT_EQ(px(d, x, 1), (std::array<int, 3>{0, 0, 0})) << x;
  for (int x : {4, 7, 12, 15}) EXPECT_EQ(px(d, x, 1), kWhite) << x;
}

TEST(Canvas, ImagesAreCopiedPixelForPixelAndEnlarged) {
  RgbImage small = make_image(2, 2, {0, 0, 0});
  small.set(1, 0, {1, 0, 0});
  small.set(0, 1, {0, 1, 0});
  Canvas cv(10, 10);
  cv.draw_image(small, 3, 4, 3);  // each pixel a 3 x 3 block: x 3..8, y 4..9
  cv.draw_image(small, 9, -1);    // cut at the right and top edges: only (0, 1) lands, at (9, 0)
  const RgbImage im = cv.image();
  EXPECT_EQ(px(im, 3, 4), (std::array<int, 3>{0, 0, 0}));
  EXPECT_EQ(px(im, 8, 6), (std::array<int, 3>{255, 0, 0}));
  EXPECT_EQ(px(im, 5, 9), (std::array<int, 3>{0, 255, 0}));
  EXPECT_EQ(px(im, 6, 7), (std::array<int, 3>{0, 0, 0}));
  EXPECT_EQ(px(im, 2, 4), kWhite);
  EXPECT_EQ(px(im, 9, 0), (std::array<int, 3>{0, 255, 0}));
  // A canvas started from an image gives it back unchanged.
  EXPECT_EQ(Canvas(small).image().rgb, small.rgb);
}

TEST(Canvas, ColourBarRunsFromTheTopColourToTheBottomColour) {
  Canvas cv(20, 60);
  cv.colour_bar(5, 5, 10, 50);
  const RgbImage im = cv.image();
  auto byte = [](double v) { return int(v * 255 + 0.5); };
  const Eigen::Vector3d top = viridis(1.0), bottom = viridis(0.0);
  EXPECT_EQ(px(im, 10, 5), (std::array<int, 3>{byte(top[0]), byte(top[1]), byte(top[2])}));
  EXPECT_EQ(px(im, 10, 54), (std::array<int, 3>{byte(bottom[0]), byte(bottom[1]), byte(bottom[2])}));
  EXPECT_EQ(px(im, 10, 4), kWhite);
  EXPECT_EQ(px(im, 10, 55), kWhite);
  EXPECT_EQ(px(im, 4, 30), kWhite);
  EXPECT_EQ(px(im, 15, 30), kWhite);
}

TEST(Canvas, ClipAndTextStayWhereTheyAreSent) {
  Canvas cv(60, 40);
  cv.push_clip(10, 10, 20, 10);
  cv.fill_rect(0, 0, 60, 40, {0, 0, 0});
  cv.pop_clip();
  cv.fill_rect(40, 30, 5, 5, {0, 0, 0});  // unclipped again
  RgbImage im = cv.image();
  int black = 0;
  for (int y = 0; y < 40; ++y)
    for (int x = 0; x < 60; ++x) black += px(im, x, y)[0] == 0;
  EXPECT_EQ(black, 20 * 10 + 5 * 5);
  // Text: ink only in the box from the baseline up by the font size, starting at x; a wider
  // string is wider, and a larger size is wider still.
  Canvas t(200, 40);
  t.text(10, 30, "Skin", {.size_px = 20, .colour = {0, 0, 0}});
  im = t.image();
  int ink = 0, outside = 0;
  for (int y = 0; y < 40; ++y)
    for (int x = 0; x < 200; ++x) {
      const bool dark = px(im, x, y)[0] < 128;
      const bool in_box = x >= 10 && x < 10 + t.text_width("Skin", 20) + 1 && y >= 30 - 20 && y <= 31;
      (in_box ? ink : outside) += dark;
    }
  EXPECT_GT(ink, 40);
  EXPECT_EQ(outside, 0);
  EXPECT_GT(t.text_width("Skin tension", 20), t.text_width("Skin", 20));
  // Twice the size, twice the width, up to the hinting that rounds advances to whole pixels.
  EXPECT_NEAR(t.text_width("Skin", 40) / t.text_width("Skin", 20), 2.0, 0.1);
}

TEST(Canvas, WritesThePngItShows) {
  const fs::path dir = temp_dir("canvas");
  Canvas cv(12, 9);
  cv.fill_circle({6, 4.5}, 3, {0.2, 0.4, 0.6});
  cv.write_png(dir / "c.png");
  EXPECT_EQ(read_png(dir / "c.png").rgb, cv.image().rgb);
  fs::remove_all(dir);
}
