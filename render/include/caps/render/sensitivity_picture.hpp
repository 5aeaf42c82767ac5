#pragma once
/// @brief The picture of where a constant thickness misleads (`caps model sensitivity`): the
/// patient's skin from the front, coloured by the relative change of the closing force (left)
/// and of the largest displacement (right) when the measured thickness is replaced by a constant.

#include <filesystem>
#include <string>

#include "caps/study/thickness_sensitivity.hpp"
#include "caps/image/rgb_image.hpp"

namespace caps {
class PatientModel;
}

namespace caps::render {

/// The change field of a sensitivity map at (theta deg, z mm): bilinear between the four
/// surrounding plan centres when all four were planned, else the nearest planned centre within
/// half a grid step, else NaN (outside the grid or not planned). `force` picks the closing
/// force's change, else the displacement's; the value is a fraction ((constant - measured) /
/// measured).
double sensitivity_at(const study::SensitivityMap& map, double theta_deg, double z_mm, bool force);

/// Two front views of the model's range skin side by side (each `panel_px` square), coloured by
/// the change in percent (blue: the constant underestimates, red: it overestimates, white: no
/// change; one symmetric scale, the larger of 10 % and the 95th percentile of |change| rounded
/// up), with a colour bar, a dot at every plan centre, a cross where the plan could not be
/// made, the title and the credit line. Returns the image.
RgbImage sensitivity_picture(const study::SensitivityMap& map, const PatientModel& model,
                             const std::string& title, const std::string& credit = "",
                             int panel_px = 800);

}  // namespace caps::render
