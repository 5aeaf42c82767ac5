#pragma once
// The small phantom patient model the app and server tests share (96 x 96 x 90 voxels of 2.5 mm,
// a 128 x 64 cylindrical grid), built through app:: as a user would, and a file reader.

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "caps/app/model.hpp"

namespace caps_test {

/// The file's text ("" if it cannot be read).
inline std::string slurp(const std::filesystem::path& p) {
  std::ifstream in(p);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

/// Writes the phantom CT into `folder`/ct.nii.gz and its patient model into `model`, on an
/// n_theta x n_z grid (256 x 128: cells of about 2 mm on the face, what the registration tests
/// cut their face scans from). `face`: the phantom with a face of analytic landmarks (`caps
/// phantom --face`: glabella, nasion, nose, chin, ...) instead of the plain nose that has none.
/// `tissue`: false leaves out the whole-face tissue model (`--no-tissue`), for tests that close
/// no wound in the whole face (on the 256 x 128 grid it is 4 of from-volume's 5 s of CPU).
inline void make_phantom_model(const std::filesystem::path& folder, const std::string& model,
                               int n_theta = 128, int n_z = 64, bool face = false,
                               bool tissue = true) {
  caps::app::PhantomRequest ph;
  ph.output = (folder / "ct.nii.gz").string();
  ph.voxels = "96,96,90";
  ph.spacing = "2.5,2.5,2.5";
  ph.face = face;
  caps::app::run_phantom(ph);
  caps::app::FromVolumeRequest fv;
  fv.input = ph.output;
  fv.output = model;
  fv.n_theta = n_theta;
  fv.n_z = n_z;
  fv.no_tissue = !tissue;
  caps::app::run_from_volume(fv);
}

/// A fresh temporary folder `prefix`_<pid> for the test program, made once.
inline const std::filesystem::path& program_folder(const std::string& prefix) {
  static const std::filesystem::path d = [&] {
    const std::filesystem::path p =
        std::filesystem::temp_directory_path() / (prefix + "_" + std::to_string(::getpid()));
    std::filesystem::remove_all(p);
    std::filesystem::create_directories(p);
    return p;
  }();
  return d;
}

/// The phantom's patient model on the 256 x 128 grid, made once per test program in
/// program_folder(prefix)/model (the first call's arguments make it); `tissue` as for
/// make_phantom_model().
inline const std::string& program_phantom_model(const std::string& prefix, bool tissue = true) {
  static const std::string dir = [&] {
    const std::string d = (program_folder(prefix) / "model").string();
    make_phantom_model(program_folder(prefix), d, 256, 128, false, tissue);
    return d;
  }();
  return dir;
}

}  // namespace caps_test
