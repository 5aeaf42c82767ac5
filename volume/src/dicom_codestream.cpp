#include "dicom_codestream.hpp"

#include "caps/core/error.hpp"

namespace caps::detail {
namespace {

unsigned u8(const std::string& s, std::size_t at) { return static_cast<unsigned char>(s[at]); }
unsigned be16(const std::string& s, std::size_t at) { return (u8(s, at) << 8) | u8(s, at + 1); }
std::uint32_t be32(const std::string& s, std::size_t at) {
  return (static_cast<std::uint32_t>(be16(s, at)) << 16) | be16(s, at + 2);
}
std::uint32_t le32(const std::string& s, std::size_t at) {
  return u8(s, at) | (u8(s, at + 1) << 8) | (u8(s, at + 2) << 16) |
         (static_cast<std::uint32_t>(u8(s, at + 3)) << 24);
}

// PS3.5 Annex G: a 64-byte header (segment count, 15 offsets), then the segments, one per byte
// of a sample (most significant first).
std::string check_rle(const std::vector<std::string>& fragments, const FrameFormat& f,
                      int frames) {
  if (static_cast<int>(fragments.size()) != frames)
    return cat("RLE pixel data hold ", fragments.size(), " fragments for ", frames,
               " frame(s); RLE has exactly one per frame");
  const std::uint32_t segments = static_cast<std::uint32_t>(f.bits_allocated / 8);
  for (std::size_t k = 0; k < fragments.size(); ++k) {
    const std::string& s = fragments[k];
    if (s.size() < 64) return cat("RLE frame ", k + 1, " is shorter than its 64-byte header");
    if (le32(s, 0) != segments)
      return cat("RLE frame ", k + 1, " has ", le32(s, 0), " segments; ", segments,
                 " expected for BitsAllocated ", f.bits_allocated);
    std::uint32_t previous = 63;
    for (std::uint32_t i = 0; i < segments; ++i) {
      const std::uint32_t offset = le32(s, 4 + 4 * i);
      if (offset <= previous || offset >= s.size())
        return cat("RLE frame ", k + 1, ": segment ", i + 1, " starts at byte ", offset,
                   ", outside its ", s.size(), "-byte fragment or before the previous one");
      previous = offset;
    }
  }
  return {};
}

// The start of frame of a JPEG or JPEG-LS stream that starts with SOI: its precision, lines,
// samples per line and component count must agree with the DICOM header.
std::string check_jpeg_frame(const std::string& s, std::size_t k, const FrameFormat& f) {
  std::size_t at = 2;  // after SOI
  while (at + 4 <= s.size()) {
    if (u8(s, at) != 0xff) return cat("JPEG frame ", k, ": no marker at byte ", at);
    const unsigned m = u8(s, at + 1);
    if (m == 0xff) {  // fill byte
      ++at;
      continue;
    }
    if (m == 0x01 || (m >= 0xd0 && m <= 0xd7)) {  // markers without a length
      at += 2;
      continue;
    }
    const unsigned length = be16(s, at + 2);
    if (length < 2 || at + 2 + length > s.size())
      return cat("JPEG frame ", k, ": a marker segment runs past the fragment");
    const bool sof = (m >= 0xc0 && m <= 0xcf && m != 0xc4 && m != 0xc8 && m != 0xcc) ||
                     m == 0xf7;  // SOF0-15 (not DHT, JPG, DAC); SOF55 (JPEG-LS)
    if (sof) {
      if (length < 8) return cat("JPEG frame ", k, ": a start of frame too short");
      const unsigned precision = u8(s, at + 4), lines = be16(s, at + 5),
                     samples = be16(s, at + 7), components = u8(s, at + 9);
      if (static_cast<int>(lines) != f.rows || static_cast<int>(samples) != f.cols)
        return cat("JPEG frame ", k, " is ", samples, "x", lines, " pixels, but Columns/Rows say ",
                   f.cols, "x", f.rows);
      if (components != 1)
        return cat("JPEG frame ", k, " has ", components, " components; caps reads greyscale");
      if (precision < 2 || static_cast<int>(precision) > f.bits_allocated)
        return cat("JPEG frame ", k, " has a precision of ", precision,
                   " bits, more than BitsAllocated = ", f.bits_allocated, " (or below 2)");
      return {};
    }
    if (m == 0xda || m == 0xd9) break;  // start of scan or end of image before any frame
    at += 2 + length;
  }
  return cat("JPEG frame ", k, " has no start-of-frame marker");
}

// The SIZ marker of a JPEG 2000 codestream (raw, or inside a JP2 file's box).
std::string check_j2k_frame(const std::string& s, std::size_t k, const FrameFormat& f) {
  const std::size_t at = s.find(std::string("\xff\x4f\xff\x51", 4));
  if (at == std::string::npos || at > 256)
    return cat("JPEG 2000 frame ", k, " has no SOC and SIZ markers at its start");
  const std::size_t siz = at + 2;  // FF51, then Lsiz
  if (siz + 41 > s.size()) return cat("JPEG 2000 frame ", k, ": its SIZ marker is cut short");
  const std::uint32_t x = be32(s, siz + 6), y = be32(s, siz + 10), x0 = be32(s, siz + 14),
                      y0 = be32(s, siz + 18);
  const unsigned components = be16(s, siz + 38), ssiz = u8(s, siz + 40);
  if (x < x0 || y < y0 || static_cast<std::int64_t>(x - x0) != f.cols ||
      static_cast<std::int64_t>(y - y0) != f.rows)
    return cat("JPEG 2000 frame ", k, " is not ", f.cols, "x", f.rows,
               " pixels as Columns/Rows say");
  if (components != 1)
    return cat("JPEG 2000 frame ", k, " has ", components, " components; caps reads greyscale");
  if (static_cast<int>((ssiz & 0x7f) + 1) > f.bits_allocated)
    return cat("JPEG 2000 frame ", k, " has a precision of ", (ssiz & 0x7f) + 1,
               " bits, more than BitsAllocated = ", f.bits_allocated);
  return {};
}

}  // namespace

Codestream codestream_of(const std::string& uid) {
  if (uid == "1.2.840.10008.1.2.5") return Codestream::Rle;
  for (const char* jpeg : {"1.2.840.10008.1.2.4.50", "1.2.840.10008.1.2.4.51",
                           "1.2.840.10008.1.2.4.57", "1.2.840.10008.1.2.4.70"})
    if (uid == jpeg) return Codestream::Jpeg;
  if (uid == "1.2.840.10008.1.2.4.80" || uid == "1.2.840.10008.1.2.4.81")
    return Codestream::JpegLs;
  if (uid == "1.2.840.10008.1.2.4.90" || uid == "1.2.840.10008.1.2.4.91")
    return Codestream::Jpeg2000;
  return Codestream::Unsupported;
}

std::string check_codestream(Codestream kind, const std::vector<std::string>& fragments,
                             const FrameFormat& format, int frames) {
  if (fragments.empty()) return "the encapsulated pixel data hold no fragment";
  switch (kind) {
    case Codestream::Rle: return check_rle(fragments, format, frames);
    case Codestream::Jpeg:
    case Codestream::JpegLs: {
      int images = 0;
      for (const std::string& s : fragments) {
        if (s.size() < 2 || u8(s, 0) != 0xff || u8(s, 1) != 0xd8) continue;  // a continuation
        if (std::string why = check_jpeg_frame(s, ++images, format); !why.empty()) return why;
      }
      if (images < frames)
        return cat("the pixel data start ", images, " JPEG image(s) for ", frames, " frame(s)");
      return {};
    }
    case Codestream::Jpeg2000: {
      int images = 0;
      for (const std::string& s : fragments) {
        if (s.find(std::string("\xff\x4f\xff\x51", 4)) > 256) continue;  // a continuation
        if (std::string why = check_j2k_frame(s, ++images, format); !why.empty()) return why;
      }
      if (images < frames)
        return cat("the pixel data start ", images, " JPEG 2000 image(s) for ", frames,
                   " frame(s)");
      return {};
    }
    case Codestream::Unsupported: break;
  }
  return "a compression caps does not read";
}

}  // namespace caps::detail
