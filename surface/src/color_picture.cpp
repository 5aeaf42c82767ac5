#include "caps/surface/color_picture.hpp"

#include "caps/core/error.hpp"
#include "caps/volume/model_figures.hpp"

namespace caps {

void write_color_picture(const std::filesystem::path& path, const PatientModel& model,
                         const std::string& title, const std::string& credit) {
  if (!model.has_color())
    throw InvalidInput(cat(path.string(), ": the model has no colour (no color.png)"));
  write_map_png(path, model.grid(), model.color(), title, credit);
}

}  // namespace caps
