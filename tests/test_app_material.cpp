// The closure's materials as the CLI, the server and Python set them (SolverFields: material,
// material_params), and what result.json records of them.

#include <gtest/gtest.h>

#include "error_of.hpp"

#include <filesystem>
#include <fstream>
#include <functional>
#include <nlohmann/json.hpp>

#include "caps/app/simulation.hpp"
#include "caps/core/error.hpp"
#include "caps/fem/material_registry.hpp"

namespace fs = std::filesystem;
using namespace caps;

namespace {

using caps_test::error_of;

app::SolverFields with(const std::string& material, const std::string& params = {}) {
  app::SolverFields s;
  s.material = material;
  s.material_params = params;
  return s;
}

}  // namespace

TEST(AppMaterials, MaterialPicksTheKinematicsAndTheSkinsMaterialAndParamsSetEachLayer) {
  const closure::SimulateOptions neo = app::simulate_options({}, {});
  EXPECT_EQ(neo.solve.kinematics, fem::Kinematics::Finite);
  EXPECT_EQ(neo.continuum.material, fem::default_skin());
  EXPECT_EQ(neo.continuum.fat, fem::default_fat());
  // linear: the small-strain model, every layer the linear material of its preset's E and nu.
  const closure::SimulateOptions lin = app::simulate_options({}, with("linear"));
  EXPECT_EQ(lin.solve.kinematics, fem::Kinematics::Linear);
  for (const auto& m : {lin.continuum.material, lin.continuum.dermis, lin.continuum.fat, lin.continuum.deep})
    EXPECT_EQ(m->name(), "linear");
  EXPECT_EQ(fem::parameters_of(*lin.continuum.fat), fem::parameters_of(*fem::default_fat()));
  // goh: the skin's surface layer (element layer 0: the measured dermis, the uniform model's top
  // element layer) gets the porcine-skin preset, the tissue below stays neo-Hookean; skin and
  // dermis parameters are the goh layer's.
  const closure::SimulateOptions goh = app::simulate_options({}, with("goh", "skin.k1=5, dermis.kappa=0.1,fat.E=4kPa"));
  EXPECT_EQ(goh.solve.kinematics, fem::Kinematics::Finite);
  EXPECT_EQ(goh.continuum.material, fem::default_skin());
  EXPECT_EQ(goh.continuum.dermis, fem::default_dermis());
  EXPECT_EQ(goh.continuum.deep, fem::default_deep());
  ASSERT_TRUE(goh.continuum.surface_material);
  auto expected = fem::parameters_of(*fem::default_goh_skin());
  expected["k1"] = 5;
  expected["kappa"] = 0.1;
  EXPECT_EQ(goh.continuum.surface_material->name(), "goh");
  EXPECT_EQ(fem::parameters_of(*goh.continuum.surface_material), expected);
  EXPECT_FALSE(neo.continuum.surface_material);
  EXPECT_EQ(fem::parameters_of(*goh.continuum.fat), (fem::MaterialParameters{{"E", 0.004}, {"nu", 0.45}}));
  // Refusals name the option and what to give.
  EXPECT_NE(error_of([] { app::simulate_options({}, with("rubber")); }).find("material 'rubber' is unknown"),
            std::string::npos);
  EXPECT_NE(error_of([] { app::simulate_options({}, with("neo-hookean", "dermis.E")); })
                .find("give LAYER.NAME=VALUE"),
            std::string::npos);
  EXPECT_NE(error_of([] { app::simulate_options({}, with("neo-hookean", "dermis.E=soft")); })
                .find("give LAYER.NAME=VALUE"),
            std::string::npos);
  EXPECT_NE(error_of([] { app::simulate_options({}, with("neo-hookean", "lip.E=0.1")); })
                .find("the layers are skin"),
            std::string::npos);
  EXPECT_NE(error_of([] { app::simulate_options({}, with("neo-hookean", "dermis.k1=5")); })
                .find("material_params dermis: neo-hookean has no parameter 'k1'"),
            std::string::npos);
  // A modulus in the surgeon's kPa or in MPa; a bare 50 (kPa meant, 50 MPa read: skin 500 times
  // too stiff) is refused with the unit to write.
  const closure::SimulateOptions kpa = app::simulate_options({}, with("neo-hookean", "dermis.E=120kPa"));
  const closure::SimulateOptions mpa = app::simulate_options({}, with("neo-hookean", "dermis.E=0.12MPa"));
  EXPECT_NEAR(fem::parameters_of(*kpa.continuum.dermis).at("E"), 0.12, 1e-15);
  EXPECT_EQ(fem::parameters_of(*mpa.continuum.dermis).at("E"), 0.12);
  EXPECT_NE(error_of([] { app::simulate_options({}, with("neo-hookean", "skin.E=50")); })
                .find("'skin.E=50': 50 MPa is far stiffer than soft tissue (0.001-1 MPa); write "
                      "the unit: skin.E=50kPa, or skin.E=50MPa if you mean it"),
            std::string::npos);
  EXPECT_EQ(fem::parameters_of(*app::simulate_options({}, with("neo-hookean", "skin.E=50MPa"))
                                    .continuum.material).at("E"), 50);
}

TEST(AppMaterials, ASolveRecordsTheMaterialItWasGivenInResultJson) {
  // A slotted block sutured shut (caps fem box --slot), solved with each --material; goh is
  // recorded as goh (it was recorded as "kinematics": "neo-hookean" and no material).
  const fs::path dir = fs::temp_directory_path() / "caps_test_app_material";
  fs::remove_all(dir);
  fs::create_directories(dir);
  app::BoxRequest box;
  box.output = (dir / "mesh").string();
  box.box_size = "30,20,6";
  box.cells = "5,6,2";
  box.slot = true;
  app::run_box(box);
  for (const auto& [material, kinematics] :
       std::vector<std::pair<std::string, std::string>>{{"goh", "finite-strain"},
                                                        {"linear", "small-strain"},
                                                        {"neo-hookean", "finite-strain"}}) {
    SCOPED_TRACE(material);
    app::SolveRequest r;
    r.mesh = box.output;
    r.output = (dir / material).string();
    r.solver = with(material, material == "goh" ? "skin.k1=2" : "skin.E=0.05");
    r.solver.solver = "cholmod";  // (MUMPS's PORD exits the process on so small a graph)
    r.solver.steps = 2;
    app::run_solve(r);
    std::ifstream in(dir / material / "result.json");
    const nlohmann::json j = nlohmann::json::parse(in);
    EXPECT_EQ(j["kinematics"], kinematics);
    ASSERT_EQ(j["materials"].size(), 1u);
    EXPECT_EQ(j["materials"][0]["material"], material);
    const auto& recorded = j["materials"][0]["parameters"];
    EXPECT_EQ(material == "goh" ? recorded["k1"] : recorded["E"], material == "goh" ? 2.0 : 0.05);
  }
  fs::remove_all(dir);
}
