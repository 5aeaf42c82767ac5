#include "caps/fem/inp_io.hpp"

#include "caps/core/atomic_output.hpp"
#include "caps/core/error.hpp"
#include "caps/fem/material_registry.hpp"
#include "constraints.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <map>
#include <set>
#include <sstream>
#include <vector>

namespace caps::fem {
namespace {

std::string num(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.12g", v);
  return buf;
}

/// Writes ids 16 to a line (the format's limit), as continuation lines.
void id_lines(std::ostringstream& os, const std::vector<int>& ids) {
  for (std::size_t i = 0; i < ids.size(); ++i)
    os << ids[i] + 1 << (i + 1 == ids.size() ? "\n" : (i % 16 == 15 ? ",\n" : ", "));
}

// The layer's material in a CalculiX form: small strain, *ELASTIC of its small-strain constants;
// finite strain, *HYPERELASTIC, NEO HOOKE (the neo-Hookean solid only).
const IsotropicElastic& calculix_material(const Mesh& mesh, int layer, bool finite_strain) {
  const Material& m = *mesh.materials.at(layer);
  const IsotropicElastic* iso = m.small_strain();
  if (!iso || (finite_strain && m.name() != "neo-hookean"))
    throw InvalidInput(cat("inp export: layer ", layer, " has the ", finite_strain ? "finite" : "small",
                           "-strain material '", m.name(),
                           "', which has no CalculiX form here; use neo-hookean"));
  return *iso;
}

// The elements by layer and type (element ids in caps order + 1) and each layer's material and
// section.
void write_elements_and_materials(std::ostream& os, const Mesh& mesh, const InpOptions& options) {
  std::set<int> layers;
  for (const auto& e : mesh.elements) layers.insert(e.layer);
  for (int layer : layers)
    for (ElementType type : {ElementType::Hex20, ElementType::Wedge15, ElementType::Tet10}) {
      bool header = false;
      for (std::size_t e = 0; e < mesh.n_elements(); ++e) {
        const Element& el = mesh.elements[e];
        if (el.layer != layer || el.type != type) continue;
        if (!header) {
          os << "*ELEMENT, TYPE="
             << (type == ElementType::Hex20 ? "C3D20" : type == ElementType::Wedge15 ? "C3D15" : "C3D10")
             << ", ELSET=LAYER" << layer << "\n";
          header = true;
        }
        // C3D20, C3D15 and C3D10 follow the caps numbering node for node (see inp_io.hpp).
        os << e + 1;
        for (int k = 0; k < el.n_nodes(); ++k)
          os << (k == 15 ? ",\n" : ", ") << el.nodes[k] + 1;
        os << "\n";
      }
    }
  for (int layer : layers) {
    const IsotropicElastic& m = calculix_material(mesh, layer, options.finite_strain);
    os << "** layer " << layer << ": " << material_json(*mesh.materials.at(layer)) << "\n";
    os << "*MATERIAL, NAME=MAT" << layer << "\n";
    if (options.finite_strain) {  // C10 = mu/2, D1 = 2/K (NeoHookean)
      os << "*HYPERELASTIC, NEO HOOKE\n" << num(0.5 * m.mu_mpa()) << ", " << num(2 / m.bulk_mpa()) << "\n";
    } else {
      os << "*ELASTIC\n" << num(m.E_mpa()) << ", " << num(m.nu()) << "\n";
    }
    os << "*SOLID SECTION, ELSET=LAYER" << layer << ", MATERIAL=MAT" << layer << "\n";
  }
}

// Ties: u_s - sum_i w_i u_m_i = 0 for each component, exact (caps holds them by a penalty that
// gives way by about 1e-6 of the displacement); the slave's dof is the dependent one, which
// solve() keeps free of prescriptions, sutures and sliding (constraints.cpp, check_ties).
void write_tie_equations(std::ostream& os, const Mesh& mesh) {
  if (mesh.ties.empty()) return;
  os << "** ties (" << mesh.ties.size() << " slave nodes): u_slave - sum w u_master = 0\n";
  for (const TiedNode& t : mesh.ties)
    for (int c = 1; c <= 3; ++c) {
      os << "*EQUATION\n" << t.masters.size() + 1 << "\n" << t.node + 1 << ", " << c << ", 1.";
      for (std::size_t k = 0; k < t.masters.size(); ++k)
        os << ((k + 1) % 4 == 0 ? ",\n" : ", ") << t.masters[k] + 1 << ", " << c << ", " << num(-t.weights[k]);
      os << "\n";
    }
}

// Entries sliding on a curved surface are written as their linearisation at the start.
void write_sliding_surface_note(std::ostream& os, const Mesh& mesh, const InpOptions& options) {
  long n = 0;
  for (const SlidingNode& s : mesh.sliding) n += s.on_surface;
  if (n == 0) return;
  os << "** " << n << " nodes slide on the '" << mesh.sliding_surface_name
     << "' surface: written as its linearisation at the start, n . u = 0 with n = grad phi(X) / "
        "|grad phi(X)|"
     << (options.finite_strain ? " (caps's finite-strain solve follows the curved surface: the "
                                 "two differ by about d^2 / 2R for a slide d on a radius R)"
                               : "")
     << "\n";
}

}  // namespace

std::string inp_text(const Mesh& mesh, const InpOptions& options) {
  validate(mesh, "inp export");
  if (options.finite_strain && (options.increments < 1 || options.increments > 100000))
    throw InvalidInput(cat("inp export: increments = ", options.increments, " must be in 1..100000"));
  std::ostringstream os;
  const int N = static_cast<int>(mesh.n_nodes());
  os << "** caps mesh: " << N << " nodes, " << mesh.n_elements() << " elements; units mm, N, MPa\n";
  if (!mesh.model.empty()) os << "** model: " << mesh.model << "\n";
  if (!mesh.plan.empty()) os << "** plan: " << mesh.plan << "\n";
  if (std::any_of(mesh.elements.begin(), mesh.elements.end(),
                  [](const Element& e) { return e.type == ElementType::Wedge15; }))
    os << (mesh.wedge_rule == WedgeRule::CalculiX
               ? "** caps integrated the C3D15 elements with CalculiX's 9 points: the same problem\n"
               : "** caps integrated the C3D15 elements with 21 points, CalculiX uses 9: expect "
                 "differences of about 0.1 %\n** (caps simulate --wedge-rule calculix gives a mesh "
                 "both integrate alike)\n");
  os << "*HEADING\ncaps wound-closure mesh\n*NODE, NSET=NALL\n";
  for (int i = 0; i < N; ++i)
    os << i + 1 << ", " << num(mesh.nodes(i, 0)) << ", " << num(mesh.nodes(i, 1)) << ", "
       << num(mesh.nodes(i, 2)) << "\n";

  // Suture groups: a spanning forest of the pairs, so that no equation is redundant.
  UnionFind groups(N);  // each group's root is its smallest node
  for (const auto& s : mesh.sutures) groups.unite(s.a, s.b);
  std::vector<int> members;
  for (int i = 0; i < N; ++i)
    if (groups.find(i) != i) members.push_back(i);
  const std::set<int> fixed(mesh.fixed_nodes.begin(), mesh.fixed_nodes.end());
  // Prescribed values per dof (NaN = free), and per group root and component the common final
  // position when a member's value is prescribed (as solve() does). Such a component gets no
  // equation: CalculiX refuses an equation whose dependent dof is also in *BOUNDARY ("*ERROR in
  // cascade"), so every member that is not prescribed itself is prescribed to meet it.
  std::vector<double> prescribed(3 * static_cast<std::size_t>(N), NAN);
  for (int node : fixed)
    for (int c = 0; c < 3; ++c) prescribed[3 * node + c] = 0.0;
  for (const auto& d : mesh.fixed_dofs) prescribed[3 * d.node + d.component] = d.value_mm;
  std::vector<double> group_pos(3 * static_cast<std::size_t>(N), NAN);
  for (int i = 0; i < N; ++i)
    for (int c = 0; c < 3; ++c)
      if (!std::isnan(prescribed[3 * i + c]) && std::isnan(group_pos[3 * groups.find(i) + c]))
        group_pos[3 * groups.find(i) + c] = mesh.nodes(i, c) + prescribed[3 * i + c];
  auto meets_prescribed = [&](int n, int c) {
    return !std::isnan(group_pos[3 * groups.find(n) + c]);
  };
  if (!members.empty()) {
    os << "*NODE, NSET=SUTURE_HELPERS\n";
    for (std::size_t k = 0; k < members.size(); ++k) os << N + 1 + k << ", 0, 0, 0\n";
  }

  write_elements_and_materials(os, mesh, options);
  if (!fixed.empty()) {
    os << "*NSET, NSET=FIXED\n";
    id_lines(os, std::vector<int>(fixed.begin(), fixed.end()));
  }
  for (const auto& [name, ids] : mesh.node_sets) {  // names are checked by validate()
    if (ids.empty()) continue;
    std::string upper = name;
    for (char& c : upper) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
    os << "*NSET, NSET=" << upper << "\n";
    id_lines(os, ids);
  }
  for (std::size_t k = 0; k < members.size(); ++k) {
    const int n = members[k], m = groups.find(n), h = N + static_cast<int>(k);
    bool header = false;
    for (int c = 1; c <= 3; ++c) {
      if (meets_prescribed(n, c - 1)) continue;
      if (!header) os << "*EQUATION\n";
      header = true;
      os << "3\n" << n + 1 << ", " << c << ", 1., " << m + 1 << ", " << c << ", -1., " << h + 1
         << ", " << c << ", -1.\n";
    }
  }
  // Sliding supports: n . u = 0 as an exact equation (caps holds it by a stiff spring, which
  // gives way by about 1e-6 mm); the dependent dof is the normal's largest component. A sutured
  // node's displacement is its group root's plus its helper's (the equations above), so its
  // support is written on those two: n . (u_root + u_helper) = 0.
  std::map<int, int> helper_of;
  for (std::size_t k = 0; k < members.size(); ++k) helper_of[members[k]] = N + static_cast<int>(k);
  write_sliding_surface_note(os, mesh, options);
  for (const SlidingNode& sliding : mesh.sliding) {
    SlidingNode s = sliding;
    s.normal = detail::start_normal(mesh, sliding);
    int first = 0;
    for (int c = 1; c < 3; ++c)
      if (std::abs(s.normal[c]) > std::abs(s.normal[first])) first = c;
    std::vector<int> comps{first};
    for (int c = 0; c < 3; ++c)
      if (c != first && std::abs(s.normal[c]) > 1e-12) comps.push_back(c);
    const auto helper = helper_of.find(s.node);
    std::vector<int> nodes{helper == helper_of.end() ? s.node : groups.find(s.node)};
    if (helper != helper_of.end()) nodes.push_back(helper->second);
    os << "*EQUATION\n" << comps.size() * nodes.size() << "\n";
    int written = 0;  // terms so far: at most four a line
    for (int node : nodes)
      for (int c : comps) {
        if (written > 0) os << (written % 4 == 0 ? ",\n" : ", ");
        os << node + 1 << ", " << c + 1 << ", " << num(s.normal[c]);
        ++written;
      }
    os << "\n";
  }
  write_tie_equations(os, mesh);
  if (options.finite_strain) {
    // *STATIC: initial increment, step time, smallest and largest increment.
    const double inc = 1.0 / options.increments;
    os << "*STEP, NLGEOM, INC=" << 100 * options.increments << "\n*STATIC\n" << num(inc) << ", 1., "
       << num(inc * 1e-6) << ", " << num(options.grow_increments ? 1.0 : inc) << "\n*BOUNDARY\n";
  } else {
    os << "*STEP\n*STATIC\n*BOUNDARY\n";
  }
  if (!fixed.empty()) os << "FIXED, 1, 3, 0.\n";
  for (const auto& d : mesh.fixed_dofs)
    os << d.node + 1 << ", " << d.component + 1 << ", " << d.component + 1 << ", "
       << num(d.value_mm) << "\n";
  for (std::size_t k = 0; k < members.size(); ++k) {
    const int n = members[k], m = groups.find(n), h = N + static_cast<int>(k);
    // u_n - u_m = x_m - x_n: the group meets at the root's final position.
    for (int c = 0; c < 3; ++c)
      if (!meets_prescribed(n, c))
        os << h + 1 << ", " << c + 1 << ", " << c + 1 << ", "
           << num(mesh.nodes(m, c) - mesh.nodes(n, c)) << "\n";
  }
  // Groups whose final position is prescribed: every member not prescribed itself moves there.
  // (A node outside every suture is its own group: it meets only its own prescription.)
  for (int i = 0; i < N; ++i)
    for (int c = 0; c < 3; ++c)
      if (meets_prescribed(i, c) && std::isnan(prescribed[3 * i + c]))
        os << i + 1 << ", " << c + 1 << ", " << c + 1 << ", "
           << num(group_pos[3 * groups.find(i) + c] - mesh.nodes(i, c)) << "\n";
  if (!mesh.loads.empty()) {
    os << "*CLOAD\n";
    for (const auto& l : mesh.loads)
      for (int c = 0; c < 3; ++c)
        if (l.force_n[c] != 0) os << l.node + 1 << ", " << c + 1 << ", " << num(l.force_n[c]) << "\n";
  }
  os << "*NODE PRINT, NSET=NALL\nU\n*NODE FILE\nU\n*EL FILE\nS\n*END STEP\n";
  return os.str();
}

void write_inp(const Mesh& mesh, const std::filesystem::path& path, const InpOptions& options) {
  write_text_atomic(path, inp_text(mesh, options));
}

}  // namespace caps::fem
