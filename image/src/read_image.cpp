#include "caps/image/image_io.hpp"

#include <fstream>
#include <iterator>

#include "caps/core/error.hpp"
#include "caps/core/file_access.hpp"

namespace caps {

RgbImage read_image(const std::filesystem::path& path) {
  // A folder or a FIFO opens as a stream and fails (or blocks) in the middle of reading.
  require_readable(path, false, "give a PNG or JPEG image file");
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec))
    throw IoError(cat(path.string(), ": not a regular file; give a PNG or JPEG image file"));
  std::ifstream in(path, std::ios::binary);
  if (!in) throw IoError(cat(path.string(), ": cannot open the image (missing or unreadable)"));
  const std::vector<unsigned char> bytes{std::istreambuf_iterator<char>(in),
                                         std::istreambuf_iterator<char>()};
  if (bytes.size() >= 3 && bytes[0] == 0xFF && bytes[1] == 0xD8 && bytes[2] == 0xFF)
    return decode_jpeg(bytes, path.string());
  if (bytes.size() >= 8 && bytes[0] == 0x89 && bytes[1] == 'P' && bytes[2] == 'N' && bytes[3] == 'G')
    return read_png(path);
  throw IoError(cat(path.string(), ": not a JPEG or PNG image"));
}

}  // namespace caps
