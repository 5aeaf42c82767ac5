#include "caps/volume/image_io.hpp"

#include <cairo.h>
#include <png.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <memory>
#include <sstream>

#include "caps/core/atomic_output.hpp"
#include "caps/core/error.hpp"
#include "caps/core/units.hpp"

namespace fs = std::filesystem;

namespace caps {

void write_map_nrrd(const fs::path& path, const std::vector<float>& values, const CylinderGrid& g,
                    const std::string& content, const std::string& unit) {
  CAPS_ASSERT(values.size() == g.size(), "map size does not match its grid");
  std::ostringstream h;
  h.precision(10);
  h << "NRRD0004\n"
    << "# caps patient model, format 1: a map over (theta, z) of the cylindrical model\n"
    << "# values in " << unit << "; theta = 0 at the front, +90 at the patient's left\n"
    << "content: " << content << "\n"
    << "type: float\n"
    << "dimension: 2\n"
    << "sizes: " << g.n_theta << " " << g.n_z << "\n"
    << "spacings: " << g.dtheta_deg() << " " << g.dz_mm << "\n"
    << "axis mins: " << g.theta0_deg << " " << g.z0_mm << "\n"
    << "centers: node node\n"
    << "kinds: domain domain\n"
    << "labels: \"theta\" \"z\"\n"
    << "units: \"deg\" \"mm\"\n"
    << "endian: little\n"
    << "encoding: raw\n\n";
  write_file_atomic(path, [&](const fs::path& tmp) {
    std::ofstream out(tmp, std::ios::binary);
    const std::string header = h.str();
    out.write(header.data(), static_cast<std::streamsize>(header.size()));
    out.write(reinterpret_cast<const char*>(values.data()),
              static_cast<std::streamsize>(values.size() * sizeof(float)));
    out.close();
    if (!out) throw IoError(cat(path.string(), ": write failed (disk full?)"));
  });
}

std::vector<float> read_map_nrrd(const fs::path& path, const CylinderGrid& g) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw IoError(cat(path.string(), ": cannot open the map"));
  std::string line;
  std::getline(in, line);
  if (line.rfind("NRRD", 0) != 0) throw InvalidInput(cat(path.string(), ": not a NRRD file"));
  int n0 = -1, n1 = -1;
  while (std::getline(in, line) && !line.empty()) {
    if (line.rfind("sizes:", 0) == 0) std::istringstream(line.substr(6)) >> n0 >> n1;
    if (line.rfind("type:", 0) == 0 && line.find("float") == std::string::npos)
      throw InvalidInput(cat(path.string(), ": expected float data, found '", line, "'"));
    if (line.rfind("encoding:", 0) == 0 && line.find("raw") == std::string::npos)
      throw InvalidInput(cat(path.string(), ": expected raw encoding, found '", line, "'"));
  }
  if (n0 != g.n_theta || n1 != g.n_z)
    throw InvalidInput(cat(path.string(), ": map is ", n0, " x ", n1, " but model.json says ",
                           g.n_theta, " x ", g.n_z));
  std::vector<float> v(g.size());
  in.read(reinterpret_cast<char*>(v.data()), static_cast<std::streamsize>(v.size() * sizeof(float)));
  if (!in) throw IoError(cat(path.string(), ": the map's data are truncated"));
  return v;
}

RgbImage read_png(const fs::path& path) {
  png_image image;
  std::memset(&image, 0, sizeof(image));
  image.version = PNG_IMAGE_VERSION;
  if (!png_image_begin_read_from_file(&image, path.c_str()))
    throw IoError(cat(path.string(), ": cannot read PNG: ", image.message));
  image.format = PNG_FORMAT_RGB;
  RgbImage out;
  out.width = static_cast<int>(image.width);
  out.height = static_cast<int>(image.height);
  out.rgb.resize(PNG_IMAGE_SIZE(image));
  if (!png_image_finish_read(&image, nullptr, out.rgb.data(), 0, nullptr)) {
    png_image_free(&image);
    throw IoError(cat(path.string(), ": cannot decode PNG: ", image.message));
  }
  return out;
}

void write_png(const fs::path& path, const RgbImage& image) {
  if (image.width < 1 || image.height < 1 ||
      image.rgb.size() != static_cast<std::size_t>(image.width) * image.height * 3)
    throw InvalidInput(cat(path.string(), ": image buffer does not match its size"));
  write_file_atomic(path, [&](const fs::path& tmp) {
    png_image p{};
    p.version = PNG_IMAGE_VERSION;
    p.width = static_cast<png_uint_32>(image.width);
    p.height = static_cast<png_uint_32>(image.height);
    p.format = PNG_FORMAT_RGB;
    if (!png_image_write_to_file(&p, tmp.c_str(), 0, image.rgb.data(), 0, nullptr))
      throw IoError(cat(path.string(), ": cannot write PNG: ", p.message));
  });
}

Eigen::Vector3d viridis(double t) {
  static const double kStops[11][3] = {
      {68, 1, 84},    {72, 36, 117},  {65, 68, 135},  {53, 95, 141},  {42, 120, 142},
      {33, 145, 140}, {34, 168, 132}, {68, 191, 112}, {122, 209, 81}, {189, 223, 38},
      {253, 231, 37}};
  t = std::clamp(t, 0.0, 1.0) * 10.0;
  const int i = std::min(9, static_cast<int>(t));
  const double f = t - i;
  Eigen::Vector3d c;
  for (int a = 0; a < 3; ++a) c[a] = (kStops[i][a] * (1 - f) + kStops[i + 1][a] * f) / 255.0;
  return c;
}

namespace {

using SurfacePtr = std::unique_ptr<cairo_surface_t, decltype(&cairo_surface_destroy)>;
using ContextPtr = std::unique_ptr<cairo_t, decltype(&cairo_destroy)>;

// A figure: the map drawn at `scale` pixels per cell inside margins, then text and axes.
struct Figure {
  int map_w, map_h, left = 70, top = 46, right = 150, bottom = 64;
  SurfacePtr surface{nullptr, cairo_surface_destroy};
  ContextPtr cr{nullptr, cairo_destroy};

  Figure(int w, int h) : map_w(w), map_h(h) {
    surface.reset(cairo_image_surface_create(CAIRO_FORMAT_RGB24, left + w + right, top + h + bottom));
    cr.reset(cairo_create(surface.get()));
    cairo_set_source_rgb(cr.get(), 1, 1, 1);
    cairo_paint(cr.get());
    cairo_select_font_face(cr.get(), "DejaVu Sans", CAIRO_FONT_SLANT_NORMAL,
                           CAIRO_FONT_WEIGHT_NORMAL);
  }
  // Sets map pixel (x, y) (y = 0 at the top) to an RGB colour in [0, 1].
  void pixel(int x, int y, const Eigen::Vector3d& c) {
    cairo_surface_flush(surface.get());
    unsigned char* data = cairo_image_surface_get_data(surface.get());
    const int stride = cairo_image_surface_get_stride(surface.get());
    auto* px = reinterpret_cast<std::uint32_t*>(data + (top + y) * stride) + left + x;
    auto byte = [](double v) { return static_cast<std::uint32_t>(std::clamp(v, 0.0, 1.0) * 255 + 0.5); };
    *px = (byte(c[0]) << 16) | (byte(c[1]) << 8) | byte(c[2]);
  }
  void text(double x, double y, const std::string& s, double size, double align = 0.0) {
    cairo_set_font_size(cr.get(), size);
    cairo_text_extents_t ext;
    cairo_text_extents(cr.get(), s.c_str(), &ext);
    cairo_move_to(cr.get(), x - align * ext.x_advance, y);
    cairo_set_source_rgb(cr.get(), 0.1, 0.1, 0.1);
    cairo_show_text(cr.get(), s.c_str());
  }
  void line(double x0, double y0, double x1, double y1) {
    cairo_set_source_rgb(cr.get(), 0.1, 0.1, 0.1);
    cairo_set_line_width(cr.get(), 1.0);
    cairo_move_to(cr.get(), x0, y0);
    cairo_line_to(cr.get(), x1, y1);
    cairo_stroke(cr.get());
  }
  // Theta ticks along the bottom, z ticks along the left, frame, and axis titles.
  void axes(const CylinderGrid& g, double scale) {
    cairo_surface_mark_dirty(surface.get());
    const double x0 = left, y0 = top, x1 = left + map_w, y1 = top + map_h;
    cairo_rectangle(cr.get(), x0 - 0.5, y0 - 0.5, map_w + 1, map_h + 1);
    cairo_set_source_rgb(cr.get(), 0.1, 0.1, 0.1);
    cairo_stroke(cr.get());
    for (int deg = -180; deg <= 180; deg += 45) {
      const double x = x0 + (deg - g.theta0_deg) / g.dtheta_deg() * scale;
      line(x, y1, x, y1 + 5);
      text(x, y1 + 18, std::to_string(deg), 11, 0.5);
    }
    text(0.5 * (x0 + x1), y1 + 36, "theta (deg):  0 = front (face),  +90 = patient's left,  "
                                   "-90 = patient's right", 12, 0.5);
    const double z_top = g.z_mm(g.n_z - 1);
    const double step = (z_top - g.z0_mm) > 150 ? 50.0 : 20.0;
    for (double z = std::ceil(g.z0_mm / step) * step; z <= z_top; z += step) {
      const double y = y1 - (z - g.z0_mm) / g.dz_mm * scale;
      line(x0 - 5, y, x0, y);
      text(x0 - 8, y + 4, cat(static_cast<int>(z)), 11, 1.0);
    }
    cairo_save(cr.get());
    cairo_translate(cr.get(), 16, 0.5 * (y0 + y1));
    cairo_rotate(cr.get(), -kPi / 2);
    text(0, 0, "z (mm, superior up)", 12, 0.5);
    cairo_restore(cr.get());
  }
  void write(const fs::path& path) {
    cairo_surface_flush(surface.get());
    write_file_atomic(path, [&](const fs::path& tmp) {
      if (cairo_surface_write_to_png(surface.get(), tmp.c_str()) != CAIRO_STATUS_SUCCESS)
        throw IoError(cat(path.string(), ": cannot write PNG"));
    });
  }
};

// Pixels per cell so the map is about 1000 pixels wide.
int map_scale(const CylinderGrid& g) { return std::max(1, 1024 / g.n_theta); }

}  // namespace

void write_thickness_png(const fs::path& path, const CylindricalMaps& maps,
                         const std::vector<float>& values, const std::string& title,
                         const std::string& credit) {
  const auto& g = maps.grid;
  const int s = map_scale(g);
  Figure fig(g.n_theta * s, g.n_z * s);
  // Colour range: 0 to the 98th percentile of valid cells, rounded up to 5 mm.
  std::vector<float> valid;
  for (std::size_t i = 0; i < values.size(); ++i)
    if (maps.flags[i] == 0) valid.push_back(values[i]);
  double vmax = 10.0;
  if (!valid.empty()) {
    std::nth_element(valid.begin(), valid.begin() + valid.size() * 98 / 100, valid.end());
    vmax = std::max(5.0, std::ceil(valid[valid.size() * 98 / 100] / 5.0) * 5.0);
  }
  for (int k = 0; k < g.n_z; ++k)
    for (int j = 0; j < g.n_theta; ++j) {
      const std::size_t c = g.index(j, k);
      for (int dy = 0; dy < s; ++dy)
        for (int dx = 0; dx < s; ++dx) {
          const int x = j * s + dx, y = (g.n_z - 1 - k) * s + dy;
          Eigen::Vector3d col;
          if (maps.flags[c] & kNoSkin) col = {1, 1, 1};
          else if (maps.flags[c] != 0) col = ((x + y) / 3) % 2 ? Eigen::Vector3d(0.78, 0.78, 0.78)
                                                                : Eigen::Vector3d(0.88, 0.88, 0.88);
          else col = viridis(values[c] / vmax);
          fig.pixel(x, y, col);
        }
    }
  fig.axes(g, s);
  fig.text(fig.left, 28, title, 15);
  // Colour bar.
  const int bx = fig.left + fig.map_w + 30, bw = 22, by = fig.top, bh = fig.map_h;
  cairo_t* cr = fig.cr.get();
  for (int y = 0; y < bh; ++y) {
    const Eigen::Vector3d c = viridis(1.0 - double(y) / (bh - 1));
    cairo_set_source_rgb(cr, c[0], c[1], c[2]);
    cairo_rectangle(cr, bx, by + y, bw, 1);
    cairo_fill(cr);
  }
  const double tick = vmax <= 10 ? 2.0 : (vmax <= 30 ? 5.0 : 10.0);
  for (double v = 0; v <= vmax + 1e-9; v += tick) {
    const double y = by + bh - 1 - v / vmax * (bh - 1);
    fig.line(bx + bw, y, bx + bw + 5, y);
    fig.text(bx + bw + 8, y + 4, cat(static_cast<int>(v), " mm"), 11);
  }
  cairo_save(cr);
  cairo_translate(cr, bx + bw + 60, by + 0.5 * bh);
  cairo_rotate(cr, -kPi / 2);
  fig.text(0, 0, "soft-tissue thickness (mm)", 12, 0.5);
  cairo_restore(cr);
  // Legend for invalid cells, and the credit line.
  const int ly = fig.top + fig.map_h + 52;
  for (int y = 0; y < 10; ++y)
    for (int x = 0; x < 18; ++x) {
      const double v = ((x + y) / 3) % 2 ? 0.78 : 0.88;
      cairo_set_source_rgb(cr, v, v, v);
      cairo_rectangle(cr, fig.left + x, ly - 9 + y, 1, 1);
      cairo_fill(cr);
    }
  fig.text(fig.left + 24, ly, "no valid measurement (no bone within the cap, undercut, grazing "
                              "ray; filled by interpolation)", 11);
  if (!credit.empty()) fig.text(fig.left + fig.map_w + fig.right - 10, ly, credit, 10, 1.0);
  fig.write(path);
}

void write_skin_png(const fs::path& path, const CylindricalMaps& maps, const std::string& title,
                    const std::string& credit) {
  const auto& g = maps.grid;
  const int s = map_scale(g);
  Figure fig(g.n_theta * s, g.n_z * s);
  // Lambert shading of the range surface, lit from the front, above and the viewer's side.
  const Eigen::Vector3d light = Eigen::Vector3d(0.3, 0.6, 1.0).normalized();  // (left, up, out)
  const double dth = deg_to_rad(g.dtheta_deg());
  const Eigen::Vector3d tone(0.93, 0.76, 0.65);
  for (int k = 0; k < g.n_z; ++k)
    for (int j = 0; j < g.n_theta; ++j) {
      const std::size_t c = g.index(j, k);
      Eigen::Vector3d col(1, 1, 1);
      if (!(maps.flags[c] & kNoSkin)) {
        const int jl = (j + g.n_theta - 1) % g.n_theta, jr = (j + 1) % g.n_theta;
        const int kd = std::max(0, k - 1), ku = std::min(g.n_z - 1, k + 1);
        const double r = maps.r_skin[c];
        const double dr_dth = (maps.r_skin[g.index(jr, k)] - maps.r_skin[g.index(jl, k)]) / (2 * dth);
        const double dr_dz = (maps.r_skin[g.index(j, ku)] - maps.r_skin[g.index(j, kd)]) /
                             ((ku - kd) * g.dz_mm);
        // Normal in the local (tangential, axial, radial) frame of the cylinder.
        const Eigen::Vector3d n = Eigen::Vector3d(-dr_dth / std::max(r, 1.0), -dr_dz, 1.0).normalized();
        const double shade = 0.25 + 0.75 * std::max(0.0, n.dot(light));
        col = tone * shade;
      }
      for (int dy = 0; dy < s; ++dy)
        for (int dx = 0; dx < s; ++dx) fig.pixel(j * s + dx, (g.n_z - 1 - k) * s + dy, col);
    }
  fig.axes(g, s);
  fig.text(fig.left, 28, title, 15);
  if (!credit.empty()) fig.text(fig.left, fig.top + fig.map_h + 56, credit, 10);
  fig.write(path);
}

}  // namespace caps
