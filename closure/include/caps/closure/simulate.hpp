#pragma once
/// @brief A plan on a patient model, from border to post-operative shape in one call: the plan is
/// checked on the model, its wound border meshed (surface mesher, then the variable-thickness
/// continuum mesher) and the closure solved.

#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "caps/core/reporter.hpp"
#include "caps/mesher/continuum_mesher.hpp"
#include "caps/fem/solve.hpp"
#include "caps/mesher/surface_mesher.hpp"
#include "caps/closure/face_domain.hpp"
#include "caps/closure/suture_spacing.hpp"
#include "caps/plan/plan.hpp"
#include "caps/surface/feature_lines.hpp"

namespace caps {
class PatientModel;
}

namespace caps::closure {

/// simulate() warns when one material stands for all the soft tissue (`--tissue uniform`) over
/// at least this much measured fat (mm, along the normal at the wound's centre, and at least
/// 40 % of the soft tissue there): the fat is modelled as stiff as the dermis.
inline constexpr double kThickFatMm = 5.0;

struct SimulateOptions {
  mesher::SurfaceMeshOptions surface;
  mesher::ContinuumMeshOptions continuum;
  fem::SolveOptions solve;
  /// The spacing of the sutures the closing force is reported per (mm; suture_spacing()).
  double suture_spacing_mm = 5.0;
  /// Where the closure is solved. Face needs `tissue` (the model directory's whole-face tissue
  /// model) and meshes the patch with a tied rim (continuum.rim is set to Tied); Patch is the
  /// 1992 patch with continuum.rim as given (the library's default, fixed).
  Domain domain = Domain::Patch;
  FaceDomainOptions face;
  std::shared_ptr<const mesher::TissueModel> tissue;
  /// The patient's feature lines (surface/feature_lines.hpp): their displacement is reported.
  std::shared_ptr<const FeatureLines> features;
};

struct Simulation {
  mesher::WoundMesh wound;
  fem::SolveResult result;
  /// The largest distance (mm) between sutured nodes after the closure: 0 up to round-off.
  double max_suture_gap_mm = 0;
  /// Elements turned inside out by the closure (det J <= 0 at a Gauss point of the deformed
  /// mesh): possible only with the small-strain model, which then does not hold (a warning says so).
  int inverted_elements = 0;
  /// With a prestretch (SolveOptions::prestretch > 1): how far the wound gapes before it is
  /// sutured, the largest widening (mm) between the nodes of a suture pair when the prestressed
  /// skin is cut and left open (a solve of its own, without the sutures); 0 without prestretch.
  double gape_mm = 0;
  /// The closing force per suture at SimulateOptions::suture_spacing_mm, the largest one and
  /// the force per mm of wound (suture_spacing()).
  fem::SutureSpacing sutures;
  /// Domain::Face: the joined mesh (patch first) and its solve; `result` above is then the
  /// patch's part of it (patch_part()), so every patch-level report reads as before.
  std::optional<FaceDomain> face;
  fem::SolveResult face_result;
  /// The displacement of each feature line the closure reaches (SimulateOptions::features).
  std::vector<FeatureDisplacement> features;
};

/// Checks the plan on the model (plan::check_plan), meshes its wound border and solves the
/// closure. Throws InvalidInput naming the plan's point or edge, or the mesh's place, that cannot
/// be operated; SolverError if the solve fails.
Simulation simulate(const PatientModel& model, const plan::Plan& plan,
                    const SimulateOptions& options = {}, Reporter* reporter = nullptr);

/// Writes a simulation into an existing directory: mesh.vtu, mesh.json, mesh.inp, result.vtu,
/// result.json and, with `mesh_pictures`, surface.png and section.png (titled with `name`).
void write_simulation(const Simulation& sim, const PatientModel& model,
                      const SimulateOptions& options, const std::filesystem::path& dir,
                      const std::string& name, bool mesh_pictures = true);

}  // namespace caps::closure
