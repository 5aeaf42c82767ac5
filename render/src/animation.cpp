#include "caps/render/animation.hpp"

#include "caps/core/atomic_output.hpp"
#include "caps/core/error.hpp"

#include <fcntl.h>
#include <gif_lib.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

namespace caps::render {
namespace {

// A 256-colour palette and the nearest-colour map of an RGB image onto it.
class Palette {
 public:
  // Median cut (giflib's GifQuantizeBuffer) over the pixels of `images` together.
  Palette(const std::vector<const RgbImage*>& images, const std::filesystem::path& path) {
    std::vector<GifByteType> r, g, b;
    for (const RgbImage* im : images)
      for (std::size_t p = 0; p < im->rgb.size(); p += 3) {
        r.push_back(im->rgb[p]);
        g.push_back(im->rgb[p + 1]);
        b.push_back(im->rgb[p + 2]);
      }
    std::vector<GifByteType> out(r.size());
    int size = 256;
    // one row of all pixels: the quantiser only counts colours, the shape does not matter
    if (GifQuantizeBuffer(static_cast<unsigned>(r.size()), 1, &size, r.data(), g.data(), b.data(),
                          out.data(), colors_.data()) != GIF_OK)
      throw Error(cat(path.string(), ": giflib could not quantise the frames' colours"));
    n_ = std::clamp(size, 1, 256);
    // GifQuantizeBuffer reports each box's mean of 5-bit colours shifted back to 8 bits (the
    // cells' lower corners: ~3.5 levels too dark); the mean of the 8-bit pixels it assigned to
    // each entry removes that bias (one Lloyd step).
    std::vector<std::array<double, 4>> sum(256, {0, 0, 0, 0});
    for (std::size_t p = 0; p < out.size(); ++p) {
      auto& e = sum[out[p]];
      e[0] += r[p], e[1] += g[p], e[2] += b[p], e[3] += 1;
    }
    for (int i = 0; i < n_; ++i)
      if (sum[i][3] > 0) {
        const auto mean = [&](int c) {
          return static_cast<GifByteType>(
              std::lround(std::clamp(sum[i][c] / sum[i][3], 0.0, 255.0)));
        };
        colors_[i] = {mean(0), mean(1), mean(2)};
      }
    // unused entries repeat the first colour, so the nearest search never prefers them
    for (int i = n_; i < 256; ++i) colors_[i] = colors_[0];
    lut_.assign(std::size_t(1) << 18, -1);
  }

  const std::array<GifColorType, 256>& colors() const { return colors_; }

  // Palette index of each pixel: nearest colour to the centre of the pixel's 6-bit-per-channel
  // cell (squared RGB distance, ties to the lower index), cached per cell.
  std::vector<GifPixelType> map(const RgbImage& im) {
    std::vector<GifPixelType> idx(static_cast<std::size_t>(im.width) * im.height);
    for (std::size_t p = 0; p < idx.size(); ++p) {
      const int r = im.rgb[3 * p] >> 2, g = im.rgb[3 * p + 1] >> 2, b = im.rgb[3 * p + 2] >> 2;
      std::int16_t& cell = lut_[(std::size_t(r) << 12) | (std::size_t(g) << 6) | std::size_t(b)];
      if (cell < 0) cell = static_cast<std::int16_t>(nearest(4 * r + 2, 4 * g + 2, 4 * b + 2));
      idx[p] = static_cast<GifPixelType>(cell);
    }
    return idx;
  }

 private:
  int nearest(int r, int g, int b) const {
    int best = 0, best_d = 1 << 30;
    for (int i = 0; i < n_; ++i) {
      const int dr = r - colors_[i].Red, dg = g - colors_[i].Green, db = b - colors_[i].Blue;
      const int d = dr * dr + dg * dg + db * db;
      if (d < best_d) best = i, best_d = d;
    }
    return best;
  }

  std::array<GifColorType, 256> colors_{};
  int n_ = 0;
  std::vector<std::int16_t> lut_;
};

// An open GIF encoder; closes (and frees) the handle on every path.
class GifWriter {
 public:
  GifWriter(const std::filesystem::path& tmp, std::string where) : where_(std::move(where)) {
    // open() ourselves: EGifOpenFileName creates the file 0600, other outputs are 0666 & ~umask
    const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0666);
    if (fd < 0) throw IoError(cat(where_, ": cannot create the GIF: ", std::strerror(errno)));
    int err = 0;
    gif_ = EGifOpenFileHandle(fd, &err);  // owns fd from here on
    if (!gif_) {
      ::close(fd);
      throw IoError(cat(where_, ": cannot start the GIF: ", GifErrorString(err)));
    }
  }
  ~GifWriter() {
    if (gif_) EGifCloseFile(gif_, nullptr);
  }
  GifWriter(const GifWriter&) = delete;
  GifWriter& operator=(const GifWriter&) = delete;

  GifFileType* get() { return gif_; }
  void check(int status, const char* what) {
    if (status != GIF_OK)
      throw IoError(
          cat(where_, ": cannot write the GIF (", what, "): ", GifErrorString(gif_->Error)));
  }
  void close() {
    int err = 0;
    const int status = EGifCloseFile(gif_, &err);  // frees gif_ whatever the status
    gif_ = nullptr;
    if (status != GIF_OK)
      throw IoError(cat(where_, ": cannot finish the GIF: ", GifErrorString(err)));
  }

 private:
  GifFileType* gif_ = nullptr;  // owned
  std::string where_;
};

int centiseconds(double seconds) {
  return std::max(2, static_cast<int>(std::lround(100 * seconds)));
}

}  // namespace

TriMesh blend_skin(const SkinSurfaces& s, double t) {
  if (!(t >= 0.0 && t <= 1.0)) throw InvalidInput(cat("blend_skin: t = ", t, " is outside [0, 1]"));
  if (s.post.V.rows() != s.pre.V.rows())
    throw InvalidInput(
        cat("blend_skin: pre has ", s.pre.V.rows(), " vertices, post ", s.post.V.rows()));
  TriMesh m;
  m.F = s.pre.F;
  if (t == 0.0)
    m.V = s.pre.V;
  else if (t == 1.0)
    m.V = s.post.V;
  else
    m.V = s.pre.V + t * (s.post.V - s.pre.V);
  return m;
}

void write_transition_gif(const SkinSurfaces& s, const Camera& camera, const RenderOptions& options,
                          int frames, const std::filesystem::path& path) {
  if (frames < 2 || frames > 600)
    throw InvalidInput(cat(path.string(), ": ", frames, " frames; expected 2..600"));
  const auto frame = [&](int k) {
    return render_skin(s, k == frames - 1 ? 1.0 : double(k) / (frames - 1), s.color, camera,
                       options);
  };
  const RgbImage first = frame(0), last = frame(frames - 1);
  Palette palette({&first, &last}, path);
  const int W = camera.width_px, H = camera.height_px;
  const int step_cs = centiseconds(kGifTransitionSeconds / (frames - 1));

  write_file_atomic(path, [&](const std::filesystem::path& tmp) {
    GifWriter gif(tmp, path.string());
    EGifSetGifVersion(gif.get(), true);
    ColorMapObject* map = GifMakeMapObject(256, palette.colors().data());
    if (!map) throw Error(cat(path.string(), ": out of memory for the GIF colour map"));
    const int screen = EGifPutScreenDesc(gif.get(), W, H, 8, 0, map);
    GifFreeMapObject(map);  // EGifPutScreenDesc keeps its own copy
    gif.check(screen, "screen descriptor");
    // loop forever: the NETSCAPE2.0 application extension, loop count 0
    gif.check(EGifPutExtensionLeader(gif.get(), APPLICATION_EXT_FUNC_CODE), "loop extension");
    gif.check(EGifPutExtensionBlock(gif.get(), 11, "NETSCAPE2.0"), "loop extension");
    const unsigned char loop[3] = {1, 0, 0};
    gif.check(EGifPutExtensionBlock(gif.get(), 3, loop), "loop extension");
    gif.check(EGifPutExtensionTrailer(gif.get()), "loop extension");

    std::vector<GifPixelType> prev;
    for (int k = 0; k < frames; ++k) {
      std::vector<GifPixelType> idx = palette.map(k == 0            ? first
                                                  : k == frames - 1 ? last
                                                                    : frame(k));
      // the rectangle that changed since the previous frame (all of frame 0)
      int x0 = 0, y0 = 0, x1 = W - 1, y1 = H - 1;
      if (k > 0) {
        x0 = W, y0 = H, x1 = -1, y1 = -1;
        for (int y = 0; y < H; ++y)
          for (int x = 0; x < W; ++x)
            if (idx[std::size_t(y) * W + x] != prev[std::size_t(y) * W + x]) {
              x0 = std::min(x0, x), x1 = std::max(x1, x);
              y0 = std::min(y0, y), y1 = std::max(y1, y);
            }
        if (x1 < 0) x0 = y0 = x1 = y1 = 0;  // nothing changed: one unchanged pixel
      }
      GraphicsControlBlock gcb{};
      gcb.DisposalMode = DISPOSE_DO_NOT;
      gcb.UserInputFlag = false;
      gcb.TransparentColor = NO_TRANSPARENT_COLOR;
      gcb.DelayTime = k == 0            ? centiseconds(kGifHoldPreSeconds)
                      : k == frames - 1 ? centiseconds(kGifHoldPostSeconds)
                                        : step_cs;
      GifByteType ext[4];
      const std::size_t n_ext = EGifGCBToExtension(&gcb, ext);
      gif.check(EGifPutExtension(gif.get(), GRAPHICS_EXT_FUNC_CODE, int(n_ext), ext),
                "frame delay");
      const int w = x1 - x0 + 1, h = y1 - y0 + 1;
      gif.check(EGifPutImageDesc(gif.get(), x0, y0, w, h, false, nullptr), "frame descriptor");
      for (int y = y0; y <= y1; ++y)
        gif.check(EGifPutLine(gif.get(), idx.data() + std::size_t(y) * W + x0, w), "frame pixels");
      prev = std::move(idx);
    }
    gif.close();
  });
}

std::vector<std::filesystem::path> write_transition_gifs(const PatientModel& model,
                                                         const SkinSurfaces& s,
                                                         const std::vector<View>& views,
                                                         const RenderOptions& options, int frames,
                                                         const std::filesystem::path& dir) {
  std::vector<std::filesystem::path> written;
  for (View v : views) {
    const auto path = dir / cat("transition_", view_name(v), ".gif");
    write_transition_gif(s, standard_camera(v, model, s, options.width, options.height), options,
                         frames, path);
    written.push_back(path);
  }
  return written;
}

}  // namespace caps::render
