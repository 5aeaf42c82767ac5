#pragma once
/// @brief The drawing surface of every figure: lines, polylines, filled polygons, circles, text
/// in DejaVu Sans, RGB images drawn in, and a colour bar, on an RGB raster written as PNG, or on
/// a vector page written as PDF (pdf_page(): the same calls, in points).
///
/// Coordinates are pixels, x to the right and y downwards, with (0, 0) the top-left corner of the
/// top-left pixel: a 1-pixel line along y = 10.5 covers row 10 exactly. Colours are RGB in [0, 1].
/// Drawing is antialiased; images drawn in are copied pixel for pixel.

#include <Eigen/Core>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "caps/image/colormap.hpp"
#include "caps/image/rgb_image.hpp"

namespace caps {

/// How lines are stroked.
struct Pen {
  Eigen::Vector3d colour{0.1, 0.1, 0.1};
  double width_px = 1.0;
  std::vector<double> dash_px{};  ///< on/off lengths in pixels; empty: solid
  bool round_joins = false;     ///< round corners (else mitred)
};

/// How text is set.
struct TextStyle {
  double size_px = 12;
  Eigen::Vector3d colour{0.1, 0.1, 0.1};
  /// 0: the text starts at x; 0.5: centred on x; 1: ends at x (by its advance width).
  double align = 0;
  double rotate_deg = 0;  ///< about (x, y); -90 reads upwards
  bool halo = false;      ///< a translucent white box behind the text
};

/// A raster with a drawing context (cairo behind a pimpl).
class Canvas {
 public:
  /// A width × height canvas filled with `background`. Throws InvalidInput unless both sizes are
  /// positive.
  Canvas(int width, int height, const Eigen::Vector3d& background = {1, 1, 1});
  /// A canvas that starts as a copy of `image`.
  explicit Canvas(const RgbImage& image);
  /// A white vector page of width_pt × height_pt points (1/72 inch; A4 is 595.28 × 841.89)
  /// drawn into a PDF by cairo's PDF surface: coordinates are points, text stays text. image()
  /// and write_png() refuse it; pdf() gives the file. Throws InvalidInput unless both sizes are
  /// positive and finite.
  static Canvas pdf_page(double width_pt, double height_pt);
  ~Canvas();
  Canvas(Canvas&&) noexcept;
  Canvas& operator=(Canvas&&) noexcept;

  int width() const;
  int height() const;

  /// A straight segment from a to b (pixels).
  void line(const Eigen::Vector2d& a, const Eigen::Vector2d& b, const Pen& pen = {});
  /// A polyline through `points` (pixels), closed back to the first point if `closed`.
  void polyline(const std::vector<Eigen::Vector2d>& points, const Pen& pen = {},
                bool closed = false);
  /// Fills the polygon through `points` (pixels; non-zero winding) with `colour` at `opacity`.
  void fill_polygon(const std::vector<Eigen::Vector2d>& points, const Eigen::Vector3d& colour,
                    double opacity = 1.0);
  /// Fills the axis-aligned rectangle with top-left corner (x, y), w × h pixels.
  void fill_rect(double x, double y, double w, double h, const Eigen::Vector3d& colour,
                 double opacity = 1.0);
  /// Strokes the outline of a rectangle.
  void stroke_rect(double x, double y, double w, double h, const Pen& pen = {});
  /// A filled disc of `radius_px` around `centre`.
  void fill_circle(const Eigen::Vector2d& centre, double radius_px, const Eigen::Vector3d& colour);
  /// A circle's outline.
  void stroke_circle(const Eigen::Vector2d& centre, double radius_px, const Pen& pen = {});

  /// Sets `text` (UTF-8, one line) in DejaVu Sans with its baseline at y.
  void text(double x, double y, const std::string& text, const TextStyle& style = {});
  /// The advance width of `text` in pixels at `size_px`.
  double text_width(const std::string& text, double size_px) const;

  /// Copies `image` in with its top-left corner at pixel (x, y), each pixel enlarged to a
  /// scale × scale block (nearest neighbour, no smoothing). Parts outside the canvas are cut.
  void draw_image(const RgbImage& image, int x, int y, int scale = 1);
  /// Draws `image` stretched over the rectangle with top-left corner (x, y), w × h (in the
  /// canvas's units: pixels, or points on a PDF page), interpolated bilinearly.
  void draw_image_in(const RgbImage& image, double x, double y, double w, double h);

  /// A vertical colour bar with top-left corner (x, y), w × h pixels: `map(1)` at the top row,
  /// `map(0)` at the bottom row, one colour per row.
  void colour_bar(double x, double y, double w, double h,
                  const std::function<Eigen::Vector3d(double)>& map = viridis);

  /// Scales everything drawn from now on by `factor` (> 0) about the top-left corner: a page
  /// drawn in points onto a raster of dpi / 72 pixels per point. Pen widths and text scale too.
  void scale(double factor);

  /// Limits drawing to a rectangle until pop_clip().
  void push_clip(double x, double y, double w, double h);
  void pop_clip();

  /// The pixels drawn so far. Throws Error for a PDF page.
  RgbImage image() const;
  /// A PDF page's file (one page): finishes the page, after which nothing more may be drawn.
  /// Throws Error for a raster canvas or when cairo failed to write the page.
  std::string pdf();
  /// Writes the pixels as an RGB PNG, atomically (write_png()). Throws IoError.
  void write_png(const std::filesystem::path& path) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace caps
