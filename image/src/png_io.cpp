#include "caps/image/image_io.hpp"

#include <png.h>

#include <cstdio>
#include <cstring>
#include <memory>

#include "caps/core/atomic_output.hpp"
#include "caps/core/error.hpp"

namespace fs = std::filesystem;

namespace caps {
namespace {

// libpng reports through these: quietly, since the exception that follows says what failed.
void png_error_quiet(png_structp png, png_const_charp) { png_longjmp(png, 1); }
void png_warning_quiet(png_structp, png_const_charp) {}

// Writes `pixels` in the simplified API's `format`, atomically.
void write_png_format(const fs::path& path, int width, int height, png_uint_32 format,
                      const void* pixels) {
  write_file_atomic(path, [&](const fs::path& tmp) {
    png_image p{};
    p.version = PNG_IMAGE_VERSION;
    p.width = static_cast<png_uint_32>(width);
    p.height = static_cast<png_uint_32>(height);
    p.format = format;
    if (!png_image_write_to_file(&p, tmp.c_str(), 0, pixels, 0, nullptr))
      throw IoError(cat(path.string(), ": cannot write PNG: ", p.message));
  });
}

}  // namespace

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
  write_png_format(path, image.width, image.height, PNG_FORMAT_RGB, image.rgb.data());
}

GreyImage read_grey_png(const fs::path& path, const char* what) {
  std::unique_ptr<FILE, decltype(&std::fclose)> file(std::fopen(path.c_str(), "rb"), &std::fclose);
  if (!file) throw IoError(cat(path.string(), ": cannot open the ", what));
  png_byte signature[8];
  if (std::fread(signature, 1, 8, file.get()) != 8 || png_sig_cmp(signature, 0, 8))
    throw InvalidInput(cat(path.string(), ": the ", what, " must be a PNG (8- or 16-bit grey)"));
  png_structp png =
      png_create_read_struct(PNG_LIBPNG_VER_STRING, nullptr, png_error_quiet, png_warning_quiet);
  png_infop info = png ? png_create_info_struct(png) : nullptr;
  if (!info) {
    png_destroy_read_struct(&png, nullptr, nullptr);
    throw Error("out of memory reading a PNG");
  }
  GreyImage img;
  if (setjmp(png_jmpbuf(png))) {
    png_destroy_read_struct(&png, &info, nullptr);
    throw IoError(cat(path.string(), ": the ", what, " is damaged or truncated"));
  }
  png_init_io(png, file.get());
  png_set_sig_bytes(png, 8);
  png_read_png(png, info, PNG_TRANSFORM_EXPAND | PNG_TRANSFORM_SWAP_ENDIAN, nullptr);
  const int type = png_get_color_type(png, info), depth = png_get_bit_depth(png, info);
  if (type != PNG_COLOR_TYPE_GRAY) {
    png_destroy_read_struct(&png, &info, nullptr);
    throw InvalidInput(cat(path.string(), ": the ", what, " must be grey (one channel), not colour"));
  }
  img.width = static_cast<int>(png_get_image_width(png, info));
  img.height = static_cast<int>(png_get_image_height(png, info));
  png_bytepp rows = png_get_rows(png, info);
  img.value.resize(std::size_t(img.width) * img.height);
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x)
      img.value[std::size_t(y) * img.width + x] =
          depth == 16 ? reinterpret_cast<const std::uint16_t*>(rows[y])[x] : rows[y][x];
  png_destroy_read_struct(&png, &info, nullptr);
  return img;
}

void write_grey16_png(const fs::path& path, const GreyImage& image) {
  if (image.width < 1 || image.height < 1 ||
      image.value.size() != static_cast<std::size_t>(image.width) * image.height)
    throw InvalidInput(cat(path.string(), ": image buffer does not match its size"));
  // PNG_FORMAT_LINEAR_Y: 16-bit grey, written as is.
  write_png_format(path, image.width, image.height, PNG_FORMAT_LINEAR_Y, image.value.data());
}

}  // namespace caps
