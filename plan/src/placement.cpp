#include "caps/plan/placement.hpp"

#include <cctype>
#include <cmath>
#include <sstream>

#include "caps/core/error.hpp"
#include "caps/plan/skin_walk.hpp"
#include "caps/volume/model_dir.hpp"

namespace caps::plan {

namespace {

std::string names_list() {
  std::string s;
  for (const auto& n : landmark_names()) s += (s.empty() ? "" : ", ") + n;
  return s;
}

}  // namespace

std::optional<LandmarkPlacement> parse_landmark_placement(const std::string& text) {
  if (text.empty() || !std::isalpha(static_cast<unsigned char>(text[0]))) return std::nullopt;
  const std::size_t sign = text.find_first_of("+-");
  LandmarkPlacement p;
  p.landmark = text.substr(0, sign);
  bool known = false;
  for (const auto& n : landmark_names()) known = known || n == p.landmark;
  if (!known)
    throw InvalidInput(cat("'", text, "': ", p.landmark, " is not a landmark; use one of ",
                           names_list(), ", e.g. glabella+15,20 (mm to the patient's left, up)"));
  if (sign == std::string::npos) return p;
  const std::string rest = text.substr(sign);  // "+15,20" or "-10,-5"
  const std::size_t comma = rest.find(',');
  try {
    if (comma == std::string::npos) throw std::invalid_argument("no comma");
    std::size_t used = 0;
    p.left_mm = std::stod(rest.substr(0, comma), &used);
    if (used != comma) throw std::invalid_argument("left");
    const std::string up = rest.substr(comma + 1);
    p.up_mm = std::stod(up, &used);
    if (used != up.size()) throw std::invalid_argument("up");
  } catch (const std::exception&) {
    throw InvalidInput(cat("'", text, "': after the landmark give +LEFT,UP in mm, e.g. ",
                           p.landmark, "+15,20 or ", p.landmark, "-10,-5"));
  }
  if (!std::isfinite(p.left_mm) || !std::isfinite(p.up_mm) || std::abs(p.left_mm) > 500 ||
      std::abs(p.up_mm) > 500)
    throw InvalidInput(cat("'", text, "': the offsets must be finite and within 500 mm"));
  return p;
}

Landmarks model_landmarks(const std::filesystem::path& dir, const PatientModel& model) {
  const ModelInfo info = read_model_info(dir);
  if (!info.landmarks_json.empty())
    return landmarks_from_json(info.landmarks_json, (dir / model_file::kJson).string());
  return find_landmarks(model);
}

Eigen::Vector2d walk_left_up(const PatientModel& model, const Eigen::Vector2d& from_tz,
                             const Eigen::Vector2d& left_up_mm) {
  if (!(left_up_mm.norm() > 0)) return from_tz;
  return walk_on_skin(model, skin_frame(model, from_tz[0], from_tz[1], 90.0), left_up_mm).theta_z;
}

Eigen::Vector2d resolve_placement(const PatientModel& model, const Landmarks& landmarks,
                                  const LandmarkPlacement& placement) {
  const Landmark* l = landmarks.find(placement.landmark);
  if (!l)
    throw InvalidInput(cat(placement.landmark, " is not a landmark; use one of ", names_list()));
  if (!l->found)
    throw InvalidInput(cat("the model has no ", placement.landmark, " (", l->note,
                           "); place the plan with --at THETA,Z or another landmark"));
  Eigen::Vector2d tz = walk_left_up(model, Eigen::Vector2d(l->theta_deg, l->z_mm),
                                    Eigen::Vector2d(placement.left_mm, placement.up_mm));
  tz[0] = std::remainder(tz[0], 360.0);
  if (tz[0] >= 180.0) tz[0] -= 360.0;
  if (!model.has_z(tz[1]))
    throw InvalidInput(cat(placement.landmark, std::showpos, placement.left_mm, ",",
                           placement.up_mm, std::noshowpos, ": the point lies at z = ", tz[1],
                           " mm, outside the model"));
  return tz;
}

std::optional<LandmarkPlacement> nearest_landmark_placement(const PatientModel& model,
                                                            const Landmarks& landmarks,
                                                            double theta_deg, double z_mm,
                                                            double max_mm) {
  if (!std::isfinite(theta_deg) || !std::isfinite(z_mm) || !model.has_z(z_mm)) return std::nullopt;
  const Eigen::Vector3d target = model.skin_point(theta_deg, z_mm);
  // The nearest of the landmarks found clearly (confidence at least 0.5, no doubt about their
  // depth), unless one found less clearly lies at less than half its distance (the outer eye
  // corner beside the eye, rather than the nasion): a spot is better said from a landmark the
  // surgeon finds surely, but not from across the face.
  const Landmark *clear = nullptr, *any = nullptr;
  double d_clear = max_mm, d_any = max_mm;
  for (const Landmark& l : landmarks.items) {
    if (!l.found) continue;
    const double d = (model.skin_point(l.theta_deg, l.z_mm) - target).norm();
    if (d <= d_any) {
      d_any = d;
      any = &l;
    }
    if (l.confidence >= 0.5 && l.doubt.empty() && d <= d_clear) {
      d_clear = d;
      clear = &l;
    }
  }
  const Landmark* nearest = clear && !(any && d_any < 0.5 * d_clear) ? clear : any;
  if (!nearest) return std::nullopt;
  // The offsets (left, up) whose walk from the landmark (resolve_placement()) ends on the point.
  const Eigen::Vector2d step = step_on_skin(
      model, skin_frame(model, nearest->theta_deg, nearest->z_mm, 90.0), {theta_deg, z_mm});
  LandmarkPlacement p;
  p.landmark = nearest->name;
  p.left_mm = step.x();
  p.up_mm = step.y();
  return p;
}

std::optional<LandmarkPlacement> nearest_kept_landmark_placement(
    const std::filesystem::path& model_dir, const PatientModel& model, double theta_deg,
    double z_mm) {
  const std::string kept = read_model_info(model_dir).landmarks_json;
  if (kept.empty()) return std::nullopt;
  return nearest_landmark_placement(
      model, landmarks_from_json(kept, (model_dir / model_file::kJson).string()), theta_deg, z_mm);
}

std::string placement_in_words(const LandmarkPlacement& placement) {
  const auto mm = [](double v, const char* pos, const char* neg) {
    return cat(std::lround(std::abs(v)), " mm ", v < 0 ? neg : pos);
  };
  return cat(mm(placement.left_mm, "to the patient's left", "to the patient's right"), " and ",
             mm(placement.up_mm, "up", "down"), " from the ",
             landmark_in_words(placement.landmark));
}

}  // namespace caps::plan
