#include "caps/plan/plan_io.hpp"

#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "caps/core/atomic_output.hpp"
#include "caps/core/error.hpp"
#include "caps/core/file_access.hpp"
#include "caps/core/json_file.hpp"
#include "suture_json.hpp"

namespace caps::plan {

using nlohmann::json;

std::string plan_to_json(const Plan& plan, const PlanReport* report) {
  json j;
  j["format"] = "caps-plan";
  j["format_version"] = kPlanFormatVersion;
  j["units"] = {{"length", "mm"}, {"angle", "deg"}, {"frame", "LPS"}};
  j["model"] = plan.model;
  if (!plan.model_hash.empty()) j["model_hash"] = plan.model_hash;
  j["procedure"] = {{"name", plan.procedure}, {"parameters", plan.parameters}};
  const auto& m = plan.frame.local_to_theta_z;
  j["frame"] = {{"theta_deg", plan.frame.theta_deg},
                {"z_mm", plan.frame.z_mm},
                {"orientation_deg", plan.frame.orientation_deg},
                {"local_to_theta_z", {{m(0, 0), m(0, 1)}, {m(1, 0), m(1, 1)}}}};
  // Where the plan was placed: at (theta, z), or relative to a landmark (and where it resolved).
  j["at"] = {{"theta_deg", plan.frame.theta_deg}, {"z_mm", plan.frame.z_mm}};
  if (plan.placement) {
    j["at"]["landmark"] = plan.placement->landmark;
    j["at"]["left_mm"] = plan.placement->left_mm;
    j["at"]["up_mm"] = plan.placement->up_mm;
  }
  j["points"] = json::array();
  for (const auto& p : plan.points)
    j["points"].push_back({{"theta_deg", p.theta_deg}, {"z_mm", p.z_mm},
                           {"lps", {p.lps.x(), p.lps.y(), p.lps.z()}}});
  j["paths"] = plan.paths;
  j["excisions"] = json::array();
  for (const auto& e : plan.excisions)
    j["excisions"].push_back(
        {{"loop_index", e.loop_index}, {"offset_mm", {e.offset_mm.x(), e.offset_mm.y()}}});
  j["sutures"] = json::array();
  for (const auto& s : plan.sutures)
    j["sutures"].push_back(detail::suture_to_json(s));
  if (!plan.flaps.empty()) j["flaps"] = plan.flaps;
  // Derived, for reading (ignored on load): the loop, its correspondence and positions.
  try {
    const BorderLoop loop = border_loop(plan);
    json l = json::array();
    for (int i = 0; i < loop.size(); ++i)
      l.push_back({{"point", loop.point[i]}, {"theta_deg", loop.theta_z[i][0]},
                   {"z_mm", loop.theta_z[i][1]}});
    j["border_loop"] = l;
    json q = json::array();
    for (const auto& s : plan.sutures) q.push_back(oriented_suture(s, loop.size()));
    j["suture_quadruples"] = q;
  } catch (const InvalidInput&) {
    // A plan being written need not be valid (e.g. a draft); check_plan() says why.
  }
  if (report) {
    json r;
    r["cut_length_mm"] = report->cut_length_mm;
    r["suture_lengths_mm"] = json::array();
    for (const auto& s : report->suture_lengths)
      r["suture_lengths_mm"].push_back({s.first_mm, s.second_mm});
    r["warnings"] = report->warnings;
    if (report->near)
      r["near"] = {{"landmark", report->near->landmark},
                   {"left_mm", report->near->left_mm},
                   {"up_mm", report->near->up_mm}};
    j["check"] = r;
  }
  j["notes"] = plan.notes;
  return j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) + "\n";
}

Plan parse_plan_json(const std::string& text, const std::string& source) {
  const json j = parse_json<json>(text, source);
  // The header's fields are read by hand: json::value() throws on a field of another type.
  if (!j.is_object() || !j.contains("format") || j["format"] != "caps-plan")
    throw InvalidInput(cat(source, ": not a caps plan (\"format\" must be \"caps-plan\")"));
  const json version = j.contains("format_version") ? j["format_version"] : json(0);
  if (!version.is_number_integer() || version.get<long long>() != kPlanFormatVersion)
    throw InvalidInput(cat(source, ": plan format_version ", version.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace),
                           " is not supported (this caps reads version ", kPlanFormatVersion, ")"));
  Plan plan;
  plan.source = source;
  std::string field;
  try {
    field = "model";
    plan.model = j.value("model", "");
    field = "model_hash";
    plan.model_hash = j.value("model_hash", "");
    field = "procedure";
    if (j.contains("procedure")) {
      plan.procedure = j["procedure"].value("name", "custom");
      if (j["procedure"].contains("parameters"))
        plan.parameters = j["procedure"]["parameters"].get<std::map<std::string, double>>();
    }
    field = "at";
    if (j.contains("at") && j["at"].contains("landmark")) {
      const auto& a = j["at"];
      plan.placement = LandmarkPlacement{a.at("landmark").get<std::string>(),
                                         a.value("left_mm", 0.0), a.value("up_mm", 0.0)};
    }
    field = "frame";
    const auto& f = j.at("frame");
    plan.frame.theta_deg = f.at("theta_deg").get<double>();
    plan.frame.z_mm = f.at("z_mm").get<double>();
    plan.frame.orientation_deg = f.at("orientation_deg").get<double>();
    const auto& m = f.at("local_to_theta_z");
    plan.frame.local_to_theta_z << m.at(0).at(0).get<double>(), m.at(0).at(1).get<double>(),
        m.at(1).at(0).get<double>(), m.at(1).at(1).get<double>();
    field = "points";
    for (const auto& p : j.at("points")) {
      SkinPoint s;
      s.theta_deg = p.at("theta_deg").get<double>();
      s.z_mm = p.at("z_mm").get<double>();
      if (p.contains("lps")) s.lps = {p["lps"].at(0).get<double>(), p["lps"].at(1).get<double>(), p["lps"].at(2).get<double>()};
      plan.points.push_back(s);
    }
    field = "paths";
    plan.paths = detail::index_lists(j.at("paths"), cat(source, ": paths"));
    field = "excisions";
    if (j.contains("excisions"))
      for (const auto& e : j["excisions"])
        plan.excisions.push_back({to_int(e.at("loop_index").get<double>(), cat(source, ": excisions: loop_index")),
                                  {e.at("offset_mm").at(0).get<double>(), e.at("offset_mm").at(1).get<double>()}});
    field = "sutures";
    for (const auto& s : j.at("sutures")) plan.sutures.push_back(detail::suture_from_json(s, source));
    field = "flaps";
    if (j.contains("flaps")) plan.flaps = detail::index_lists(j["flaps"], cat(source, ": flaps"));
    field = "notes";
    plan.notes = j.value("notes", "");
  } catch (const json::exception& e) {
    // With JSON_DIAGNOSTICS the message holds the JSON pointer of the offending value.
    throw InvalidInput(cat(source, ": field \"", field, "\": ", e.what(),
                           "; see docs/plan-format.md"));
  }
  return plan;
}

Plan read_plan(const std::filesystem::path& path) {
  const std::string text = read_json_text(path, "check the plan file's path and permissions");
  Plan plan = parse_plan_json(text, path.string());
  // "model_relative": the model's folder relative to the plan's, used when it is there (a plan
  // copied with its model); "model" as given otherwise.
  const json j = json::parse(text);
  if (j.contains("model_relative") && j["model_relative"].is_string()) {
    const auto beside = (path.parent_path() / j["model_relative"].get<std::string>()).lexically_normal();
    std::error_code ec;
    if (std::filesystem::is_directory(beside, ec)) plan.model = beside.string();
  }
  return plan;
}

void write_plan(const std::filesystem::path& path, const Plan& plan, const PlanReport* report) {
  // The plan finds its model again by this name: one with replaced bytes would not be found.
  require_utf8(plan.model, "the plan's model folder");
  json j = json::parse(plan_to_json(plan, report));
  if (!plan.model.empty()) {
    std::error_code ec;
    const auto folder = std::filesystem::absolute(path, ec).parent_path();
    const auto model = std::filesystem::absolute(plan.model, ec);
    const auto relative = model.lexically_relative(folder);
    if (!ec && !relative.empty()) j["model_relative"] = relative.generic_string();
  }
  write_text_atomic(path, j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) + "\n");
}

WoundBorder read_wound_border(const std::filesystem::path& path) {
  const json j = read_json_file<json>(path, "give a wound border file: {\"loop_theta_z\": ...}");
  WoundBorder b;
  try {
    for (const auto& p : j.at("loop_theta_z"))
      b.loop_theta_z.emplace_back(p.at(0).get<double>(), p.at(1).get<double>());
    if (j.contains("sutures"))
      for (const auto& s : j.at("sutures")) {
        const std::vector<int> q = detail::index_list(s, cat(path.string(), ": sutures"));
        if (q.size() != 4) throw InvalidInput(cat(path.string(), ": a suture is [a, b, c, d]"));
        b.sutures.push_back({q[0], q[1], q[2], q[3]});
      }
  } catch (const json::exception& e) {
    throw InvalidInput(cat(path.string(), ": expected {\"loop_theta_z\": [[theta_deg, z_mm], ...], "
                           "\"sutures\": [[a, b, c, d], ...]} (", e.what(), ")"));
  }
  return b;
}

}  // namespace caps::plan
