// InVesalius 3 projects (.inv3): a gzipped tar holding main.plist (an XML property list) and the
// volume as a raw numpy memmap. Keys used from main.plist: matrix/{filename, shape, dtype},
// spacing, modality, orientation, scalar_range.
//
// Layout and frame (checked on the Debian demo Cranium.inv3): matrix.shape is (n_slices, n_rows,
// n_cols), C order, so column index i varies fastest; spacing is (x, y, z) = (column, row,
// slice). InVesalius fills the memmap from VTK images, whose row 0 is the bottom of the DICOM
// image, so rows are flipped relative to DICOM: j runs towards anterior (the demo's nose and
// maxillary sinuses sit at high j, the table at j = 0), i keeps DICOM's column direction (patient
// left, +x) and the slice index k runs towards superior (the skull vault is at high k).
// direction = diag(1, -1, 1) in LPS. Left/right cannot be checked on anatomy (a head is nearly
// symmetric); it follows from InVesalius flipping rows only. The origin is not stored; voxel 0 is
// placed at (0, 0, 0).

#include <archive.h>
#include <archive_entry.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstring>
#include <fstream>
#include <map>
#include <memory>
#include <string>

#include "caps/core/error.hpp"
#include "volume_io_detail.hpp"

namespace fs = std::filesystem;

namespace caps::detail {
namespace {

/// A parsed property-list value.
struct PValue {
  enum Kind { kString, kInteger, kReal, kBool, kArray, kDict, kOther } kind = kOther;
  std::string text;
  std::vector<PValue> items;
  std::map<std::string, PValue> dict;

  const PValue* get(const std::string& key) const {
    const auto it = dict.find(key);
    return it == dict.end() ? nullptr : &it->second;
  }
  bool is_number() const { return kind == kInteger || kind == kReal; }
  double number() const { return std::strtod(text.c_str(), nullptr); }
};

/// Minimal parser for Apple XML property lists as Python's plistlib writes them.
class PlistParser {
 public:
  PlistParser(const std::string& text, std::string where) : s_(text), where_(std::move(where)) {}

  PValue parse() {
    skip_prolog();
    std::string tag = next_tag();
    if (tag.rfind("plist", 0) != 0) fail("expected <plist>");
    PValue v = parse_value(next_tag());
    return v;
  }

 private:
  [[noreturn]] void fail(const std::string& what) const {
    throw InvalidInput(cat(where_, ": malformed property list near byte ", pos_, " (", what,
                           "); the project file is damaged"));
  }

  void skip_ws() {
    while (pos_ < s_.size() && std::isspace(static_cast<unsigned char>(s_[pos_]))) ++pos_;
  }

  void skip_prolog() {
    while (true) {
      skip_ws();
      if (s_.compare(pos_, 2, "<?") == 0) {
        const auto e = s_.find("?>", pos_);
        if (e == std::string::npos) fail("unterminated <?");
        pos_ = e + 2;
      } else if (s_.compare(pos_, 4, "<!--") == 0) {
        const auto e = s_.find("-->", pos_);
        if (e == std::string::npos) fail("unterminated comment");
        pos_ = e + 3;
      } else if (s_.compare(pos_, 2, "<!") == 0) {
        const auto e = s_.find('>', pos_);
        if (e == std::string::npos) fail("unterminated <!");
        pos_ = e + 1;
      } else {
        return;
      }
    }
  }

  /// Reads the next tag's inside (without < >), skipping whitespace and comments.
  std::string next_tag() {
    skip_prolog();
    if (pos_ >= s_.size() || s_[pos_] != '<') fail("expected a tag");
    const auto e = s_.find('>', pos_);
    if (e == std::string::npos) fail("unterminated tag");
    std::string tag = s_.substr(pos_ + 1, e - pos_ - 1);
    pos_ = e + 1;
    return tag;
  }

  /// Text up to the closing </name>, with the five XML entities decoded.
  std::string text_until(const std::string& name) {
    const std::string close = "</" + name + ">";
    const auto e = s_.find(close, pos_);
    if (e == std::string::npos) fail("missing " + close);
    std::string raw = s_.substr(pos_, e - pos_);
    pos_ = e + close.size();
    std::string out;
    for (std::size_t i = 0; i < raw.size(); ++i) {
      if (raw[i] == '&') {
        static const std::pair<const char*, char> ents[] = {
            {"&amp;", '&'}, {"&lt;", '<'}, {"&gt;", '>'}, {"&quot;", '"'}, {"&apos;", '\''}};
        bool done = false;
        for (const auto& [ent, ch] : ents)
          if (raw.compare(i, std::strlen(ent), ent) == 0) {
            out += ch;
            i += std::strlen(ent) - 1;
            done = true;
            break;
          }
        if (!done) out += raw[i];
      } else {
        out += raw[i];
      }
    }
    return out;
  }

  PValue parse_value(const std::string& tag) {
    if (++depth_ > 64) fail("nesting too deep");
    PValue v;
    const bool empty = !tag.empty() && tag.back() == '/';
    const std::string name = empty ? tag.substr(0, tag.size() - 1) : tag;
    if (name == "dict") {
      v.kind = PValue::kDict;
      while (!empty) {
        std::string t = next_tag();
        if (t == "/dict") break;
        if (t != "key") fail("expected <key> in <dict>, got <" + t + ">");
        std::string key = text_until("key");
        v.dict[key] = parse_value(next_tag());
      }
    } else if (name == "array") {
      v.kind = PValue::kArray;
      while (!empty) {
        std::string t = next_tag();
        if (t == "/array") break;
        v.items.push_back(parse_value(t));
      }
    } else if (name == "true" || name == "false") {
      v.kind = PValue::kBool;
      v.text = name;
      if (!empty && next_tag() != "/" + name) fail("expected </" + name + ">");
    } else if (name == "string" || name == "integer" || name == "real" || name == "date" ||
               name == "data") {
      v.kind = name == "string"    ? PValue::kString
               : name == "integer" ? PValue::kInteger
               : name == "real"    ? PValue::kReal
                                   : PValue::kOther;
      if (!empty) v.text = text_until(name);
    } else {
      fail("unknown element <" + name + ">");
    }
    --depth_;
    return v;
  }

  const std::string& s_;
  std::string where_;
  std::size_t pos_ = 0;
  int depth_ = 0;
};

struct ArchiveFree {
  void operator()(archive* a) const { archive_read_free(a); }
};

std::string base_name(const std::string& entry) {
  const auto p = entry.find_last_of('/');
  return p == std::string::npos ? entry : entry.substr(p + 1);
}

/// Reads the first archive member whose base name is `wanted` into `out`; returns false if there
/// is none. Throws InvalidInput if the file is not a tar archive, IoError if it is damaged.
/// `to_end`: then walk the rest of the archive, so that one cut short after the member is an
/// IoError too.
bool extract_entry(const fs::path& file, const std::string& wanted, std::string& out,
                   std::uintmax_t max_bytes, bool to_end = false) {
  const std::string name = file.string();
  std::unique_ptr<archive, ArchiveFree> a(archive_read_new());
  archive_read_support_filter_all(a.get());
  archive_read_support_format_tar(a.get());
  archive_read_support_format_gnutar(a.get());
  if (archive_read_open_filename(a.get(), name.c_str(), 1 << 16) != ARCHIVE_OK)
    throw InvalidInput(cat(name, ": not an InVesalius project (expected a gzipped tar archive: ",
                           archive_error_string(a.get()) ? archive_error_string(a.get()) : "?",
                           ")"));
  archive_entry* entry = nullptr;
  int n_entries = 0;
  while (true) {
    const int rc = archive_read_next_header(a.get(), &entry);
    if (rc == ARCHIVE_EOF) break;
    if (rc != ARCHIVE_OK && rc != ARCHIVE_WARN) {
      const char* err = archive_error_string(a.get());
      if (n_entries == 0)
        throw InvalidInput(cat(name, ": not an InVesalius project (expected a gzipped tar "
                                     "archive: ", err ? err : "unreadable", ")"));
      throw IoError(cat(name, ": the archive is damaged or truncated after ", n_entries,
                        " entries (", err ? err : "?", "); re-save the project"));
    }
    ++n_entries;
    const char* path = archive_entry_pathname(entry);
    if (!path || base_name(path) != wanted) continue;
    const la_int64_t size = archive_entry_size(entry);
    if (size < 0 || static_cast<std::uintmax_t>(size) > max_bytes)
      throw InvalidInput(cat(name, ": archive member ", path, " has an implausible size ", size));
    // The declared size is a claim: grow the buffer with the data actually decompressed, so a
    // tiny archive that declares gigabytes allocates no more than it holds.
    const std::size_t declared = static_cast<std::size_t>(size);
    out.clear();
    std::size_t got = 0;
    while (got < declared) {
      if (out.size() == got)
        out.resize(got + std::min<std::size_t>(declared - got, std::max<std::size_t>(got, 1u << 20)));
      const la_ssize_t r = archive_read_data(a.get(), out.data() + got, out.size() - got);
      if (r < 0) {
        const char* err = archive_error_string(a.get());
        throw IoError(cat(name, ": reading archive member ", path, " failed (",
                          err ? err : "?", "); the project file is truncated or corrupt"));
      }
      if (r == 0) break;
      got += static_cast<std::size_t>(r);
    }
    if (got != declared)
      throw IoError(cat(name, ": archive member ", path, " holds ", got, " of its ", declared,
                        " bytes; the project file is truncated"));
    if (to_end) {
      // The archive must go on to its end: a gzip stream cut short after the member read
      // would pass unseen (libarchive reports it when the rest is walked). The member's name
      // is copied first: libarchive frees it with the next header (a use after free that
      // fuzz_inv3 found).
      const std::string member = path;
      for (;;) {
        const int next = archive_read_next_header(a.get(), &entry);
        if (next == ARCHIVE_EOF) break;
        if ((next != ARCHIVE_OK && next != ARCHIVE_WARN) ||
            archive_read_data_skip(a.get()) != ARCHIVE_OK) {
          const char* err = archive_error_string(a.get());
          throw IoError(cat(name, ": the archive is truncated or damaged after member ", member,
                            " (", err ? err : "?", "); re-save the project"));
        }
      }
    }
    return true;
  }
  return false;
}

std::string numpy_type(const std::string& dtype) {
  static const std::map<std::string, std::string> types = {
      {"int16", "i16"}, {"uint16", "u16"}, {"int8", "i8"},     {"uint8", "u8"},
      {"int32", "i32"}, {"uint32", "u32"}, {"float32", "f32"}, {"float64", "f64"},
      {"<i2", "i16"},   {"<u2", "u16"},    {"|i1", "i8"},      {"|u1", "u8"},
      {"<i4", "i32"},   {"<u4", "u32"},    {"<f4", "f32"},     {"<f8", "f64"}};
  const auto it = types.find(dtype);
  return it == types.end() ? "" : it->second;
}

}  // namespace

Volume read_inv3(const fs::path& file, const ReadOptions& options) {
  file_size_or_throw(file);
  const std::string name = file.string();

  std::string plist_text;
  if (!extract_entry(file, "main.plist", plist_text, 16u << 20))
    throw InvalidInput(cat(name, ": the archive has no main.plist; not an InVesalius 3 project"));
  const PValue root = PlistParser(plist_text, name + ":main.plist").parse();
  if (root.kind != PValue::kDict)
    throw InvalidInput(cat(name, ": main.plist is not a dictionary"));

  const PValue* matrix = root.get("matrix");
  if (!matrix || matrix->kind != PValue::kDict)
    throw InvalidInput(cat(name, ": main.plist has no 'matrix' entry; not an image project"));
  const PValue* fname = matrix->get("filename");
  const PValue* shape = matrix->get("shape");
  const PValue* dtype = matrix->get("dtype");
  if (!fname || fname->kind != PValue::kString || !shape || shape->kind != PValue::kArray ||
      shape->items.size() != 3 || !dtype || dtype->kind != PValue::kString)
    throw InvalidInput(cat(name, ": main.plist matrix needs filename, a 3-element shape and a "
                                 "dtype"));
  std::vector<long long> zyx;
  for (const auto& it : shape->items) {
    if (it.kind != PValue::kInteger)
      throw InvalidInput(cat(name, ": main.plist matrix.shape holds a non-integer '", it.text, "'"));
    zyx.push_back(std::atoll(it.text.c_str()));
  }
  const std::string type = numpy_type(dtype->text);
  if (type.empty())
    throw InvalidInput(cat(name, ": main.plist matrix.dtype = ", dtype->text,
                           " is not supported (int8/16/32, uint8/16/32, float32/64)"));
  check_dims(file, "matrix.shape", zyx, options,
             static_cast<double>(zyx[0]) * static_cast<double>(zyx[1]) *
                 static_cast<double>(zyx[2]) * static_cast<double>(type_size(type)));

  Volume v;
  v.source = name;
  v.format = "InVesalius";
  auto& g = v.geom;
  g.dims = Eigen::Vector3i(static_cast<int>(zyx[2]), static_cast<int>(zyx[1]),
                           static_cast<int>(zyx[0]));

  const PValue* spacing = root.get("spacing");
  if (!spacing || spacing->kind != PValue::kArray || spacing->items.size() != 3)
    throw InvalidInput(cat(name, ": main.plist needs a 3-element 'spacing'"));
  for (int a = 0; a < 3; ++a) {
    if (!spacing->items[a].is_number())
      throw InvalidInput(cat(name, ": main.plist spacing[", a, "] is not a number"));
    g.spacing_mm[a] = spacing->items[a].number();
  }

  const PValue* orientation = root.get("orientation");
  const std::string orient = orientation ? orientation->text : "1";
  if (orient != "1" && to_lower(orient) != "axial")
    throw InvalidInput(cat(name, ": main.plist orientation = ", orient,
                           "; caps reads axial InVesalius projects only (orientation 1); export "
                           "the volume from InVesalius as NIfTI or DICOM instead"));
  g.direction = Eigen::Vector3d(1, -1, 1).asDiagonal();
  g.origin_lps = Eigen::Vector3d::Zero();

  std::string raw;
  const std::size_t n_bytes = g.n_voxels() * type_size(type);
  if (!extract_entry(file, base_name(fname->text), raw, n_bytes + (1u << 20), true))
    throw InvalidInput(cat(name, ": the archive has no member '", fname->text,
                           "' named by main.plist matrix.filename"));
  // libarchive stops at the tar's end-of-archive blocks without reading on: a gzip stream cut
  // short after them (its CRC and length) would pass. Looked for up to the byte budget.
  {
    std::ifstream in(file, std::ios::binary);
    unsigned char magic[2] = {};
    in.read(reinterpret_cast<char*>(magic), 2);
    const double budget = std::isfinite(options.max_bytes) && options.max_bytes > 0
                              ? std::min(options.max_bytes, 1e18)
                              : 1e18;
    if (magic[0] == 0x1f && magic[1] == 0x8b)
      require_whole_gzip(file, file, 0, 0, static_cast<std::uint64_t>(budget));
  }
  if (raw.size() != n_bytes)
    throw InvalidInput(cat(name, ": ", fname->text, " holds ", raw.size(), " bytes but matrix.shape ",
                           zyx[0], "x", zyx[1], "x", zyx[2], " of ", dtype->text, " needs ",
                           n_bytes, "; the project is inconsistent"));
  v.data.resize(g.n_voxels());
  // numpy memmaps are written in the writer's native order; InVesalius runs on little-endian
  // machines and plistlib dtype names carry no byte order.
  decode_to_float(raw.data(), v.data.size(), type, false, v.data.data());

  const PValue* modality = root.get("modality");
  const std::string mod = modality ? modality->text : "";
  if (mod == "CT") {
    v.modality = Modality::CT;
  } else if (mod == "MRI" || mod == "MR") {
    v.modality = Modality::MR;
  } else {
    v.modality = guess_modality(v.data, v.notes);
  }
  v.notes.push_back(cat("InVesalius project '", root.get("name") ? root.get("name")->text : "",
                        "', modality field '", mod, "'; origin not stored, voxel 0 placed at 0"));
  validate_volume(v);
  return v;
}

}  // namespace caps::detail
