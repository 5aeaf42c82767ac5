#pragma once
/// @brief Patient models loaded once per process: a long-lived front end (the planner's server)
/// answers many requests on one model without reading its maps again for each.

#include <memory>
#include <string>

namespace caps {
class PatientModel;
struct FeatureLines;
namespace mesher {
struct TissueModel;
}
namespace render {
struct DrawnSkin;
}
}

namespace caps::app {

/// The model in the folder `dir`, as PatientModel::load() reads it, kept in memory while none of
/// the folder's files changes (their sizes and modification times are compared on each call, a
/// few stat() calls); a changed or rewritten model is read again. Thread-safe. Throws what
/// PatientModel::load() throws (IoError, InvalidInput) for a missing or broken model.
/// @param dir  the model directory (caps model from-volume / from-scan)
/// @return     the model, shared and read-only
std::shared_ptr<const PatientModel> loaded_model(const std::string& dir);

/// The model directory's whole-face tissue model (mesher::read_tissue_model()), kept the same way.
std::shared_ptr<const mesher::TissueModel> loaded_tissue_model(const std::string& dir);

/// The model directory's feature lines (read_feature_lines()), kept the same way.
std::shared_ptr<const FeatureLines> loaded_feature_lines(const std::string& dir);

/// The model directory's drawn skin (render::load_drawn_skin() of loaded_model(dir): the range
/// resampled from its skin isosurface and filtered of slice terraces), kept the same way.
std::shared_ptr<const render::DrawnSkin> loaded_drawn_skin(const std::string& dir);

}  // namespace caps::app
