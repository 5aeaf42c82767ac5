#include "caps/fem/mesh_io.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "caps/core/atomic_output.hpp"
#include "caps/core/checked_numbers.hpp"
#include "caps/core/error.hpp"
#include "caps/core/file_access.hpp"
#include "caps/core/json_file.hpp"
#include "caps/core/json_limits.hpp"
#include "caps/fem/material_registry.hpp"
#include "constraints.hpp"
#include "vtu.hpp"

namespace fs = std::filesystem;

namespace caps::fem {
namespace {

// The largest nodal load component accepted from a mesh file: 1e6 N is far beyond any load on
// skin, and values near 1e308 overflow the solver's arithmetic.
constexpr double kMaxNodalLoadN = 1e6;

}  // namespace

namespace detail {
namespace {

constexpr int kVtkQuadraticHexahedron = 25;
constexpr int kVtkQuadraticWedge = 26;
constexpr int kVtkQuadraticTetra = 24;

int vtk_cell_type(ElementType type) {
  switch (type) {
    case ElementType::Hex20: return kVtkQuadraticHexahedron;
    case ElementType::Wedge15: return kVtkQuadraticWedge;
    case ElementType::Tet10: return kVtkQuadraticTetra;
  }
  return 0;
}

std::string attribute(const std::string& tag, const std::string& name) {
  const std::string key = " " + name + "=\"";
  const auto p = tag.find(key);
  if (p == std::string::npos) return {};
  const auto q = tag.find('"', p + key.size());
  return tag.substr(p + key.size(), q - p - key.size());
}

}  // namespace

void write_vtu(const fs::path& path, const Eigen::MatrixX3d& points,
               const std::vector<Element>& elements, const std::vector<VtuArray>& point_data,
               const std::vector<VtuArray>& cell_data) {
  write_file_atomic(path, [&](const fs::path& tmp) {
    std::ofstream o(tmp);
    o.precision(17);
    o << "<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" "
         "byte_order=\"LittleEndian\" header_type=\"UInt64\">\n<UnstructuredGrid>\n"
      << "<Piece NumberOfPoints=\"" << points.rows() << "\" NumberOfCells=\"" << elements.size()
      << "\">\n";
    auto write_array = [&](const VtuArray& a) {
      o << "<DataArray type=\"" << (a.integer ? "Int32" : "Float64") << "\" Name=\"" << a.name
        << "\" NumberOfComponents=\"" << a.values.cols() << "\" format=\"ascii\">\n";
      for (Eigen::Index i = 0; i < a.values.rows(); ++i) {
        for (Eigen::Index c = 0; c < a.values.cols(); ++c) {
          if (a.integer) {
            o << static_cast<long>(std::lround(a.values(i, c)));
          } else {
            // The shortest text that reads back as the same double (std::to_chars): exact, and
            // several times faster than the stream's 17 digits, which took a tenth of a small
            // closure's time in the planner's first answer.
            char text[32];
            const auto end = std::to_chars(text, text + sizeof text, a.values(i, c)).ptr;
            o.write(text, end - text);
          }
          o << (c + 1 < a.values.cols() ? ' ' : '\n');
        }
      }
      o << "</DataArray>\n";
    };
    o << "<PointData>\n";
    for (const auto& a : point_data) write_array(a);
    o << "</PointData>\n<CellData>\n";
    for (const auto& a : cell_data) write_array(a);
    o << "</CellData>\n<Points>\n";
    write_array({"Points", points, false});
    o << "</Points>\n<Cells>\n<DataArray type=\"Int64\" Name=\"connectivity\" format=\"ascii\">\n";
    for (const Element& el : elements) {
      for (int k = 0; k < el.n_nodes(); ++k)
        o << el.nodes[el.type == ElementType::Wedge15 ? kWedge15ToVtk[k] : k]
          << (k + 1 < el.n_nodes() ? ' ' : '\n');
    }
    o << "</DataArray>\n<DataArray type=\"Int64\" Name=\"offsets\" format=\"ascii\">\n";
    long off = 0;
    for (const Element& el : elements) o << (off += el.n_nodes()) << '\n';
    o << "</DataArray>\n<DataArray type=\"UInt8\" Name=\"types\" format=\"ascii\">\n";
    for (const Element& el : elements)
      o << vtk_cell_type(el.type) << '\n';
    o << "</DataArray>\n</Cells>\n</Piece>\n</UnstructuredGrid>\n</VTKFile>\n";
    if (!o) throw IoError(cat(path.string(), ": write failed (disk full?)"));
  });
}

VtuContent read_vtu(const fs::path& path) {
  std::ifstream in(path);
  if (!in) throw IoError(cat(path.string(), ": cannot open; is this a caps mesh directory?"));
  std::stringstream ss;
  ss << in.rdbuf();
  const std::string text = ss.str();
  VtuContent v;
  const auto piece = text.find("<Piece");
  if (piece == std::string::npos)
    throw InvalidInput(cat(path.string(), ": no <Piece> element; not a VTK UnstructuredGrid file"));
  const std::string ptag = text.substr(piece, text.find('>', piece) - piece);
  v.n_points = std::atol(attribute(ptag, "NumberOfPoints").c_str());
  v.n_cells = std::atol(attribute(ptag, "NumberOfCells").c_str());
  std::size_t pos = 0;
  while ((pos = text.find("<DataArray", pos)) != std::string::npos) {
    const auto end_tag = text.find('>', pos);
    const std::string tag = text.substr(pos, end_tag - pos);
    const std::string name = attribute(tag, "Name");
    if (attribute(tag, "format") != "ascii")
      throw InvalidInput(cat(path.string(), ": DataArray '", name, "' is not ascii; caps-mesh "
                             "version 1 reads ascii VTU only (write it with caps or ParaView's "
                             "ascii option)"));
    const auto close = text.find("</DataArray>", end_tag);
    if (close == std::string::npos)
      throw InvalidInput(cat(path.string(), ": DataArray '", name, "' is not closed (truncated file?)"));
    std::vector<double> values;
    const char* p = text.c_str() + end_tag + 1;
    const char* stop = text.c_str() + close;
    while (p < stop) {
      char* next = nullptr;
      const double x = std::strtod(p, &next);
      if (next == p) {
        if (std::isspace(static_cast<unsigned char>(*p))) {
          ++p;
          continue;
        }
        throw InvalidInput(cat(path.string(), ": DataArray '", name, "' entry ", values.size(),
                               " is not a number"));
      }
      values.push_back(x);
      p = next;
    }
    const std::string nc = attribute(tag, "NumberOfComponents");
    v.components[name] = nc.empty() ? 1 : std::atoi(nc.c_str());
    v.arrays[name] = std::move(values);
    pos = close;
  }
  return v;
}

}  // namespace detail

namespace {

// mesh.json "ties": [[slave, [masters], [weights]]]; "sliding_surface": the surface's name
// (the surface itself is not stored: docs/fem.md, "Ties and sliding on the bone").
void write_ties_and_surface(const Mesh& mesh, nlohmann::json& j) {
  if (!mesh.ties.empty()) {
    j["ties"] = nlohmann::json::array();
    for (const TiedNode& t : mesh.ties) j["ties"].push_back({t.node, t.masters, t.weights});
  }
  const bool on_surface = std::any_of(mesh.sliding.begin(), mesh.sliding.end(),
                                      [](const SlidingNode& s) { return s.on_surface; });
  if (on_surface) j["sliding_surface"] = mesh.sliding_surface_name;
  if (mesh.wedge_rule != WedgeRule::Full) j["wedge_rule"] = wedge_rule_name(mesh.wedge_rule);
  if (!mesh.node_sets.empty()) {
    j["node_sets"] = nlohmann::json::object();
    for (const auto& [name, ids] : mesh.node_sets) j["node_sets"][name] = ids;
  }
}

void read_ties_and_surface(const nlohmann::json& j, const std::string& jw, Mesh& mesh) {
  const nlohmann::json ties = j.value("ties", nlohmann::json::array());
  if (!ties.is_array()) throw InvalidInput(cat(jw, ": ties must be an array"));
  for (std::size_t i = 0; i < ties.size(); ++i) {
    const nlohmann::json& t = ties[i];
    if (!t.is_array() || t.size() != 3 || !t[1].is_array() || !t[2].is_array())
      throw InvalidInput(cat(jw, ": ties[", i, "] must be [slave, [masters], [weights]]"));
    TiedNode tie;
    tie.node = to_int(t[0].get<double>(), cat(jw, ": ties[", i, "][0]"));
    for (std::size_t k = 0; k < t[1].size(); ++k)
      tie.masters.push_back(to_int(t[1][k].get<double>(), cat(jw, ": ties[", i, "][1][", k, "]")));
    for (const auto& w : t[2]) tie.weights.push_back(w.get<double>());
    mesh.ties.push_back(std::move(tie));
  }
  if (const auto rule = j.find("wedge_rule"); rule != j.end()) {
    try {
      mesh.wedge_rule = parse_wedge_rule(rule->is_string() ? rule->get<std::string>() : rule->dump());
    } catch (const InvalidInput& e) {
      throw InvalidInput(cat(jw, ": wedge_rule: ", e.what()));
    }
  }
  const nlohmann::json sets = j.value("node_sets", nlohmann::json::object());
  if (!sets.is_object()) throw InvalidInput(cat(jw, ": node_sets must be an object of id arrays"));
  for (const auto& [name, ids] : sets.items()) {
    if (!ids.is_array()) throw InvalidInput(cat(jw, ": node_sets.", name, " must be an array of node ids"));
    std::vector<int>& out = mesh.node_sets[name];
    for (std::size_t k = 0; k < ids.size(); ++k) {
      if (!ids[k].is_number())
        throw InvalidInput(cat(jw, ": node_sets.", name, "[", k, "] must be a node id"));
      out.push_back(to_int(ids[k].get<double>(), cat(jw, ": node_sets.", name, "[", k, "]")));
    }
  }
  const long n_on_surface = std::count_if(mesh.sliding.begin(), mesh.sliding.end(),
                                          [](const SlidingNode& s) { return s.on_surface; });
  if (n_on_surface == 0) return;
  mesh.sliding_surface_name = j.value("sliding_surface", std::string());
  const std::string note =
      cat("the ", n_on_surface, " nodes sliding on the '", mesh.sliding_surface_name,
          "' surface slide along their start normals: mesh.json does not store the surface");
  if (std::find(mesh.warnings.begin(), mesh.warnings.end(), note) == mesh.warnings.end())
    mesh.warnings.push_back(note);
}

}  // namespace

void write_mesh_dir(const Mesh& mesh, const fs::path& dir) {
  validate(mesh, dir.string());
  const Eigen::Index n = mesh.n_nodes();
  Eigen::MatrixXd fixed = Eigen::MatrixXd::Zero(n, 1), partner = Eigen::MatrixXd::Constant(n, 1, -1);
  for (int i : mesh.fixed_nodes) fixed(i, 0) = 1;
  for (const SuturePair& s : mesh.sutures) {
    partner(s.a, 0) = s.b;
    partner(s.b, 0) = s.a;
  }
  Eigen::MatrixXd layer(static_cast<Eigen::Index>(mesh.elements.size()), 1);
  for (std::size_t e = 0; e < mesh.elements.size(); ++e) layer(static_cast<Eigen::Index>(e), 0) = mesh.elements[e].layer;
  detail::write_vtu(dir / "mesh.vtu", mesh.nodes, mesh.elements,
                    {{"fixed", fixed, true}, {"suture_partner", partner, true}},
                    {{"layer", layer, true}});
  nlohmann::json j;
  j["format"] = "caps-mesh";
  j["version"] = 1;
  j["units"] = {{"length", "mm"}, {"force", "N"}, {"stress", "MPa"}, {"frame", "LPS"}};
  long n_hex = 0, n_wedge = 0, n_tet = 0;
  for (const Element& e : mesh.elements) {
    n_hex += e.type == ElementType::Hex20;
    n_wedge += e.type == ElementType::Wedge15;
    n_tet += e.type == ElementType::Tet10;
  }
  j["counts"] = {{"nodes", n}, {"elements", mesh.elements.size()}, {"hex20", n_hex},
                 {"wedge15", n_wedge}, {"tet10", n_tet},
                 {"fixed_nodes", mesh.fixed_nodes.size()}, {"sutures", mesh.sutures.size()}};
  j["materials"] = nlohmann::json::array();
  for (const auto& [layer_id, m] : mesh.materials) {
    nlohmann::json entry = nlohmann::json::parse(material_json(*m));  // material, parameters, units
    entry["layer"] = layer_id;
    j["materials"].push_back(entry);
  }
  j["fixed_nodes"] = mesh.fixed_nodes;
  j["fixed_dofs"] = nlohmann::json::array();
  for (const FixedDof& f : mesh.fixed_dofs) j["fixed_dofs"].push_back({f.node, f.component, f.value_mm});
  j["loads_n"] = nlohmann::json::array();
  for (const NodalLoad& l : mesh.loads)
    j["loads_n"].push_back({l.node, l.force_n.x(), l.force_n.y(), l.force_n.z()});
  j["sutures"] = nlohmann::json::array();
  for (const SuturePair& s : mesh.sutures) j["sutures"].push_back({s.a, s.b});
  if (!mesh.sliding.empty()) {
    j["sliding_nodes"] = nlohmann::json::array();  // node, normal x y z, stiffness N/mm
    for (const SlidingNode& s : mesh.sliding) {
      // An entry on the sliding surface: its start normal, and a sixth value 1.
      const Eigen::Vector3d n = detail::start_normal(mesh, s);
      nlohmann::json entry = {s.node, n.x(), n.y(), n.z(), s.stiffness_n_per_mm};
      if (s.on_surface) entry.push_back(1);
      j["sliding_nodes"].push_back(entry);
    }
  }
  write_ties_and_surface(mesh, j);
  if (!mesh.flaps.empty()) j["flaps"] = mesh.flaps;  // the elements of each raised flap
  j["model"] = mesh.model;
  j["plan"] = mesh.plan;
  j["warnings"] = mesh.warnings;
  write_text_atomic(dir / "mesh.json", j.dump(1, ' ', false, nlohmann::json::error_handler_t::replace) + "\n");
}

Mesh read_mesh_dir(const fs::path& dir) {
  const fs::path jpath = dir / "mesh.json", vpath = dir / "mesh.vtu";
  require_readable(dir, true, "pass a mesh directory with mesh.json and mesh.vtu");
  const auto j = read_json_file<nlohmann::json>(jpath, "is this a caps mesh directory?");
  Mesh mesh;
  const std::string jw = jpath.string();
  try {
    if (!j.is_object() || j.value("format", "") != "caps-mesh" || j.value("version", 0.0) != 1.0)
      throw InvalidInput(cat(jw, ": format must be \"caps-mesh\" version 1"));
    // Integers are read as doubles and checked (a cast of 1e300 to int is undefined).
    const auto integer = [&](const nlohmann::json& v, const std::string& field) {
      return to_int(v.get<double>(), cat(jw, ": ", field));
    };
    const auto entries = [&](const char* key) {
      const nlohmann::json a = j.value(key, nlohmann::json::array());
      if (!a.is_array()) throw InvalidInput(cat(jw, ": ", key, " must be an array"));
      return a;
    };
    for (const auto& m : j.at("materials")) {
      const int layer = integer(m.at("layer"), "materials: layer");
      const std::string where = cat(jw, ": material of layer ", layer);
      if (m.contains("material")) {
        mesh.materials[layer] = material_from_json(m.dump(), where);
      } else {
        // Before materials were named: small-strain constants that the finite-strain solve took
        // as the neo-Hookean solid, which is what they are read as.
        mesh.materials[layer] = make_material(
            "neo-hookean", {{"E", m.at("E_kpa").get<double>() * 1e-3}, {"nu", m.at("nu").get<double>()}},
            where);
      }
    }
    const nlohmann::json fixed = entries("fixed_nodes");
    for (std::size_t i = 0; i < fixed.size(); ++i)
      mesh.fixed_nodes.push_back(integer(fixed[i], cat("fixed_nodes[", i, "]")));
    for (const auto& f : entries("fixed_dofs"))
      mesh.fixed_dofs.push_back({integer(f.at(0), cat("fixed_dofs[", mesh.fixed_dofs.size(), "][0]")),
                                 integer(f.at(1), cat("fixed_dofs[", mesh.fixed_dofs.size(), "][1]")),
                                 f.at(2).get<double>()});
    for (const auto& l : entries("loads_n")) {
      mesh.loads.push_back({integer(l.at(0), cat("loads_n[", mesh.loads.size(), "][0]")),
                            Eigen::Vector3d(l.at(1).get<double>(), l.at(2).get<double>(), l.at(3).get<double>())});
      const Eigen::Vector3d& f = mesh.loads.back().force_n;
      if (!(f.array().abs() <= kMaxNodalLoadN).all())
        throw InvalidInput(cat(jw, ": loads_n[", mesh.loads.size() - 1, "] = (", f.transpose(),
                               ") N: a nodal load must be finite and at most ", kMaxNodalLoadN,
                               " N in each component; check the units (N) of the load"));
    }
    for (const auto& s : entries("sutures"))
      mesh.sutures.push_back({integer(s.at(0), cat("sutures[", mesh.sutures.size(), "][0]")),
                              integer(s.at(1), cat("sutures[", mesh.sutures.size(), "][1]"))});
    for (const auto& s : entries("sliding_nodes")) {
      mesh.sliding.push_back({integer(s.at(0), cat("sliding_nodes[", mesh.sliding.size(), "][0]")),
                              Eigen::Vector3d(s.at(1).get<double>(), s.at(2).get<double>(), s.at(3).get<double>()),
                              s.at(4).get<double>()});
      mesh.sliding.back().on_surface =
          s.size() > 5 && integer(s.at(5), cat("sliding_nodes[", mesh.sliding.size() - 1, "][5]")) != 0;
    }
    for (const auto& f : entries("flaps")) {
      if (!f.is_array()) throw InvalidInput(cat(jw, ": flaps[", mesh.flaps.size(), "] must be an array of element ids"));
      mesh.flaps.emplace_back();
      for (const auto& e : f) mesh.flaps.back().push_back(integer(e, cat("flaps[", mesh.flaps.size() - 1, "]")));
    }
    mesh.model = j.value("model", "");
    mesh.plan = j.value("plan", "");
    if (j.contains("warnings")) mesh.warnings = j.at("warnings").get<std::vector<std::string>>();
    read_ties_and_surface(j, jw, mesh);
  } catch (const nlohmann::json::exception& e) {
    throw InvalidInput(cat(jw, ": missing or mistyped field: ", e.what()));
  }
  const detail::VtuContent v = detail::read_vtu(vpath);
  const std::string vw = vpath.string();
  for (const char* name : {"Points", "connectivity", "offsets", "types", "layer"})
    if (!v.arrays.count(name))
      throw InvalidInput(cat(vw, ": the DataArray '", name, "' is missing"));
  const auto& P = v.arrays.at("Points");
  if (static_cast<long>(P.size()) != 3 * v.n_points)
    throw InvalidInput(cat(vw, ": Points has ", P.size(), " values, expected 3 x ", v.n_points));
  mesh.nodes.resize(v.n_points, 3);
  for (long i = 0; i < v.n_points; ++i)
    for (int c = 0; c < 3; ++c) mesh.nodes(i, c) = P[3 * i + c];
  const auto& conn = v.arrays.at("connectivity");
  const auto& offs = v.arrays.at("offsets");
  const auto& types = v.arrays.at("types");
  const auto& layer = v.arrays.at("layer");
  if (static_cast<long>(offs.size()) != v.n_cells || static_cast<long>(types.size()) != v.n_cells ||
      static_cast<long>(layer.size()) != v.n_cells)
    throw InvalidInput(cat(vw, ": offsets/types/layer must have one entry per cell (", v.n_cells, ")"));
  // The integer arrays must hold whole numbers in range (a cast of any other double is undefined).
  const auto whole = [&](const char* array, long c, double x, double lo, double hi) {
    if (!is_whole_in(x, lo, hi))
      throw InvalidInput(cat(vw, ": ", array, "[", c, "] = ", x, " is not a whole number in [", lo,
                             ", ", hi, "]; the mesh file is damaged, write it again"));
    return static_cast<long>(x);
  };
  long begin = 0;
  for (long c = 0; c < v.n_cells; ++c) {
    Element el;
    const int t = static_cast<int>(whole("types", c, types[c], 0, 255));
    using detail::kVtkQuadraticHexahedron, detail::kVtkQuadraticTetra, detail::kVtkQuadraticWedge;
    if (t != kVtkQuadraticHexahedron && t != kVtkQuadraticWedge && t != kVtkQuadraticTetra)
      throw InvalidInput(cat(vw, ": cell ", c, " has VTK type ", t, "; only 25 (quadratic hexahedron), "
                             "26 (quadratic wedge) and 24 (quadratic tetrahedron) are supported"));
    el.type = t == kVtkQuadraticHexahedron ? ElementType::Hex20
              : t == kVtkQuadraticWedge    ? ElementType::Wedge15
                                           : ElementType::Tet10;
    el.layer = static_cast<int>(whole("layer", c, layer[c], -1e9, 1e9));
    const long end = whole("offsets", c, offs[c], 0, static_cast<double>(conn.size()));
    if (end - begin != el.n_nodes())
      throw InvalidInput(cat(vw, ": cell ", c, " has ", end - begin, " nodes, expected ", el.n_nodes()));
    for (int k = 0; k < el.n_nodes(); ++k) {
      const int src = el.type == ElementType::Wedge15 ? kWedge15ToVtk[k] : k;
      el.nodes[k] = static_cast<int>(whole("connectivity", begin + src, conn[begin + src], 0,
                                           static_cast<double>(v.n_points) - 1));
    }
    mesh.elements.push_back(el);
    begin = end;
  }
  validate(mesh, dir.string());
  return mesh;
}

}  // namespace caps::fem
