#pragma once
// Test helper: runs CalculiX (Debian calculix-ccx, `ccx`) on the .inp deck of a caps mesh and
// reads the nodal displacements it prints. Shared by the fem test programs.

#include <gtest/gtest.h>

#include <Eigen/Core>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "caps/fem/inp_io.hpp"
#include "caps/fem/mesh_io.hpp"

namespace caps::fem::test {

/// Whether `ccx` is on the PATH.
inline bool has_ccx() { return std::system("command -v ccx > /dev/null 2>&1") == 0; }

/// Runs ccx on the deck of `m` (in a temporary directory named after `name`; kept when
/// CAPS_KEEP_CCX is set) and returns the nodal displacements (#N×3 mm) of the last increment it
/// prints (NaN rows if missing).
inline Eigen::MatrixX3d ccx_displacements(const Mesh& m, const std::string& name,
                                          const InpOptions& options = {}) {
  const auto dir = std::filesystem::temp_directory_path() / ("caps_test_ccx_" + name);
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  write_inp(m, dir / "job.inp", options);
  if (std::getenv("CAPS_KEEP_CCX")) write_mesh_dir(m, dir);
  const std::string cmd = "cd '" + dir.string() + "' && ccx -i job > ccx.log 2>&1";
  EXPECT_EQ(std::system(cmd.c_str()), 0) << "see " << (dir / "ccx.log");
  // job.dat: "displacements (vx,vy,vz) for set NALL ..." then "node ux uy uz" rows, once per
  // printed increment; the last block wins.
  std::ifstream dat(dir / "job.dat");
  std::string line;
  Eigen::MatrixX3d u = Eigen::MatrixX3d::Constant(m.n_nodes(), 3, NAN);
  bool in_block = false;
  while (std::getline(dat, line)) {
    if (line.find("displacements") != std::string::npos) {
      in_block = true;
      continue;
    }
    std::istringstream is(line);
    int id;
    double x, y, z;
    if (in_block && (is >> id >> x >> y >> z) && id >= 1 && id <= m.n_nodes())
      u.row(id - 1) << x, y, z;
  }
  if (!std::getenv("CAPS_KEEP_CCX")) std::filesystem::remove_all(dir);
  return u;
}

}  // namespace caps::fem::test
