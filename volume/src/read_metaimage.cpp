// MetaImage (.mha with LOCAL data, .mhd with detached ElementDataFile), parsed here.
// Frame: MetaImage as written by ITK is LPS. TransformMatrix (alias Rotation, Orientation) holds
// 9 numbers; ITK's MetaImageIO writes direction column c (the LPS direction of image axis c) as the
// c-th triple, i.e. the row-major 3x3 is D^T, so D(r, c) = m[3 c + r]. Offset (alias Origin,
// Position) is the LPS position of voxel (0, 0, 0). AnatomicalOrientation is informational only
// (ITK ignores it on reading too).

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstring>
#include <fstream>
#include <map>
#include <sstream>

#include "caps/core/error.hpp"
#include "volume_io_detail.hpp"

#include <zlib.h>

namespace fs = std::filesystem;

namespace caps::detail {
namespace {

std::string trim(const std::string& s) {
  const auto b = s.find_first_not_of(" \t\r\n");
  if (b == std::string::npos) return "";
  const auto e = s.find_last_not_of(" \t\r\n");
  return s.substr(b, e - b + 1);
}

std::vector<double> numbers(const fs::path& file, const std::string& key, const std::string& text,
                            std::size_t expected) {
  std::istringstream in(text);
  std::vector<double> out;
  std::string tok;
  while (in >> tok) {
    char* end = nullptr;
    const double x = std::strtod(tok.c_str(), &end);
    if (end == tok.c_str() || *end != '\0' || !std::isfinite(x))
      throw InvalidInput(cat(file.string(), ": ", key, " = '", text, "' holds '", tok,
                             "', which is not a number"));
    out.push_back(x);
  }
  if (expected && out.size() != expected)
    throw InvalidInput(cat(file.string(), ": ", key, " = '", text, "' has ", out.size(),
                           " values, expected ", expected));
  return out;
}

bool is_true(const std::string& s) {
  const auto l = to_lower(s);
  return l == "true" || l == "1" || l == "yes";
}

std::string met_type(const fs::path& file, const std::string& t) {
  static const std::map<std::string, std::string> types = {
      {"MET_UCHAR", "u8"},  {"MET_CHAR", "i8"},      {"MET_USHORT", "u16"},
      {"MET_SHORT", "i16"}, {"MET_UINT", "u32"},     {"MET_INT", "i32"},
      {"MET_ULONG", "u32"}, {"MET_LONG", "i32"},     {"MET_ULONG_LONG", "u64"},
      {"MET_LONG_LONG", "i64"}, {"MET_FLOAT", "f32"}, {"MET_DOUBLE", "f64"}};
  const auto it = types.find(t);
  if (it == types.end())
    throw InvalidInput(cat(file.string(), ": ElementType = ", t,
                           " is not supported; caps reads MET_UCHAR/CHAR/USHORT/SHORT/UINT/INT/"
                           "FLOAT/DOUBLE scalar images"));
  return it->second;
}

std::vector<char> inflate_all(const fs::path& file, const char* src, std::size_t n,
                              std::size_t expected) {
  std::vector<char> out(expected);
  z_stream zs;
  std::memset(&zs, 0, sizeof zs);
  if (inflateInit2(&zs, 15 + 32) != Z_OK)  // +32: accept zlib or gzip headers
    throw IoError(cat(file.string(), ": zlib initialisation failed"));
  zs.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(src));
  zs.next_out = reinterpret_cast<Bytef*>(out.data());
  int rc = Z_OK;
  while (true) {
    // avail_* are 32-bit: feed at most 1 GB at a time; next_* advance by themselves.
    zs.avail_in = static_cast<uInt>(std::min<std::size_t>(n - zs.total_in, 1u << 30));
    zs.avail_out = static_cast<uInt>(std::min<std::size_t>(expected - zs.total_out, 1u << 30));
    rc = inflate(&zs, Z_NO_FLUSH);
    if (rc != Z_OK || zs.total_out >= expected) break;
  }
  // Inflating stops once the header's bytes are out: the stream must still end right after
  // them (its end marker and checksum), or it was cut short; 1 MiB more is looked through.
  if (rc == Z_OK && zs.total_out >= expected) {
    char scratch[1 << 12];
    std::size_t extra = 0;
    while (rc == Z_OK && extra < (std::size_t(1) << 20)) {
      zs.avail_in = static_cast<uInt>(std::min<std::size_t>(n - zs.total_in, 1u << 30));
      zs.next_out = reinterpret_cast<Bytef*>(scratch);
      zs.avail_out = sizeof scratch;
      const uLong before = zs.total_out;
      rc = inflate(&zs, Z_NO_FLUSH);
      extra += zs.total_out - before;
    }
    if (rc == Z_BUF_ERROR) {
      inflateEnd(&zs);
      throw IoError(cat(file.string(), ": the compressed data are cut short (the stream ends "
                        "without its end marker and checksum); the file is truncated: export "
                        "it again"));
    }
    if (rc == Z_OK) rc = Z_STREAM_END;  // more data than the header describes: not read
  }
  const std::size_t out_off = std::min<std::size_t>(zs.total_out, expected);
  inflateEnd(&zs);
  if (rc == Z_DATA_ERROR || rc == Z_MEM_ERROR || rc == Z_STREAM_ERROR || rc == Z_NEED_DICT)
    throw IoError(cat(file.string(), ": the compressed data are corrupt (zlib error ", rc,
                      "); re-export the file"));
  if (out_off != expected)
    throw IoError(cat(file.string(), ": the compressed data hold ", out_off,
                      " bytes but the header needs ", expected,
                      "; the file is truncated or the header is wrong"));
  return out;
}

}  // namespace

std::string slice_file_name(const fs::path& file, const std::string& field,
                            const std::string& pattern, long long i) {
  std::string out;
  int n_conversions = 0;
  for (std::size_t k = 0; k < pattern.size(); ++k) {
    if (pattern[k] != '%') {
      out += pattern[k];
      continue;
    }
    std::size_t j = k + 1;
    if (j < pattern.size() && pattern[j] == '%') {
      out += '%';
      k = j;
      continue;
    }
    const bool zero = j < pattern.size() && pattern[j] == '0';
    if (zero) ++j;
    int width = 0;
    while (j < pattern.size() && std::isdigit(static_cast<unsigned char>(pattern[j])) && width < 100)
      width = width * 10 + (pattern[j++] - '0');
    if (j >= pattern.size() || pattern[j] != 'd' || width > 32 || ++n_conversions > 1)
      throw InvalidInput(cat(file.string(), ": ", field, " pattern '", pattern,
                             "' is not a file name with one %d (or %0Nd) slice number"));
    std::string number = std::to_string(i < 0 ? -i : i);
    const std::size_t w = static_cast<std::size_t>(width) - (i < 0 ? 1 : 0);
    if (width > 0 && number.size() < w) number.insert(0, w - number.size(), zero ? '0' : ' ');
    out += (i < 0 ? "-" : "") + number;
    k = j;
  }
  if (n_conversions != 1)
    throw InvalidInput(cat(file.string(), ": ", field, " pattern '", pattern,
                           "' is not a file name with one %d (or %0Nd) slice number"));
  return out;
}

Volume read_metaimage(const fs::path& file, const ReadOptions& options) {
  const auto total_bytes = file_size_or_throw(file);
  const std::string name = file.string();
  std::ifstream in(file, std::ios::binary);
  if (!in) throw IoError(cat(name, ": cannot open the file for reading (permissions?)"));

  // Header: "Key = value" lines up to and including ElementDataFile.
  std::map<std::string, std::string> hdr;
  std::string line;
  std::uintmax_t data_start = 0;
  std::vector<std::string> list_files;
  bool found_data_file = false;
  int n_lines = 0;
  while (std::getline(in, line)) {
    if (++n_lines > 1000 || line.size() > 100000)
      throw InvalidInput(cat(name, ": no ElementDataFile line within the first 1000 header lines; "
                                   "not a MetaImage file"));
    const auto eq = line.find('=');
    if (eq == std::string::npos) {
      if (trim(line).empty()) continue;
      throw InvalidInput(cat(name, ": header line ", n_lines, " '", trim(line).substr(0, 60),
                             "' is not 'Key = value'; not a MetaImage file"));
    }
    const std::string key = trim(line.substr(0, eq));
    const std::string value = trim(line.substr(eq + 1));
    hdr[key] = value;
    if (key == "ElementDataFile") {
      found_data_file = true;
      data_start = static_cast<std::uintmax_t>(in.tellg());
      if (to_lower(value).rfind("list", 0) == 0)
        while (std::getline(in, line))
          if (!trim(line).empty()) list_files.push_back(trim(line));
      break;
    }
  }
  if (!found_data_file || hdr.count("NDims") == 0 || hdr.count("DimSize") == 0 ||
      hdr.count("ElementType") == 0)
    throw InvalidInput(cat(name, ": not a MetaImage header (needs NDims, DimSize, ElementType and "
                                 "ElementDataFile)"));

  const auto ndims_v = numbers(file, "NDims", hdr["NDims"], 1);
  const int ndims = ndims_v[0] == 2 ? 2 : ndims_v[0] == 3 ? 3 : 0;
  if (ndims != 2 && ndims != 3)
    throw InvalidInput(cat(name, ": NDims = ", hdr["NDims"], "; caps reads 3-D (or 2-D) images"));
  const auto dims_v = numbers(file, "DimSize", hdr["DimSize"], ndims);
  std::vector<long long> sizes;
  for (double d : dims_v) {
    if (d != std::floor(d))
      throw InvalidInput(cat(name, ": DimSize = ", hdr["DimSize"], " must hold integers"));
    sizes.push_back(static_cast<long long>(std::clamp(d, -1.0, 1e12)));  // check_dims refuses both ends
  }
  if (hdr.count("ElementNumberOfChannels") &&
      numbers(file, "ElementNumberOfChannels", hdr["ElementNumberOfChannels"], 1)[0] != 1)
    throw InvalidInput(cat(name, ": ElementNumberOfChannels = ", hdr["ElementNumberOfChannels"],
                           "; caps reads scalar images only"));
  const std::string type = met_type(file, hdr["ElementType"]);
  {
    double n = 1;
    for (long long s : sizes) n *= static_cast<double>(s);
    // Compressed data are held compressed and inflated: at most twice the raw bytes.
    const bool z = hdr.count("CompressedData") && is_true(hdr["CompressedData"]);
    check_dims(file, "DimSize", sizes, options, (z ? 2.0 : 1.0) * n * type_size(type));
  }

  Volume v;
  v.source = name;
  v.format = "MetaImage";
  auto& g = v.geom;
  g.dims = Eigen::Vector3i(static_cast<int>(sizes[0]), static_cast<int>(sizes[1]),
                           ndims == 3 ? static_cast<int>(sizes[2]) : 1);
  const std::size_t n_vox = g.n_voxels();
  const std::size_t n_bytes = n_vox * type_size(type);

  bool msb = false;
  for (const char* k : {"BinaryDataByteOrderMSB", "ElementByteOrderMSB"})
    if (hdr.count(k)) msb = is_true(hdr[k]);
  const bool compressed = hdr.count("CompressedData") && is_true(hdr["CompressedData"]);
  if (hdr.count("BinaryData") && !is_true(hdr["BinaryData"]))
    throw InvalidInput(cat(name, ": BinaryData = False (ASCII voxel data) is not supported; "
                                 "re-save the image as binary"));

  // Gather the raw (possibly compressed) bytes.
  std::vector<char> raw;
  const std::string data_file = hdr["ElementDataFile"];
  auto read_range = [&](const fs::path& f, std::uintmax_t offset, std::uintmax_t count) {
    std::ifstream d(f, std::ios::binary);
    if (!d) throw IoError(cat(f.string(), ": cannot open the data file named by ", name));
    d.seekg(static_cast<std::streamoff>(offset));
    const std::size_t old = raw.size();
    raw.resize(old + count);
    if (count && !d.read(raw.data() + old, static_cast<std::streamsize>(count)))
      throw IoError(cat(f.string(), ": read failed"));
  };
  std::uintmax_t header_size = 0;
  bool header_size_auto = false;
  if (hdr.count("HeaderSize")) {
    const double hs = numbers(file, "HeaderSize", hdr["HeaderSize"], 1)[0];
    if (hs == -1) header_size_auto = true;
    else if (hs >= 0 && hs <= static_cast<double>(total_bytes) + 1e9)
      header_size = static_cast<std::uintmax_t>(hs);  // larger ones fail the size checks below
    else throw InvalidInput(cat(name, ": HeaderSize = ", hdr["HeaderSize"], " is invalid or larger "
                                "than any file caps reads"));
  }
  std::uintmax_t compressed_size = 0;
  if (compressed && hdr.count("CompressedDataSize")) {
    const double cs = numbers(file, "CompressedDataSize", hdr["CompressedDataSize"], 1)[0];
    if (!(cs >= 0 && cs <= 1e15 && cs == std::floor(cs)))
      throw InvalidInput(cat(name, ": CompressedDataSize = ", hdr["CompressedDataSize"],
                             " is not a plausible byte count; the header is damaged"));
    compressed_size = static_cast<std::uintmax_t>(cs);
  }

  std::vector<fs::path> files;
  const fs::path dir = file.parent_path();
  if (data_file == "LOCAL") {
    const std::uintmax_t avail = total_bytes - data_start;
    std::uintmax_t want = compressed ? (compressed_size ? compressed_size : avail) : n_bytes;
    if (want > avail)
      throw IoError(cat(name, ": truncated: the header needs ", want,
                        " bytes of voxel data but only ", avail, " follow the header; "
                        "re-export or re-download it"));
    read_range(file, data_start, want);
  } else {
    if (!list_files.empty()) {
      for (const auto& f : list_files) files.push_back(dir / f);
    } else {
      // Pattern form: "name%03d.raw first last step".
      std::istringstream ps(data_file);
      std::string pattern;
      long long first = 0, last = 0, step = 1;
      ps >> pattern;
      if (pattern.find('%') != std::string::npos && (ps >> first >> last)) {
        if (!(ps >> step)) step = 1;
        if (step == 0 || (last - first) / step > 100000 || (last - first) / step < 0)
          throw InvalidInput(cat(name, ": ElementDataFile pattern '", data_file,
                                 "' has an invalid range"));
        for (long long i = first; step > 0 ? i <= last : i >= last; i += step) {
          files.push_back(dir / slice_file_name(file, "ElementDataFile", pattern, i));
        }
      } else {
        files.push_back(dir / data_file);
      }
    }
    if (files.size() == 1) {
      const auto size = file_size_or_throw(files[0]);
      std::uintmax_t offset = header_size;
      std::uintmax_t want = compressed ? (compressed_size ? compressed_size : size) : n_bytes;
      if (header_size_auto) offset = size >= want ? size - want : 0;
      if (!compressed && !header_size_auto && header_size == 0 && size > want)
        throw InvalidInput(cat(name, ": header/data size mismatch: ", files[0].string(), " has ",
                               size, " bytes but DimSize x ElementType (", hdr["DimSize"], ", ",
                               hdr["ElementType"], ") need ", want,
                               "; check DimSize/ElementType, or set HeaderSize if the data file "
                               "starts with a header"));
      if (offset + want > size)
        throw IoError(cat(files[0].string(), ": truncated: ", name, " needs ", want,
                          " bytes of voxel data", offset ? cat(" after ", offset, " header bytes") : "",
                          " but the file has ", size, "; re-export or re-download it"));
      read_range(files[0], offset, want);
    } else {
      if (compressed)
        throw InvalidInput(cat(name, ": compressed multi-file MetaImage data are not supported"));
      if (files.empty())
        throw InvalidInput(cat(name, ": ElementDataFile lists no data file; name the file(s) that "
                               "hold the voxels"));
      const std::size_t per_file = n_bytes / files.size();
      if (per_file * files.size() != n_bytes)
        throw InvalidInput(cat(name, ": ", files.size(), " data files do not divide ", n_bytes,
                               " bytes of voxel data evenly"));
      for (const auto& f : files) {
        const auto size = file_size_or_throw(f);
        if (size < header_size + per_file)
          throw IoError(cat(f.string(), ": truncated: holds ", size, " bytes, ", name,
                            " needs ", per_file + header_size));
        read_range(f, header_size_auto ? size - per_file : header_size, per_file);
      }
    }
  }
  if (compressed) raw = inflate_all(file, raw.data(), raw.size(), n_bytes);
  if (raw.size() != n_bytes)
    throw IoError(cat(name, ": holds ", raw.size(), " bytes of voxel data, the header needs ",
                      n_bytes));

  v.data.resize(n_vox);
  const bool host_msb = [] {
    const std::uint16_t one = 1;
    char c;
    std::memcpy(&c, &one, 1);
    return c == 0;
  }();
  decode_to_float(raw.data(), n_vox, type, msb != host_msb, v.data.data());
  raw.clear();
  raw.shrink_to_fit();

  // Geometry.
  for (const char* k : {"ElementSpacing", "ElementSize"})
    if (hdr.count(k)) {
      const auto s = numbers(file, k, hdr[k], ndims);
      for (int a = 0; a < ndims; ++a) g.spacing_mm[a] = s[a];
      break;
    }
  for (const char* k : {"Offset", "Origin", "Position"})
    if (hdr.count(k)) {
      const auto o = numbers(file, k, hdr[k], ndims);
      for (int a = 0; a < ndims; ++a) g.origin_lps[a] = o[a];
      break;
    }
  bool have_matrix = false;
  for (const char* k : {"TransformMatrix", "Rotation", "Orientation"})
    if (hdr.count(k)) {
      const auto m = numbers(file, k, hdr[k], static_cast<std::size_t>(ndims * ndims));
      for (int c = 0; c < ndims; ++c)
        for (int r = 0; r < ndims; ++r) g.direction(r, c) = m[ndims * c + r];
      have_matrix = true;
      break;
    }
  if (!have_matrix) v.notes.push_back("no TransformMatrix: identity direction assumed");
  if (ndims == 2) g.spacing_mm[2] = 1.0;
  for (int c = 0; c < 3; ++c) {
    if (g.spacing_mm[c] < 0) {
      g.spacing_mm[c] = -g.spacing_mm[c];
      g.direction.col(c) *= -1.0;
    }
  }
  for (int c = 0; c < 3; ++c) {
    const double n = g.direction.col(c).norm();
    if (n > 0) g.direction.col(c) /= n;
  }

  const std::string modality = hdr.count("Modality") ? hdr["Modality"] : "";
  if (modality == "MET_MOD_CT") {
    v.modality = Modality::CT;
    v.notes.push_back("modality CT from the Modality field");
  } else if (modality == "MET_MOD_MR") {
    v.modality = Modality::MR;
    v.notes.push_back("modality MR from the Modality field");
  } else {
    v.modality = guess_modality(v.data, v.notes);
  }
  validate_volume(v);
  return v;
}

}  // namespace caps::detail
