#pragma once
/// @brief The procedure library (the paper's menu of procedures): each template turns a few
/// clinical parameters into the cutting path, the excision offsets and the suture pairs. The
/// hand-worked topologies are documented with figures in docs/plan.md.
///
/// Templates are laid out in the local tangent frame (plan.hpp): x along the orientation, y to
/// its left, mm, centred on the given point. Users can define their own procedure by listing
/// points, paths, excisions and suture pairs in a procedure file (docs/plan-format.md) and reuse it.

#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "caps/plan/plan.hpp"
#include "caps/surface/patient_model.hpp"

namespace caps::plan {

/// One parameter of a template: its unit, default and clinical range (inclusive).
struct ParameterInfo {
  std::string name;
  std::string unit;      ///< "mm", "deg" or "count"
  double default_value = 0;
  double min = 0, max = 0;
  std::string meaning;
  /// Another parameter this one replaces (apex_angle sets the width): giving both is refused.
  std::string alternative_to = {};
};

/// A template of the library.
struct ProcedureInfo {
  std::string name;      ///< e.g. "z-plasty"
  std::string summary;
  std::vector<ParameterInfo> parameters;   ///< besides the centre and the orientation
};

/// The library, in a fixed order: data/procedures/library.json (caps/core/data_dir.hpp), each
/// template's parameters with their units, defaults and clinical ranges, read once.
const std::vector<ProcedureInfo>& procedure_library();

/// Reads a procedure library file and checks it against the layouts caps has: every entry must
/// have a layout and every layout an entry, each default within its range. Throws IoError
/// (unreadable) or InvalidInput naming the file and the entry.
std::vector<ProcedureInfo> read_procedure_library(const std::filesystem::path& file);

/// A procedure in local coordinates: what a template or a procedure file produces.
struct LocalProcedure {
  std::string name;
  std::map<std::string, double> parameters;
  std::vector<Eigen::Vector2d> points_mm;   ///< local frame, mm
  std::vector<std::vector<int>> paths;
  std::vector<ExcisionOffset> excisions;
  std::vector<SuturePair> sutures;
  std::vector<std::vector<int>> flaps;      ///< Plan::flaps: polygons of indices into points_mm
  /// How place_procedure() lays each point on the skin: the index of the point it is walked
  /// from (-1: from the centre). Empty: every point is walked from its neighbour on the cut,
  /// from the point nearest the centre (segments keep their lengths and turns). A template that
  /// names distances from one point (the rotation flap's radius, the bilobed flap's pivot) walks
  /// them from it; excised nodes of a point laid from another point are laid from that one too.
  std::vector<int> laid_from;
  std::string notes;
};

/// A template's layout from its parameters (missing ones take their defaults). Throws
/// InvalidInput for an unknown template or parameter, or a value outside its clinical range.
LocalProcedure layout_procedure(const std::string& name,
                                const std::map<std::string, double>& parameters);

/// Places a local procedure on the model at (theta, z) with the given orientation (deg from +z
/// towards +theta): the frame, the points' (theta, z) and LPS. Lengths and angles of the local
/// layout become lengths on the skin and angles in its tangent planes: each point is walked on
/// the skin (walk_on_skin()) from the point it is laid from (LocalProcedure::laid_from), and each
/// excised node from its point by its offset (from the point its point is laid from, when that is
/// another point); the plan's excision offsets are then rewritten in
/// the plan's linear frame so that border_loop() puts each moved node where the walk ended
/// (docs/plan.md, "Frame"). Does not check the plan; see check_plan().
Plan place_procedure(const LocalProcedure& procedure, const PatientModel& model, double theta_deg,
                     double z_mm, double orientation_deg);

/// A user-defined procedure (a procedure file, "format": "caps-procedure"), as JSON text.
LocalProcedure parse_procedure_json(const std::string& text, const std::string& source);
std::string procedure_to_json(const LocalProcedure& procedure);
/// A plan's procedure in its local frame, to save and reuse (the paper's "more flexible solution").
LocalProcedure procedure_from_plan(const Plan& plan);

}  // namespace caps::plan
