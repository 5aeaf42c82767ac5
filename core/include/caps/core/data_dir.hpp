#pragma once
/// @brief caps's data files (the top-level data/ folder: material presets, the procedure
/// library): the registries read them at run time rather than holding their values in code.

#include <filesystem>
#include <string>

namespace caps {

/// The data folder: $CAPS_DATA_DIR when set (a copy edited for a study, an installed caps),
/// else the data/ of the source tree caps was built from.
std::filesystem::path data_dir();

/// data_dir() / relative, which must be a regular file: IoError otherwise, naming the path and
/// CAPS_DATA_DIR.
std::filesystem::path data_file(const std::string& relative);

}  // namespace caps
