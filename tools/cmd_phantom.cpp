// caps phantom: an analytic head CT with known skin, skull and thickness, for tests and demos.
//   caps phantom -o /tmp/phantom.nii.gz
//   caps phantom -o /tmp/phantom-fine.nii.gz --size 512,512,300 --spacing 0.5,0.5,0.8
#include <filesystem>
#include <iostream>
#include <nlohmann/json.hpp>

#include "caps/core/error.hpp"
#include "caps/volume/phantom.hpp"
#include "caps/volume/read_volume.hpp"
#include "commands.hpp"

namespace caps::cli {

void add_phantom(CLI::App& app, Common& common, Action& action) {
  auto* cmd = app.add_subcommand(
      "phantom", "Write an analytic head CT phantom (HU, NIfTI) with known tissue thickness.\n"
                 "Example: caps phantom -o phantom.nii.gz --size 256,256,240 --spacing 1,1,1");
  auto out = std::make_shared<std::string>();
  auto size = std::make_shared<std::string>("256,256,240");
  auto spacing = std::make_shared<std::string>("1,1,1");
  auto no_holder = std::make_shared<bool>(false);
  cmd->add_option("-o,--output", *out, "output .nii or .nii.gz")->required();
  cmd->add_option("--size", *size, "voxels along L,P,S")->capture_default_str();
  cmd->add_option("--spacing", *spacing, "voxel size in mm along L,P,S")->capture_default_str();
  cmd->add_flag("--no-holder", *no_holder, "leave out the head-holder arc");
  add_common_flags(cmd, common, true);
  cmd->callback([&common, &action, out, size, spacing, no_holder] {
    action = [&common, out, size, spacing, no_holder] {
      const std::filesystem::path path(*out);
      const std::string name = path.filename().string();
      const bool gz = name.size() > 7 && name.substr(name.size() - 7) == ".nii.gz";
      const bool nii = name.size() > 4 && name.substr(name.size() - 4) == ".nii";
      if (!gz && !nii)
        throw InvalidInput(cat(*out, ": the phantom is written as NIfTI; name it .nii or .nii.gz"));
      if (std::filesystem::exists(path) && !common.force)
        throw InvalidInput(cat(*out, ": already exists; choose another name or pass --force"));
      PhantomOptions o;
      const auto s = parse_triple(*size, "--size");
      const auto h = parse_triple(*spacing, "--spacing");
      for (int a = 0; a < 3; ++a) {
        if (s[a] != static_cast<int>(s[a]))
          throw InvalidInput(cat("--size ", *size, ": voxel counts must be whole numbers"));
        o.dims[a] = static_cast<int>(s[a]);
        o.spacing_mm[a] = h[a];
      }
      o.head_holder = !*no_holder;
      const Volume v = make_phantom(o);
      write_nifti(v, path);
      if (common.json) {
        nlohmann::json j{{"output", *out},
                         {"dims", {o.dims[0], o.dims[1], o.dims[2]}},
                         {"spacing_mm", {h[0], h[1], h[2]}},
                         {"head_holder", o.head_holder}};
        std::cout << j.dump(2) << "\n";
      }
    };
  });
}

}  // namespace caps::cli
