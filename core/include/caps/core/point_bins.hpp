#pragma once
/// @brief Points binned in cubic cells of a given size, so that the points within that size of a
/// place are found among its cell and the 26 around it: the neighbour search of the skin's
/// inverse-distance field and the seam blend (surface/feature_lines.hpp), the whole face's tie
/// reach (closure/face_domain.cpp) and the extruder's base normals (mesher).

#include <Eigen/Core>

#include <array>
#include <cmath>
#include <map>
#include <utility>
#include <vector>

namespace caps {

class PointBins {
 public:
  /// Bins the rows of `points` for which keep(row) holds (every row with finite coordinates by
  /// default; rows with a non-finite coordinate are never binned).
  template <class Keep>
  PointBins(Eigen::MatrixX3d points, double size, Keep&& keep)
      : points_(std::move(points)), size_(size) {
    for (Eigen::Index i = 0; i < points_.rows(); ++i)
      if (points_.row(i).allFinite() && keep(i))
        cells_[cell(points_.row(i).transpose())].push_back(i);
  }
  PointBins(Eigen::MatrixX3d points, double size)
      : PointBins(std::move(points), size, [](Eigen::Index) { return true; }) {}

  double size() const { return size_; }
  const Eigen::MatrixX3d& points() const { return points_; }

  /// f(row, squared distance to x) for every binned point in x's cell and the 26 around it (all
  /// those within size() of x, and some farther), cell by cell in a fixed order.
  template <class F>
  void near(const Eigen::Vector3d& x, F&& f) const {
    const std::array<long, 3> c = cell(x);
    for (long i = -1; i <= 1; ++i)
      for (long j = -1; j <= 1; ++j)
        for (long k = -1; k <= 1; ++k) {
          const auto it = cells_.find({c[0] + i, c[1] + j, c[2] + k});
          if (it == cells_.end()) continue;
          for (Eigen::Index n : it->second) f(n, (points_.row(n).transpose() - x).squaredNorm());
        }
  }

 private:
  std::array<long, 3> cell(const Eigen::Vector3d& x) const {
    return {static_cast<long>(std::floor(x.x() / size_)),
            static_cast<long>(std::floor(x.y() / size_)),
            static_cast<long>(std::floor(x.z() / size_))};
  }
  Eigen::MatrixX3d points_;
  double size_;
  std::map<std::array<long, 3>, std::vector<Eigen::Index>> cells_;
};

}  // namespace caps
