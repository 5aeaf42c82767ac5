#pragma once
/// @brief `caps plan suggest`: for a lesion on the patient, the library's closures that fit it,
/// laid around it at every orientation, checked, closed in the whole face and ranked by an
/// objective the surgeon chooses (docs/plan.md, "Suggestions").
///
/// Two passes, as a surgeon's time allows: a sweep of every design on a coarser mesh (the same
/// whole face; the linear model where the material is isotropic), then the best few closed
/// again with the material and the mesh the user's simulate gets, which decide the ranking
/// among themselves. The designs the sweep refused (the
/// plan reaches the eye, the closure did not converge in its time) are listed with why.

#include <limits>
#include <string>
#include <vector>

#include "caps/app/fields.hpp"
#include "caps/app/simulation.hpp"
#include "caps/core/reporter.hpp"

namespace caps::app {

struct SuggestRequest {
  std::string model, at, at_xyz, output;
  double diameter = 0;  ///< the lesion's largest diameter, mm (0 with an outline: its own)
  /// The lesion's outline drawn on the skin, "THETA,Z;THETA,Z;..." (deg, mm; at least 3
  /// points); empty for a round lesion of `diameter`.
  std::string outline;
  std::string outline_xyz;  ///< the same as LPS points "X,Y,Z;X,Y,Z;..." (mm)
  /// The same as mm about the lesion's centre (`at`), "LEFT,UP;LEFT,UP;...": walked on the skin
  /// to the patient's left and up from it, as a landmark's offsets are (one lesion's shape for
  /// every patient of a cohort).
  std::string outline_mm;
  double margin = 2;    ///< the clinical margin around it, mm
  std::string procedures = "ellipse";
  double step = 15;   ///< deg between orientations
  double ratio = 3;   ///< an ellipse's length over its width
  std::string objective = "force";
  int refine = 2;
  double sweep_size = 0;  ///< the sweep's mesh size (mm); 0: twice the mesh size
  std::string sweep_material = "auto";
  double sweep_time_limit = 30;  ///< s per design in the sweep (finite strain)
  double refine_time_limit = 20;  ///< s per design closed again (finite strain)
  MeshingFields meshing;
  SolverFields solver;
  DomainFields domain;
  bool force = false;

  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v(r.model, {"model", "the patient model directory", FieldKind::Required});
    v(r.at, {"at", "the lesion's centre on the skin: THETA,Z (deg, mm), or a landmark and mm "
                   "to the patient's left and up: glabella+15,20 (docs/landmarks.md)"});
    v(r.at_xyz, {"at_xyz", "the lesion's centre as an LPS point X,Y,Z (mm)"});
    v(r.diameter, {"diameter",
                   "the lesion's largest diameter (mm), a round lesion; or give "
                   "its outline"});
    v(r.outline, {"outline",
                  "the lesion's outline drawn on the skin: THETA,Z;THETA,Z;... (deg, "
                  "mm; 3 to 200 points in order around it); each design holds it and "
                  "the margin around it, an ellipse sized for it at each orientation; "
                  "its centre is the outline's unless --at is given"});
    v(r.outline_xyz, {"outline_xyz",
                      "the lesion's outline as LPS points X,Y,Z;X,Y,Z;... (mm; "
                      "on the skin, as the planner's clicks give them)"});
    v(r.outline_mm, {"outline_mm",
                     "the lesion's outline as mm about its centre (--at): LEFT,UP;LEFT,UP;... "
                     "along the skin to the patient's left and up, as a landmark's offsets "
                     "(one lesion's shape on every patient of a cohort)"});
    v(r.margin, {"margin", "the margin excised around the lesion (mm; 1-2 for a benign lesion, "
                           "4 for a basal cell carcinoma)"});
    v(r.procedures, {"procedures",
                     "the closures to try, comma-separated: ellipse, rhomboid, "
                     "bilobed (its lobes to either side), rotation-flap (its arc "
                     "to either side)"});
    v(r.step, {"step", "degrees between the orientations tried (5-90)"});
    v(r.ratio, {"ratio", "an ellipse's length over its width (2.5-4.5; 3 gives a 37 deg apex)"});
    v(r.objective, {"objective", "what ranks the designs, least first: force (the largest "
                                 "force on one suture, N), features (the largest displacement "
                                 "of an eyelid margin, brow, lip or nostril rim, mm), scar (the "
                                 "scar's length, mm), excised (the healthy skin excised, mm2) or "
                                 "rstl (an ellipse's angle to the relaxed skin tension lines, "
                                 "Borges's map, deg)"});
    v(r.refine, {"refine", "close the best this many again at the full mesh (0-12)"});
    v(r.sweep_size, {"sweep_size", "the sweep's mesh size (mm); 0 = twice --size"});
    v(r.sweep_material, {"sweep_material", "the sweep's material: auto (linear for an isotropic "
                                           "--material, which ranks the designs as the "
                                           "finite-strain closure does at a quarter of its "
                                           "time; the material itself for goh, whose fibres "
                                           "the linear model cannot see), linear, or the same "
                                           "names as --material"});
    v(r.sweep_time_limit, {"sweep_time_limit", "finite strain: give up a design in the sweep "
                                               "after this many seconds (listed as not closed)"});
    v(r.refine_time_limit, {"refine_time_limit", "finite strain: give up closing a design again "
                                                 "after this many seconds (it keeps the sweep's "
                                                 "figures, and says so); 0 = no limit"});
    MeshingFields::fields(r.meshing, v);
    SolverFields::fields(r.solver, v);
    DomainFields::fields(r.domain, v);
    v(r.output, {"output", "the folder to create: suggestions.json, suggestions.png, each "
                           "design's plan and the refined designs' results",
                 FieldKind::Required, "-o,--output"});
    v(r.force, {"force", "replace an existing output", FieldKind::Flag});
  }
};

/// One design tried.
struct SuggestedDesign {
  std::string name;       ///< "ellipse-045": its plan is designs/NAME.json
  std::string procedure;  ///< the template
  double orientation_deg = 0;
  /// A flap's side where its mirror image is a design of its own ("bilobed-mirrored-045"): 1
  /// the bilobed flap's lobes (a rotation flap's arc) to the left of the orientation, -1 to the
  /// right; 0 where none.
  double side = 0;
  std::string plan;    ///< the plan file (relative to the output folder); empty if not placed
  std::string result;  ///< the refined closure's folder (relative), empty if not refined
  std::string refused;  ///< why it was not ranked (not placed, not closed); empty if ranked
  double scar_length_mm = 0, excised_mm2 = 0, healthy_excised_mm2 = 0;
  /// The closure's figures: the sweep's, then the refined one's when refined.
  struct Closure {
    double max_force_per_suture_n = 0, closing_force_n = 0, max_feature_mm = 0;
    std::string feature;  ///< the feature line moved most ("" where none is reached)
    int feature_warnings = 0;
    std::vector<std::string> warnings;
  };
  Closure sweep, full;
  /// An ellipse's scar against the relaxed skin tension lines at the lesion (deg, 0-90; 0 along
  /// them); NaN where the lines are not known there or for a flap.
  double angle_to_skin_lines_deg = std::numeric_limits<double>::quiet_NaN();
  bool refined = false;
  double objective = 0;  ///< the ranking value (the full closure's where refined)
  int rank = 0;          ///< 1 = best; 0 = not ranked
  /// Within kNearBest of the best's objective, by the same closure (both refined, or both
  /// the sweep's): as good as the best within what the model can tell apart.
  bool near_best = false;
};

/// Designs whose objective is within this fraction of the best's (by the same closure) are
/// reported as near it: closer than that, a ranking rests on differences that the model's own
/// uncertainties (its tissue's moduli, the mesh) exceed.
inline constexpr double kNearBest = 0.05;

/// The relaxed skin tension lines at the lesion (plan/skin_lines.hpp, Borges's map laid on the
/// head by its landmarks) against the closure's least-force direction.
struct SuggestedSkinLines {
  bool found = false;
  double orientation_deg = 0;  ///< in the designs' frame (a chart's where they lie on one)
  std::string zone, words, says;
  std::string note;  ///< why not found
  /// The ranked ellipse of least force on one suture (by the figures it is ranked by), and the
  /// angle between it and the lines; NaN without one.
  double least_force_deg = std::numeric_limits<double>::quiet_NaN();
  double least_force_angle_deg = std::numeric_limits<double>::quiet_NaN();
  std::string sentence;  ///< the cross-check in words
};

struct SuggestResult {
  std::string output;
  SuggestedSkinLines skin_lines;
  std::string suggestions_json;  ///< suggestions.json
  std::vector<SuggestedDesign> designs;  ///< ranked first (by rank), then the refused
  std::vector<std::string> warnings;
  double sweep_s = 0, refine_s = 0;

  template <class Self, class V>
  static void fields(Self& r, V&& v) {
    v.document(r.suggestions_json, {"suggestions_json", "suggestions.json"});
  }
};

/// Lays each procedure of the request around the lesion (the lesion and its margin inside the
/// excision) at every `step` degrees, checks it (a design that cannot be operated is listed as
/// refused, with the check's words), closes it at `sweep_size` (the request's material and
/// domain) and ranks the designs by the objective; then closes the best `refine` again at the
/// request's mesh (results in the output folder, as caps simulate writes them) and ranks those
/// by their own figures, ahead of the rest. Writes suggestions.json (= to_json()) and
/// suggestions.png (the objective and the feature lines' displacement against orientation).
/// Throws InvalidInput/InvalidParameter for a bad request, before any closure.
SuggestResult run_plan_suggest(const SuggestRequest& request, Reporter* reporter = nullptr);
std::string to_json(const SuggestResult& result);
std::string summary(const SuggestResult& result);

}  // namespace caps::app
