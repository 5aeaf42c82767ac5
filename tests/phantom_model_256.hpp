#pragma once
// The phantom CT model at a 256 x 128 grid (cells of about 2 mm on the face), built through app::
// as a user would: what the registration and model-comparison tests cut their face scans from.

#include <filesystem>
#include <string>

#include "caps/app/model.hpp"

namespace caps_test {

/// Writes the phantom CT into `folder`/ct.nii.gz and its model into `folder`/model; returns the
/// model's folder.
inline std::string make_phantom_model_256(const std::filesystem::path& folder) {
  caps::app::PhantomRequest ph;
  ph.output = (folder / "ct.nii.gz").string();
  ph.voxels = "96,96,90";
  ph.spacing = "2.5,2.5,2.5";
  caps::app::run_phantom(ph);
  caps::app::FromVolumeRequest fv;
  fv.input = ph.output;
  fv.output = (folder / "model").string();
  fv.n_theta = 256;
  fv.n_z = 128;
  caps::app::run_from_volume(fv);
  return fv.output;
}

}  // namespace caps_test
