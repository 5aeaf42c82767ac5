// caps volume info: what a volume file or DICOM folder holds, as caps reads it.
//   caps volume info ../shared/data/ct/vtk-headsq/quarter.nhdr
//   caps volume info ../shared/data/ct/ge-head-tilt --json
#include <iostream>
#include <nlohmann/json.hpp>

#include "caps/core/error.hpp"
#include "caps/volume/read_volume.hpp"
#include "commands.hpp"

namespace caps::cli {

void add_volume(CLI::App& app, Common& common, Action& action) {
  auto* volume = app.add_subcommand("volume", "Inspect CT and MR volumes");
  volume->require_subcommand(1);
  auto input = std::make_shared<std::string>();
  auto series = std::make_shared<std::string>();
  auto* info = volume->add_subcommand(
      "info", "Print a volume's geometry (LPS), modality, value range and how it was read.\n"
              "Example: caps volume info ct_folder/ --json");
  info->add_option("INPUT", *input, "a DICOM folder, .nii/.nii.gz, .nrrd/.nhdr, .mha/.mhd, .inv3")
      ->required();
  info->add_option("--series", *series, "DICOM SeriesInstanceUID");
  add_common_flags(info, common, false);
  info->callback([&common, &action, input, series] {
    action = [&common, input, series] {
      ReadOptions ro;
      ro.series_uid = *series;
      const Volume v = read_volume(*input, ro);
      const auto [lo, hi] = std::minmax_element(v.data.begin(), v.data.end());
      const auto& g = v.geom;
      nlohmann::json j{{"source", v.source},
                       {"format", v.format},
                       {"modality", to_string(v.modality)},
                       {"dims", {g.dims[0], g.dims[1], g.dims[2]}},
                       {"spacing_mm", {g.spacing_mm[0], g.spacing_mm[1], g.spacing_mm[2]}},
                       {"origin_lps", {g.origin_lps[0], g.origin_lps[1], g.origin_lps[2]}},
                       {"direction_columns", {{g.direction(0, 0), g.direction(1, 0), g.direction(2, 0)},
                                              {g.direction(0, 1), g.direction(1, 1), g.direction(2, 1)},
                                              {g.direction(0, 2), g.direction(1, 2), g.direction(2, 2)}}},
                       {"min", *lo},
                       {"max", *hi},
                       {"notes", v.notes}};
      if (v.format == "DICOM") {
        nlohmann::json list = nlohmann::json::array();
        for (const auto& s : list_dicom_series(*input))
          list.push_back({{"uid", s.uid}, {"description", s.description},
                          {"modality", s.modality}, {"files", s.n_files}});
        j["series"] = list;
      }
      if (common.json) {
        std::cout << j.dump(2) << "\n";
        return;
      }
      std::cout << "source     " << v.source << " (" << v.format << ", " << to_string(v.modality)
                << ")\n"
                << "dims       " << g.dims.transpose() << "\n"
                << "spacing    " << g.spacing_mm.transpose() << " mm\n"
                << "origin     " << g.origin_lps.transpose() << " mm (LPS)\n"
                << "values     " << *lo << " .. " << *hi << "\n";
      for (const auto& n : v.notes) std::cout << "note       " << n << "\n";
    };
  });
}

}  // namespace caps::cli
