// NRRD (.nrrd, and .nhdr with detached data) through teem's nrrdLoad, which handles the raw,
// ascii, gzip and bzip2 encodings and `data file:` lists and patterns. The header is read first
// without data so that damaged or absurd headers are rejected before any large allocation, and so
// that a failure in the second (data) pass can be reported as a truncated/missing data file.

#include <cctype>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <memory>
#include <string>

#include "caps/core/error.hpp"
#include "volume_io_detail.hpp"

#include <Eigen/Geometry>
#include <teem/biff.h>
#include <teem/nrrd.h>

namespace fs = std::filesystem;

namespace caps::detail {
namespace {

struct NrrdFree {
  void operator()(Nrrd* n) const { nrrdNuke(n); }
};
struct IoStateFree {
  void operator()(NrrdIoState* s) const { nrrdIoStateNix(s); }
};

std::string teem_error() {
  char* err = biffGetDone(NRRD);
  std::string msg = err ? err : "unknown teem error";
  std::free(err);
  while (!msg.empty() && (msg.back() == '\n' || msg.back() == ' ')) msg.pop_back();
  // teem prefixes every line with the function name; keep the message on one line.
  for (auto& c : msg)
    if (c == '\n') c = ';';
  return msg;
}

std::string nrrd_element_type(int type) {
  switch (type) {
    case nrrdTypeChar: return "i8";
    case nrrdTypeUChar: return "u8";
    case nrrdTypeShort: return "i16";
    case nrrdTypeUShort: return "u16";
    case nrrdTypeInt: return "i32";
    case nrrdTypeUInt: return "u32";
    case nrrdTypeLLong: return "i64";
    case nrrdTypeULLong: return "u64";
    case nrrdTypeFloat: return "f32";
    case nrrdTypeDouble: return "f64";
    default: return "";
  }
}

// The header's lines (up to the blank line that ends it, at most 1 MiB), for the fields whose
// meaning teem loses: teem stores both a missing spacing and "nan" as NaN.
std::vector<std::string> header_lines(const fs::path& file) {
  std::ifstream in(file, std::ios::binary);
  std::vector<std::string> lines;
  std::string line;
  std::size_t total = 0;
  while (std::getline(in, line) && total < (1u << 20)) {
    total += line.size() + 1;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.empty() && !lines.empty()) break;
    lines.push_back(line);
  }
  return lines;
}

// A detached data file's path: as the header names it, relative to the header's folder.
fs::path data_file_path(const fs::path& header, const std::string& name) {
  const fs::path data = name;
  return data.is_relative() ? header.parent_path() / data : data;
}

// teem's nrrdLoad reads several formats and picks one by the file's first bytes: a file without
// the NRRD magic goes to its plain-text, PNM, PNG, VTK or EPS readers, and the plain-text reader
// loses its value array (8 KB) on every file it refuses (found by fuzz/fuzz_nrrd.cpp: the process
// grew about 2 KB an execution; valgrind on teem alone: "definitely lost" in airArrayNew under
// _nrrdRead). caps reads NRRD through this reader, so the magic is checked before teem opens
// the file: the whole first line must be one teem knows, "NRRD0001" to "NRRD0005" (a first line
// "NRRD0003og..." took the plain-text path too).
void check_magic(const fs::path& file, const std::vector<std::string>& lines) {
  const std::string first = lines.empty() ? std::string() : lines.front();
  const bool magic = first.size() == 8 && first.compare(0, 7, "NRRD000") == 0 &&
                     first[7] >= '1' && first[7] <= '5';
  if (!magic)
    throw InvalidInput(cat(file.string(), ": not a NRRD file (its first line is not the NRRD "
                           "magic 'NRRD0004' or another version); give a .nrrd or .nhdr written "
                           "by a NRRD writer such as 3D Slicer, ITK or teem"));
}

// teem copies a header field's text into fixed buffers when it has more than the values it
// expects, and overflows its stack on a field line longer than about 1000 characters (found by
// fuzz/fuzz_nrrd.cpp): such lines are refused before teem reads the header. Comments and
// key:=value lines are exempt (teem keeps them whole). A line is a key:=value line for teem only
// when no field ("sizes: ...") comes first: a 1900-byte sizes line with NUL bytes and a ":="
// near its end passed as one, and teem overflowed formatting it into its error message
// (fuzz_nrrd; an abort in the release build too). So the ":=" must hold the line's first colon.
constexpr std::size_t kMaxNrrdFieldChars = 512;

void check_field_lengths(const fs::path& file, const std::vector<std::string>& lines) {
  for (std::size_t i = 0; i < lines.size(); ++i) {
    const std::string& line = lines[i];
    const std::size_t mark = line.find(":=");
    const bool key_value = mark != std::string::npos && mark == line.find(':');
    if (line.size() <= kMaxNrrdFieldChars || line[0] == '#' || key_value)
      continue;
    throw InvalidInput(cat(file.string(), ": header line ", i + 1, " ('", line.substr(0, 40),
                           "...') is ", line.size(), " characters long; a NRRD field holds at "
                           "most ", kMaxNrrdFieldChars, ": the header is damaged"));
  }
}

// Refuses a spacing or space direction written as NaN (teem reads "nan" as "unknown" and caps
// would take 1 mm): the voxel size must be known to measure a patient.
void check_no_nan_spacing(const fs::path& file, const std::vector<std::string>& lines) {
  for (const std::string& line : lines) {
    const auto colon = line.find(':');
    if (colon == std::string::npos) continue;
    const std::string field = to_lower(line.substr(0, colon));
    if (field != "spacings" && field != "space directions" && field != "thicknesses" &&
        field != "space origin")
      continue;
    const std::string value = to_lower(line.substr(colon + 1));
    if (value.find("nan") != std::string::npos || value.find("inf") != std::string::npos)
      throw InvalidInput(cat(file.string(), ": '", line, "': the voxel size or position is not a "
                             "finite number; write the scanner's spacing into the header (a NaN "
                             "spacing would be read as 1 mm)"));
  }
}

// A detached raw data file must hold exactly the bytes the header describes: a larger one means
// that the header's sizes or type do not describe the file (teem would read its first bytes); a
// smaller one is truncated, and teem, failing to read it, would leave it open (a FILE and a file
// descriptor lost on every read; found by fuzz/fuzz_nrrd.cpp, valgrind --track-fds).
void check_detached_size(const fs::path& file, const NrrdIoState& nio, double n_bytes) {
  if (!nio.encoding || std::string(nio.encoding->name) != "raw" || nio.dataFNFormat ||
      !nio.dataFNArr || nio.dataFNArr->len != 1 || nio.byteSkip != 0 || nio.lineSkip != 0 ||
      nio.dataFSkip)
    return;
  const std::string data_name = nio.dataFN[0];
  if (data_name == "LIST") return;
  const fs::path data = data_file_path(file, data_name);
  std::error_code ec;
  const auto size = fs::file_size(data, ec);
  if (ec) return;  // missing: the data pass reports it
  if (static_cast<double>(size) < n_bytes)
    throw IoError(cat(file.string(), ": the data file ", data.string(), " holds ", size,
                      " bytes but the header's sizes and type describe ",
                      static_cast<std::uintmax_t>(n_bytes),
                      "; the data file is truncated (copy it again) or the header's sizes are "
                      "wrong"));
  if (static_cast<double>(size) > n_bytes)
    throw InvalidInput(cat(file.string(), ": the data file ", data.string(), " holds ", size,
                           " bytes but the header's sizes and type describe ",
                           static_cast<std::uintmax_t>(n_bytes),
                           "; the header does not match the data (check sizes, type and data "
                           "file)"));
}

// teem opens each detached data file with fopen and, when reading it fails, does not close it:
// a data file that is a folder (an empty name, or one cut short by a NUL byte, names the
// header's own folder) leaked a FILE and its descriptor on every read (found by
// fuzz/fuzz_nrrd.cpp, the process growing 4 KB a read; massif: fopen's buffer under
// nrrdByteSkip). Every named data file must be a file, or missing (teem reports that cleanly).
void check_data_files_are_files(const fs::path& file, const NrrdIoState& nio) {
  if (nio.dataFNFormat || !nio.dataFNArr) return;
  for (unsigned i = 0; i < nio.dataFNArr->len; ++i) {
    const std::string name = nio.dataFN[i] ? nio.dataFN[i] : "";
    if (name == "LIST") continue;
    std::error_code ec;
    if (name.empty() || fs::is_directory(data_file_path(file, name), ec))
      throw InvalidInput(cat(file.string(), ": data file ", i + 1, " ('", name, "') is ",
                             name.empty() ? "empty" : "a folder",
                             "; the header's 'data file' must name the file of its voxels"));
  }
}

// The byte offset of an attached header's data: just after the blank line that ends the header
// (lines end in \n or \r\n); 0 if there is none in the first MiB.
std::uint64_t attached_data_offset(const fs::path& file) {
  std::ifstream in(file, std::ios::binary);
  std::string head(1u << 20, '\0');
  in.read(head.data(), static_cast<std::streamsize>(head.size()));
  head.resize(static_cast<std::size_t>(in.gcount()));
  for (std::size_t i = head.find('\n'); i != std::string::npos; i = head.find('\n', i + 1)) {
    if (i + 1 < head.size() && head[i + 1] == '\n') return i + 2;
    if (i + 2 < head.size() && head[i + 1] == '\r' && head[i + 2] == '\n') return i + 3;
  }
  return 0;
}

// teem's gzip decoding stops once it has the header's bytes: a stream cut short after them
// would pass. Checked for attached data and a single detached file without skips (a list or
// pattern of files, or byte/line skips, are read by teem alone).
void check_gzip_whole(const fs::path& file, const NrrdIoState& nio, double n_bytes) {
  if (!nio.encoding || std::string(nio.encoding->name) != "gzip" || nio.byteSkip != 0 ||
      nio.lineSkip != 0 || nio.dataFNFormat || !nio.dataFNArr)
    return;
  const auto needed = static_cast<std::uint64_t>(n_bytes);
  if (nio.dataFNArr->len == 0) {
    const std::uint64_t offset = attached_data_offset(file);
    if (offset > 0) require_whole_gzip(file, file, offset, needed);
    return;
  }
  if (nio.dataFNArr->len != 1 || nio.dataFSkip) return;
  const std::string data_name = nio.dataFN[0];
  if (data_name == "LIST") return;
  const fs::path data = data_file_path(file, data_name);
  require_whole_gzip(file, data, 0, needed);
}

}  // namespace

Volume read_nrrd(const fs::path& file, const ReadOptions& options) {
  file_size_or_throw(file);
  const std::string name = file.string();

  const std::vector<std::string> lines = header_lines(file);
  check_magic(file, lines);
  check_field_lengths(file, lines);
  std::unique_ptr<Nrrd, NrrdFree> header(nrrdNew());
  std::unique_ptr<NrrdIoState, IoStateFree> nio(nrrdIoStateNew());
  nio->skipData = AIR_TRUE;
  if (nrrdLoad(header.get(), name.c_str(), nio.get()) != 0)
    throw InvalidInput(cat(name, ": not a readable NRRD header (", teem_error(),
                           "); check the header fields"));

  const unsigned dim = header->dim;
  if (dim != 3 && dim != 2)
    throw InvalidInput(cat(name, ": dimension = ", dim,
                           "; caps reads scalar 3-D (or 2-D) NRRD images only"));
  std::vector<long long> sizes;
  for (unsigned a = 0; a < dim; ++a) sizes.push_back(static_cast<long long>(header->axis[a].size));
  const std::string type = nrrd_element_type(header->type);
  if (type.empty())
    throw InvalidInput(cat(name, ": type ", header->type,
                           " is not a scalar numeric type; caps reads integer and float images"));
  double n_vox = 1;
  for (long long s : sizes) n_vox *= static_cast<double>(s);
  check_dims(file, "sizes", sizes, options, n_vox * static_cast<double>(type_size(type)));
  check_no_nan_spacing(file, lines);
  // teem expands a "data file" pattern with sprintf: only a plain %d pattern may reach it.
  if (nio->dataFNFormat)
    (void)slice_file_name(file, "data file", nio->dataFNFormat, nio->dataFNMin);
  check_data_files_are_files(file, *nio);
  check_detached_size(file, *nio, n_vox * static_cast<double>(type_size(type)));

  std::unique_ptr<Nrrd, NrrdFree> nrrd(nrrdNew());
  if (nrrdLoad(nrrd.get(), name.c_str(), nullptr) != 0 || nrrd->data == nullptr)
    throw IoError(cat(name, ": the voxel data could not be read (", teem_error(),
                      "); a detached data file is missing or truncated, or the compressed data "
                      "are corrupt"));
  check_gzip_whole(file, *nio, n_vox * static_cast<double>(type_size(type)));

  Volume v;
  v.source = name;
  v.format = "NRRD";
  auto& g = v.geom;
  g.dims = Eigen::Vector3i(static_cast<int>(sizes[0]), static_cast<int>(sizes[1]),
                           dim == 3 ? static_cast<int>(sizes[2]) : 1);
  v.data.resize(g.n_voxels());
  decode_to_float(static_cast<const char*>(nrrd->data), v.data.size(), type, false,
                  v.data.data());
  if (dim == 2) v.notes.push_back("2-D image read as a single slice, slice spacing 1 mm");

  bool have_directions = nrrd->spaceDim == 3;
  for (unsigned a = 0; a < dim && have_directions; ++a)
    for (int r = 0; r < 3; ++r) have_directions &= std::isfinite(nrrd->axis[a].spaceDirection[r]);

  if (have_directions) {
    Eigen::Matrix3d M = Eigen::Matrix3d::Zero();
    for (unsigned a = 0; a < dim; ++a)
      for (int r = 0; r < 3; ++r) M(r, a) = nrrd->axis[a].spaceDirection[r];
    if (dim == 2) M.col(2) = M.col(0).cross(M.col(1)).normalized();
    Eigen::Vector3d origin = Eigen::Vector3d::Zero();
    if (std::isfinite(nrrd->spaceOrigin[0]) && std::isfinite(nrrd->spaceOrigin[1]) &&
        std::isfinite(nrrd->spaceOrigin[2]))
      origin = Eigen::Vector3d(nrrd->spaceOrigin[0], nrrd->spaceOrigin[1], nrrd->spaceOrigin[2]);
    else
      v.notes.push_back("no space origin: voxel 0 placed at the origin");

    Eigen::Vector3d flip(1, 1, 1);
    switch (nrrd->space) {
      case nrrdSpaceLeftPosteriorSuperior: break;
      case nrrdSpaceRightAnteriorSuperior: flip = {-1, -1, 1}; break;
      case nrrdSpaceLeftAnteriorSuperior: flip = {1, -1, 1}; break;
      case nrrdSpaceScannerXYZ:
        v.notes.push_back("space scanner-xyz taken as DICOM patient axes (LPS)");
        break;
      case nrrdSpace3DRightHanded:
      case nrrdSpace3DLeftHanded:
      case nrrdSpaceUnknown:
        v.notes.push_back("the NRRD space is not anatomical; its axes were taken as LPS, so "
                          "check left/right before planning");
        break;
      default:
        throw InvalidInput(cat(name, ": space '", airEnumStr(nrrdSpace, nrrd->space),
                               "' is not a 3-D anatomical space; caps reads 3-D images only"));
    }
    const Eigen::Matrix3d F = flip.asDiagonal();
    const Eigen::Matrix3d A = F * M;
    origin = F * origin;
    for (int c = 0; c < 3; ++c) {
      g.spacing_mm[c] = A.col(c).norm();
      if (g.spacing_mm[c] > 0) g.direction.col(c) = A.col(c) / g.spacing_mm[c];
    }
    if (dim == 2) g.spacing_mm[2] = 1.0;
    g.origin_lps = origin;
  } else {
    bool missing = false;
    for (unsigned a = 0; a < dim; ++a) {
      const double s = nrrd->axis[a].spacing;
      if (std::isfinite(s) && s != 0.0) {
        g.spacing_mm[a] = std::abs(s);
        if (s < 0) g.direction(a, a) = -1.0;
      } else {
        missing = true;
      }
    }
    if (std::isfinite(nrrd->spaceOrigin[0]) && nrrd->spaceDim == 3)
      g.origin_lps = Eigen::Vector3d(nrrd->spaceOrigin[0], nrrd->spaceOrigin[1],
                                     nrrd->spaceOrigin[2]);
    v.notes.push_back(cat("no space directions: axes taken as LPS with spacings ",
                          g.spacing_mm.transpose(), " mm", missing ? " (missing ones set to 1)" : "",
                          "; the true patient orientation is unknown"));
  }
  for (unsigned a = 0; a < nrrd->spaceDim && a < NRRD_SPACE_DIM_MAX; ++a) {
    const char* unit = nrrd->spaceUnits[a];
    if (unit && *unit && to_lower(unit) != "mm" && to_lower(unit) != "millimeter" &&
        to_lower(unit) != "millimeters")
      v.notes.push_back(cat("space unit '", unit, "' along axis ", a, " ignored; read as mm"));
  }

  v.modality = guess_modality(v.data, v.notes);
  validate_volume(v);
  return v;
}

}  // namespace caps::detail
