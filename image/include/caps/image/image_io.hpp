#pragma once
/// @brief Reading and writing images: RGB PNG, 8/16-bit grey PNG, JPEG, and either by signature.
/// Every writer writes atomically (a temporary file renamed into place).

#include <filesystem>
#include <string>
#include <vector>

#include "caps/image/rgb_image.hpp"

namespace caps {

/// Reads a PNG of any colour type into 8-bit RGB. Throws IoError.
RgbImage read_png(const std::filesystem::path& path);

/// Writes an 8-bit RGB PNG atomically. Throws InvalidInput if the buffer does not match the
/// size, IoError if it cannot be written.
void write_png(const std::filesystem::path& path, const RgbImage& image);

/// Reads an 8- or 16-bit grey PNG with its exact values (no gamma or colour conversion).
/// Throws IoError if the file is missing, damaged or truncated, InvalidInput if it is not a PNG
/// or not grey (one channel); `what` names the image in the messages (e.g. "range image").
GreyImage read_grey_png(const std::filesystem::path& path, const char* what = "image");

/// Writes a 16-bit grey PNG with the values as they are, atomically. Throws InvalidInput if the
/// buffer does not match the size, IoError if it cannot be written.
void write_grey16_png(const std::filesystem::path& path, const GreyImage& image);

/// Decodes a JPEG held in memory into RGB; `where` names it in messages. Throws IoError.
RgbImage decode_jpeg(const std::vector<unsigned char>& bytes, const std::string& where);

/// Reads a JPEG or PNG image into RGB, telling them apart by their signature. Throws IoError.
RgbImage read_image(const std::filesystem::path& path);

}  // namespace caps
