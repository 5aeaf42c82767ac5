#include "caps/app/model.hpp"

#include <algorithm>
#include <chrono>
#include <fstream>
#include <sstream>
#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <type_traits>

#include "caps/core/atomic_output.hpp"
#include "caps/core/error.hpp"
#include "caps/core/units.hpp"
#include "caps/mesher/tissue_model.hpp"
#include "caps/surface/chart.hpp"
#include "caps/surface/color_picture.hpp"
#include "caps/surface/cylindrical_scan.hpp"
#include "caps/plan/placement.hpp"
#include "caps/surface/feature_lines.hpp"
#include "caps/surface/landmarks.hpp"
#include "caps/surface/picking.hpp"
#include "caps/volume/mesh_io.hpp"
#include "caps/volume/model_dir.hpp"
#include "caps/volume/read_volume.hpp"
#include "json_fields.hpp"
#include "numbers.hpp"
#include "model_result.hpp"
#include "output_check.hpp"
#include "skin_place.hpp"

CAPS_APP_REQUEST_JSON(caps::app::FromVolumeRequest)
CAPS_APP_REQUEST_JSON(caps::app::FromScanRequest)
CAPS_APP_REQUEST_JSON(caps::app::ChartRequest)
CAPS_APP_REQUEST_JSON(caps::app::ModelInfoRequest)
CAPS_APP_REQUEST_JSON(caps::app::PickRequest)
CAPS_APP_REQUEST_JSON(caps::app::ExportRangeRequest)
CAPS_APP_REQUEST_JSON(caps::app::ColorPictureRequest)
CAPS_APP_REQUEST_JSON(caps::app::VolumeInfoRequest)
CAPS_APP_REQUEST_JSON(caps::app::PhantomRequest)
CAPS_APP_REQUEST_JSON(caps::app::LandmarksRequest)
CAPS_APP_REQUEST_JSON(caps::app::FeaturesRequest)
CAPS_APP_REQUEST_JSON(caps::app::SiteRequest)
CAPS_APP_REQUEST_JSON(caps::app::TissueRequest)
CAPS_APP_RESULT_JSON(caps::app::ModelResult)
CAPS_APP_RESULT_JSON(caps::app::LandmarksResult)
CAPS_APP_RESULT_JSON(caps::app::FeaturesResult)
CAPS_APP_RESULT_JSON(caps::app::SiteResult)
CAPS_APP_RESULT_JSON(caps::app::TissueResult)
CAPS_APP_RESULT_JSON(caps::app::PickResult)
CAPS_APP_RESULT_JSON(caps::app::PathResult)
CAPS_APP_RESULT_JSON(caps::app::VolumeInfoResult)
CAPS_APP_RESULT_JSON(caps::app::PhantomResult)

namespace caps::app {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

Eigen::Vector3d triple(const std::string& s, const std::string& option, const std::string& meaning) {
  const auto t = parse_numbers<3>(s, option, meaning);
  return {t[0], t[1], t[2]};
}

// "metal was found ..." with the band of cells it left unmeasured, from the model.json in `dir`
// (segmentation.metal); empty without metal or in a model made before metal was looked for.
std::string metal_band(const std::string& dir) {
  const json j = json::parse(read_model_json(dir), nullptr, false);
  const json* metal = j.is_object() && j.contains("segmentation") && j["segmentation"].is_object() &&
                              j["segmentation"].contains("metal")
                          ? &j["segmentation"]["metal"]
                          : nullptr;
  if (!metal || !metal->is_object() || !metal->value("found", false)) return "";
  const json cells = metal->value("cells", json::object());
  const json z = cells.is_object() ? cells.value("z_mm", json::array()) : json::array();
  if (!z.is_array() || z.size() != 2 || !z[0].is_number() || !z[1].is_number()) return "";
  return cat("metal was found in this CT and the skin is not measured from z ",
             round_to(z[0].get<double>(), 1), " to ", round_to(z[1].get<double>(), 1),
             " mm, around its streaks: a landmark there cannot be found");
}

// Finds the landmarks of the model in `dir` and writes them into its model.json; an absent
// landmark is a note (the model.json entry says why).
Landmarks add_landmarks(const std::string& dir, Reporter* reporter) {
  const PatientModel model = PatientModel::load(dir);
  Landmarks l = find_landmarks(model);
  // Dental metal's band of cells is not measured (docs/volume.md, "Metal"): a landmark absent
  // says that the band may be why, and where it lies; the detector sees only unmeasured cells
  // there, which it cannot tell from the end of the CT (issue 37).
  if (const std::string band = metal_band(dir); !band.empty())
    for (auto& item : l.items)
      if (!item.found) item.note += cat("; ", band);
  write_model_landmarks(dir, landmarks_to_json(l));
  for (const auto& item : l.items)
    if (!item.found)
      note(reporter, cat("landmark ", item.name, " absent: ", item.note));
    else if (!item.doubt.empty())
      warn(reporter, cat("landmark ", item.name, ": ", item.doubt));
  // The feature lines beside them: a few hundred curvature samples per line, cheap.
  write_model_features(dir, feature_lines_to_json(find_feature_lines(model, l)));
  return l;
}

// An option the parent model recorded in its model.json (`where`: its JSON path), `fallback`
// when absent. A value of another type (a hand-edited file) is bad input naming the field, not
// an internal error.
template <class T>
T recorded(const json& o, const char* key, T fallback, const std::string& where) {
  if (!o.contains(key)) return fallback;
  try {
    return o.at(key).get<T>();
  } catch (const json::exception&) {
    throw InvalidInput(cat(where, "/", key, " = ", o.at(key).dump(), " is not a ",
                           std::is_same_v<T, bool> ? "true/false" :
                           std::is_arithmetic_v<T> ? "number" : "string",
                           "; rebuild the model"));
  }
}

// Builds and writes the whole-face tissue model of the model directory `dir` from its CT's
// segmentation; its warnings go to the reporter.
TissueResult make_tissue(const std::string& dir, const Segmentation& seg, const CylindricalMaps& maps,
                         const ModelStatistics& stats, const mesher::TissueModelOptions& o,
                         Reporter* reporter) {
  const auto t0 = std::chrono::steady_clock::now();
  const mesher::TissueLevelSets ls = mesher::tissue_level_sets(seg, o);
  const double level_sets_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  mesher::TissueModel m = mesher::build_tissue_model(seg, maps, stats, ls, o, reporter);
  m.seconds_level_sets = level_sets_s;
  m.seconds_total += level_sets_s;
  mesher::write_tissue_model(dir, m, ls);
  TissueResult out;
  out.model = dir;
  std::ifstream in(fs::path(dir) / mesher::tissue_file::kJson);
  std::stringstream text;
  text << in.rdbuf();
  out.tissue_json = text.str();
  out.warnings = m.warnings;
  out.summary = cat(dir, ": tissue model ", m.n_nodes(), " nodes, ", m.n_tets(), " tets, ",
                    std::lround(m.volume_ml), " ml (dermis ", std::lround(m.layer_volume_ml[0]),
                    ", fat ", std::lround(m.layer_volume_ml[1]), ", deep ",
                    std::lround(m.layer_volume_ml[2]), " ml), built in ",
                    std::lround(m.seconds_total * 10) / 10.0, " s");
  return out;
}

}  // namespace

ModelResult detail::model_result(const std::string& dir, const std::string& output) {
  ModelResult m;
  m.output = output;
  m.model_json = read_model_json(dir);
  m.summary = model_summary(dir);
  const json j = json::parse(m.model_json);
  if (j.contains("warnings")) m.warnings = j.at("warnings").get<std::vector<std::string>>();
  return m;
}

std::string summary(const ModelResult& m) {
  std::string s = m.summary;
  while (!s.empty() && s.back() == '\n') s.pop_back();
  return s;
}

namespace {

// The cylindrical grid's memory, checked before it is made: about 144 bytes a cell (measured:
// caps model from-volume on the 80 x 80 x 72 phantom peaked at 566 MB with a 2048 x 2048 grid,
// 190 MB at 512 x 256; 8192 x 8192 asked 9.5 GB and failed after trying).
void check_grid_budget(int n_theta, int n_z, double max_bytes, const char* limit) {
  constexpr double kBytesPerCell = 144;
  const double bytes = static_cast<double>(n_theta) * n_z * kBytesPerCell;
  if (!(bytes <= max_bytes))
    throw InvalidInput(cat("--n-theta ", n_theta, " x --n-z ", n_z, ": the cylindrical grid "
                           "needs about ", round_to(bytes / 1e9, 1), " GB of memory (",
                           kBytesPerCell, " bytes a cell), more than the limit of ",
                           round_to(max_bytes / 1e9, 1), " GB (", limit, "); use a coarser "
                           "grid", std::string(limit) == "max_bytes" ? " or raise --max-bytes" : ""));
}

}  // namespace

// ---- from-volume --------------------------------------------------------------------------

namespace {

// Whether the landmarks show the face's midline profile: the glabella, the nasion, the nose tip
// and the subnasale all found (none withdrawn as out of the face's order). Not the chin, which
// many head CTs leave out (Cranium's ends above it).
bool midline_found(const Landmarks& l) {
  for (const char* name : {"glabella", "nasion", "pronasale", "subnasale"}) {
    const Landmark* x = l.find(name);
    if (!x || !x->found) return false;
  }
  return true;
}
// Whether the landmark detector asked whether the head is tilted: a nose where the brow should
// be, or landmarks out of the face's order (docs/landmarks.md). A head without a face (the plain
// phantom) or a CT cut above the nose is not searched for a pose.
bool suspects_tilt(const Landmarks& l) {
  for (const Landmark& x : l.items)
    if (!x.found && x.note.find("tilted in the scanner?") != std::string::npos) return true;
  return false;
}
bool midline_found(const CylindricalMaps& maps) {
  return midline_found(find_landmarks(PatientModel(maps)));
}

// `a` turned by `deg` about `about` through the head's middle (z = 0 there): the axis turned
// with a head tilted or leaning in the scanner.
CylinderAxis turned_axis(const CylinderAxis& a, const CylinderGrid& g, const Eigen::Vector3d& about,
                         double deg) {
  const Eigen::AngleAxisd turn(deg_to_rad(deg), about);
  CylinderAxis t;
  t.direction = (turn * a.direction).normalized();
  t.front = (turn * a.front).normalized();
  t.origin_lps = a.to_lps(0, g.z_mm(g.n_z / 2), 0);
  return t;
}

// The head's pitch in the scanner (issue 37; docs/landmarks.md, "A head tilted or turned in the
// scanner"). Along the scanner's axis the profile of a head tilted 20 deg or more is not a face's
// and its landmarks are withdrawn. The axis is then tilted about the head's left-right direction
// (square to the axis and to the face's midline, `midline_theta_deg`: a head also turned is
// tilted about its own left-right axis), through the head's middle, by -30 .. 30 deg in 10 deg
// steps; each trial's skin (maps without layers or surfaces) is searched for the midline
// landmarks, and the middle of the neighbouring tilts that find them all is taken as the head's
// pitch: a face is found within about 10-15 deg of upright either way (docs/landmarks.md's
// table), so the middle of that range is the upright one.
// nullopt when no two neighbouring tilts find it (the scanner's axis stays, its landmarks absent).
struct Pitch {
  CylinderAxis axis;
  double deg = 0;
  std::vector<double> found_at;  // the tilts that found the midline profile
};
std::optional<Pitch> head_pitch(const Volume& v, const VolumeModel& upright,
                                double midline_theta_deg, ModelOptions o, Reporter* reporter) {
  const CylinderAxis& a = upright.maps.axis;
  const Eigen::Vector3d left = a.direction.cross(a.ray(deg_to_rad(midline_theta_deg))).normalized();
  // The scanner's axis tilted by `deg` about `left`, through the head's middle.
  const auto tilted = [&](double deg) { return turned_axis(a, upright.maps.grid, left, deg); };
  o.surfaces = false;
  o.maps.layers.measure = false;
  std::vector<double> found_at;
  for (const double deg : {-30.0, -20.0, -10.0, 10.0, 20.0, 30.0}) {
    o.axis = tilted(deg);
    note(reporter, cat("the head's pose: trying its axis tilted ", deg, " deg"));
    if (midline_found(build_volume_model(v, o, nullptr).maps)) found_at.push_back(deg);
  }
  // The longest run of neighbouring tilts (10 deg apart) that found it; one tilt alone is not
  // taken (on VTK's headsq, whose upright profile lacks a landmark, only -10 deg found all four).
  std::size_t best_first = 0, best_n = 0;
  for (std::size_t i = 0; i < found_at.size();) {
    std::size_t j = i + 1;
    while (j < found_at.size() && found_at[j] - found_at[j - 1] < 10.5) ++j;
    if (j - i > best_n) best_first = i, best_n = j - i;
    i = j;
  }
  if (best_n < 2) return std::nullopt;
  const auto first = found_at.begin() + static_cast<std::ptrdiff_t>(best_first);
  found_at = std::vector<double>(first, first + static_cast<std::ptrdiff_t>(best_n));
  const std::size_t mid = found_at.size() / 2;
  const double deg =
      found_at.size() % 2 ? found_at[mid] : 0.5 * (found_at[mid - 1] + found_at[mid]);
  return Pitch{tilted(deg), deg, found_at};
}

// The head's roll in the scanner (issue 37; docs/landmarks.md, "A head leaning to one side"):
// the vertex leaning towards a shoulder. The face's left and right landmarks (the outer eye
// corners, the zygia, the tragia) lie at one height on an upright head; leaning by `deg` (the
// vertex towards the patient's left), the left one lies lower by sin(deg) times their distance.
// The pairs found give the roll, each weighted by its width (the tragia's 150-170 mm weigh more
// than the eye corners' 70-100 mm); nullopt without a pair.
struct Roll {
  double deg = 0;
  std::vector<std::pair<std::string, double>> pairs;  // each pair's own roll (deg)
};
std::optional<Roll> head_roll(const CylinderAxis& a, const Landmarks& l) {
  Roll r;
  double sum = 0, weight = 0;
  for (const char* base : {"exocanthion", "zygion", "tragion"}) {
    const Landmark* left = l.find(cat(base, "_left"));
    const Landmark* right = l.find(cat(base, "_right"));
    if (!left || !right || !left->found || !right->found) continue;
    const Eigen::Vector3d d = left->lps - right->lps;
    const Eigen::Vector3d lr = a.direction.cross(a.ray(deg_to_rad(l.midline_theta_deg)));
    const double deg = -std::atan2(d.dot(a.direction), d.dot(lr)) * 180.0 / M_PI;
    r.pairs.emplace_back(base, deg);
    sum += d.norm() * deg;
    weight += d.norm();
  }
  if (weight == 0) return std::nullopt;
  r.deg = sum / weight;
  return r;
}

// `a` turned by `deg` about the face's front (anterior at `midline_theta_deg`) through the
// head's middle, as a head leaning by `deg` towards its left turns its own axis (fit_axis() then
// moves it onto the centre of the head's sections square to it).
CylinderAxis leaned(const CylinderAxis& a, const CylinderGrid& g, double midline_theta_deg,
                    double deg) {
  return turned_axis(a, g, a.ray(deg_to_rad(midline_theta_deg)), -deg);
}

// Whether the detector asked whether the head is turned or leaning (the skin most symmetric at
// the edge of the midline's search).
bool leaning_suspected(const Landmarks& l) {
  for (const Landmark& x : l.items)
    if (!x.found && x.note.find("leaning in the scanner?") != std::string::npos) return true;
  return false;
}

// The roll (deg) whose axis shows the face's midline landmarks: 15, -15, 30, -30 in turn, each
// a model without layers or surfaces; nullopt if none.
std::optional<double> roll_search(const Volume& v, const VolumeModel& m, ModelOptions o,
                                  Reporter* reporter) {
  o.surfaces = false;
  o.maps.layers.measure = false;
  for (const double deg : {15.0, -15.0, 30.0, -30.0}) {
    o.axis = fit_axis(m.segmentation, leaned(m.maps.axis, m.maps.grid, 0.0, deg));
    note(reporter, cat("the head's pose: trying its axis turned ", deg, " deg about the front"));
    if (midline_found(build_volume_model(v, o, nullptr).maps)) return deg;
  }
  return std::nullopt;
}

// A head leaning kMinRollDeg or more towards a shoulder is put upright: the model is rebuilt on
// its axis turned with the head about the face's front, and once more if the pairs still say
// more than kRollToleranceDeg. A turn that loses the face's midline landmarks is not taken.
// model.json's source.pose gets the roll and each pair's, source.notes a sentence.
constexpr double kMinRollDeg = 3.0, kRollToleranceDeg = 0.5;
void lean_upright(const Volume& v, ModelOptions& o, VolumeModel& m, Landmarks l, double searched,
                  Reporter* reporter) {
  double total = searched;
  std::vector<std::pair<std::string, double>> first;
  for (int pass = 0; pass < 2; ++pass) {
    const std::optional<Roll> roll = head_roll(m.maps.axis, l);
    const double least = pass == 0 && searched == 0 ? kMinRollDeg : kRollToleranceDeg;
    if (!roll || !(std::abs(roll->deg) >= least)) break;
    if (pass == 0) first = roll->pairs;
    note(reporter, cat("the head's pose: leaning ", round_to(roll->deg, 1), " deg; turning the "
                       "model's axis with it"));
    ModelOptions turned = o;
    // Through the centre of the head's sections square to the turned axis: turned about a
    // point off the head's own axis (the scanner's centres lie on a slant), the model's rays
    // would start a few mm aside and the ears and cheeks stand out otherwise.
    turned.axis =
        fit_axis(m.segmentation, leaned(m.maps.axis, m.maps.grid, l.midline_theta_deg, roll->deg));
    VolumeModel again = build_volume_model(v, turned, reporter);
    Landmarks after = find_landmarks(PatientModel(again.maps));
    if (midline_found(l) && !midline_found(after)) break;
    o = turned;
    m = std::move(again);
    l = std::move(after);
    total += roll->deg;
  }
  if (total == 0) return;
  std::string pairs;
  for (const auto& [name, deg] : first)
    pairs += cat(pairs.empty() ? "" : ", ", name, "s ", round_to(deg, 1));
  const std::string how =
      searched != 0
          ? cat("its face's midline found with the axis turned ", searched, " deg, then its left "
                "and right landmarks at different heights: ", pairs.empty() ? "none" : pairs,
                " deg more")
          : cat("its left and right landmarks at different heights: ", pairs, " deg");
  const std::string why =
      cat("the head leans ", round_to(std::abs(total), 1), " deg towards its ",
          total > 0 ? "left" : "right", " shoulder in the scanner (", how, "); the model's axis "
          "is turned with it, so up and left are the head's own (model.json axis; "
          "docs/landmarks.md)");
  note(reporter, why);
  m.notes.push_back(why);
  json pose = m.pose_json.empty() ? json::object() : json::parse(m.pose_json);
  pose["roll_deg"] = total;
  if (searched != 0) pose["roll_searched_deg"] = searched;
  json each = json::object();
  for (const auto& [name, deg] : first) each[name] = deg;
  pose["roll_pairs_deg"] = each;
  pose["roll_method"] = "the left and right landmarks' heights (outer eye corners, zygia, "
                        "tragia; weighted by their width), the axis turned about the face's "
                        "front and refitted through the centre of the head's sections square to "
                        "it (docs/landmarks.md, \"A head leaning "
                        "to one side\")";
  m.pose_json = pose.dump();
}

}  // namespace

ModelResult run_from_volume(const FromVolumeRequest& r, Reporter* reporter) {
  detail::refuse_output_over_inputs(r);
  // Check the output and the options before the slow work, so a mistake fails at once.
  { OutputDirectory probe(r.output, r.force); }
  if (!(r.decimate > 0 && r.decimate <= 1))
    throw InvalidInput(cat("--decimate ", r.decimate, ": give the fraction of faces to keep, in (0, 1]"));
  if (!r.modality.empty() && r.modality != "CT" && r.modality != "MR")
    throw InvalidInput(cat("--modality '", r.modality, "': use CT or MR"));
  ModelOptions o;
  if (r.skin_threshold) o.segment.skin_threshold = *r.skin_threshold;
  if (r.bone_threshold) o.segment.bone_threshold = *r.bone_threshold;
  o.segment.mr_scalp_mm = r.mr_scalp;
  if (!(r.max_bytes >= 1)) throw InvalidInput(cat("--max-bytes ", r.max_bytes, ": give a positive number of bytes (max_bytes)"));
  check_grid_budget(r.n_theta, r.n_z, r.max_bytes, "max_bytes");
  o.maps.n_theta = r.n_theta;
  o.maps.n_z = r.n_z;
  o.maps.bone_cap_mm = r.bone_cap;
  o.maps.bone.method = parse_bone_method(r.bone_method);
  o.maps.bone.floor_hu = r.bone_floor;
  o.maps.bone.cavity_base = !r.no_cavity_base;
  o.maps.bone.tissue_reach_mm = r.tissue_reach;
  o.maps.layers.measure = !r.no_layers;
  o.maps.layers.fat_level_hu = r.fat_level;
  o.maps.layers.merge_gap_mm = r.fat_merge_gap;
  o.maps.layers.min_band_mm = r.fat_min_band;
  o.decimate_fraction = r.decimate;
  if (!(r.min_head_ml >= 0 && r.min_head_ml <= 1e5))
    throw InvalidInput(cat("--min-head-ml ", r.min_head_ml, ": give ml, 0 (no check) to 100000"));
  o.min_head_ml = r.min_head_ml;
  if (!r.axis_origin.empty() || !r.axis_dir.empty()) {
    CylinderAxis axis;
    if (!r.axis_origin.empty())
      axis.origin_lps = triple(r.axis_origin, "--axis-origin", "a point of the axis, LPS mm");
    if (!r.axis_dir.empty()) {
      const Eigen::Vector3d d = triple(r.axis_dir, "--axis-dir", "a direction, LPS");
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
  ReadOptions ro;
  ro.series_uid = r.series;
  ro.allow_missing_slices = r.allow_missing_slices;
  ro.max_voxels = r.max_voxels;
  ro.max_bytes = r.max_bytes;
  Volume v = read_volume(r.input, ro);
  if (r.modality == "CT") v.modality = Modality::CT;
  if (r.modality == "MR") v.modality = Modality::MR;
  for (const auto& n : v.notes) note(reporter, cat(r.input, ": ", n));
  // A volume that does not say what it is and does not look like a CT was modelled as an MR,
  // with its bone assumed a few mm under the skin everywhere: on a CT in other units that is a
  // model silently wrong (issue 37). The user says which.
  if (v.modality == Modality::Unknown)
    throw InvalidInput(cat(r.input, ": the file does not say its modality and its intensities do "
                           "not look like a CT's (air at -1000 HU, or at 0 when stored HU + 1024): "
                           "give --modality MR to model it as an MR (its bone assumed ",
                           r.mr_scalp, " mm under the skin, or --bone-mask FILE), or --modality "
                           "CT with --skin-threshold and --bone-threshold in the file's units"));
  Volume bone_mask;
  if (!r.bone_mask.empty()) {
    bone_mask = read_volume(r.bone_mask);
    o.segment.bone_mask = &bone_mask;
  }
  VolumeModel m = build_volume_model(v, o, reporter);
  // The head's pose when the scanner's axis does not show a face's profile (an axis given with
  // --axis-dir is kept as it is).
  const bool axis_given = o.axis.has_value();
  const Landmarks upright = o.axis ? Landmarks{} : find_landmarks(PatientModel(m.maps));
  if (!o.axis && !midline_found(upright) && suspects_tilt(upright)) {
    if (const std::optional<Pitch> pitch =
            head_pitch(v, m, upright.midline_theta_deg, o, reporter)) {
      o.axis = pitch->axis;
      m = build_volume_model(v, o, reporter);
      std::string tried;
      for (double d : pitch->found_at) tried += cat(tried.empty() ? "" : ", ", d);
      const std::string why =
          cat("the head lies tilted in the scanner: along the scanner's axis its profile is not "
              "a face's, and the face's midline landmarks were found with the axis tilted ", tried,
              " deg about the left-right direction; the model's axis is tilted ", pitch->deg,
              " deg, the middle of those (model.json axis; docs/landmarks.md)");
      note(reporter, why);
      m.notes.push_back(why);
      m.pose_json = json{{"pitch_deg", pitch->deg},
                         {"found_at_deg", pitch->found_at},
                         {"about", "the head's left-right direction, through the head's middle"},
                         {"method", "the middle of the neighbouring axis tilts (10 deg steps) "
                                    "whose skin shows the glabella, nasion, nose tip and "
                                    "subnasale (docs/landmarks.md, \"The head's pitch\")"}}
                        .dump();
    }
  }
  if (!axis_given) {
    // The landmarks of the model as it stands: the upright one's unless the pitch rebuilt it.
    Landmarks now = o.axis ? find_landmarks(PatientModel(m.maps)) : upright;
    double searched_roll = 0;
    // A head leaning so far that its skin is most symmetric at the edge of the midline's search
    // (25 deg or more on the face phantom): the axis turned with it by 15 and 30 deg either way,
    // the first that shows the face's midline landmarks taken, and refined below.
    if (!o.axis && !midline_found(now) && leaning_suspected(now))
      if (const std::optional<double> deg = roll_search(v, m, o, reporter)) {
        o.axis = fit_axis(m.segmentation, leaned(m.maps.axis, m.maps.grid, 0.0, *deg));
        m = build_volume_model(v, o, reporter);
        now = find_landmarks(PatientModel(m.maps));
        searched_roll = *deg;
      }
    lean_upright(v, o, m, std::move(now), searched_roll, reporter);
  }
  write_model(m, r.output, r.force, reporter);
  add_landmarks(r.output, reporter);
  // The whole-face tissue model; a volume it cannot be made of (no bone, no soft tissue) still
  // gives the model, with a warning.
  if (!r.no_tissue && m.chart_json.empty()) {
    try {
      make_tissue(r.output, m.segmentation, m.maps, m.stats, mesher::TissueModelOptions{},
                  reporter);
    } catch (const InvalidInput& e) {
      warn(reporter, cat("no whole-face tissue model: ", e.what()));
    }
  }
  return detail::model_result(r.output, r.output);
}

// ---- chart --------------------------------------------------------------------------------

ModelResult run_chart(const ChartRequest& r, Reporter* reporter) {
  detail::refuse_output_over_inputs(r);
  { OutputDirectory probe(r.output, r.force); }
  if (!(r.half_height > 0 && r.half_height <= 200))
    throw InvalidInput(cat("--half-height ", r.half_height, " mm: give a length in (0, 200] mm"));
  if (!(r.radius > 0 && r.radius <= 500))
    throw InvalidInput(cat("--radius ", r.radius, " mm: give a distance in (0, 500] mm"));
  const PatientModel parent = PatientModel::load(r.model);
  const json info = json::parse(read_model_json(r.model));
  detail::refuse_unchartable(r.model);
  const json& source = info.at("source");
  const std::string volume_path = source.value("path", "");
  const json& seg = info.at("segmentation");
  if (r.at.empty() == r.at_xyz.empty())
    throw InvalidInput("give the point with --at THETA,Z, --at LANDMARK+LEFT,UP or --at-xyz X,Y,Z");
  Eigen::Vector2d tz = resolve_at(r.model, parent, r.at, r.at_xyz);
  // An LPS point is taken to 0.01 deg and 0.01 mm (a few micrometres on the skin), so that the
  // chart is named readably ("-5,55") and made again from that name alike.
  if (r.at.empty()) tz = {round_to(tz[0], 2), round_to(tz[1], 2)};
  const std::string at = !r.at.empty() ? r.at : cat(tz[0], ",", tz[1]);
  if (!parent.has_z(tz[1]))
    throw InvalidInput(cat("--at ", at, ": z ", tz[1], " mm lies outside the model (",
                           parent.grid().z0_mm, " .. ", parent.grid().z_mm(parent.grid().n_z - 1),
                           " mm)"));
  const TriMesh skin = read_ply(fs::path(r.model) / model_file::kSkinMesh);
  const ChartFrame frame =
      chart_frame(parent, skin, tz[0], tz[1], r.radius, r.normal_radius);

  ModelOptions o;
  if (seg.contains("skin_threshold") && seg.at("skin_threshold").is_number())
    o.segment.skin_threshold = seg.at("skin_threshold").get<double>();
  if (seg.contains("bone_threshold") && seg.at("bone_threshold").is_number())
    o.segment.bone_threshold = seg.at("bone_threshold").get<double>();
  const json& thickness = info.at("thickness");
  if (thickness.contains("base")) {
    const json& b = thickness.at("base");
    const std::string at_b = cat(r.model, "/model.json: /thickness/base");
    o.maps.bone.method = parse_bone_method(recorded<std::string>(b, "bone_method", "edge", at_b));
    o.maps.bone.floor_hu = recorded(b, "floor_hu", o.maps.bone.floor_hu, at_b);
    o.maps.bone.cavity_base = recorded(b, "cavity_base", o.maps.bone.cavity_base, at_b);
    // A model made before base_tissue existed had none.
    o.maps.bone.tissue_reach_mm = recorded(b, "tissue_reach_mm", 0.0, at_b);
    o.maps.bone_cap_mm = recorded(b, "bone_cap_mm", o.maps.bone_cap_mm, at_b);
  }
  if (thickness.contains("layers")) {
    const json& l = thickness.at("layers");
    const std::string at_l = cat(r.model, "/model.json: /thickness/layers");
    o.maps.layers.measure = recorded(l, "measured", true, at_l);
    o.maps.layers.fat_level_hu = recorded(l, "fat_level_hu", o.maps.layers.fat_level_hu, at_l);
    o.maps.layers.merge_gap_mm = recorded(l, "merge_gap_mm", o.maps.layers.merge_gap_mm, at_l);
    o.maps.layers.min_band_mm = recorded(l, "min_band_mm", o.maps.layers.min_band_mm, at_l);
  }
  check_grid_budget(r.n_theta, r.n_z, kDefaultMaxBytes, "8 GiB");
  o.maps.n_theta = r.n_theta;
  o.maps.n_z = r.n_z;
  o.maps.z_min_mm = -r.half_height;
  o.maps.z_max_mm = r.half_height;
  o.axis = frame.axis;

  ReadOptions ro;
  ro.series_uid = r.series;
  Volume v = read_volume(volume_path, ro);
  const std::string modality = source.value("modality", "");
  if (modality == "CT") v.modality = Modality::CT;
  if (modality == "MR") v.modality = Modality::MR;
  VolumeModel m = build_volume_model(v, o, reporter);
  const auto vec = [](const Eigen::Vector3d& x) { return json::array({x[0], x[1], x[2]}); };
  m.chart_json =
      json{{"parent", r.model},
           {"parent_content_hash", parent.content_hash()},
           {"at", at},
           {"parent_theta_deg", tz[0]},
           {"parent_z_mm", tz[1]},
           {"point_lps", vec(frame.point)},
           {"normal_lps", vec(frame.normal)},
           {"radius_mm", frame.radius_mm},
           {"normal_radius_mm", r.normal_radius},
           {"centre", "the point is at theta 0, z 0 of this chart, its ray along the skin's normal"}}
          .dump();
  write_model(m, r.output, r.force, reporter);
  return detail::model_result(r.output, r.output);
}

namespace detail {

void refuse_unchartable(const std::string& model) {
  const json info = json::parse(read_model_json(model));
  const json& source = info.at("source");
  if (source.value("kind", "volume") != "volume")
    throw InvalidInput(cat(model, ": a chart measures the CT or MR again, and this model was "
                           "built from a surface scan; build the chart from a volume model"));
  if (source.contains("chart"))
    throw InvalidInput(cat(model, " is itself a chart; make the chart from the whole-head "
                           "model it came from"));
  if (info.at("segmentation").value("bone_method", "").rfind("mask ", 0) == 0)
    throw InvalidInput(cat(model, ": its bone came from a separate mask (--bone-mask), which a "
                           "chart cannot reuse yet; build the chart's model with caps model "
                           "from-volume --axis-origin/--axis-dir and the mask"));
  const std::string volume_path = source.value("path", "");
  if (volume_path.empty() || !fs::exists(volume_path))
    throw IoError(cat(model, ": the volume it was built from (", volume_path, ") is not there; "
                      "a chart measures that volume again: put it back or rebuild the model"));
}

std::string chart_parent(const std::string& model_dir) {
  const ModelInfo info = read_model_info(model_dir);
  const json source = json::parse(info.source_json, nullptr, false);
  if (!source.is_object() || !source.contains("chart") || !source["chart"].is_object()) return {};
  const json& chart = source["chart"];
  if (!chart.contains("parent") || !chart["parent"].is_string() ||
      !chart.contains("parent_content_hash") || !chart["parent_content_hash"].is_string())
    return {};
  const std::string parent = chart["parent"].get<std::string>();
  std::error_code ec;
  if (parent.empty() || !fs::is_regular_file(fs::path(parent) / model_file::kJson, ec))
    return {};
  try {
    if (read_model_info(parent).content_hash != chart["parent_content_hash"].get<std::string>())
      return {};
  } catch (const Error&) {
    return {};
  }
  return parent;
}

std::string plan_model_dir(const std::string& given, const std::string& plan_model,
                           const std::string& plan_model_hash) {
  if (plan_model.empty() || plan_model_hash.empty() || plan_model == given) return given;
  try {
    const std::string given_hash = read_model_info(given).content_hash;
    if (given_hash == plan_model_hash) return given;
    const std::string parent = chart_parent(plan_model);
    if (parent.empty() || read_model_info(plan_model).content_hash != plan_model_hash ||
        read_model_info(parent).content_hash != given_hash)
      return given;
    return plan_model;
  } catch (const Error&) {
    return given;  // no model there: the given one's check names the plan's model
  }
}

}  // namespace detail

// ---- from-scan ----------------------------------------------------------------------------

namespace {

ScanMesh read_any_scan(const FromScanRequest& r) {
  if (fs::path(r.input).extension() == ".json")
    return cylindrical_scan_mesh(read_cylindrical_sidecar(r.input));
  if (r.r_scale || r.z_scale || !r.color.empty()) {
    CylindricalScanSpec spec;
    spec.range = r.input;
    spec.color = r.color;
    spec.r_scale_mm = r.r_scale.value_or(0.0);
    spec.r_offset_mm = r.r_offset;
    spec.z_scale_mm = r.z_scale.value_or(0.0);
    spec.theta_span_deg = r.theta_span;
    spec.theta_along_rows = r.theta_rows;
    spec.theta_reverse = r.theta_reverse;
    spec.top_first = !r.bottom_first;
    return cylindrical_scan_mesh(spec);
  }
  ScanReadOptions ro;
  ro.texture = r.texture;
  ro.flip_v = r.flip_v;
  return read_scan_mesh(r.input, ro);
}

}  // namespace

ModelResult run_from_scan(const FromScanRequest& r, Reporter* reporter) {
  detail::refuse_output_over_inputs(r);
  { OutputDirectory probe(r.output, r.force); }
  if (!r.thickness)
    throw InvalidInput("--thickness is required: the constant soft-tissue thickness in mm "
                       "(a scan shows no depth)");
  ScanModelOptions o;
  o.thickness_mm = *r.thickness;
  o.mm_per_unit = r.scale;
  o.head_height_mm = r.head_height_mm;
  // Defaults: glTF is +y up with the asset facing +z; other formats are taken the same way.
  o.up = parse_axis_name(r.up, "--up");
  o.front = parse_axis_name(r.front, "--front");
  check_grid_budget(r.n_theta, r.n_z, kDefaultMaxBytes, "8 GiB");
  o.maps.n_theta = r.n_theta;
  o.maps.n_z = r.n_z;
  o.credit = r.credit;
  o.flip_faces = r.flip_faces;
  if (!r.axis_origin.empty()) {
    CylinderAxis axis;
    axis.origin_lps = triple(r.axis_origin, "--axis-origin", "a point of the axis, LPS mm");
    o.axis = axis;
  }
  const ScanMesh scan = read_any_scan(r);
  const ScanModel m = build_scan_model(scan, o, reporter);
  write_scan_model(m, r.output, r.force, reporter);
  add_landmarks(r.output, reporter);
  return detail::model_result(r.output, r.output);
}

// ---- info, pick, export-range, color-picture ----------------------------------------------

ModelResult run_model_info(const ModelInfoRequest& r, Reporter*) {
  return detail::model_result(r.model, "");
}

TissueResult run_model_tissue(const TissueRequest& r, Reporter* reporter) {
  const ModelInfo info = read_model_info(r.model);
  if (mesher::has_tissue_model(r.model) && !r.force)
    throw InvalidInput(cat(r.model, " has a tissue model already (", mesher::tissue_file::kMesh,
                           "); give --force to build it again"));
  mesher::TissueModelOptions o;
  o.depth_limit_mm = r.depth_limit;
  o.face_size_mm = r.face_size;
  o.scalp_size_mm = r.scalp_size;
  if (!(r.depth_limit > 0 && r.depth_limit <= 100))
    throw InvalidInput(cat("--depth-limit ", r.depth_limit, " mm: give a depth in (0, 100] mm"));
  if (!(r.face_size >= 0.5 && r.face_size <= 20) || !(r.scalp_size >= 0.5 && r.scalp_size <= 20))
    throw InvalidInput(cat("--face-size ", r.face_size, " / --scalp-size ", r.scalp_size,
                           " mm: give sizes in [0.5, 20] mm"));
  const json j = json::parse(read_model_json(r.model));
  const json& source = j.at("source");
  if (source.value("kind", "volume") != "volume")
    throw InvalidInput(cat(r.model, ": a model built from a surface scan has no CT to segment; "
                           "its tissue model (the scan's skin and the constant thickness) is not "
                           "made yet"));
  if (source.contains("chart"))
    throw InvalidInput(cat(r.model, " is a chart; build the tissue model on the whole-head model "
                           "it came from"));
  const json& seg_json = j.at("segmentation");
  if (seg_json.value("bone_method", "").rfind("mask ", 0) == 0)
    throw InvalidInput(cat(r.model, ": its bone came from a separate mask (--bone-mask), which "
                           "caps model tissue cannot reuse yet; rebuild the model with caps model "
                           "from-volume and the mask"));
  const std::string volume_path = source.value("path", "");
  if (volume_path.empty() || !fs::exists(volume_path))
    throw IoError(cat(r.model, ": the volume it was built from (", volume_path, ") is not there; "
                      "put it back or rebuild the model"));
  SegmentOptions so;
  const std::string at_s = cat(r.model, "/model.json: /segmentation");
  if (seg_json.contains("skin_threshold") && seg_json.at("skin_threshold").is_number())
    so.skin_threshold = recorded(seg_json, "skin_threshold", 0.0, at_s);
  if (seg_json.contains("bone_threshold") && seg_json.at("bone_threshold").is_number())
    so.bone_threshold = recorded(seg_json, "bone_threshold", 0.0, at_s);
  Volume v = read_volume(volume_path);
  const std::string modality = source.value("modality", "");
  if (modality == "CT") v.modality = Modality::CT;
  if (modality == "MR") v.modality = Modality::MR;
  const Segmentation seg = segment_head(v, so, reporter);
  const CylindricalMaps maps = read_model_maps(r.model, info);
  return make_tissue(r.model, seg, maps, info.stats, o, reporter);
}

std::string summary(const TissueResult& r) { return r.summary; }

LandmarksResult run_model_landmarks(const LandmarksRequest& r, Reporter* reporter) {
  LandmarksResult out;
  out.model = r.model;
  Landmarks l;
  if (r.no_write) {
    l = find_landmarks(PatientModel::load(r.model));
  } else {
    l = add_landmarks(r.model, reporter);
    out.written = true;
  }
  out.landmarks_json = landmarks_to_json(l);
  out.table = landmarks_table(l);
  return out;
}

std::string summary(const LandmarksResult& r) {
  std::string s = r.table;
  while (!s.empty() && s.back() == '\n') s.pop_back();
  return s;
}

FeaturesResult run_model_features(const FeaturesRequest& r, Reporter* reporter) {
  FeaturesResult out;
  out.model = r.model;
  const PatientModel model = PatientModel::load(r.model);
  const ModelInfo info = read_model_info(r.model);
  const Landmarks l = info.landmarks_json.empty()
                          ? find_landmarks(model)
                          : landmarks_from_json(info.landmarks_json,
                                                (fs::path(r.model) / model_file::kJson).string());
  const FeatureLines lines = find_feature_lines(model, l);
  for (const auto& item : lines.items)
    if (!item.found) note(reporter, cat("feature line ", item.name, " absent: ", item.note));
  out.features_json = feature_lines_to_json(lines);
  out.table = feature_lines_table(lines);
  if (!r.no_write) {
    write_model_features(r.model, out.features_json);
    out.written = true;
  }
  if (!r.picture.empty()) {
    write_feature_lines_png(r.picture, model, l, lines,
                            cat("Feature lines on the skin, ", fs::path(r.model).filename().string()));
    out.picture = r.picture;
  }
  return out;
}

std::string summary(const FeaturesResult& r) {
  std::string s = r.table;
  while (!s.empty() && s.back() == '\n') s.pop_back();
  if (!r.picture.empty()) s += "\npicture: " + r.picture;
  return s;
}

SiteResult run_model_site(const SiteRequest& r, Reporter*) {
  const PatientModel model = PatientModel::load(r.model);
  SiteResult out;
  out.model = r.model;
  out.at = r.at;
  const Eigen::Vector2d tz = resolve_at(r.model, model, r.at);
  out.theta_deg = tz[0];
  out.z_mm = tz[1];
  const auto& maps = model.maps();
  out.lps = model.skin_point(out.theta_deg, out.z_mm);
  out.thickness_mm = model.thickness_normal(out.theta_deg, out.z_mm);
  out.thickness_radial_mm = model.thickness(out.theta_deg, out.z_mm);
  out.has_layers = maps.has_layers() && !maps.thickness_skin_normal.empty();
  if (out.has_layers) {
    out.skin_mm = model.sample(maps.thickness_skin_normal, out.theta_deg, out.z_mm);
    out.fat_mm = model.sample(maps.thickness_fat_normal, out.theta_deg, out.z_mm);
    out.deep_mm = model.sample(maps.thickness_deep_normal, out.theta_deg, out.z_mm);
  }
  out.flags = describe_flags(model.flags_at(out.theta_deg, out.z_mm));
  out.doubt = tissue_doubt(out.thickness_mm, out.has_layers ? out.skin_mm : NAN);
  if (!out.doubt.empty()) out.warnings.push_back(cat("implausible here: ", out.doubt));
  return out;
}

std::string summary(const SiteResult& r) {
  std::string s = cat(r.at, ": theta ", round_to(r.theta_deg, 2), " deg, z ", round_to(r.z_mm, 2),
                      " mm, soft tissue ", round_to(r.thickness_mm, 2), " mm along the normal");
  if (r.has_layers)
    s += cat(" (skin ", round_to(r.skin_mm, 2), ", fat ", round_to(r.fat_mm, 2), ", deep ",
             round_to(r.deep_mm, 2), ")");
  s += cat(", ", r.flags);
  if (!r.doubt.empty()) s += cat(" [implausible: ", r.doubt, "]");
  return s;
}

PickResult run_pick(const PickRequest& r, Reporter*) {
  const auto v = parse_numbers<6>(r.ray, "--ray", "OX,OY,OZ,DX,DY,DZ in LPS mm");
  const PatientModel model = PatientModel::load(r.model);
  const Ray ray{{v[0], v[1], v[2]}, {v[3], v[4], v[5]}};
  const SkinPicker picker(model);
  const SkinHit h = picker.pick(ray);
  PickResult p;
  p.hit = h.hit;
  if (h.hit) {
    p.lps = h.lps;
    p.theta_deg = h.theta_deg;
    p.z_mm = h.z_mm;
    p.distance_mm = h.distance_mm;
    p.flags = describe_flags(h.flags);
    p.on_pole_cap = h.on_pole_cap;
  }
  return p;
}

std::string summary(const PickResult& p) {
  if (!p.hit) return "miss";
  return cat("hit theta ", round_to(p.theta_deg, 2), " deg, z ", round_to(p.z_mm, 2), " mm, LPS (",
             round_to(p.lps.x(), 2), " ", round_to(p.lps.y(), 2), " ", round_to(p.lps.z(), 2),
             ") mm, ", p.flags);
}

std::string summary(const PathResult& p) { return cat("-> ", p.output); }

PathResult run_export_range(const ExportRangeRequest& r, Reporter*) {
  detail::refuse_output_over_inputs(r);
  const PatientModel model = PatientModel::load(r.model);
  OutputDirectory out(r.output, r.force);
  write_cylindrical_scan(model, out.path(), r.r_scale);
  out.commit();
  return {(fs::path(r.output) / "range.json").string(), {}};
}

PathResult run_color_picture(const ColorPictureRequest& r, Reporter*) {
  detail::refuse_output_over_inputs(r);
  if (fs::exists(r.output) && !r.force)
    throw InvalidInput(cat(r.output, ": exists; pass --force to replace it"));
  const PatientModel model = PatientModel::load(r.model);
  const auto j = json::parse(read_model_json(r.model));
  const std::string credit = j["source"].value("credit", std::string());
  const std::string name = fs::path(j["source"].value("path", r.model)).filename();
  write_color_picture(r.output, model, cat("Skin colour, ", name), credit);
  return {r.output, {}};
}

// ---- volume info --------------------------------------------------------------------------

VolumeInfoResult run_volume_info(const VolumeInfoRequest& r, Reporter*) {
  ReadOptions ro;
  ro.series_uid = r.series;
  ro.max_voxels = r.max_voxels;
  ro.max_bytes = r.max_bytes;
  ro.volume_index = r.volume_index;
  const Volume v = read_volume(r.input, ro);
  const auto [lo, hi] = std::minmax_element(v.data.begin(), v.data.end());
  const auto& g = v.geom;
  // Moments of the acquired voxels, to compare a read with another reader's: the mean, the
  // standard deviation and the centroid (LPS) of value - min, which moves if values or axes do.
  double n = 0, sum = 0, sum2 = 0, wsum = 0;
  Eigen::Vector3d wpos = Eigen::Vector3d::Zero();
  for (int k = 0; k < g.dims[2]; ++k)
    for (int j = 0; j < g.dims[1]; ++j)
      for (int i = 0; i < g.dims[0]; ++i) {
        const std::size_t at = g.linear(i, j, k);
        if (!v.acquired.empty() && !v.acquired[at]) continue;
        const double x = v.data[at], w = x - *lo;
        n += 1;
        sum += x;
        sum2 += x * x;
        wsum += w;
        wpos += w * v.index_to_lps(Eigen::Vector3d(i, j, k));
      }
  const double mean = n > 0 ? sum / n : 0.0;
  const double sd = n > 0 ? std::sqrt(std::max(0.0, sum2 / n - mean * mean)) : 0.0;
  const Eigen::Vector3d centroid = wsum > 0 ? Eigen::Vector3d(wpos / wsum) : g.origin_lps;
  json j{{"source", v.source},
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
         {"mean", mean},
         {"std", sd},
         {"centroid_lps", {centroid[0], centroid[1], centroid[2]}},
         {"outside_field_voxels", static_cast<std::size_t>(g.n_voxels() - n)},
         {"notes", v.notes}};
  if (v.format == "DICOM") {
    json list = json::array();
    // A single .dcm file is read with its series from its folder: list that folder's series.
    std::error_code ec;
    fs::path folder = r.input;
    if (!fs::is_directory(folder, ec))
      folder = folder.has_parent_path() ? folder.parent_path() : fs::path(".");
    for (const auto& s : list_dicom_series(folder))
      list.push_back({{"uid", s.uid}, {"description", s.description}, {"modality", s.modality},
                      {"files", s.n_files}});
    j["series"] = list;
  }
  std::ostringstream text;
  text << "source     " << v.source << " (" << v.format << ", " << to_string(v.modality) << ")\n"
       << "dims       " << g.dims.transpose() << "\n"
       << "spacing    " << g.spacing_mm.transpose() << " mm\n"
       << "origin     " << g.origin_lps.transpose() << " mm (LPS)\n"
       << "values     " << *lo << " .. " << *hi;
  for (const auto& n : v.notes) text << "\nnote       " << n;
  return {j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace), text.str()};
}

std::string summary(const VolumeInfoResult& r) { return r.text; }

// ---- phantom ------------------------------------------------------------------------------

PhantomResult run_phantom(const PhantomRequest& r, Reporter*) {
  const fs::path path(r.output);
  const std::string name = path.filename().string();
  if (!name.ends_with(".nii.gz") && !name.ends_with(".nii"))
    throw InvalidInput(cat(r.output, ": the phantom is written as NIfTI; name it .nii or .nii.gz"));
  if (fs::exists(path) && !r.force)
    throw InvalidInput(cat(r.output, ": already exists; choose another name or pass --force"));
  PhantomOptions o;
  const auto s = parse_numbers<3>(r.voxels, "--voxels", "voxels along L,P,S");
  const auto h = parse_numbers<3>(r.spacing, "--spacing", "mm along L,P,S");
  for (int a = 0; a < 3; ++a) {
    if (s[a] != static_cast<int>(s[a]))
      throw InvalidInput(cat("--voxels ", r.voxels, ": voxel counts must be whole numbers"));
    o.dims[a] = static_cast<int>(s[a]);
    o.spacing_mm[a] = h[a];
  }
  // 2048^3 voxels are allowed per axis but need 34 GB as floats: the whole is checked.
  const double bytes = o.dims.cast<double>().prod() * sizeof(float);
  if (!(bytes <= kDefaultMaxBytes))
    throw InvalidInput(cat("--voxels ", r.voxels, ": the phantom needs about ",
                           round_to(bytes / 1e9, 1), " GB of memory, more than the limit of ",
                           round_to(kDefaultMaxBytes / 1e9, 1), " GB; give fewer voxels"));
  o.head_holder = !r.no_holder;
  o.layered = r.layered;
  o.thin_bone = r.thin_bone;
  o.face = r.face;
  o.metal = r.metal;
  o.metal_z_mm = r.metal_z;
  o.scale = r.scale;
  o.pitch_deg = r.pitch;
  o.yaw_deg = r.yaw;
  o.roll_deg = r.roll;
  const Volume v = make_phantom(o);
  write_nifti(v, path);
  return {r.output, o.dims,  o.spacing_mm, o.head_holder, o.layered,
          o.thin_bone, o.face, o.scale,      o.metal};
}

std::string summary(const PhantomResult& p) {
  return cat("caps phantom: ", p.dims[0], " x ", p.dims[1], " x ", p.dims[2], " voxels -> ",
             p.output);
}

}  // namespace caps::app
