// Whether a gzip stream on disk is whole (see volume_io_detail.hpp).

#include <zlib.h>

#include <algorithm>
#include <cstring>
#include <fstream>
#include <vector>

#include "caps/core/error.hpp"
#include "volume_io_detail.hpp"

namespace fs = std::filesystem;

namespace caps::detail {

void require_whole_gzip(const fs::path& file, const fs::path& data, std::uint64_t offset,
                        std::uint64_t needed_bytes, std::uint64_t search_bytes) {
  std::ifstream in(data, std::ios::binary);
  if (!in) throw IoError(cat(data.string(), ": cannot open the compressed data for reading"));
  in.seekg(static_cast<std::streamoff>(offset));
  z_stream zs;
  std::memset(&zs, 0, sizeof zs);
  if (inflateInit2(&zs, 15 + 32) != Z_OK)  // +32: a gzip or a zlib header
    throw IoError(cat(file.string(), ": zlib initialisation failed"));
  struct End {
    z_stream* zs;
    ~End() { inflateEnd(zs); }
  } end{&zs};
  // Past what the reader uses, the end of the stream is looked for only so far: the rest of a
  // 4-D image is not read, and a decompression bomb must not cost more than that.
  const std::uint64_t search = search_bytes > 0 ? std::max(search_bytes, needed_bytes)
                                                : needed_bytes + (std::uint64_t(1) << 20);
  std::vector<char> input(1 << 16), scratch(1 << 16);
  std::uint64_t total = 0;  // decompressed bytes over every member
  bool at_eof = false;
  for (;;) {
    if (zs.avail_in == 0 && !at_eof) {
      in.read(input.data(), static_cast<std::streamsize>(input.size()));
      zs.next_in = reinterpret_cast<Bytef*>(input.data());
      zs.avail_in = static_cast<uInt>(in.gcount());
      at_eof = in.gcount() == 0 || !in;
    }
    zs.next_out = reinterpret_cast<Bytef*>(scratch.data());
    zs.avail_out = static_cast<uInt>(scratch.size());
    const uLong before = zs.total_out;
    const int rc = inflate(&zs, Z_NO_FLUSH);
    total += zs.total_out - before;
    if (rc == Z_STREAM_END) {
      // What follows a member that ends the data is ignored, as zlib's gzread does.
      if (total >= needed_bytes) return;
      // Concatenated members (pigz, bgzip) are read on as one stream by gzread.
      if (zs.avail_in == 0 && at_eof) break;
      inflateReset(&zs);
      continue;
    }
    if (rc == Z_DATA_ERROR || rc == Z_MEM_ERROR || rc == Z_STREAM_ERROR || rc == Z_NEED_DICT)
      throw IoError(cat(file.string(), ": the compressed data are corrupt (zlib: ",
                        zs.msg ? zs.msg : "error", " after ", total,
                        " decompressed bytes); copy or export the file again"));
    if (total > search) return;
    if (zs.avail_in == 0 && at_eof) break;
  }
  throw IoError(cat(file.string(), ": the gzip stream is cut short: it ends after ", total,
                    " decompressed bytes without its end marker and checksum",
                    total < needed_bytes ? cat(" (the header needs ", needed_bytes, ")") : "",
                    "; the file is truncated: copy or export it again"));
}

}  // namespace caps::detail
