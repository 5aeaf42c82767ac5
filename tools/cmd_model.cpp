// caps model: build and inspect patient models.
//   caps model from-volume /usr/share/doc/invesalius-examples/examples/Cranium.inv3 -o /tmp/cranium
//   caps model from-volume ../shared/data/ct/ge-head-tilt -o /tmp/ge --force
//   caps model from-volume /usr/share/mricron/templates/ch2.nii.gz -o /tmp/ch2 --force
//   caps model info /tmp/cranium --json
#include <filesystem>
#include <iostream>
#include <nlohmann/json.hpp>

#include "caps/core/error.hpp"
#include "caps/core/atomic_output.hpp"
#include "caps/core/progress.hpp"
#include "caps/volume/model.hpp"
#include "caps/volume/read_volume.hpp"
#include "commands.hpp"

namespace caps::cli {
namespace {

struct FromVolumeArgs {
  std::string input, output, series, bone_mask, axis_origin, axis_dir, modality;
  double skin_threshold = NAN, bone_threshold = NAN;
  int n_theta = 512, n_z = 256;
  double bone_cap_mm = 40.0, decimate = 1.0, mr_scalp_mm = 6.0;
  bool allow_missing_slices = false;
};

Eigen::Vector3d triple(const std::string& s, const std::string& option) {
  const auto t = parse_triple(s, option);
  return {t[0], t[1], t[2]};
}

void run_from_volume(const FromVolumeArgs& a, const Common& common) {
  // Check the output before the slow work, so a bad path fails at once.
  { OutputDirectory probe(a.output, common.force); }
  ReadOptions ro;
  ro.series_uid = a.series;
  ro.allow_missing_slices = a.allow_missing_slices;
  Volume v = read_volume(a.input, ro);
  if (!a.modality.empty()) {
    if (a.modality == "CT") v.modality = Modality::CT;
    else if (a.modality == "MR") v.modality = Modality::MR;
    else throw InvalidInput(cat("--modality '", a.modality, "': use CT or MR"));
  }
  for (const auto& n : v.notes) inform(cat(a.input, ": ", n));
  ModelOptions o;
  if (std::isfinite(a.skin_threshold)) o.segment.skin_threshold = a.skin_threshold;
  if (std::isfinite(a.bone_threshold)) o.segment.bone_threshold = a.bone_threshold;
  o.segment.mr_scalp_mm = a.mr_scalp_mm;
  Volume bone_mask;
  if (!a.bone_mask.empty()) {
    bone_mask = read_volume(a.bone_mask);
    o.segment.bone_mask = &bone_mask;
  }
  o.maps.n_theta = a.n_theta;
  o.maps.n_z = a.n_z;
  o.maps.bone_cap_mm = a.bone_cap_mm;
  if (!(a.decimate > 0 && a.decimate <= 1))
    throw InvalidInput(cat("--decimate ", a.decimate, ": give the fraction of faces to keep, in (0, 1]"));
  o.decimate_fraction = a.decimate;
  if (!a.axis_origin.empty() || !a.axis_dir.empty()) {
    CylinderAxis axis;
    if (!a.axis_origin.empty()) axis.origin_lps = triple(a.axis_origin, "--axis-origin");
    if (!a.axis_dir.empty()) {
      const Eigen::Vector3d d = triple(a.axis_dir, "--axis-dir");
      if (d.norm() < 1e-9) throw InvalidInput("--axis-dir: the direction must not be zero");
      axis.direction = d.normalized();
      // theta = 0 stays anterior, made perpendicular to the axis.
      const Eigen::Vector3d anterior(0, -1, 0);
      const Eigen::Vector3d f = anterior - anterior.dot(axis.direction) * axis.direction;
      if (f.norm() < 1e-6)
        throw InvalidInput("--axis-dir: the axis must not point anterior-posterior");
      axis.front = f.normalized();
    }
    o.axis = axis;
  }
  const VolumeModel m = build_volume_model(v, o);
  write_model(m, a.output, common.force);
  if (common.json) std::cout << read_model_json(a.output) << "\n";
  else if (!common.quiet) std::cerr << model_summary(a.output);
}

}  // namespace

void add_model(CLI::App& app, Common& common, Action& action) {
  auto* model = app.add_subcommand("model", "Build and inspect patient models");
  model->require_subcommand(1);

  auto a = std::make_shared<FromVolumeArgs>();
  auto* fv = model->add_subcommand(
      "from-volume",
      "Build a patient model from a CT or MR: skin and bone surfaces, cylindrical range images\n"
      "and a measured soft-tissue thickness map.\n"
      "Example: caps model from-volume Cranium.inv3 -o cranium\n"
      "INPUT is a DICOM folder, .nii/.nii.gz, .nrrd/.nhdr, .mha/.mhd or an InVesalius .inv3.");
  fv->add_option("INPUT", a->input, "the volume (file or DICOM folder)")->required();
  fv->add_option("-o,--output", a->output, "the model directory to create")->required();
  fv->add_option("--series", a->series, "DICOM SeriesInstanceUID (default: the largest series)");
  fv->add_flag("--allow-missing-slices", a->allow_missing_slices,
              "DICOM: interpolate across gaps where slices seem to be missing");
  fv->add_option("--modality", a->modality, "override the modality: CT or MR");
  fv->add_option("--skin-threshold", a->skin_threshold,
                 "tissue/air threshold (default: -400 HU for CT, Otsu for MR)");
  fv->add_option("--bone-threshold", a->bone_threshold, "bone threshold (default: 250 HU for CT)");
  fv->add_option("--bone-mask", a->bone_mask,
                 "bone mask or label volume (non-zero = bone), e.g. for MR");
  fv->add_option("--mr-scalp", a->mr_scalp_mm,
                 "MR without --bone-mask: assumed scalp depth in mm")->capture_default_str();
  fv->add_option("--axis-origin", a->axis_origin, "a point of the cylinder axis, LPS mm: X,Y,Z");
  fv->add_option("--axis-dir", a->axis_dir, "the axis direction (towards superior), LPS: X,Y,Z");
  fv->add_option("--n-theta", a->n_theta, "cylindrical grid: samples around")->capture_default_str();
  fv->add_option("--n-z", a->n_z, "cylindrical grid: samples along the axis")->capture_default_str();
  fv->add_option("--bone-cap", a->bone_cap_mm,
                 "no bone within this depth (mm) marks a cell invalid")->capture_default_str();
  fv->add_option("--decimate", a->decimate, "fraction of mesh faces to keep (0..1]")
      ->capture_default_str();
  add_common_flags(fv, common, true);
  fv->callback([&common, &action, a] { action = [&common, a] { run_from_volume(*a, common); }; });

  add_model_scan(model, common, action);

  auto dir = std::make_shared<std::string>();
  auto* info = model->add_subcommand("info", "Print a model directory's summary.\n"
                                             "Example: caps model info cranium --json");
  info->add_option("MODEL_DIR", *dir, "a model directory")->required();
  add_common_flags(info, common, false);
  info->callback([&common, &action, dir] {
    action = [&common, dir] {
      if (common.json) std::cout << read_model_json(*dir) << "\n";
      else std::cout << model_summary(*dir);
    };
  });
}

}  // namespace caps::cli
