#include "caps/study/compare_models.hpp"

#include <nlohmann/json.hpp>

#include <cmath>
#include <map>
#include <optional>

#include "caps/core/error.hpp"
#include "caps/core/units.hpp"
#include "caps/plan/procedures.hpp"
#include "caps/plan/skin_walk.hpp"
#include "caps/surface/patient_model.hpp"

namespace caps::study {

using namespace caps::fem;
using namespace caps::mesher;
using namespace caps::closure;
namespace {

// The skins of the compared models may disagree by this much at the plan's centre before a
// warning says so (mm): beyond it the plan sits on visibly different skin.
constexpr double kCentreGapWarningMm = 3.0;

// The uniform scale of a similarity's linear part (the cube root of its determinant), after
// checking that it is one: A^T A = s^2 I.
double similarity_scale(const Eigen::Matrix4d& T) {
  if (!T.allFinite()) throw InvalidInput("the transform between the models is not finite");
  const Eigen::Matrix3d A = T.topLeftCorner<3, 3>();
  const double det = A.determinant();
  if (!(det > 0))
    throw InvalidInput(cat("the transform between the models has determinant ", det,
                           "; it must be a rotation with a positive uniform scale"));
  const double s = std::cbrt(det);
  if ((A.transpose() * A - s * s * Eigen::Matrix3d::Identity()).norm() > 1e-6 * s * s)
    throw InvalidInput("the transform between the models is not a similarity (rotation, uniform "
                       "scale, translation)");
  return s;
}

// The plan's template from its parameters as the user gave them: a plan records both of two
// alternative parameters (an ellipse's width and the apex angle it sets), and the layout takes
// only one, the primary. Null when the procedure is not a library template.
std::optional<plan::LocalProcedure> template_layout(const plan::Plan& plan) {
  for (const auto& info : plan::procedure_library()) {
    if (info.name != plan.procedure) continue;
    std::map<std::string, double> given = plan.parameters;
    for (const auto& p : info.parameters)
      if (!p.alternative_to.empty() && given.count(p.alternative_to)) given.erase(p.name);
    return plan::layout_procedure(plan.procedure, given);
  }
  return std::nullopt;
}

}  // namespace

Eigen::Vector3d plan_direction(const plan::Plan& plan, const PatientModel& model) {
  return plan::skin_frame(model, plan.frame.theta_deg, plan.frame.z_mm, plan.frame.orientation_deg).ex;
}

TransferredPlan transfer_plan(const plan::Plan& plan, const PatientModel& from, const PatientModel& to,
                              const Eigen::Matrix4d& T) {
  const double s = similarity_scale(T);
  const Eigen::Vector3d p = from.skin_point(plan.frame.theta_deg, plan.frame.z_mm);
  const Eigen::Vector3d q = T.topLeftCorner<3, 3>() * p + T.topRightCorner<3, 1>();
  const CylindricalPoint c = to.to_cylindrical(q);
  if (!to.has_z(c.z_mm))
    throw InvalidInput(cat("the plan's centre (theta ", plan.frame.theta_deg, " deg, z ", plan.frame.z_mm,
                           " mm) falls at z ", c.z_mm, " mm on the other model, outside its rows"));
  const Eigen::Vector3d d = T.topLeftCorner<3, 3>() * plan_direction(plan, from) / s;
  const plan::SkinTangent t = plan::skin_tangent(to, c.theta_deg, c.z_mm);
  const Eigen::Vector3d right = t.d_theta.normalized();
  const Eigen::Vector3d up = t.normal.cross(right);
  const double orientation = rad_to_deg(std::atan2(d.dot(right), d.dot(up)));
  const std::optional<plan::LocalProcedure> laid_out = template_layout(plan);
  const plan::LocalProcedure local = laid_out ? *laid_out : plan::procedure_from_plan(plan);
  TransferredPlan out;
  out.plan = plan::place_procedure(local, to, c.theta_deg, c.z_mm, orientation);
  out.plan.model_hash = to.content_hash();
  out.plan.notes = plan.notes;
  out.centre_gap_mm = (to.skin_point(c.theta_deg, c.z_mm) - q).norm();
  return out;
}

ModelComparison compare_models(const ComparedModel& reference_side, const plan::Plan& plan, const std::vector<ComparedModel>& others,
                               const SimulateOptions& options, Reporter* reporter) {
  if (!reference_side.model) throw InvalidInput("compare_models: the reference model is missing");
  if (!reference_side.reference_to_model.isIdentity())
    throw InvalidInput("compare_models: the reference's transform must be the identity");
  const PatientModel& reference = *reference_side.model;
  for (const ComparedModel& o : others)
    if (!o.model) throw InvalidInput(cat("compare_models: the model \"", o.label, "\" is missing"));
  Progress progress(reporter, "simulating the plan on each model", 1 + static_cast<int>(others.size()));
  ModelComparison c;
  auto run = [&](ModelComparisonSide& side, const PatientModel& model, const SimulateOptions& o) {
    try {
      side.simulation = simulate(model, side.plan, o, reporter);
    } catch (const InvalidInput& e) {
      throw InvalidInput(cat(side.label, ": ", e.what()));
    } catch (const SolverError& e) {
      throw SolverError(cat(side.label, ": ", e.what()));
    }
    side.summary = summarize(side.simulation, model, side.label);
    for (const std::string& w : side.simulation.wound.continuum.mesh.warnings)
      c.warnings.push_back(side.label + ": " + w);
  };
  ModelComparisonSide ref;
  ref.key = reference_side.key;
  ref.label = reference_side.label;
  ref.plan = plan;
  run(ref, reference, options);
  progress.update(1);
  SimulateOptions same_extent = options;
  same_extent.surface.extent_mm = ref.simulation.wound.surface.extent_mm;
  c.sides.push_back(std::move(ref));
  for (const ComparedModel& o : others) {
    ModelComparisonSide side;
    side.key = o.key;
    side.label = o.label;
    side.reference_to_model = o.reference_to_model;
    TransferredPlan moved;
    try {
      moved = transfer_plan(plan, reference, *o.model, o.reference_to_model);
    } catch (const InvalidInput& e) {
      throw InvalidInput(cat(o.label, ": ", e.what()));
    }
    side.plan = std::move(moved.plan);
    side.centre_gap_mm = moved.centre_gap_mm;
    if (side.centre_gap_mm > kCentreGapWarningMm)
      c.warnings.push_back(cat(o.label, ": the plan's centre lies ", side.centre_gap_mm,
                               " mm from the reference's skin point carried over (the skins "
                               "disagree there; check the registration)"));
    run(side, *o.model, same_extent);
    c.sides.push_back(std::move(side));
    progress.update(static_cast<int>(c.sides.size()));
  }
  progress.done();
  return c;
}

std::string model_comparison_json(const ModelComparison& c, const std::string& plan_name) {
  nlohmann::json sides = nlohmann::json::array();
  for (const ModelComparisonSide& side : c.sides) {
    const SimulationSummary& s = side.summary;
    nlohmann::json T = nlohmann::json::array();
    for (int r = 0; r < 4; ++r)
      T.push_back({side.reference_to_model(r, 0), side.reference_to_model(r, 1),
                   side.reference_to_model(r, 2), side.reference_to_model(r, 3)});
    sides.push_back({{"key", side.key},
                     {"label", side.label},
                     {"placement", {{"theta_deg", side.plan.frame.theta_deg},
                                    {"z_mm", side.plan.frame.z_mm},
                                    {"orientation_deg", side.plan.frame.orientation_deg},
                                    {"centre_gap_mm", side.centre_gap_mm},
                                    {"reference_to_model", T}}},
                     {"thickness_under_wound_mm",
                      {{"mean", s.thickness_mean_mm}, {"min", s.thickness_min_mm}, {"max", s.thickness_max_mm}}},
                     {"closing_force_n", s.closing_force_n},
                     {"max_suture_force_n", s.max_suture_force_n},
                     {"max_skin_tension_kpa", s.max_skin_tension_kpa},
                     {"max_displacement_mm", s.max_displacement_mm},
                     {"mean_displacement_near_wound_mm", s.mean_displacement_mm},
                     {"strain_energy_mj", s.strain_energy_mj},
                     {"elements", s.elements},
                     {"nodes", s.nodes}});
  }
  return nlohmann::json{{"plan", plan_name}, {"reference", c.sides.empty() ? "" : c.sides[0].label},
                        {"sides", sides}, {"warnings", c.warnings}}
      .dump(2, ' ', false, nlohmann::json::error_handler_t::replace);
}

}  // namespace caps::study
