#include "caps/volume/map_nrrd.hpp"

#include <fstream>
#include <sstream>

#include "caps/core/atomic_output.hpp"
#include "caps/core/error.hpp"

namespace fs = std::filesystem;

namespace caps {

void write_map_nrrd(const fs::path& path, const std::vector<float>& values, const CylinderGrid& g,
                    const std::string& content, const std::string& unit) {
  CAPS_ASSERT(values.size() == g.size(), "map size does not match its grid");
  std::ostringstream h;
  h.precision(10);
  h << "NRRD0004\n"
    << "# caps patient model, format 1: a map over (theta, z) of the cylindrical model\n"
    << "# values in " << unit << "; theta = 0 at the front, +90 at the patient's left\n"
    << "content: " << content << "\n"
    << "type: float\n"
    << "dimension: 2\n"
    << "sizes: " << g.n_theta << " " << g.n_z << "\n"
    << "spacings: " << g.dtheta_deg() << " " << g.dz_mm << "\n"
    << "axis mins: " << g.theta0_deg << " " << g.z0_mm << "\n"
    << "centers: node node\n"
    << "kinds: domain domain\n"
    << "labels: \"theta\" \"z\"\n"
    << "units: \"deg\" \"mm\"\n"
    << "endian: little\n"
    << "encoding: raw\n\n";
  write_file_atomic(path, [&](const fs::path& tmp) {
    std::ofstream out(tmp, std::ios::binary);
    const std::string header = h.str();
    out.write(header.data(), static_cast<std::streamsize>(header.size()));
    out.write(reinterpret_cast<const char*>(values.data()),
              static_cast<std::streamsize>(values.size() * sizeof(float)));
    out.close();
    if (!out) throw IoError(cat(path.string(), ": write failed (disk full?)"));
  });
}

std::vector<float> read_map_nrrd(const fs::path& path, const CylinderGrid& g) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw IoError(cat(path.string(), ": cannot open the map"));
  std::string line;
  std::getline(in, line);
  if (line.rfind("NRRD", 0) != 0) throw InvalidInput(cat(path.string(), ": not a NRRD file"));
  int n0 = -1, n1 = -1;
  while (std::getline(in, line) && !line.empty()) {
    if (line.rfind("sizes:", 0) == 0) std::istringstream(line.substr(6)) >> n0 >> n1;
    if (line.rfind("type:", 0) == 0 && line.find("float") == std::string::npos)
      throw InvalidInput(cat(path.string(), ": expected float data, found '", line, "'"));
    if (line.rfind("encoding:", 0) == 0 && line.find("raw") == std::string::npos)
      throw InvalidInput(cat(path.string(), ": expected raw encoding, found '", line, "'"));
  }
  if (n0 != g.n_theta || n1 != g.n_z)
    throw InvalidInput(cat(path.string(), ": map is ", n0, " x ", n1, " but model.json says ",
                           g.n_theta, " x ", g.n_z));
  std::vector<float> v(g.size());
  in.read(reinterpret_cast<char*>(v.data()), static_cast<std::streamsize>(v.size() * sizeof(float)));
  if (!in) throw IoError(cat(path.string(), ": the map's data are truncated"));
  return v;
}

}  // namespace caps
