#pragma once
/// @brief The in-memory images: 8-bit RGB (pictures, colour maps, textures) and 16-bit grey
/// (range images).

#include <Eigen/Core>
#include <cstdint>
#include <vector>

namespace caps {

/// An 8-bit RGB image, rows top to bottom, pixels left to right.
struct RgbImage {
  int width = 0, height = 0;
  std::vector<std::uint8_t> rgb;  ///< width*height*3, row-major, R G B per pixel

  bool empty() const { return rgb.empty(); }
  /// Pixel (x right, y down) as RGB in [0, 1]. Unchecked.
  Eigen::Vector3d get(int x, int y) const;
  /// Sets pixel (x, y) to an RGB colour in [0, 1] (clamped, rounded to the nearest byte). Unchecked.
  void set(int x, int y, const Eigen::Vector3d& colour);
};

/// A width × height image filled with one colour (RGB in [0, 1]). Throws InvalidInput unless
/// both sizes are positive.
RgbImage make_image(int width, int height, const Eigen::Vector3d& colour = {1, 1, 1});

/// A grey image of up to 16 bits per pixel, values stored exactly (no gamma).
struct GreyImage {
  int width = 0, height = 0;
  std::vector<std::uint16_t> value;  ///< width*height, row-major
};

}  // namespace caps
