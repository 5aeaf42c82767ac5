// The material seam: every registered material made by name from JSON, solved on a block and
// found in result.json and the CalculiX deck; the presets of data/materials; the refusals.

#include <gtest/gtest.h>

#include "error_of.hpp"

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <nlohmann/json.hpp>
#include <set>

#include "caps/core/error.hpp"
#include "caps/fem/box.hpp"
#include "caps/fem/inp_io.hpp"
#include "caps/fem/material_registry.hpp"
#include "caps/fem/mesh_io.hpp"
#include "caps/fem/result_io.hpp"
#include "caps/fem/solve.hpp"

using namespace caps;
using namespace caps::fem;
namespace fs = std::filesystem;

namespace {

using caps_test::error_of;

// A 10 mm cube of one Hex20 on symmetry planes x = 0, y = 0, z = 0, its face y = 10 pulled by
// `strain` (uniaxial stress along y).
Mesh pulled_cube(std::shared_ptr<const Material> material, double strain) {
  BoxOptions o;
  o.size_mm = {10, 10, 10};
  o.cells = {1, 1, 1};
  o.fix_bottom = false;
  o.material = std::move(material);
  Mesh m = make_box_mesh(o);
  for (int i = 0; i < m.n_nodes(); ++i) {
    for (int c = 0; c < 3; ++c)
      if (std::abs(m.nodes(i, c)) < 1e-9) m.fixed_dofs.push_back({i, c, 0.0});
    if (std::abs(m.nodes(i, 1) - 10) < 1e-9) m.fixed_dofs.push_back({i, 1, 10 * strain});
  }
  return m;
}

struct Case {
  std::string json;  // as a file or a request gives it
  // The small-strain Young's modulus along y (MPa) from the parameters: the expected stress is
  // this times the strain.
  std::function<double(const MaterialParameters&)> modulus;
};

// One case per registered material; the test fails when a material is registered without one.
const std::map<std::string, Case>& cases() {
  static const std::map<std::string, Case> c{
      {"linear", {R"({"material": "linear", "parameters": {"E": 0.12, "nu": 0.3}})",
                  [](const MaterialParameters& p) { return p.at("E"); }}},
      {"neo-hookean", {R"({"material": "neo-hookean", "parameters": {"E": 0.08, "nu": 0.45}})",
                       [](const MaterialParameters& p) { return p.at("E"); }}},
      // Fibres along x, pulled along y: across the fibres, which go slack; the ground matrix's
      // E = 9 K mu / (3 K + mu) carries the load.
      {"goh", {R"({"material": "goh", "parameters": {"mu": 0.05, "K": 0.3, "k1": 4.97, "k2": 2.88,
                  "kappa": 0.0498, "gamma": 0, "fibre_x": 1, "fibre_y": 0, "fibre_z": 0},
                  "units": {"mu": "MPa", "gamma": "deg"}})",
               [](const MaterialParameters& p) {
                 return 9 * p.at("K") * p.at("mu") / (3 * p.at("K") + p.at("mu"));
               }}}};
  return c;
}

}  // namespace

TEST(MaterialRegistry, EveryRegisteredMaterialIsMadeFromJsonSolvedAndNamedInResultJson) {
  const std::vector<std::string> names = material_names();
  std::set<std::string> tested;
  for (const auto& [name, c] : cases()) tested.insert(name);
  EXPECT_EQ(std::set<std::string>(names.begin(), names.end()), tested);
  const fs::path dir = fs::temp_directory_path() / "caps_test_fem_material";
  for (const std::string& name : names) {
    SCOPED_TRACE(name);
    const Case& c = cases().at(name);
    const std::shared_ptr<const Material> m = material_from_json(c.json, name);
    ASSERT_EQ(m->name(), name);
    const MaterialParameters p = parameters_of(*m);
    for (const auto& [key, value] : nlohmann::json::parse(c.json)["parameters"].items())
      EXPECT_EQ(p.at(key), value.get<double>()) << key;
    // A small pull: the stress is the material's small-strain modulus times the strain.
    const double strain = 1e-4;
    const Mesh mesh = pulled_cube(m, strain);
    SolveOptions o;
    o.kinematics = m->hyperelastic() ? Kinematics::Finite : Kinematics::Linear;
    o.newton.n_steps = 1;
    o.solver = SolverKind::Cholmod;  // (MUMPS's PORD exits the process on so small a graph)
    const SolveResult r = solve(mesh, o);
    EXPECT_NEAR(r.gauss_stress_mpa(0, 1), c.modulus(p) * strain, 2e-3 * c.modulus(p) * strain);
    fs::remove_all(dir);
    fs::create_directories(dir);
    write_result_dir(mesh, r, dir);
    std::ifstream in(dir / "result.json");
    const nlohmann::json j = nlohmann::json::parse(in);
    EXPECT_EQ(j["kinematics"], kinematics_name(o.kinematics));
    ASSERT_EQ(j["materials"].size(), 1u);
    const nlohmann::json& rec = j["materials"][0];
    EXPECT_EQ(rec["layer"], 0);
    EXPECT_EQ(rec["material"], name);
    ASSERT_EQ(rec["parameters"].size(), m->parameters().size());
    for (const ParameterSpec& s : m->parameters()) {
      EXPECT_EQ(rec["parameters"][s.name].get<double>(), p.at(s.name)) << s.name;
      EXPECT_EQ(rec["units"][s.name], s.unit) << s.name;
    }
    // The record makes the same material again.
    EXPECT_EQ(parameters_of(*material_from_json(rec.dump(), "result.json")), p);
    // The CalculiX deck names it too (where CalculiX has a form of it).
    if (m->small_strain()) {
      InpOptions io;
      io.finite_strain = o.kinematics == Kinematics::Finite;
      EXPECT_NE(inp_text(mesh, io).find("** layer 0: {\"material\":\"" + name + "\""), std::string::npos);
    } else {
      EXPECT_NE(error_of([&] { inp_text(mesh, {}); }).find("'" + name + "'"), std::string::npos);
    }
  }
  fs::remove_all(dir);
}

TEST(MaterialRegistry, RefusesUnknownMaterialsAndParametersAndValuesOutOfRange) {
  EXPECT_NE(error_of([] { make_material("rubber", {}); }).find("the registered materials are goh, linear, neo-hookean"),
            std::string::npos);
  EXPECT_NE(error_of([] { make_material("linear", {{"E", 0.1}}, "dermis"); })
                .find("dermis: linear needs its parameter nu"),
            std::string::npos);
  EXPECT_NE(error_of([] { make_material("linear", {{"E", 0.1}, {"nu", 0.3}, {"mu", 1}}); })
                .find("has no parameter 'mu'; its parameters are E, nu"),
            std::string::npos);
  EXPECT_NE(error_of([] { make_material("neo-hookean", {{"E", -1}, {"nu", 0.3}}, "fat"); })
                .find("fat: neo-hookean parameter E = -1 MPa is out of its valid range"),
            std::string::npos);
  EXPECT_NE(error_of([] { with_parameters(*make_material("linear", {{"E", 0.1}, {"nu", 0.3}}), {{"k1", 1}}); })
                .find("has no parameter 'k1'"),
            std::string::npos);
  EXPECT_NE(error_of([] { material_from_json(R"({"material": "linear", "parameters": {"E": 100, "nu": 0.3}, "units": {"E": "kPa"}})", "x"); })
                .find("parameter E is in MPa, not \"kPa\""),
            std::string::npos);
  EXPECT_NE(error_of([] { material_from_json("{\"material\": ", "req"); }).find("req: not valid JSON"),
            std::string::npos);
  EXPECT_NE(error_of([] { material_from_json(R"({"parameters": {}})", "req"); }).find("req: a material is"),
            std::string::npos);
  // A name is registered once.
  EXPECT_THROW(register_material({"linear", "again", {}, [](const std::vector<double>&, const std::string&) {
                                    return std::shared_ptr<const Material>();
                                  }}),
               InvalidInput);
}

TEST(MaterialRegistry, EachKinematicsRefusesTheMaterialsItHasNoFormOf) {
  // Linear elasticity is not objective: refused by the finite-strain solve. The fibre-reinforced
  // skin has no isotropic small-strain constants: refused by the small-strain solve.
  SolveOptions o;
  o.solver = SolverKind::Cholmod;
  o.kinematics = Kinematics::Finite;
  const Mesh linear = pulled_cube(make_material("linear", {{"E", 0.1}, {"nu", 0.3}}), 1e-3);
  EXPECT_NE(error_of([&] { solve(linear, o); }).find("layer 0: the finite-strain solve was given the 'linear' material"),
            std::string::npos);
  o.kinematics = Kinematics::Linear;
  const Mesh goh = pulled_cube(default_goh_skin(), 1e-3);
  EXPECT_NE(error_of([&] { solve(goh, o); }).find("layer 0: the small-strain solve has no form of the 'goh' material"),
            std::string::npos);
  // The neo-Hookean solid's small-strain constants are its E and nu: the same linear answer.
  const Mesh neo = pulled_cube(make_material("neo-hookean", {{"E", 0.1}, {"nu", 0.3}}), 1e-3);
  const Mesh lin = pulled_cube(make_material("linear", {{"E", 0.1}, {"nu", 0.3}}), 1e-3);
  EXPECT_EQ(solve(neo, o).displacement_mm, solve(lin, o).displacement_mm);
}

TEST(MaterialPresets, AreFilesWithTheirSources) {
  const std::vector<std::string> names = material_preset_names();
  for (const char* n : {"skin", "dermis", "fat", "deep", "subcutaneous", "goh-porcine-skin"}) {
    ASSERT_NE(std::find(names.begin(), names.end(), n), names.end()) << n;
    const MaterialPreset p = material_preset(n);
    EXPECT_FALSE(p.sources.empty()) << n;
    EXPECT_FALSE(p.description.empty()) << n;
  }
  // The library's defaults are the files' (docs/fem.md lists the same values and sources).
  EXPECT_EQ(parameters_of(*default_skin()), parameters_of(*preset_material("skin")));
  EXPECT_EQ(default_skin()->name(), "neo-hookean");
  EXPECT_EQ(default_goh_skin()->name(), "goh");
  EXPECT_EQ(BoxOptions{}.material, preset_material("skin"));
}

TEST(MaterialPresets, AMissingOrBadFileIsAClearError) {
  const fs::path dir = fs::temp_directory_path() / "caps_test_material_presets";
  fs::remove_all(dir);
  fs::create_directories(dir / "materials");
  std::ofstream(dir / "materials" / "broken.json") << "{\"format\": ";
  std::ofstream(dir / "materials" / "wrong.json")
      << R"({"format": "caps-material-preset", "version": 1, "material": "neo-hookean", "parameters": {"E": 0.1}})";
  ASSERT_EQ(setenv("CAPS_DATA_DIR", dir.c_str(), 1), 0);
  EXPECT_EQ(materials_dir(), dir / "materials");
  EXPECT_NE(error_of([] { material_preset("broken"); }).find("broken.json: not valid JSON"), std::string::npos);
  EXPECT_NE(error_of([] { material_preset("wrong"); }).find("wrong.json: neo-hookean needs its parameter nu"),
            std::string::npos);
  EXPECT_NE(error_of([] { material_preset("skin"); }).find("cannot read"), std::string::npos);
  EXPECT_NE(error_of([] { material_preset("skin"); }).find("the presets are broken, wrong"), std::string::npos);
  ASSERT_EQ(setenv("CAPS_DATA_DIR", (dir / "none").c_str(), 1), 0);
  EXPECT_NE(error_of([] { materials_dir(); }).find("has no materials/ folder (from CAPS_DATA_DIR)"), std::string::npos);
  ASSERT_EQ(unsetenv("CAPS_DATA_DIR"), 0);
  EXPECT_NO_THROW(preset_material("skin"));
  fs::remove_all(dir);
}

TEST(MaterialRegistry, AMeshDirectoryOfTheOldFormatReadsItsConstantsAsTheNeoHookeanSolid) {
  // Before materials were named, mesh.json had {"layer", "model": "linear_elastic", "E_kpa",
  // "nu"}: constants both solves used (the finite-strain one as the neo-Hookean solid).
  const fs::path dir = fs::temp_directory_path() / "caps_test_fem_material_old_mesh";
  fs::remove_all(dir);
  fs::create_directories(dir);
  write_mesh_dir(pulled_cube(default_skin(), 1e-3), dir);
  nlohmann::json j = nlohmann::json::parse(std::ifstream(dir / "mesh.json"));
  ASSERT_EQ(j["materials"][0]["material"], "neo-hookean");
  j["materials"] = nlohmann::json::array({{{"layer", 0}, {"model", "linear_elastic"}, {"E_kpa", 50.0}, {"nu", 0.4}}});
  std::ofstream(dir / "mesh.json") << j.dump();
  const Mesh back = read_mesh_dir(dir);
  EXPECT_EQ(back.materials.at(0)->name(), "neo-hookean");
  EXPECT_EQ(parameters_of(*back.materials.at(0)), (MaterialParameters{{"E", 0.05}, {"nu", 0.4}}));
  fs::remove_all(dir);
}
