#include "caps/fem/material_registry.hpp"

#include <algorithm>
#include <cstdlib>
#include <mutex>
#include <nlohmann/json.hpp>

#include "caps/core/data_dir.hpp"
#include "caps/core/error.hpp"
#include "caps/core/json_file.hpp"


namespace caps::fem {
namespace {

using nlohmann::json;

// The built-in kinds. Their declared parameters come from the classes themselves (one
// declaration: Material::parameters()), read off an instance made with valid values.
std::vector<MaterialKind> builtin_kinds() {
  std::vector<MaterialKind> kinds;
  kinds.push_back({"linear", "isotropic linear elasticity (small strain only)",
                   LinearElastic(0.1, 0.3).parameters(),
                   [](const std::vector<double>& v, const std::string& where) {
                     return std::make_shared<const LinearElastic>(v[0], v[1], where);
                   }});
  kinds.push_back({"neo-hookean", "compressible neo-Hookean solid (Abaqus / CalculiX NEO HOOKE)",
                   NeoHookean(0.1, 0.3).parameters(),
                   [](const std::vector<double>& v, const std::string& where) {
                     return std::make_shared<const NeoHookean>(v[0], v[1], where);
                   }});
  kinds.push_back(
      {"goh", "Gasser-Ogden-Holzapfel skin: neo-Hookean matrix with collagen fibres in the layer's plane",
       GasserOgdenHolzapfel(0.05, 0.24, 1, 1, 0, 0, Eigen::Vector3d::UnitX()).parameters(),
       [](const std::vector<double>& v, const std::string& where) {
         return std::make_shared<const GasserOgdenHolzapfel>(
             v[0], v[1], v[2], v[3], v[4], v[5], Eigen::Vector3d(v[6], v[7], v[8]), where);
       }});
  return kinds;
}

struct Registry {
  std::mutex mutex;
  std::map<std::string, MaterialKind> kinds;
  std::map<std::string, MaterialPreset> presets;  // by file path
};

Registry& registry() {
  static Registry* r = [] {
    auto* reg = new Registry;  // never destroyed: materials may be made during static teardown
    for (MaterialKind& k : builtin_kinds()) reg->kinds.emplace(k.name, std::move(k));
    return reg;
  }();
  return *r;
}

std::string joined(const std::vector<std::string>& names) {
  std::string s;
  for (const std::string& n : names) s += (s.empty() ? "" : ", ") + n;
  return s;
}

std::vector<std::string> parameter_names(const MaterialKind& kind) {
  std::vector<std::string> names;
  for (const ParameterSpec& p : kind.parameters) names.push_back(p.name);
  return names;
}

}  // namespace

void register_material(MaterialKind kind) {
  if (kind.name.empty() || !kind.make)
    throw InvalidInput("register_material: a material kind needs a name and a factory");
  Registry& r = registry();
  std::lock_guard lock(r.mutex);
  if (r.kinds.count(kind.name))
    throw InvalidInput(cat("register_material: '", kind.name, "' is already registered"));
  r.kinds.emplace(kind.name, std::move(kind));
}

std::vector<std::string> material_names() {
  Registry& r = registry();
  std::lock_guard lock(r.mutex);
  std::vector<std::string> names;
  for (const auto& [name, kind] : r.kinds) names.push_back(name);
  return names;
}

const MaterialKind& material_kind(const std::string& name) {
  Registry& r = registry();
  {
    std::lock_guard lock(r.mutex);
    const auto it = r.kinds.find(name);
    if (it != r.kinds.end()) return it->second;  // kinds are never removed: the reference stays valid
  }
  throw InvalidInput(cat("material '", name, "' is unknown; the registered materials are ",
                         joined(material_names())));
}

std::shared_ptr<const Material> make_material(const std::string& name,
                                              const MaterialParameters& parameters,
                                              const std::string& where) {
  const MaterialKind& kind = material_kind(name);
  std::vector<double> values;
  std::vector<std::string> missing;
  for (const ParameterSpec& p : kind.parameters) {
    const auto it = parameters.find(p.name);
    if (it == parameters.end())
      missing.push_back(p.name);
    else
      values.push_back(it->second);
  }
  const std::vector<std::string> declared = parameter_names(kind);
  for (const auto& [key, value] : parameters)
    if (std::find(declared.begin(), declared.end(), key) == declared.end())
      throw InvalidInput(cat(where, ": ", name, " has no parameter '", key, "'; its parameters are ",
                             joined(declared)));
  if (!missing.empty())
    throw InvalidInput(cat(where, ": ", name, " needs its parameter", missing.size() > 1 ? "s " : " ",
                           joined(missing), " (its parameters are ", joined(declared), ")"));
  return kind.make(values, where);
}

MaterialParameters parameters_of(const Material& material) {
  const std::vector<ParameterSpec> spec = material.parameters();
  const std::vector<double> v = material.values();
  MaterialParameters p;
  for (std::size_t i = 0; i < spec.size(); ++i) p[spec[i].name] = v[i];
  return p;
}

std::shared_ptr<const Material> with_parameters(const Material& material,
                                                const MaterialParameters& changes,
                                                const std::string& where) {
  MaterialParameters p = parameters_of(material);
  for (const auto& [key, value] : changes) {
    if (!p.count(key)) {
      std::vector<std::string> declared;
      for (const ParameterSpec& s : material.parameters()) declared.push_back(s.name);
      throw InvalidInput(cat(where, ": ", material.name(), " has no parameter '", key,
                             "'; its parameters are ", joined(declared)));
    }
    p[key] = value;
  }
  return make_material(material.name(), p, where);
}

std::string material_json(const Material& material) {
  json params = json::object(), units = json::object();
  const std::vector<ParameterSpec> spec = material.parameters();
  const std::vector<double> v = material.values();
  for (std::size_t i = 0; i < spec.size(); ++i) {
    params[spec[i].name] = v[i];
    units[spec[i].name] = spec[i].unit;
  }
  return json{{"material", material.name()}, {"parameters", params}, {"units", units}}.dump();
}

namespace {

std::shared_ptr<const Material> material_of(const json& j, const std::string& where) {
  if (!j.is_object() || !j.contains("material") || !j["material"].is_string())
    throw InvalidInput(cat(where, ": a material is {\"material\": NAME, \"parameters\": {...}}; "
                           "the registered materials are ", joined(material_names())));
  const std::string name = j["material"].get<std::string>();
  const MaterialKind& kind = material_kind(name);
  const json params = j.value("parameters", json::object());
  if (!params.is_object()) throw InvalidInput(cat(where, ": \"parameters\" must be an object"));
  MaterialParameters p;
  for (const auto& [key, value] : params.items()) {
    if (!value.is_number())
      throw InvalidInput(cat(where, ": ", name, " parameter ", key, " must be a number"));
    p[key] = value.get<double>();
  }
  if (j.contains("units")) {
    const json& units = j["units"];
    if (!units.is_object()) throw InvalidInput(cat(where, ": \"units\" must be an object"));
    for (const ParameterSpec& s : kind.parameters)
      if (units.contains(s.name) && units[s.name] != s.unit)
        throw InvalidInput(cat(where, ": ", name, " parameter ", s.name, " is in ", s.unit,
                               ", not ", units[s.name].dump()));
  }
  return make_material(name, p, where);
}

json parsed(const std::string& text, const std::string& where) {
  return parse_json<json>(text, where);
}

}  // namespace

std::shared_ptr<const Material> material_from_json(const std::string& json_text,
                                                   const std::string& where) {
  return material_of(parsed(json_text, where), where);
}

std::filesystem::path materials_dir() {
  const std::filesystem::path dir = data_dir() / "materials";
  std::error_code ec;
  if (!std::filesystem::is_directory(dir, ec)) {
    const char* env = std::getenv("CAPS_DATA_DIR");
    throw InvalidInput(cat("the data folder ", data_dir().string(), " has no materials/ folder",
                           env && *env ? " (from CAPS_DATA_DIR)" : " (the source tree's data/)",
                           "; set CAPS_DATA_DIR to the caps data folder"));
  }
  return dir;
}

MaterialPreset material_preset(const std::string& name) {
  const std::filesystem::path path = materials_dir() / (name + ".json");
  const std::string where = path.string();
  Registry& r = registry();
  {
    std::lock_guard lock(r.mutex);
    const auto it = r.presets.find(where);
    if (it != r.presets.end()) return it->second;
  }
  std::error_code ec;
  if (name.empty() || name.find('/') != std::string::npos ||
      !std::filesystem::is_regular_file(path, ec)) {
    std::vector<std::string> names;
    try {
      names = material_preset_names();
    } catch (const InvalidInput&) {
    }
    throw InvalidInput(cat("material preset '", name, "': cannot read ", where,
                           "; the presets are ", joined(names)));
  }
  // A preset is a few hundred bytes: 1 MiB bounds what a damaged data folder can make us read.
  const json j = read_json_file<json>(path, "the presets are caps's data/materials/*.json",
                                      std::size_t(1) << 20);
  if (!j.is_object() || j.value("format", "") != "caps-material-preset" || j.value("version", 0.0) != 1.0)
    throw InvalidInput(cat(where, ": format must be \"caps-material-preset\" version 1"));
  MaterialPreset p;
  p.name = name;
  p.material = material_of(j, where);
  try {
    p.description = j.value("description", "");
    for (const auto& s : j.value("sources", json::array())) p.sources.push_back(s.get<std::string>());
  } catch (const json::exception& e) {
    throw InvalidInput(cat(where, ": description and sources must be text: ", e.what()));
  }
  std::lock_guard lock(r.mutex);
  r.presets.emplace(where, p);
  return p;
}

std::shared_ptr<const Material> preset_material(const std::string& name) {
  return material_preset(name).material;
}

std::vector<std::string> material_preset_names() {
  std::vector<std::string> names;
  for (const auto& e : std::filesystem::directory_iterator(materials_dir()))
    if (e.path().extension() == ".json") names.push_back(e.path().stem().string());
  std::sort(names.begin(), names.end());
  return names;
}

}  // namespace caps::fem
