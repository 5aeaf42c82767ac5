#pragma once
// The library's messages as the planner page shows them to a surgeon (issue 38): the command
// line's messages name loop nodes, JSON pointers, the model's (theta, z) and the commands and
// options that would help; the page has buttons and settings for those, and the surgeon finds a
// spot on the patient from a landmark. Internal to the server.

#include <nlohmann/json.hpp>
#include <string>

namespace caps {
class PatientModel;
}

namespace caps::server::detail {

/// `message` in the page's words: "loop node 0 (point 2), /points/2" becomes "the cut's point
/// 3"; a loop node or edge alone "a corner" or "a stretch of the wound's edge"; a suture by its
/// loop nodes "suture pair k + 1"; "(theta T deg, z Z mm)" the nearest landmark's offsets in mm
/// (nearest_landmark_placement(), from the landmarks model.json of `model_dir` keeps; dropped
/// without them); the advice to make a local chart ("caps model chart ...") the page's button;
/// the command line's simulation options the page's settings of the same name, and the other
/// options "(a setting of the command line, caps simulate)" without the option's spelling.
/// Text without such words, and text over 2000 characters, is returned unchanged.
std::string page_words(const std::string& message, const PatientModel& model,
                       const std::string& model_dir);

/// page_words() on every string of every "warnings" array in `answer` (at any depth) and on
/// an "error" string at its top.
void page_words_json(nlohmann::json& answer, const PatientModel& model,
                     const std::string& model_dir);

}  // namespace caps::server::detail
