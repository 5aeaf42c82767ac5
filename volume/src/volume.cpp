#include "caps/volume/volume.hpp"

#include <cmath>

#include "caps/core/error.hpp"

namespace caps {

const char* to_string(Modality m) {
  switch (m) {
    case Modality::CT: return "CT";
    case Modality::MR: return "MR";
    default: return "unknown";
  }
}

std::size_t Mask::count() const {
  std::size_t n = 0;
  for (auto v : data) n += v != 0;
  return n;
}

float sample_trilinear(const Volume& v, const Eigen::Vector3d& ijk, float outside) {
  const auto& d = v.geom.dims;
  const double x = ijk[0], y = ijk[1], z = ijk[2];
  if (!(x >= 0 && y >= 0 && z >= 0 && x <= d[0] - 1 && y <= d[1] - 1 && z <= d[2] - 1))
    return outside;
  const int i = std::min(static_cast<int>(x), d[0] - 2 < 0 ? 0 : d[0] - 2);
  const int j = std::min(static_cast<int>(y), d[1] - 2 < 0 ? 0 : d[1] - 2);
  const int k = std::min(static_cast<int>(z), d[2] - 2 < 0 ? 0 : d[2] - 2);
  const double fx = x - i, fy = y - j, fz = z - k;
  const int i1 = std::min(i + 1, d[0] - 1), j1 = std::min(j + 1, d[1] - 1),
            k1 = std::min(k + 1, d[2] - 1);
  auto L = [&](int a, int b, int c) { return static_cast<double>(v.data[v.geom.linear(a, b, c)]); };
  const double c00 = L(i, j, k) * (1 - fx) + L(i1, j, k) * fx;
  const double c10 = L(i, j1, k) * (1 - fx) + L(i1, j1, k) * fx;
  const double c01 = L(i, j, k1) * (1 - fx) + L(i1, j, k1) * fx;
  const double c11 = L(i, j1, k1) * (1 - fx) + L(i1, j1, k1) * fx;
  const double c0 = c00 * (1 - fy) + c10 * fy;
  const double c1 = c01 * (1 - fy) + c11 * fy;
  return static_cast<float>(c0 * (1 - fz) + c1 * fz);
}

bool near_data_edge(const Volume& v, const Eigen::Vector3d& p_lps, double margin_voxels) {
  const Eigen::Vector3d q = v.lps_to_index(p_lps);
  const auto& d = v.geom.dims;
  for (int a = 0; a < 3; ++a)
    if (d[a] > 1 && (q[a] < margin_voxels || q[a] > d[a] - 1 - margin_voxels)) return true;
  if (v.acquired.empty()) return false;
  const int m = static_cast<int>(std::ceil(margin_voxels));
  const Eigen::Vector3i c = q.array().round().cast<int>();
  for (int dk = -m; dk <= m; ++dk)
    for (int dj = -m; dj <= m; ++dj)
      for (int di = -m; di <= m; ++di) {
        const int i = c[0] + di, j = c[1] + dj, k = c[2] + dk;
        if (v.geom.contains(i, j, k) && !v.acquired[v.geom.linear(i, j, k)]) return true;
      }
  return false;
}

void validate_volume(const Volume& v) {
  const auto& g = v.geom;
  if (g.dims.minCoeff() <= 0)
    throw InvalidInput(cat(v.source, ": image dimensions (", g.dims.transpose(),
                           ") must all be positive; the file header is damaged or not an image"));
  constexpr double kMaxDim = 8192;
  if (g.dims.cast<double>().maxCoeff() > kMaxDim)
    throw InvalidInput(cat(v.source, ": image dimensions (", g.dims.transpose(),
                           ") are larger than caps accepts (", kMaxDim,
                           " per axis); the header is probably damaged"));
  if (!(g.spacing_mm.minCoeff() > 0.0) || !g.spacing_mm.allFinite() ||
      g.spacing_mm.maxCoeff() > 100.0)
    throw InvalidInput(cat(v.source, ": voxel spacing (", g.spacing_mm.transpose(),
                           ") mm must be positive and below 100 mm; check PixelSpacing / "
                           "SliceThickness or the header's spacing fields"));
  if (!g.direction.allFinite() || std::abs(g.direction.determinant()) < 1e-6)
    throw InvalidInput(cat(v.source, ": the direction cosines are singular or not finite; "
                           "the orientation fields of the header are damaged"));
  if (!g.origin_lps.allFinite())
    throw InvalidInput(cat(v.source, ": the image origin is not finite"));
  if (!v.acquired.empty() && v.acquired.size() != v.data.size())
    throw InvalidInput(cat(v.source, ": internal: the acquired-data mask does not match the image"));
  if (v.data.size() != g.n_voxels())
    throw InvalidInput(cat(v.source, ": holds ", v.data.size(), " voxels but its header says ",
                           g.dims[0], "x", g.dims[1], "x", g.dims[2], " = ", g.n_voxels()));
  for (std::size_t n = 0; n < v.data.size(); ++n)
    if (!std::isfinite(v.data[n])) {
      const int i = static_cast<int>(n % g.dims[0]);
      const int j = static_cast<int>((n / g.dims[0]) % g.dims[1]);
      const int k = static_cast<int>(n / (static_cast<std::size_t>(g.dims[0]) * g.dims[1]));
      throw InvalidInput(cat(v.source, ": voxel (", i, ", ", j, ", ", k,
                             ") is not a finite number; the data are damaged"));
    }
}

}  // namespace caps
