#include "caps/core/data_dir.hpp"

#include <cstdlib>

#include "caps/core/error.hpp"

namespace caps {

std::filesystem::path data_dir() {
  if (const char* env = std::getenv("CAPS_DATA_DIR"); env && *env) return env;
  return CAPS_SOURCE_DATA_DIR;
}

std::filesystem::path data_file(const std::string& relative) {
  const std::filesystem::path p = data_dir() / relative;
  std::error_code ec;
  if (!std::filesystem::is_regular_file(p, ec))
    throw IoError(cat("caps's data file ", p.string(), " is missing: caps reads its data from ",
                      std::getenv("CAPS_DATA_DIR") ? "$CAPS_DATA_DIR" : "the source tree's data/",
                      "; set CAPS_DATA_DIR to a folder with the project's data/ files"));
  return p;
}

}  // namespace caps
