// Distance transforms, components and hole filling against brute-force references.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "caps/core/error.hpp"
#include "caps/volume/distance_field.hpp"
#include "caps/volume/isosurface.hpp"
#include "caps/volume/morphology.hpp"
#include "caps/volume/segment.hpp"

using namespace caps;

namespace {

Mask random_mask(Eigen::Vector3i dims, double fill, unsigned seed) {
  Mask m;
  m.geom.dims = dims;
  m.geom.spacing_mm = {0.7, 1.3, 2.1};  // anisotropic on purpose
  m.data.resize(m.geom.n_voxels());
  std::mt19937 rng(seed);
  std::bernoulli_distribution on(fill);
  for (auto& v : m.data) v = on(rng);
  return m;
}

Eigen::Vector3d centre(const VolumeGeometry& g, std::size_t idx) {
  const int i = static_cast<int>(idx % g.dims[0]);
  const int j = static_cast<int>((idx / g.dims[0]) % g.dims[1]);
  const int k = static_cast<int>(idx / (std::size_t(g.dims[0]) * g.dims[1]));
  return g.spacing_mm.cwiseProduct(Eigen::Vector3d(i, j, k));
}

}  // namespace

TEST(Morphology, DistanceTransformIsExactWithFeatures) {
  // 37 x 21 x 19: not a multiple of the 16-line blocks; sparse sites.
  const Mask sites = random_mask({37, 21, 19}, 0.004, 7);
  ASSERT_GT(sites.count(), 10u);
  std::vector<std::int64_t> nearest;
  const auto d2 = squared_distance_mm2(sites, &nearest);
  std::vector<std::size_t> site_idx;
  for (std::size_t i = 0; i < sites.data.size(); ++i)
    if (sites.data[i]) site_idx.push_back(i);
  for (std::size_t x = 0; x < sites.data.size(); x += 3) {
    double best = 1e300;
    for (auto s : site_idx) best = std::min(best, (centre(sites.geom, x) - centre(sites.geom, s)).squaredNorm());
    ASSERT_NEAR(d2[x], best, 1e-3 * std::max(1.0, best)) << "voxel " << x;
    // The feature is a site at that distance (ties may pick either).
    ASSERT_GE(nearest[x], 0);
    EXPECT_TRUE(sites.data[nearest[x]]);
    EXPECT_NEAR((centre(sites.geom, x) - centre(sites.geom, nearest[x])).squaredNorm(), best,
                1e-3 * std::max(1.0, best));
  }
}

TEST(Morphology, NoSitesGivesFar) {
  Mask empty = random_mask({5, 6, 7}, 0.0, 1);
  std::vector<std::int64_t> nearest;
  const auto d2 = squared_distance_mm2(empty, &nearest);
  for (std::size_t i = 0; i < d2.size(); ++i) {
    EXPECT_GE(d2[i], kFar);
    EXPECT_EQ(nearest[i], -1);
  }
}

TEST(Morphology, ErodeAndDilateABall) {
  Mask m;
  m.geom.dims = {41, 41, 41};
  m.geom.spacing_mm = {1, 1, 1};
  m.data.assign(m.geom.n_voxels(), 0);
  for (int k = 0; k < 41; ++k)
    for (int j = 0; j < 41; ++j)
      for (int i = 0; i < 41; ++i)
        m.data[m.geom.linear(i, j, k)] = std::hypot(i - 20, j - 20, k - 20) <= 12.0;
  const Mask e = erode(m, 4.0), d = dilate(m, 4.0);
  // Eroded: a ball of radius about 8 (voxel-exact distances to the background's centres).
  EXPECT_TRUE(e.at(20, 20, 20));
  EXPECT_TRUE(e.at(20, 20, 28));
  EXPECT_FALSE(e.at(20, 20, 30));
  EXPECT_TRUE(d.at(20, 20, 36));
  EXPECT_FALSE(d.at(20, 20, 37));
  EXPECT_LT(e.count(), m.count());
  EXPECT_GT(d.count(), m.count());
}

TEST(Morphology, ComponentsAreSortedBySize) {
  const Mask m = random_mask({30, 25, 20}, 0.3, 11);
  std::vector<std::int64_t> sizes;
  const auto labels = label_components(m, sizes);
  // Reference: flood fill from every voxel.
  std::vector<int> ref(m.data.size(), 0);
  std::vector<std::int64_t> ref_sizes;
  const auto& g = m.geom;
  for (std::size_t s = 0; s < m.data.size(); ++s) {
    if (!m.data[s] || ref[s]) continue;
    const int id = static_cast<int>(ref_sizes.size()) + 1;
    std::vector<std::size_t> stack{s};
    ref[s] = id;
    std::int64_t n = 0;
    while (!stack.empty()) {
      const std::size_t x = stack.back();
      stack.pop_back();
      ++n;
      const int i = x % g.dims[0], j = (x / g.dims[0]) % g.dims[1], k = x / (g.dims[0] * g.dims[1]);
      const int nb[6][3] = {{-1, 0, 0}, {1, 0, 0}, {0, -1, 0}, {0, 1, 0}, {0, 0, -1}, {0, 0, 1}};
      for (const auto& o : nb) {
        if (!g.contains(i + o[0], j + o[1], k + o[2])) continue;
        const std::size_t y = g.linear(i + o[0], j + o[1], k + o[2]);
        if (m.data[y] && !ref[y]) { ref[y] = id; stack.push_back(y); }
      }
    }
    ref_sizes.push_back(n);
  }
  ASSERT_EQ(sizes.size(), ref_sizes.size() + 1);
  for (std::size_t l = 2; l < sizes.size(); ++l) EXPECT_LE(sizes[l], sizes[l - 1]);
  // Same partition: voxels share a label exactly when they share a reference component.
  std::vector<int> map(sizes.size(), 0);
  for (std::size_t x = 0; x < m.data.size(); ++x) {
    ASSERT_EQ(labels[x] == 0, ref[x] == 0);
    if (!ref[x]) continue;
    if (map[labels[x]] == 0) map[labels[x]] = ref[x];
    ASSERT_EQ(map[labels[x]], ref[x]);
    EXPECT_EQ(sizes[labels[x]], ref_sizes[ref[x] - 1]);
  }
}

TEST(Morphology, FillsEnclosedAirOnly) {
  // A hollow box with a hole in its top face: fill_enclosed_3d leaves it (open), the slice fill
  // closes it (each k-slice is a closed ring), and a closed cavity is filled in 3-D.
  Mask m;
  m.geom.dims = {20, 20, 20};
  m.data.assign(m.geom.n_voxels(), 0);
  for (int k = 3; k <= 16; ++k)
    for (int j = 3; j <= 16; ++j)
      for (int i = 3; i <= 16; ++i) {
        const bool wall = i == 3 || i == 16 || j == 3 || j == 16 || k == 3 || k == 16;
        m.data[m.geom.linear(i, j, k)] = wall;
      }
  m.data[m.geom.linear(10, 10, 16)] = 0;  // a hole in the top
  Mask open = m;
  fill_enclosed_3d(open);
  EXPECT_FALSE(open.at(10, 10, 10));
  Mask sliced = m;
  fill_enclosed_slices(sliced, 2);
  EXPECT_TRUE(sliced.at(10, 10, 10));
  m.data[m.geom.linear(10, 10, 16)] = 1;  // closed
  fill_enclosed_3d(m);
  EXPECT_TRUE(m.at(10, 10, 10));
  EXPECT_FALSE(m.at(1, 1, 1));
}

TEST(Segmentation, OtsuSplitsTwoClasses) {
  Volume v;
  v.geom.dims = {100, 10, 1};
  v.data.resize(1000);
  for (int i = 0; i < 1000; ++i) v.data[i] = (i % 100) < 60 ? 10.0f + (i % 7) : 200.0f + (i % 5);
  const double t = otsu_threshold(v);
  EXPECT_GT(t, 16.0);
  EXPECT_LT(t, 200.0);
}

TEST(Morphology, SmallRadiusStencilMatchesDefinition) {
  // Radii within two voxels use a digital-ball stencil; it must equal the definition: dilation =
  // within r of a set voxel; erosion = set and farther than r from every unset voxel (the
  // outside of the grid counting as unset).
  const Mask m = random_mask({23, 17, 13}, 0.5, 5);
  const double r = 1.5;  // spacing 0.7, 1.3, 2.1: reaches 2, 1, 0 voxels
  const Mask d = dilate(m, r), e = erode(m, r);
  const auto& g = m.geom;
  for (int k = 0; k < g.dims[2]; ++k)
    for (int j = 0; j < g.dims[1]; ++j)
      for (int i = 0; i < g.dims[0]; ++i) {
        bool near_set = false, near_unset = false;
        for (int c = -3; c <= 3; ++c)
          for (int b = -3; b <= 3; ++b)
            for (int a = -3; a <= 3; ++a) {
              if (g.spacing_mm.cwiseProduct(Eigen::Vector3d(a, b, c)).norm() > r) continue;
              const bool inside = g.contains(i + a, j + b, k + c);
              const bool set = inside && m.at(i + a, j + b, k + c);
              near_set |= set;
              near_unset |= !set;
            }
        ASSERT_EQ(d.at(i, j, k) != 0, near_set) << i << " " << j << " " << k;
        ASSERT_EQ(e.at(i, j, k) != 0, m.at(i, j, k) && !near_unset) << i << " " << j << " " << k;
      }
}

TEST(DistanceField, SphereDistancesAreExactInTheBand) {
  // A sphere of radius 20 mm about c, as a marching-cubes mesh of its analytic distance (1 mm
  // voxels: the facets lie within h^2 / (8 r) = 0.006 mm of the sphere).
  const Eigen::Vector3d c(31.0, 32.0, 30.5);
  Volume f;
  f.geom.dims = {64, 64, 64};
  f.geom.spacing_mm = {1, 1, 1};
  f.data.resize(f.geom.n_voxels());
  for (int k = 0; k < 64; ++k)
    for (int j = 0; j < 64; ++j)
      for (int i = 0; i < 64; ++i)
        f.at(i, j, k) = static_cast<float>(20.0 - (Eigen::Vector3d(i, j, k) - c).norm());
  const TriMesh sphere = extract_isosurface(f, 0.0f);
  const SignedDistanceField sdf = SignedDistanceField::from_mesh(sphere, 0.5, 12.0, 3.0);
  EXPECT_DOUBLE_EQ(sdf.voxel_mm(), 0.5);
  EXPECT_GT(sdf.n_active_voxels(), 100000u);
  for (double r : {17.5, 19.0, 20.0, 21.3, 25.0, 31.0}) {
    for (const Eigen::Vector3d d : {Eigen::Vector3d(1, 0, 0), Eigen::Vector3d(0, -0.6, 0.8),
                                    Eigen::Vector3d(0.48, 0.6, -0.64)}) {
      const Eigen::Vector3d p = c + r * d;
      // Trilinear between voxels of exact distances: within a few hundredths of a millimetre.
      EXPECT_NEAR(sdf(p), r - 20.0, 0.05) << "r " << r;
      if (r > 18.0) EXPECT_NEAR(sdf.gradient(p).dot(d), 1.0, 0.05) << "r " << r;
    }
  }
  // Outside the band: the band's value.
  EXPECT_NEAR(sdf(c + Eigen::Vector3d(40, 0, 0)), 12.0, 1e-3);
  EXPECT_NEAR(sdf(c), -3.0, 1e-3);
  EXPECT_THROW(SignedDistanceField::from_mesh(TriMesh{}, 1.0, 3.0, 3.0), InvalidInput);
}
