// DICOM series reading through GDCM.
//
// Geometry: DICOM patient coordinates are already LPS. Row direction r and column direction c
// come from ImageOrientationPatient, the slice normal is n = r x c, and slices are sorted by
// d = ImagePositionPatient . n. PixelSpacing is (row spacing, column spacing), so the spacing
// along i (= r) is PixelSpacing[1] and along j (= c) is PixelSpacing[0].
//
// A stack with equal gaps and no in-plane shift between slices is copied as is. Otherwise
// (uneven gaps and/or gantry tilt, where each slice is shifted in-plane) it is resampled onto the
// orthogonal grid (r, c, n) with slice spacing = the smallest gap: each output voxel is
// interpolated bilinearly in-plane inside the two bracketing (sheared) slices and linearly
// between them. The in-plane grid is grown so that every slice's field of view is kept.
//
// Missing-slice rule: gap g_i is a missing slice when, for each neighbouring gap g_n that exists
// (i-1, i+1), g_i is within 5% of an integer multiple k >= 2 of g_n. A deleted file in a uniform
// run gives exactly that (2g between g and g), while genuinely mixed spacing (a 4 mm run followed
// by a 7 mm run, with a 1.08 mm junction gap) does not, because a run's first or last gap always
// has a neighbour of the same size. Missing slices are an InvalidInput unless
// ReadOptions::allow_missing_slices is set, which interpolates across them and adds a note.

#include <algorithm>
#include <chrono>
#include <csignal>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <set>
#include <sstream>
#include <thread>

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/wait.h>
#include <unistd.h>

#include "caps/core/error.hpp"
#include "caps/core/units.hpp"
#include "dicom_codestream.hpp"
#include "dicom_structure.hpp"
#include "volume_io_detail.hpp"

#include <Eigen/Geometry>
#include <gdcmImage.h>
#include <gdcmPixelFormat.h>
#include <gdcmReader.h>
#include <gdcmSequenceOfFragments.h>
#include <gdcmSequenceOfItems.h>
#include <gdcmStringFilter.h>
#include <gdcmTrace.h>
#include <tbb/parallel_for.h>

namespace fs = std::filesystem;

// Defined only when a sanitizer runtime is linked (scripts/sanitize.sh, fuzz/).
extern "C" void __sanitizer_set_death_callback(void (*callback)(void)) __attribute__((weak));

namespace caps {
namespace detail {
namespace {

struct SliceHeader {
  fs::path file;
  std::string series_uid, description, modality, transfer_syntax;
  std::string patient_id, patient_name, study_uid;
  std::vector<double> ipp, iop, pixel_spacing;
  int rows = 0, cols = 0, frames = 1, instance = 0;
  double slope = 1.0, intercept = 0.0;
  double d = 0.0;  // position along the slice normal
  int bits_allocated = 16, bits_stored = 0, pixel_representation = 0, samples_per_pixel = 1;
  std::string photometric;
  bool encapsulated = false, big_endian = false;
  bool has_pixel_data = false;             // a PixelData (7FE0,0010) element is present
  std::uintmax_t pixel_bytes_in_file = 0;  // file size minus the offset of the PixelData value
  std::vector<double> frame_offsets;       // GridFrameOffsetVector (3004,000C) of an RT dose
};

std::string trim(std::string s) {
  while (!s.empty() && (s.back() == ' ' || s.back() == '\0')) s.pop_back();
  std::size_t b = 0;
  while (b < s.size() && s[b] == ' ') ++b;
  return s.substr(b);
}

std::vector<double> split_numbers(const std::string& s) {
  std::vector<double> out;
  std::stringstream in(s);
  std::string tok;
  while (std::getline(in, tok, '\\')) {
    tok = trim(tok);
    if (tok.empty()) continue;
    char* end = nullptr;
    const double x = std::strtod(tok.c_str(), &end);
    if (end == tok.c_str()) return {};
    out.push_back(x);
  }
  return out;
}

void quiet_gdcm() {
  gdcm::Trace::DebugOff();
  gdcm::Trace::WarningOff();
  gdcm::Trace::ErrorOff();
}

/// True if `file` starts like DICOM: the 'DICM' magic after the 128-byte preamble (Part 10), or,
/// for files without one, a first element in group 0002 or 0008 (little endian). GDCM asserts
/// (aborting the process) on some short non-DICOM files, so nothing else reaches it.
bool looks_like_dicom(const fs::path& file) {
  std::ifstream in(file, std::ios::binary);
  if (!in) return false;
  char b[132] = {};
  in.read(b, sizeof b);
  const std::streamsize n = in.gcount();
  if (n == 132 && std::memcmp(b + 128, "DICM", 4) == 0) return true;
  if (n < 132) return false;  // too short for any image header
  const unsigned group = static_cast<unsigned char>(b[0]) | (static_cast<unsigned char>(b[1]) << 8);
  const unsigned element = static_cast<unsigned char>(b[2]) | (static_cast<unsigned char>(b[3]) << 8);
  return (group == 0x0002 || group == 0x0008) && element < 0x0100;
}

/// Reads the header of one file; returns false if it is not a DICOM image with a series UID.
bool read_header(const fs::path& file, SliceHeader& h) {
  if (!looks_like_dicom(file)) return false;
  check_dicom_structure(file);
  gdcm::Reader reader;
  reader.SetFileName(file.c_str());
  const gdcm::Tag pixel_data(0x7fe0, 0x0010);
  if (!reader.ReadUpToTag(pixel_data, std::set<gdcm::Tag>{pixel_data})) return false;
  const gdcm::DataSet& ds = reader.GetFile().GetDataSet();
  if (!ds.FindDataElement(gdcm::Tag(0x0020, 0x000e))) return false;
  gdcm::StringFilter sf;
  sf.SetFile(reader.GetFile());
  auto str = [&](uint16_t g, uint16_t e) {
    const gdcm::Tag t(g, e);
    return ds.FindDataElement(t) ? trim(sf.ToString(t)) : std::string();
  };
  // GDCM asserts (aborting the process) on SamplesPerPixel above 4 (found by fuzz_dicom).
  const std::string spp = str(0x0028, 0x0002);
  if (!spp.empty() && !(std::atoi(spp.c_str()) >= 1 && std::atoi(spp.c_str()) <= 4))
    throw InvalidInput(cat(file.string(), ": SamplesPerPixel (0028,0002) = ", spp,
                           " is not 1 to 4; the file is damaged"));
  h.file = file;
  h.series_uid = str(0x0020, 0x000e);
  if (h.series_uid.empty()) return false;
  h.patient_name = str(0x0010, 0x0010);
  h.patient_id = str(0x0010, 0x0020);
  h.study_uid = str(0x0020, 0x000d);
  h.description = str(0x0008, 0x103e);
  h.modality = str(0x0008, 0x0060);
  h.ipp = split_numbers(str(0x0020, 0x0032));
  h.iop = split_numbers(str(0x0020, 0x0037));
  h.pixel_spacing = split_numbers(str(0x0028, 0x0030));
  h.frame_offsets = split_numbers(str(0x3004, 0x000c));
  h.rows = std::atoi(str(0x0028, 0x0010).c_str());
  h.cols = std::atoi(str(0x0028, 0x0011).c_str());
  const std::string frames = str(0x0028, 0x0008);
  if (!frames.empty() && frames.find_first_not_of("+0123456789") != std::string::npos)
    throw InvalidInput(cat(file.string(), ": NumberOfFrames (0028,0008) = '", frames,
                           "' is not a whole number; the file is damaged"));
  h.frames = frames.empty() ? 1 : std::atoi(frames.c_str());
  h.instance = std::atoi(str(0x0020, 0x0013).c_str());
  const auto slope = split_numbers(str(0x0028, 0x1053));
  const auto intercept = split_numbers(str(0x0028, 0x1052));
  if (slope.size() == 1 && (!std::isfinite(slope[0]) || slope[0] == 0.0))
    throw InvalidInput(cat(file.string(), ": RescaleSlope (0028,1053) = ", str(0x0028, 0x1053),
                           " would map every pixel to one value; the file is damaged"));
  if (slope.size() == 1) h.slope = slope[0];
  if (intercept.size() == 1 && std::isfinite(intercept[0])) h.intercept = intercept[0];
  const gdcm::TransferSyntax& ts = reader.GetFile().GetHeader().GetDataSetTransferSyntax();
  h.transfer_syntax = ts.GetString() ? ts.GetString() : "";
  h.encapsulated = ts.IsEncapsulated();
  h.big_endian = ts == gdcm::TransferSyntax::ExplicitVRBigEndian;
  const std::string bits = str(0x0028, 0x0100);
  if (!bits.empty()) h.bits_allocated = std::atoi(bits.c_str());
  h.bits_stored = std::atoi(str(0x0028, 0x0101).c_str());
  h.pixel_representation = std::atoi(str(0x0028, 0x0103).c_str());
  if (!spp.empty()) h.samples_per_pixel = std::atoi(spp.c_str());
  h.photometric = str(0x0028, 0x0004);
  // ReadUpToTag stops just after the PixelData element header, so the rest of the file is what
  // the pixel data can hold; GDCM itself pads short native pixel data with a mere warning.
  std::error_code ec;
  const auto size = fs::file_size(file, ec);
  const auto pos = reader.GetStreamCurrentPosition();
  h.pixel_bytes_in_file = !ec && size > pos ? size - pos : 0;
  // ReadUpToTag leaves the PixelData element out of the data set: bytes left after the point
  // where it stopped say that one was found.
  h.has_pixel_data = h.pixel_bytes_in_file > 0;
  return true;
}

/// All DICOM image headers under `folder` (recursively), and how many files were not DICOM.
/// A damaged file refuses the folder, unless `damaged` is given: then it is listed there
/// ("name: why") and left out.
std::vector<SliceHeader> scan_folder(const fs::path& folder, int& n_skipped,
                                     std::vector<std::string>* damaged = nullptr) {
  quiet_gdcm();
  std::vector<SliceHeader> out;
  n_skipped = 0;
  std::error_code ec;
  fs::recursive_directory_iterator it(folder, fs::directory_options::skip_permission_denied, ec);
  if (ec) throw IoError(cat(folder.string(), ": cannot list the folder: ", ec.message()));
  std::vector<fs::path> files;
  for (; it != fs::recursive_directory_iterator(); it.increment(ec)) {
    if (ec) throw IoError(cat(folder.string(), ": cannot list the folder: ", ec.message()));
    const auto& p = it->path();
    if (!it->is_regular_file(ec)) continue;
    const std::string base = p.filename().string();
    if (base.empty() || base[0] == '.' || base == "DICOMDIR") continue;
    files.push_back(p);
    if (files.size() > 200000)
      throw InvalidInput(cat(folder.string(), ": holds more than 200000 files; point caps at the "
                                              "folder of one study"));
  }
  std::sort(files.begin(), files.end());
  for (const auto& f : files) {
    SliceHeader h;
    try {
      if (read_header(f, h)) out.push_back(std::move(h));
      else ++n_skipped;
    } catch (const Error& e) {
      if (damaged == nullptr) throw;
      std::string why = e.what();
      if (why.rfind(f.string() + ": ", 0) == 0) why = why.substr(f.string().size() + 2);
      damaged->push_back(cat(f.filename().string(), ": ", why));
    }
  }
  return out;
}

std::map<std::string, std::vector<SliceHeader>> group_series(std::vector<SliceHeader> headers) {
  std::map<std::string, std::vector<SliceHeader>> series;
  for (auto& h : headers) series[h.series_uid].push_back(std::move(h));
  return series;
}

// The patient a slice belongs to, in words: its PatientName and PatientID.
std::string patient_of(const SliceHeader& h) {
  return cat("'", h.patient_name.empty() ? std::string("(no PatientName)") : h.patient_name,
             "' (PatientID '", h.patient_id, "')");
}

// Slices of one series from more than one patient or study: reading them as one volume would put
// another patient's slices into this patient's model. Refused naming both and the files.
void refuse_mixed_patients(const std::string& where, const std::vector<SliceHeader>& files) {
  for (const SliceHeader& h : files) {
    const SliceHeader& a = files.front();
    if (h.patient_id != a.patient_id || h.patient_name != a.patient_name)
      throw InvalidInput(cat(where, ": the series ", a.series_uid, " holds slices of two patients, ",
                             patient_of(a), " in ", a.file.filename().string(), " and ",
                             patient_of(h), " in ", h.file.filename().string(),
                             "; caps reads one patient's series: separate the files by patient "
                             "and read each on its own"));
    if (h.study_uid != a.study_uid)
      throw InvalidInput(cat(where, ": the series ", a.series_uid, " holds slices of two studies, ",
                             a.study_uid, " in ", a.file.filename().string(), " and ", h.study_uid,
                             " in ", h.file.filename().string(),
                             "; separate the files by study and read each on its own"));
  }
}

// A folder whose series belong to more than one patient: refused naming two of them unless a
// series was chosen (--series), whose own slices are then checked.
void refuse_several_patients(const std::string& where,
                             const std::map<std::string, std::vector<SliceHeader>>& series) {
  const SliceHeader* first = nullptr;
  for (const auto& [uid, files] : series)
    if (!files.empty()) {  // each series by its first slice: the chosen one is checked whole
      const SliceHeader& h = files.front();
      if (!first) first = &h;
      if (h.patient_id != first->patient_id || h.patient_name != first->patient_name)
        throw InvalidInput(cat(where, ": the folder holds more than one patient: ",
                               patient_of(*first), " (series ", first->series_uid, ") and ",
                               patient_of(h), " (series ", h.series_uid, "); choose the series "
                               "to read with --series, or separate the files by patient"));
    }
}

std::vector<DicomSeriesInfo> summarize(
    const std::map<std::string, std::vector<SliceHeader>>& series) {
  std::vector<DicomSeriesInfo> out;
  for (const auto& [uid, files] : series) {
    DicomSeriesInfo s;
    s.uid = uid;
    s.description = files.front().description;
    s.modality = files.front().modality;
    s.n_files = static_cast<int>(files.size());
    out.push_back(s);
  }
  std::stable_sort(out.begin(), out.end(),
                   [](const auto& a, const auto& b) { return a.n_files > b.n_files; });
  return out;
}

std::string list_series(const std::vector<DicomSeriesInfo>& infos) {
  std::string s;
  for (const auto& i : infos)
    s += cat("\n  ", i.uid, " (", i.modality, ", '", i.description, "', ", i.n_files, " files)");
  return s;
}

Modality modality_from_tag(const std::string& m, std::vector<std::string>& notes) {
  if (m == "CT") return Modality::CT;
  if (m == "MR") return Modality::MR;
  notes.push_back(cat("DICOM Modality '", m, "' is neither CT nor MR; modality unknown"));
  return Modality::Unknown;
}

/// The full data set of one file (GDCM's parser only: none of its image helpers, which abort
/// the process on assertions a damaged header reaches, such as a RescaleSlope of 0).
gdcm::File read_data_set(const fs::path& file) {
  gdcm::Reader reader;
  reader.SetFileName(file.c_str());
  if (!reader.Read())
    throw IoError(cat(file.string(), ": GDCM cannot read the file (truncated or damaged); "
                                     "re-export or re-copy it"));
  return reader.GetFile();
}

/// Runs `decode`, which writes `n` bytes to the buffer it is given, in a child process and
/// copies its result to `out`; returns why it failed (empty on success). GDCM's codecs, as Debian
/// builds them, abort the process on assertions and crash on some damaged streams (fuzz_dicom
/// found a null dereference and an `assert(0)` on a libjpeg warning in the JPEG codec), which no
/// check before them can rule out: a child process contains them. The child writes into shared
/// memory and leaves with _exit; a child running longer than a minute is killed.
std::string decode_contained(std::size_t n, char* out, const std::function<bool(char*)>& decode) {
  void* shared = mmap(nullptr, std::max<std::size_t>(n, 1), PROT_READ | PROT_WRITE,
                      MAP_SHARED | MAP_ANONYMOUS, -1, 0);
  if (shared == MAP_FAILED) return cat("no memory for ", n, " decoded bytes");
  const pid_t pid = fork();
  if (pid < 0) {
    munmap(shared, std::max<std::size_t>(n, 1));
    return "cannot start the decoding process";
  }
  if (pid == 0) {
    // The child's end is the parent's to report: GDCM's assertion text, a sanitizer's report or
    // a fuzzer's crash handler (which would save the input as a finding) stay quiet here.
    for (const int sig : {SIGABRT, SIGSEGV, SIGBUS, SIGFPE, SIGILL}) std::signal(sig, SIG_DFL);
    if (__sanitizer_set_death_callback != nullptr) __sanitizer_set_death_callback(nullptr);
    if (const int devnull = open("/dev/null", O_WRONLY); devnull >= 0) dup2(devnull, 2);
    bool ok = false;
    try {
      ok = decode(static_cast<char*>(shared));
    } catch (...) {
    }
    _exit(ok ? 0 : 3);
  }
  int status = 0;
  pid_t done = 0;
  const auto start = std::chrono::steady_clock::now();
  auto pause = std::chrono::microseconds(50);
  while ((done = waitpid(pid, &status, WNOHANG)) == 0) {
    if (std::chrono::steady_clock::now() - start > std::chrono::seconds(60)) {
      kill(pid, SIGKILL);
      waitpid(pid, &status, 0);
      munmap(shared, std::max<std::size_t>(n, 1));
      return "the decoder ran for over a minute";
    }
    std::this_thread::sleep_for(pause);
    pause = std::min(pause * 2, std::chrono::microseconds(20000));
  }
  std::string why;
  if (done < 0) why = "lost the decoding process";
  else if (WIFSIGNALED(status)) why = cat("the decoder crashed (signal ", WTERMSIG(status), ")");
  else if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) why = "the decoder refused the data";
  else std::memcpy(out, shared, n);
  munmap(shared, std::max<std::size_t>(n, 1));
  return why;
}

/// Refuses (InvalidInput naming the file) a pixel format caps does not read: colour, inverted
/// greyscale, BitsAllocated other than 8/16/32, a damaged PixelRepresentation.
void check_pixel_format(const SliceHeader& h) {
  const std::string name = h.file.string();
  if (h.samples_per_pixel != 1)
    throw InvalidInput(cat(name, ": ", h.samples_per_pixel,
                           " samples per pixel (colour); caps reads greyscale CT/MR only"));
  if (h.photometric == "MONOCHROME1")
    throw InvalidInput(cat(name, ": MONOCHROME1 (inverted greyscale) images are not supported "
                                 "for CT/MR volumes"));
  if (!h.photometric.empty() && h.photometric != "MONOCHROME2")
    throw InvalidInput(cat(name, ": PhotometricInterpretation ", h.photometric,
                           " is not greyscale (MONOCHROME2); caps reads CT/MR only"));
  if (h.bits_allocated != 8 && h.bits_allocated != 16 && h.bits_allocated != 32)
    throw InvalidInput(cat(name, ": BitsAllocated = ", h.bits_allocated,
                           " is not supported (8, 16 or 32)"));
  if (h.pixel_representation != 0 && h.pixel_representation != 1)
    throw InvalidInput(cat(name, ": PixelRepresentation (0028,0103) = ", h.pixel_representation,
                           " is neither 0 (unsigned) nor 1 (signed); the file is damaged"));
}

/// Decoded pixels of one file as floats (rescale applied), rows*cols*frames values. The pixel
/// format is the one read_header took from the header and checked here; native pixel data are
/// copied from the file as they are, encapsulated (compressed) ones go through GDCM's codec for
/// the transfer syntax.
std::vector<float> read_pixels(const SliceHeader& h, int expected_frames) {
  const std::string name = h.file.string();
  check_pixel_format(h);
  const unsigned bits = static_cast<unsigned>(h.bits_allocated);
  const unsigned stored = h.bits_stored >= 1 && h.bits_stored <= h.bits_allocated
                              ? static_cast<unsigned>(h.bits_stored) : bits;
  const bool is_signed = h.pixel_representation == 1;
  const std::size_t n = static_cast<std::size_t>(h.cols) * h.rows * expected_frames;
  const std::size_t bytes = n * (bits / 8);
  // GDCM accepts native pixel data that stop short ("Incomplete Pixel Data") and pads the
  // buffer, so compare the bytes present in the file with what the header promises.
  if (!h.encapsulated && h.pixel_bytes_in_file < bytes)
    throw IoError(cat(name, ": truncated: the file holds ", h.pixel_bytes_in_file,
                      " bytes of pixel data, ", bytes, " expected for ", h.cols, "x", h.rows, "x",
                      expected_frames, " pixels of ", bits, " bits; re-export or re-copy the file"));

  const gdcm::File file = read_data_set(h.file);
  const gdcm::DataSet& ds = file.GetDataSet();
  const gdcm::Tag pixel_data(0x7fe0, 0x0010);
  if (!ds.FindDataElement(pixel_data))
    throw InvalidInput(cat(name, ": no PixelData (7FE0,0010); not an image"));
  const gdcm::DataElement& de = ds.GetDataElement(pixel_data);
  std::vector<char> buf;
  if (!h.encapsulated) {
    const gdcm::ByteValue* bv = de.GetByteValue();
    if (bv == nullptr || bv->GetLength() < bytes)
      throw IoError(cat(name, ": the pixel data hold ", bv ? std::size_t{bv->GetLength()} : std::size_t{0}, " bytes, ",
                        bytes, " expected; the file is truncated"));
    buf.assign(bv->GetPointer(), bv->GetPointer() + bytes);
    if (h.big_endian) {
      // GDCM has already swapped a big-endian value into host order in units of its VR's
      // word (2 bytes for OW, 4 for OL/OF, none for OB). Undo that to get the file's big-endian
      // bytes back; decode_to_float below then swaps each pixel of BitsAllocated.
      const std::size_t unit = std::max<std::size_t>(1, de.GetVR().GetSize());
      if (unit > 1)
        for (std::size_t at = 0; at + unit <= buf.size(); at += unit)
          std::reverse(buf.begin() + static_cast<std::ptrdiff_t>(at),
                       buf.begin() + static_cast<std::ptrdiff_t>(at + unit));
    }
  } else {
    // GDCM's codecs trust the frames' own headers (its JPEG codec crashed on a precision above
    // BitsAllocated): each frame's header is checked against the DICOM header first.
    const Codestream kind = codestream_of(h.transfer_syntax);
    if (kind == Codestream::Unsupported)
      throw InvalidInput(cat(name, ": pixel data compressed with transfer syntax ",
                             h.transfer_syntax, ", which caps does not read (RLE, JPEG, JPEG-LS "
                             "and JPEG 2000 it does); decompress the series first, e.g. "
                             "gdcmconv --raw in.dcm out.dcm"));
    const gdcm::SequenceOfFragments* sf = de.GetSequenceOfFragments();
    if (sf == nullptr)
      throw IoError(cat(name, ": the transfer syntax says compressed but the pixel data are not "
                              "in fragments; the file is damaged"));
    std::vector<std::string> fragments;
    for (unsigned i = 0; i < sf->GetNumberOfFragments(); ++i) {
      const gdcm::ByteValue* fb = sf->GetFragment(i).GetByteValue();
      fragments.emplace_back(fb && fb->GetPointer() ? std::string(fb->GetPointer(), fb->GetLength())
                                                    : std::string());
    }
    const FrameFormat format{h.rows, h.cols, h.bits_allocated, static_cast<int>(stored)};
    if (std::string why = check_codestream(kind, fragments, format, expected_frames);
        !why.empty())
      throw IoError(cat(name, ": ", why, "; the file is damaged or not what its header says"));
    gdcm::Image img;
    img.SetNumberOfDimensions(expected_frames > 1 ? 3 : 2);
    img.SetDimension(0, static_cast<unsigned>(h.cols));
    img.SetDimension(1, static_cast<unsigned>(h.rows));
    if (expected_frames > 1) img.SetDimension(2, static_cast<unsigned>(expected_frames));
    img.SetPixelFormat(gdcm::PixelFormat(1, static_cast<unsigned short>(bits),
                                         static_cast<unsigned short>(stored),
                                         static_cast<unsigned short>(stored - 1),
                                         static_cast<unsigned short>(h.pixel_representation)));
    img.SetPhotometricInterpretation(gdcm::PhotometricInterpretation::MONOCHROME2);
    img.SetTransferSyntax(file.GetHeader().GetDataSetTransferSyntax());
    img.SetDataElement(de);
    if (img.GetBufferLength() != bytes)
      throw InvalidInput(cat(name, ": the pixel data decode to ", img.GetBufferLength(),
                             " bytes, ", bytes, " expected; the file is damaged"));
    buf.resize(bytes);
    const std::string failed = decode_contained(bytes, buf.data(), [&](char* out) {
      return img.GetBuffer(out);
    });
    if (!failed.empty())
      throw IoError(cat(name, ": the pixel data could not be decoded (transfer syntax ",
                        h.transfer_syntax, ": ", failed, "); the file is truncated or corrupt"));
  }

  std::vector<float> out(n);
  decode_to_float(buf.data(), n, cat(is_signed ? "i" : "u", bits), h.big_endian, out.data());
  if (stored < bits) {
    // Keep only the stored bits and sign-extend them (BitsStored 12 in a 16-bit word).
    const std::int64_t mask = (std::int64_t{1} << stored) - 1;
    const std::int64_t sign = std::int64_t{1} << (stored - 1);
    for (auto& x : out) {
      std::int64_t raw = static_cast<std::int64_t>(x) & mask;
      if (is_signed && (raw & sign)) raw -= (std::int64_t{1} << stored);
      x = static_cast<float>(raw);
    }
  }
  for (auto& x : out) x = static_cast<float>(h.slope * x + h.intercept);
  return out;
}

std::string fmt(double x, int digits = 2) {
  std::ostringstream os;
  os.setf(std::ios::fixed);
  os.precision(digits);
  os << x;
  return os.str();
}

/// The text of an element of `ds` (a DS/IS/CS value: ASCII), empty when it is absent.
std::string element_text(const gdcm::DataSet& ds, const gdcm::Tag& t) {
  if (!ds.FindDataElement(t)) return {};
  const gdcm::ByteValue* bv = ds.GetDataElement(t).GetByteValue();
  if (bv == nullptr || bv->GetPointer() == nullptr) return {};
  return trim(std::string(bv->GetPointer(), bv->GetLength()));
}

/// The items of the sequence `t` in `ds` (null when it is absent or not a sequence).
gdcm::SmartPointer<gdcm::SequenceOfItems> sequence(const gdcm::DataSet& ds, const gdcm::Tag& t) {
  if (!ds.FindDataElement(t)) return nullptr;
  return ds.GetDataElement(t).GetValueAsSQ();
}

/// The data set of item `k` (1-based) of `sq`, or nullptr.
const gdcm::DataSet* item(const gdcm::SmartPointer<gdcm::SequenceOfItems>& sq, std::size_t k) {
  if (!sq || k < 1 || k > sq->GetNumberOfItems()) return nullptr;
  return &sq->GetItem(k).GetNestedDataSet();
}

/// A multi-frame image's functional groups (enhanced CT/MR): per frame and shared.
struct FunctionalGroups {
  gdcm::SmartPointer<gdcm::SequenceOfItems> per_frame, shared;
  explicit FunctionalGroups(const gdcm::DataSet& ds)
      : per_frame(sequence(ds, gdcm::Tag(0x5200, 0x9230))),
        shared(sequence(ds, gdcm::Tag(0x5200, 0x9229))) {}

  /// A numeric attribute `t` of frame `frame`: in the functional group `group` (e.g.
  /// PlanePositionSequence) of that frame's item, of the shared item, or else in `ds` itself.
  std::vector<double> numbers(const gdcm::DataSet& ds, const gdcm::Tag& group, const gdcm::Tag& t,
                              std::size_t frame) const {
    for (const gdcm::DataSet* top : {item(per_frame, frame), item(shared, 1)}) {
      if (top == nullptr) continue;
      if (const gdcm::DataSet* g = item(sequence(*top, group), 1)) {
        auto v = split_numbers(element_text(*g, t));
        if (!v.empty()) return v;
      }
    }
    return split_numbers(element_text(ds, t));
  }
};

/// A multi-frame file (classic or enhanced CT/MR): the geometry from ImagePositionPatient,
/// ImageOrientationPatient and PixelSpacing, per frame in the functional groups of an enhanced
/// image or once at the top of a classic one (then SpacingBetweenSlices or SliceThickness gives
/// the frame step). The frames must be evenly spaced along the normal.
Volume read_multiframe(const SliceHeader& h, const ReadOptions& options) {
  // The whole pixel data are read at once: check the budget first.
  check_dims(h.file, "Columns x Rows x NumberOfFrames", {h.cols, h.rows, h.frames}, options,
             static_cast<double>(h.cols) * h.rows * h.frames * std::max(1, h.bits_allocated / 8));
  const std::string name = h.file.string();
  Volume v;
  v.source = name;
  v.format = "DICOM";
  const gdcm::File file = read_data_set(h.file);
  const gdcm::DataSet& ds = file.GetDataSet();
  const gdcm::Tag position_group(0x0020, 0x9113), orientation_group(0x0020, 0x9116),
      measures_group(0x0028, 0x9110), ipp_tag(0x0020, 0x0032), iop_tag(0x0020, 0x0037),
      spacing_tag(0x0028, 0x0030);
  const FunctionalGroups groups(ds);
  const auto iop = groups.numbers(ds, orientation_group, iop_tag, 1);
  const auto sp = groups.numbers(ds, measures_group, spacing_tag, 1);
  const auto first = groups.numbers(ds, position_group, ipp_tag, 1);
  if (iop.size() != 6 || first.size() != 3 || sp.size() != 2 || !(sp[0] > 0) || !(sp[1] > 0))
    throw InvalidInput(cat(name, ": a multi-frame image without ImagePositionPatient, "
                                 "ImageOrientationPatient and PixelSpacing (at the top or in its "
                                 "functional groups); caps cannot place its frames"));
  const Eigen::Vector3d r(iop[0], iop[1], iop[2]), c(iop[3], iop[4], iop[5]);
  const Eigen::Vector3d nrm = r.cross(c);
  if (!(std::abs(r.norm() - 1) < 1e-2 && std::abs(c.norm() - 1) < 1e-2 && nrm.norm() > 0.99))
    throw InvalidInput(cat(name, ": ImageOrientationPatient is not two orthogonal unit vectors"));
  const Eigen::Vector3d p0(first[0], first[1], first[2]);
  double step = 0.0;
  const auto second = groups.numbers(ds, position_group, ipp_tag, 2);
  if (second.size() == 3 && second != first) {
    // Enhanced image: every frame has its position; they must lie evenly along the normal.
    step = (Eigen::Vector3d(second[0], second[1], second[2]) - p0).dot(nrm.normalized());
    for (int k = 3; k <= h.frames; ++k) {
      const auto pk = groups.numbers(ds, position_group, ipp_tag, static_cast<std::size_t>(k));
      const double dk = pk.size() == 3
                            ? (Eigen::Vector3d(pk[0], pk[1], pk[2]) - p0).dot(nrm.normalized())
                            : std::numeric_limits<double>::quiet_NaN();
      if (!(std::abs(dk - (k - 1) * step) <= 0.01 * std::abs(step) + 1e-3))
        throw InvalidInput(cat(name, ": frame ", k, " is not where even spacing puts it; caps "
                                     "reads multi-frame images with evenly spaced frames"));
    }
  } else if (h.frame_offsets.size() == static_cast<std::size_t>(h.frames) && h.frames > 1) {
    // An RT dose grid: GridFrameOffsetVector gives each frame's offset along the normal,
    // relative to the first (PS3.3 C.8.8.3.2: relative from 0, or absolute z for axial grids:
    // either way frame k lies at IPP + (o[k] - o[0]) n).
    const auto& o = h.frame_offsets;
    step = o[1] - o[0];
    for (int k = 2; k < h.frames; ++k)
      if (!(std::abs(o[k] - o[0] - k * step) <= 0.01 * std::abs(step) + 1e-3))
        throw InvalidInput(cat(name, ": GridFrameOffsetVector places frame ", k + 1,
                               " away from where even spacing puts it; caps reads multi-frame "
                               "images with evenly spaced frames"));
  } else {
    for (const gdcm::Tag& t : {gdcm::Tag(0x0018, 0x0088), gdcm::Tag(0x0018, 0x0050)}) {
      const auto x = split_numbers(element_text(ds, t));
      if (x.size() == 1 && x[0] > 0) { step = x[0]; break; }
    }
  }
  if (!(std::abs(step) > 1e-6) || !std::isfinite(step))
    throw InvalidInput(cat(name, ": the spacing between frames is unknown or 0 (no per-frame "
                                 "positions, GridFrameOffsetVector, SpacingBetweenSlices or "
                                 "SliceThickness)"));
  auto& g = v.geom;
  g.dims = Eigen::Vector3i(h.cols, h.rows, h.frames);
  g.spacing_mm = Eigen::Vector3d(sp[1], sp[0], std::abs(step));
  g.origin_lps = p0;
  g.direction.col(0) = r.normalized();
  g.direction.col(1) = c.normalized();
  g.direction.col(2) = (step > 0 ? 1.0 : -1.0) * nrm.normalized();
  v.data = read_pixels(h, h.frames);
  v.modality = modality_from_tag(h.modality, v.notes);
  v.notes.push_back(cat("multi-frame DICOM: ", h.frames, " frames ", fmt(std::abs(step), 3),
                        " mm apart"));
  validate_volume(v);
  return v;
}

/// Why `s` cannot be placed as a slice (empty if it can): position, orientation, spacing, size.
std::string placement_problem(const SliceHeader& s) {
  if (s.ipp.size() != 3 || s.iop.size() != 6)
    return "ImagePositionPatient / ImageOrientationPatient missing or malformed; caps needs both "
           "to place the slices (not a cross-sectional image?)";
  if (s.pixel_spacing.size() != 2 || !(s.pixel_spacing[0] > 0) || !(s.pixel_spacing[1] > 0))
    return "PixelSpacing missing or not positive";
  if (s.rows <= 0 || s.cols <= 0)
    return cat("Rows/Columns = ", s.rows, "/", s.cols, " must be positive");
  return {};
}

/// Builds the volume of one series' slices. `named` is the file the user named (empty for a
/// folder): its orientation group is read, other files at its position and files of the series
/// that cannot be placed are left out (noted) instead of refusing the series.
Volume build_volume(std::vector<SliceHeader> slices, const std::string& where,
                    const ReadOptions& options, std::vector<std::string> notes,
                    const fs::path& named) {
  Volume v;
  v.source = where;
  v.format = "DICOM";
  v.notes = std::move(notes);

  // Folder: every file of the series must be a placeable slice. Named file (checked before):
  // the other files of its series that are not are left out, with a note.
  {
    std::vector<SliceHeader> kept;
    std::vector<std::string> left_out;
    for (auto& s : slices) {
      std::string why = placement_problem(s);
      if (why.empty() && s.frames != 1)
        why = cat("a multi-frame file inside a series of ", slices.size(),
                  " files; read it on its own");
      if (why.empty()) kept.push_back(std::move(s));
      else if (!named.empty()) left_out.push_back(cat(s.file.filename().string(), " (", why, ")"));
      else throw InvalidInput(cat(s.file.string(), ": ", why));
    }
    slices = std::move(kept);
    if (slices.empty())
      throw InvalidInput(cat(where, ": no file of the series is a single slice caps can place, "
                                    "first: ", left_out.front()));
    if (!left_out.empty())
      v.notes.push_back(cat("left out ", left_out.size(), " file(s) of the series that are not "
                            "single slices caps can place, first: ", left_out.front()));
  }
  auto is_named = [&](const SliceHeader& s) {
    std::error_code ec;
    return !named.empty() && fs::equivalent(s.file, named, ec);
  };

  // Keep the largest group of slices sharing one orientation (drops localizers in the series).
  {
    std::vector<std::vector<SliceHeader>> groups;
    for (auto& s : slices) {
      bool placed = false;
      for (auto& gr : groups) {
        double diff = 0;
        for (int a = 0; a < 6; ++a) diff = std::max(diff, std::abs(gr[0].iop[a] - s.iop[a]));
        if (diff < 1e-3 && gr[0].rows == s.rows && gr[0].cols == s.cols &&
            std::abs(gr[0].pixel_spacing[0] - s.pixel_spacing[0]) < 1e-4 &&
            std::abs(gr[0].pixel_spacing[1] - s.pixel_spacing[1]) < 1e-4) {
          gr.push_back(std::move(s));
          placed = true;
          break;
        }
      }
      if (!placed) groups.push_back({std::move(s)});
    }
    std::stable_sort(groups.begin(), groups.end(),
                     [](const auto& a, const auto& b) { return a.size() > b.size(); });
    // A named file's own group is read, whatever its size.
    for (std::size_t gi = 1; gi < groups.size(); ++gi)
      if (std::any_of(groups[gi].begin(), groups[gi].end(), is_named))
        std::rotate(groups.begin(), groups.begin() + static_cast<std::ptrdiff_t>(gi),
                    groups.begin() + static_cast<std::ptrdiff_t>(gi) + 1);
    if (groups.size() > 1) {
      std::size_t dropped = 0;
      for (std::size_t gi = 1; gi < groups.size(); ++gi) dropped += groups[gi].size();
      v.notes.push_back(cat("ignored ", dropped, " file(s) whose orientation or size differs from "
                            "the main stack (e.g. localizers), first: ",
                            groups[1][0].file.filename().string()));
    }
    slices = std::move(groups[0]);
  }

  const SliceHeader s0 = slices.front();  // a copy: `slices` is filtered below
  Eigen::Vector3d r(s0.iop[0], s0.iop[1], s0.iop[2]), c(s0.iop[3], s0.iop[4], s0.iop[5]);
  if (r.norm() < 0.5 || c.norm() < 0.5 || std::abs(r.normalized().dot(c.normalized())) > 1e-2)
    throw InvalidInput(cat(s0.file.string(), ": ImageOrientationPatient (",
                           r.transpose(), ", ", c.transpose(),
                           ") is not a pair of perpendicular unit vectors"));
  r.normalize();
  c = (c - r.dot(c) * r).normalized();
  const Eigen::Vector3d n = r.cross(c);
  const double sx = s0.pixel_spacing[1], sy = s0.pixel_spacing[0];
  const int nx = s0.cols, ny = s0.rows;

  for (auto& s : slices) s.d = Eigen::Vector3d(s.ipp[0], s.ipp[1], s.ipp[2]).dot(n);
  // A named file wins over the other files of its series at its own position (copies of the
  // slice, other encodings of it): those are left out, with a note.
  if (const auto it = std::find_if(slices.begin(), slices.end(), is_named); it != slices.end()) {
    const double d_named = it->d;
    std::vector<SliceHeader> kept;
    std::size_t n_same = 0;
    std::string first_same;
    for (auto& s : slices) {
      if (!is_named(s) && std::abs(s.d - d_named) < 0.01) {
        if (n_same++ == 0) first_same = s.file.filename().string();
        continue;
      }
      kept.push_back(std::move(s));
    }
    slices = std::move(kept);
    if (n_same > 0)
      v.notes.push_back(cat("left out ", n_same, " other file(s) of the series at the position of ",
                            named.filename().string(), " (copies or other encodings of the same "
                            "slice), first: ", first_same));
  }
  std::stable_sort(slices.begin(), slices.end(),
                   [](const auto& a, const auto& b) { return a.d < b.d; });
  const std::size_t n_slices = slices.size();

  std::vector<double> gaps;
  for (std::size_t k = 0; k + 1 < n_slices; ++k) {
    const double g = slices[k + 1].d - slices[k].d;
    if (g < 0.01)
      throw InvalidInput(cat(where, ": ", slices[k].file.filename().string(), " and ",
                             slices[k + 1].file.filename().string(),
                             " lie at the same position along the slice normal (", fmt(slices[k].d),
                             " mm); the series mixes several acquisitions or holds duplicate "
                             "files; remove them or choose another series"));
    gaps.push_back(g);
  }

  // In-plane offset of each slice relative to the first (non-zero under gantry tilt).
  const Eigen::Vector3d p0(s0.ipp[0], s0.ipp[1], s0.ipp[2]);
  const Eigen::Vector3d first(slices[0].ipp[0], slices[0].ipp[1], slices[0].ipp[2]);
  std::vector<double> off_u(n_slices), off_v(n_slices);
  bool sheared = false;
  for (std::size_t k = 0; k < n_slices; ++k) {
    const Eigen::Vector3d p(slices[k].ipp[0], slices[k].ipp[1], slices[k].ipp[2]);
    off_u[k] = (p - first).dot(r);
    off_v[k] = (p - first).dot(c);
    sheared |= std::abs(off_u[k]) > 0.02 * sx || std::abs(off_v[k]) > 0.02 * sy;
  }

  double gmin = 0, gmax = 0, gmed = 0;
  if (!gaps.empty()) {
    gmin = *std::min_element(gaps.begin(), gaps.end());
    gmax = *std::max_element(gaps.begin(), gaps.end());
    std::vector<double> sorted = gaps;
    std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
    gmed = sorted[sorted.size() / 2];
  }

  std::vector<std::string> missing;
  for (std::size_t i = 0; i < gaps.size(); ++i) {
    bool suspicious = gaps.size() > 1;
    for (long nb : {static_cast<long>(i) - 1, static_cast<long>(i) + 1}) {
      if (nb < 0 || nb >= static_cast<long>(gaps.size())) continue;
      const double ratio = gaps[i] / gaps[nb];
      const double k = std::round(ratio);
      suspicious &= k >= 2 && std::abs(ratio - k) <= 0.05 * k;
    }
    if (suspicious)
      missing.push_back(cat(fmt(gaps[i]), " mm between ", slices[i].file.filename().string(),
                            " and ", slices[i + 1].file.filename().string()));
  }
  if (!missing.empty()) {
    std::string list;
    for (const auto& m : missing) list += (list.empty() ? "" : "; ") + m;
    if (!options.allow_missing_slices)
      throw InvalidInput(cat(where, ": slices seem to be missing: gap ", list,
                             " is a whole multiple of its neighbouring gaps (median gap ",
                             fmt(gmed), " mm); restore the missing files, or set "
                             "allow_missing_slices (--allow-missing-slices) to interpolate "
                             "across the gap"));
    v.notes.push_back(cat("missing slices interpolated across: ", list));
  }

  // The per-slice pixels are held beside the volume: check both against the budget before GDCM
  // decodes anything.
  check_dims(s0.file, "Columns x Rows x slices", {nx, ny, static_cast<long long>(n_slices)},
             options, 4.0 * nx * ny * static_cast<double>(n_slices));

  // Per-slice pixels with rescale applied.
  std::vector<std::vector<float>> pixels(n_slices);
  for (std::size_t k = 0; k < n_slices; ++k) pixels[k] = read_pixels(slices[k], 1);

  v.modality = modality_from_tag(s0.modality, v.notes);
  auto& g = v.geom;
  g.direction.col(0) = r;
  g.direction.col(1) = c;
  g.direction.col(2) = n;

  const bool uniform = gaps.empty() || gmax - gmin <= std::max(0.01, 0.01 * gmed);
  if (uniform && !sheared) {
    g.dims = Eigen::Vector3i(nx, ny, static_cast<int>(n_slices));
    double mean = 1.0;
    if (!gaps.empty()) {
      mean = (slices.back().d - slices.front().d) / static_cast<double>(gaps.size());
    } else {
      v.notes.push_back("single slice: slice spacing set to 1 mm");
    }
    g.spacing_mm = Eigen::Vector3d(sx, sy, mean);
    g.origin_lps = first;
    v.data.resize(g.n_voxels());
    const std::size_t plane = static_cast<std::size_t>(nx) * ny;
    for (std::size_t k = 0; k < n_slices; ++k)
      std::copy(pixels[k].begin(), pixels[k].end(), v.data.begin() + k * plane);
    v.notes.push_back(cat("DICOM series of ", n_slices, " slices, regular spacing ", fmt(mean, 3),
                          " mm"));
    validate_volume(v);
    return v;
  }

  // Resample onto the orthogonal grid (r, c, n).
  const double dz = gmin;
  const double span = slices.back().d - slices.front().d;
  const double u_min = *std::min_element(off_u.begin(), off_u.end());
  const double u_max = *std::max_element(off_u.begin(), off_u.end());
  const double v_min = *std::min_element(off_v.begin(), off_v.end());
  const double v_max = *std::max_element(off_v.begin(), off_v.end());
  // The grid's size follows from the positions, which may be anything: size it in doubles,
  // clamped before the cast, and check it against the budget (the volume, its acquired flags and
  // the slices' pixels) before allocating.
  auto clamp_count = [](double x) {
    return static_cast<long long>(std::min(std::max(x, 0.0), 1e12));
  };
  const long long nz_d = clamp_count(std::floor(span / dz + 1e-6) + 1);
  const long long nx_d = nx + clamp_count(std::ceil((u_max - u_min) / sx - 1e-6));
  const long long ny_d = ny + clamp_count(std::ceil((v_max - v_min) / sy - 1e-6));
  const double n_out = static_cast<double>(nx_d) * ny_d * nz_d;
  if (n_out > 64.0 * nx * ny * static_cast<double>(n_slices) + 1e6)
    throw InvalidInput(cat(where, ": resampling the slices onto a regular grid would take ",
                           nx_d, "x", ny_d, "x", nz_d, " voxels from ", n_slices, " slices of ",
                           nx, "x", ny, ": the slice positions (ImagePositionPatient) drift "
                           "implausibly; the series is damaged or mixes acquisitions"));
  check_dims(where, "resampled grid", {nx_d, ny_d, nz_d}, options,
             n_out + 4.0 * nx * ny * static_cast<double>(n_slices));
  const int nz = static_cast<int>(nz_d), nx_out = static_cast<int>(nx_d),
            ny_out = static_cast<int>(ny_d);
  g.dims = Eigen::Vector3i(nx_out, ny_out, nz);
  g.spacing_mm = Eigen::Vector3d(sx, sy, dz);
  g.origin_lps = first + u_min * r + v_min * c;

  float data_min = pixels[0][0];
  for (const auto& p : pixels)
    for (float x : p) data_min = std::min(data_min, x);
  const float fill = v.modality == Modality::CT ? std::max(data_min, -1024.0f) : data_min;

  v.data.assign(g.n_voxels(), fill);
  v.acquired.assign(g.n_voxels(), 0);
  const std::size_t plane_out = static_cast<std::size_t>(nx_out) * ny_out;
  tbb::parallel_for(0, nz, [&](int k) {
    const double w = slices.front().d + k * dz;
    std::size_t b = 1;
    while (b + 1 < n_slices && slices[b].d < w) ++b;
    const std::size_t a = b - 1;
    const double t = std::clamp((w - slices[a].d) / (slices[b].d - slices[a].d), 0.0, 1.0);
    // Bilinear sample of slice m at in-plane position (u, v) relative to the first slice.
    auto sample = [&](std::size_t m, double u, double vv, float& out) {
      const double x = (u - off_u[m]) / sx, y = (vv - off_v[m]) / sy;
      if (!(x >= -1e-6 && y >= -1e-6 && x <= nx - 1 + 1e-6 && y <= ny - 1 + 1e-6)) return false;
      const int i0 = std::clamp(static_cast<int>(std::floor(x)), 0, std::max(nx - 2, 0));
      const int j0 = std::clamp(static_cast<int>(std::floor(y)), 0, std::max(ny - 2, 0));
      const int i1 = std::min(i0 + 1, nx - 1), j1 = std::min(j0 + 1, ny - 1);
      const double fx = std::clamp(x - i0, 0.0, 1.0), fy = std::clamp(y - j0, 0.0, 1.0);
      const float* p = pixels[m].data();
      const double top = p[j0 * nx + i0] * (1 - fx) + p[j0 * nx + i1] * fx;
      const double bot = p[j1 * nx + i0] * (1 - fx) + p[j1 * nx + i1] * fx;
      out = static_cast<float>(top * (1 - fy) + bot * fy);
      return true;
    };
    float* dst = v.data.data() + static_cast<std::size_t>(k) * plane_out;
    for (int j = 0; j < ny_out; ++j) {
      const double vv = v_min + j * sy;
      for (int i = 0; i < nx_out; ++i) {
        const double u = u_min + i * sx;
        float va = 0, vb = 0;
        const bool ha = t < 1.0 && sample(a, u, vv, va);
        const bool hb = t > 0.0 && sample(b, u, vv, vb);
        if (ha && hb) dst[j * nx_out + i] = static_cast<float>((1 - t) * va + t * vb);
        else if (ha) dst[j * nx_out + i] = va;
        else if (hb) dst[j * nx_out + i] = vb;
        v.acquired[static_cast<std::size_t>(k) * plane_out + j * nx_out + i] = ha || hb;
      }
    }
  });

  std::string what;
  if (sheared) {
    const double shift = std::hypot(off_u.back(), off_v.back());
    what = cat("gantry tilt ", fmt(rad_to_deg(std::atan2(shift, span)), 1), " deg, ");
  }
  v.notes.push_back(cat("resampled: ", what, "slice gaps ", fmt(gmin), "-", fmt(gmax), " mm -> ",
                        fmt(dz), " mm; ", n_slices, " slices -> ", nz, ", in-plane ", nx, "x", ny,
                        " -> ", nx_out, "x", ny_out,
                        " so that every slice's field of view is kept (outside filled with ",
                        fill, ")"));
  validate_volume(v);
  return v;
}

}  // namespace

Volume read_dicom(const fs::path& input, const ReadOptions& options) {
  quiet_gdcm();
  std::error_code ec;
  const bool is_dir = fs::is_directory(input, ec);
  fs::path folder = input;
  ReadOptions opts = options;
  std::vector<std::string> notes;
  if (!is_dir) {
    file_size_or_throw(input);
    SliceHeader h;
    if (!read_header(input, h))
      throw InvalidInput(cat(input.string(), ": not a DICOM image (or it has no SeriesInstanceUID)"
                                             "; caps reads a DICOM folder or .dcm file, .nii, "
                                             ".nii.gz, a NIfTI .hdr/.img pair, .nrrd, .nhdr, "
                                             ".mha, .mhd or .inv3"));
    // The named file itself must be an image caps can place; the reason is about it, not about
    // its neighbours.
    if (!h.has_pixel_data)
      throw InvalidInput(cat(input.string(), ": holds no pixel data (Modality '", h.modality,
                             "'): not an image; caps reads CT/MR image series"));
    check_pixel_format(h);
    if (h.frames > 1) return read_multiframe(h, opts);
    if (std::string why = placement_problem(h); !why.empty())
      throw InvalidInput(cat(input.string(), ": ", why));
    folder = input.parent_path().empty() ? fs::path(".") : input.parent_path();
    if (opts.series_uid.empty()) opts.series_uid = h.series_uid;
    notes.push_back(cat("read the series of ", input.filename().string(), " from its folder"));
  }

  int n_skipped = 0;
  std::vector<std::string> damaged;
  auto series = group_series(scan_folder(folder, n_skipped, is_dir ? nullptr : &damaged));
  if (!damaged.empty())
    notes.push_back(cat("left out ", damaged.size(), " damaged file(s) of the folder, first: ",
                        damaged.front()));
  if (series.empty())
    throw InvalidInput(cat(folder.string(), ": no DICOM image files found (", n_skipped,
                           " other files); point caps at the folder holding the series' .dcm "
                           "files, or give a .nii/.nii.gz/.nrrd/.nhdr/.mha/.mhd/.inv3 file"));
  const auto infos = summarize(series);
  std::string uid = opts.series_uid;
  if (opts.series_uid.empty()) refuse_several_patients(folder.string(), series);
  if (uid.empty()) {
    uid = infos.front().uid;
    if (infos.size() > 1)
      notes.push_back(cat("the folder holds ", infos.size(), " series; read the largest, ", uid,
                          " ('", infos.front().description, "', ", infos.front().n_files,
                          " files); choose another with --series"));
  } else if (series.count(uid) == 0) {
    throw InvalidInput(cat(folder.string(), ": no series with SeriesInstanceUID ", uid,
                           "; the folder holds:", list_series(infos)));
  }
  if (n_skipped > 0) notes.push_back(cat("skipped ", n_skipped, " non-DICOM file(s)"));
  auto& files = series[uid];
  refuse_mixed_patients(folder.string(), files);
  if (files.size() == 1 && files[0].frames > 1) return read_multiframe(files[0], opts);
  return build_volume(std::move(files), folder.string(), opts, std::move(notes),
                      is_dir ? fs::path() : input);
}

}  // namespace detail

std::vector<DicomSeriesInfo> list_dicom_series(const fs::path& folder) {
  std::error_code ec;
  if (!fs::is_directory(folder, ec))
    throw IoError(cat(folder.string(), ": not a folder; give the folder holding the DICOM files"));
  int n_skipped = 0;
  std::vector<std::string> damaged;  // a listing names what it can read
  return detail::summarize(detail::group_series(detail::scan_folder(folder, n_skipped, &damaged)));
}

}  // namespace caps
