// The structural check of a DICOM file before GDCM reads it (dicom_structure.hpp).

#include "dicom_structure.hpp"

#include <cctype>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <set>
#include <string>

#include "caps/core/error.hpp"

namespace fs = std::filesystem;

namespace caps::detail {
namespace {

constexpr std::uint32_t kUndefinedLength = 0xffffffffu;
constexpr const char* kDeflatedSyntax = "1.2.840.10008.1.2.1.99";

/// A strict structural walk over a DICOM file before GDCM reads it: every element's declared
/// length fits in what holds it, undefined lengths appear only where DICOM allows them (SQ, UN
/// in CP-246 form, encapsulated pixel data), items and delimiters appear only inside sequences,
/// sequences nest at most kMaxDepth deep, and each data set, item and sequence ends exactly
/// where its length or delimiter says. GDCM allocates a declared length before reading it (a
/// 2 KB file took 768 MB) and aborts the process on its assertions when the structure is
/// otherwise (fuzz/fuzz_dicom.cpp found pixel data of undefined length in an implicit-VR file,
/// stray tags in the fragments, a file ending inside its meta group). The elements GDCM rewrites
/// on the fly for old broken writers (implicit VR length 13, explicit UL length 6 in group 0009,
/// the tag (00ff,4aa5)) are refused rather than followed. Linear in the number of elements;
/// reads only element headers.
class DicomWalk {
 public:
  static constexpr int kMaxDepth = 16;

  DicomWalk(std::ifstream& in, std::uint64_t size) : in_(in), size_(size) {}

  /// Why the walk failed and at which byte.
  std::string failure() const { return cat(what_, " at byte ", where_); }

  /// The meta group (0002) from `at`, explicit VR little endian; returns its transfer syntax
  /// UID (empty if there is no meta group) and leaves `at` after it.
  bool meta_group(std::uint64_t& at, std::string& syntax) {
    long previous = -1;
    while (at + 8 <= size_) {
      unsigned char b[8];
      if (!read(at, b, 2)) return false;
      if (u16(b, false) != 0x0002) return true;
      Element e;
      if (!element(at, size_, true, false, e)) return false;
      // A repeated or out-of-order element (two transfer syntaxes, found by fuzz_dicom) leaves
      // the syntax GDCM reads the data set in uncertain.
      if (static_cast<long>(e.number) <= previous)
        return fail(at, "meta group elements repeated or out of order");
      previous = static_cast<long>(e.number);
      if (e.length == kUndefinedLength || e.length > size_ - at - e.header)
        return fail(at, "a meta group element declares more bytes than the file holds");
      if (e.number == 0x0010 && e.length < 256) {
        std::string uid(static_cast<std::size_t>(e.length), '\0');
        if (!read(at + e.header, uid.data(), uid.size())) return false;
        while (!uid.empty() && (uid.back() == '\0' || uid.back() == ' ')) uid.pop_back();
        syntax = uid;
      }
      at += e.header + e.length;
    }
    // GDCM asserts on a partial element at the end of the meta group (found by fuzz_dicom).
    return fail(at, "the file ends inside its meta group");
  }

  /// The data set from `at` to the end of the file in the given encoding. `encapsulated`:
  /// pixel data may be a sequence of fragments.
  bool data_set(std::uint64_t at, bool explicit_vr, bool big_endian, bool encapsulated) {
    encapsulated_ = encapsulated;
    return elements(at, size_, explicit_vr, big_endian, false, 0);
  }

 private:
  struct Element {
    unsigned group = 0, number = 0;
    std::string vr;
    std::uint64_t length = 0, header = 8;
  };

  static unsigned u16(const unsigned char* p, bool be) {
    return be ? unsigned(p[0]) << 8 | p[1] : unsigned(p[1]) << 8 | p[0];
  }
  static std::uint32_t u32(const unsigned char* p, bool be) {
    return be ? std::uint32_t(p[0]) << 24 | std::uint32_t(p[1]) << 16 | std::uint32_t(p[2]) << 8 | p[3]
              : std::uint32_t(p[3]) << 24 | std::uint32_t(p[2]) << 16 | std::uint32_t(p[1]) << 8 | p[0];
  }

  bool fail(std::uint64_t at, const char* what) {
    if (what_.empty()) {
      what_ = what;
      where_ = at;
    }
    return false;
  }

  bool read(std::uint64_t at, void* to, std::size_t n) {
    if (n > size_ || at > size_ - n) return fail(at, "the file ends inside an element header");
    in_.clear();
    in_.seekg(static_cast<std::streamoff>(at));
    if (!in_.read(static_cast<char*>(to), static_cast<std::streamsize>(n)))
      return fail(at, "the file cannot be read");
    return true;
  }

  /// The header of the element at `at` (which must end by `end`). Items and delimiters (group
  /// FFFE) have no VR.
  bool element(std::uint64_t at, std::uint64_t end, bool explicit_vr, bool be, Element& e) {
    unsigned char b[12];
    if (at + 8 > end) return fail(at, "an element header runs past the end of what holds it");
    if (!read(at, b, 8)) return false;
    e.group = u16(b, be);
    e.number = u16(b + 2, be);
    e.vr.clear();
    e.header = 8;
    if (e.group == 0xfffe || !explicit_vr) {
      e.length = u32(b + 4, be);
      return true;
    }
    e.vr.assign(reinterpret_cast<const char*>(b + 4), 2);
    static const std::set<std::string> long_vrs = {"OB", "OD", "OF", "OL", "OV", "OW", "SQ",
                                                   "SV", "UC", "UN", "UR", "UT", "UV"};
    static const std::set<std::string> short_vrs = {"AE", "AS", "AT", "CS", "DA", "DS", "DT",
                                                    "FL", "FD", "IS", "LO", "LT", "PN", "SH",
                                                    "SL", "SS", "ST", "TM", "UI", "UL", "US"};
    if (long_vrs.count(e.vr)) {
      if (at + 12 > end) return fail(at, "an element header runs past the end of what holds it");
      if (!read(at + 8, b + 8, 4)) return false;
      e.header = 12;
      e.length = u32(b + 8, be);
      return true;
    }
    // GDCM reads an unknown VR with a 4-byte length: a walk cannot follow it.
    if (!short_vrs.count(e.vr)) return fail(at, "an unknown value representation");
    e.length = u16(b + 6, be);
    return true;
  }

  /// Elements from `at` up to `end`; `delimited`: an item of undefined length, which ends with
  /// its item delimiter (FFFE,E00D) instead. Leaves `at` after what was walked.
  bool elements(std::uint64_t& at, std::uint64_t end, bool ex, bool be, bool delimited,
                int depth) {
    while (at < end) {
      // Up to 3 bytes after the top-level data set (odd padding) end GDCM's read at a partial
      // tag, which it takes as the end of the file; 4 or more start an element.
      if (depth == 0 && end - at < 4) return true;
      Element e;
      const std::uint64_t here = at;
      if (!element(at, end, ex, be, e)) return false;
      at += e.header;
      if (e.group == 0xfffe) {
        if (delimited && e.number == 0xe00d && e.length == 0) return true;
        return fail(here, "an item or delimiter outside a sequence");
      }
      if (e.group == 0xffff) return fail(here, "an element of group FFFF");
      if ((!ex && (e.length == 13 || e.length == 0x31f031c)) ||
          (ex && e.group == 0x00ff && e.number == 0x4aa5) ||
          (ex && e.vr == "UL" && e.length == 6 && e.group == 0x0009))
        return fail(here, "an element GDCM would rewrite as written by an old broken writer");
      if (e.length == kUndefinedLength) {
        if (e.group == 0x7fe0 && e.number == 0x0010) {
          if (!(ex && encapsulated_ && (e.vr == "OB" || e.vr == "OW" || e.vr == "UN")))
            return fail(here, "pixel data of undefined length in an uncompressed transfer syntax");
          if (!fragments(at, end)) return false;
          continue;
        }
        if (ex && e.vr != "SQ" && e.vr != "UN")
          return fail(here, "an undefined length on an element that is not a sequence");
        // A UN element of undefined length holds implicit-VR items (DICOM CP-246).
        if (!sequence(at, end, true, ex && e.vr == "SQ", be, depth + 1)) return false;
        continue;
      }
      if (e.length > end - at) return fail(here, "an element declares more bytes than it has");
      // PS3.5 A.4: compressed pixel data are fragments of undefined length. GDCM reads a
      // defined length there through its workarounds for broken writers, taking item lengths
      // from the pixel bytes (fuzz_dicom: an 808 MB allocation from a 1 KB file).
      if (depth == 0 && encapsulated_ && e.group == 0x7fe0 && e.number == 0x0010)
        return fail(here, "pixel data of defined length in a compressed transfer syntax "
                          "(compressed pixel data are fragments of undefined length)");
      if (ex && e.vr == "SQ") {
        std::uint64_t inner = at;
        if (!sequence(inner, at + e.length, false, true, be, depth + 1)) return false;
      }
      at += e.length;
    }
    if (delimited) return fail(at, "an item without its delimiter");
    return true;
  }

  /// The items of a sequence from `at`: up to `end` (defined length) or to its sequence
  /// delimiter (FFFE,E0DD).
  bool sequence(std::uint64_t& at, std::uint64_t end, bool undefined, bool ex, bool be,
                int depth) {
    if (depth > kMaxDepth) return fail(at, "sequences nested too deep");
    while (undefined || at < end) {
      Element e;
      const std::uint64_t here = at;
      if (!element(at, end, false, be, e)) return false;
      at += 8;
      if (e.group == 0xfffe && e.number == 0xe0dd) {
        if (undefined && e.length == 0) return true;
        return fail(here, "a misplaced sequence delimiter");
      }
      if (e.group != 0xfffe || e.number != 0xe000)
        return fail(here, "an element where a sequence item should be");
      if (e.length == kUndefinedLength) {
        if (!elements(at, end, ex, be, true, depth)) return false;
        continue;
      }
      if (e.length > end - at) return fail(here, "an item declares more bytes than it has");
      std::uint64_t inner = at;
      if (!elements(inner, at + e.length, ex, be, false, depth)) return false;
      at += e.length;
    }
    return true;
  }

  /// The fragments of encapsulated pixel data: items of defined length, then the delimiter.
  bool fragments(std::uint64_t& at, std::uint64_t end) {
    for (;;) {
      Element e;
      const std::uint64_t here = at;
      if (!element(at, end, false, false, e)) return false;
      at += 8;
      if (e.group == 0xfffe && e.number == 0xe0dd && e.length == 0) return true;
      if (e.group != 0xfffe || e.number != 0xe000 || e.length == kUndefinedLength)
        return fail(here, "a damaged pixel data fragment");
      if (e.length > end - at) return fail(here, "a fragment declares more bytes than it has");
      at += e.length;
    }
  }

  std::ifstream& in_;
  std::uint64_t size_;
  bool encapsulated_ = false;
  std::string what_;
  std::uint64_t where_ = 0;
};

}  // namespace

void check_dicom_structure(const fs::path& file) {
  std::ifstream in(file, std::ios::binary);
  std::error_code ec;
  const std::uint64_t size = fs::file_size(file, ec);
  if (!in || ec) throw IoError(cat(file.string(), ": cannot read the file"));
  char magic[4] = {};
  in.seekg(128);
  in.read(magic, 4);
  std::uint64_t at = in && std::memcmp(magic, "DICM", 4) == 0 ? 132 : 0;
  const bool part10 = at == 132;
  DicomWalk walk(in, size);
  std::string syntax;
  bool ok = walk.meta_group(at, syntax);
  if (ok && part10 && syntax.empty()) {
    // A Part 10 file (DICM) must start with its meta group and name its transfer syntax; GDCM
    // asserts on one that does not (found by fuzz_dicom).
    throw IoError(cat(file.string(), ": the DICOM file has no transfer syntax in its meta "
                                     "group; the file is damaged: export the series again"));
  }
  if (ok && syntax == kDeflatedSyntax)
    throw InvalidInput(cat(
        file.string(), ": the data set is deflated (transfer syntax ", kDeflatedSyntax,
        ", Deflated Explicit VR Little Endian), which caps does not read: its inflated size "
        "cannot be bounded before GDCM inflates it; convert the series to an uncompressed "
        "transfer syntax first (e.g. `gdcmconv --raw in.dcm out.dcm`)"));
  if (ok) {
    bool explicit_vr = syntax != "1.2.840.10008.1.2";
    if (syntax.empty()) {
      // No meta group: GDCM takes the data set as explicit VR when the first element's bytes
      // 4-5 are a VR it knows, else implicit (gdcm::Reader::GuessTransferSyntax).
      unsigned char b[6] = {};
      in.clear();
      in.seekg(static_cast<std::streamoff>(at));
      in.read(reinterpret_cast<char*>(b), 6);
      static const std::string vrs =
          "AE AS AT CS DA DS DT FL FD IS LO LT OB OD OF OL OV OW PN SH SL SQ SS ST SV TM UC UI UL "
          "UN UR US UT UV";
      const std::string vr(reinterpret_cast<const char*>(b + 4), 2);
      explicit_vr = std::isupper(b[4]) && std::isupper(b[5]) && vrs.find(vr) != std::string::npos;
    }
    const bool native = syntax.empty() || syntax == "1.2.840.10008.1.2" ||
                        syntax == "1.2.840.10008.1.2.1" || syntax == "1.2.840.10008.1.2.2";
    ok = walk.data_set(at, explicit_vr, syntax == "1.2.840.10008.1.2.2", !native);
  }
  if (!ok)
    throw IoError(cat(file.string(), ": the DICOM file is truncated or damaged (",
                      walk.failure(), "); export the series again"));
}

}  // namespace caps::detail
