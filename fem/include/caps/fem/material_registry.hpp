#pragma once
/// @brief Materials made by name and set from their declared parameters (FEBio's
/// REGISTER_FECORE_CLASS + ADD_PARAMETER), and the material presets of data/materials.
///
/// A registered kind of material has a name ("linear", "neo-hookean", "goh"), its declared
/// parameters (name, unit, range: Material::parameters()) and a factory. make_material() makes one
/// from named values in the declared units; every declared parameter must be given, an unknown
/// name or a value out of range is InvalidInput naming `where`, the material and the parameter.
/// The same name and parameters are what mesh.json, result.json and the CalculiX deck record
/// (material_json()), so a material read back is the one that was solved.
///
/// Presets (parameters with their literature sources) are files data/materials/NAME.json:
///   {"format": "caps-material-preset", "version": 1, "material": "neo-hookean",
///    "parameters": {"E": 0.1, "nu": 0.45}, "description": "...", "sources": ["..."]}
/// found under materials_dir(). A missing or bad file is InvalidInput naming the file.

#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "caps/fem/material.hpp"

namespace caps::fem {

/// Parameter values by declared name, in the declared units (ParameterSpec::unit).
using MaterialParameters = std::map<std::string, double>;

/// One kind of material the registry can make.
struct MaterialKind {
  std::string name;                       ///< as in files and options: "neo-hookean"
  std::string summary;                    ///< one line for help texts
  std::vector<ParameterSpec> parameters;  ///< declared parameters, in the factory's order
  /// Makes the material from all declared parameters in `parameters` order (validated by the
  /// material's constructor, whose messages name `where`).
  std::function<std::shared_ptr<const Material>(const std::vector<double>& values,
                                                const std::string& where)>
      make;
};

/// Adds a kind to the registry. The built-in kinds (linear, neo-hookean, goh) are there from the
/// start. Throws InvalidInput if the name is empty, already taken, or the kind has no factory.
void register_material(MaterialKind kind);
/// The registered names, sorted.
std::vector<std::string> material_names();
/// The registered kind `name`; InvalidInput listing the registered names otherwise.
const MaterialKind& material_kind(const std::string& name);

/// Makes material `name` with `parameters` (all its declared ones; see above).
std::shared_ptr<const Material> make_material(const std::string& name,
                                              const MaterialParameters& parameters,
                                              const std::string& where = "material");
/// The material's parameters by name (Material::parameters() with values()).
MaterialParameters parameters_of(const Material& material);
/// A material of the same kind with some parameters changed (names checked as by make_material).
std::shared_ptr<const Material> with_parameters(const Material& material,
                                                const MaterialParameters& changes,
                                                const std::string& where = "material");

/// {"material": NAME, "parameters": {NAME: value, ...}, "units": {NAME: unit, ...}} as JSON text.
std::string material_json(const Material& material);
/// Makes the material that JSON text of the form material_json() writes describes ("units", if
/// present, must match the declared ones); InvalidInput naming `where` otherwise.
std::shared_ptr<const Material> material_from_json(const std::string& json_text,
                                                   const std::string& where = "material");

/// The presets' folder: materials/ in caps's data folder (caps::data_dir(), caps/core/data_dir.hpp:
/// $CAPS_DATA_DIR if set, else the source tree's data/). Throws InvalidInput if it is missing.
std::filesystem::path materials_dir();

/// A preset from materials_dir()/NAME.json.
struct MaterialPreset {
  std::string name;         ///< the file's stem: "dermis"
  std::string description;  ///< what it models
  std::vector<std::string> sources;          ///< where its values come from
  std::shared_ptr<const Material> material;  ///< made by make_material()
};

/// Reads preset `name` (cached per file). Throws InvalidInput if the file is missing or bad.
MaterialPreset material_preset(const std::string& name);
/// The preset's material (material_preset(name).material).
std::shared_ptr<const Material> preset_material(const std::string& name);
/// The preset names in materials_dir(), sorted.
std::vector<std::string> material_preset_names();

}  // namespace caps::fem
