// Checks the header of each compressed frame of encapsulated DICOM pixel data before GDCM's
// codecs see it (docs/reliability.md): GDCM's JPEG codec dereferences a null pointer when a
// frame's precision exceeds BitsAllocated (found by fuzz_dicom), so caps hands a codec only
// frames whose own header agrees with the DICOM header.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace caps::detail {

/// What the DICOM header says a frame holds.
struct FrameFormat {
  int rows = 0, cols = 0;
  int bits_allocated = 16, bits_stored = 16;
};

/// The compression family of a transfer syntax UID, or Unsupported.
enum class Codestream { Rle, Jpeg, JpegLs, Jpeg2000, Unsupported };
Codestream codestream_of(const std::string& transfer_syntax_uid);

/// Checks `fragments` (the bytes of each fragment of the pixel data, the basic offset table
/// excluded) against `format` for `frames` frames: RLE, one fragment per frame, its segment
/// count and offsets; JPEG and JPEG-LS, the start-of-frame of every fragment that starts an
/// image (rows, columns, one component, precision at most BitsAllocated); JPEG 2000, the SIZ
/// marker likewise. Returns an empty string when they agree, else what is wrong (for the
/// caller's message).
std::string check_codestream(Codestream kind, const std::vector<std::string>& fragments,
                             const FrameFormat& format, int frames);

}  // namespace caps::detail
