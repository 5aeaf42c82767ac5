#include "caps/image/rgb_image.hpp"

#include <algorithm>

#include "caps/core/error.hpp"

namespace caps {
namespace {

std::uint8_t to_byte(double v) {
  return static_cast<std::uint8_t>(std::clamp(v, 0.0, 1.0) * 255 + 0.5);
}

}  // namespace

Eigen::Vector3d RgbImage::get(int x, int y) const {
  const std::uint8_t* p = &rgb[(std::size_t(y) * width + x) * 3];
  return Eigen::Vector3d(p[0], p[1], p[2]) / 255.0;
}

void RgbImage::set(int x, int y, const Eigen::Vector3d& colour) {
  std::uint8_t* p = &rgb[(std::size_t(y) * width + x) * 3];
  for (int c = 0; c < 3; ++c) p[c] = to_byte(colour[c]);
}

RgbImage make_image(int width, int height, const Eigen::Vector3d& colour) {
  if (width < 1 || height < 1)
    throw InvalidInput(cat("image: ", width, " x ", height, " pixels; both sizes must be positive"));
  RgbImage img;
  img.width = width;
  img.height = height;
  img.rgb.resize(std::size_t(width) * height * 3);
  const std::uint8_t r = to_byte(colour[0]), g = to_byte(colour[1]), b = to_byte(colour[2]);
  for (std::size_t p = 0; p < img.rgb.size(); p += 3) {
    img.rgb[p] = r;
    img.rgb[p + 1] = g;
    img.rgb[p + 2] = b;
  }
  return img;
}

}  // namespace caps
