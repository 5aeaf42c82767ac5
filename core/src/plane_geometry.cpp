#include "caps/core/plane_geometry.hpp"

#include <algorithm>
#include <cmath>

namespace caps {

bool point_in_polygon(const std::vector<Eigen::Vector2d>& poly, const Eigen::Vector2d& p) {
  bool in = false;
  for (std::size_t i = 0, j = poly.size() - 1; i < poly.size(); j = i++) {
    const Eigen::Vector2d& a = poly[i];
    const Eigen::Vector2d& b = poly[j];
    if ((a.y() > p.y()) != (b.y() > p.y()) &&
        p.x() < (b.x() - a.x()) * (p.y() - a.y()) / (b.y() - a.y()) + a.x())
      in = !in;
  }
  return in;
}

bool point_in_or_on_polygon(const std::vector<Eigen::Vector2d>& poly, const Eigen::Vector2d& p) {
  double scale = 0;
  for (const auto& v : poly) scale = std::max(scale, (v - poly[0]).norm());
  const double tol = 1e-9 * std::max(scale, 1.0);
  for (std::size_t i = 0, j = poly.size() - 1; i < poly.size(); j = i++) {
    const Eigen::Vector2d a = poly[j], b = poly[i];
    const double L2 = (b - a).squaredNorm();
    const double t = L2 > 0 ? std::clamp((p - a).dot(b - a) / L2, 0.0, 1.0) : 0.0;
    if ((a + t * (b - a) - p).norm() <= tol) return true;
  }
  return point_in_polygon(poly, p);
}

double signed_area(const std::vector<Eigen::Vector2d>& poly) {
  double area2 = 0;
  for (std::size_t i = 0; i < poly.size(); ++i) {
    const Eigen::Vector2d &p = poly[i], &n = poly[(i + 1) % poly.size()];
    area2 += p.x() * n.y() - p.y() * n.x();
  }
  return area2 / 2;
}

Eigen::Vector2d area_centroid(const std::vector<Eigen::Vector2d>& poly) {
  double area2 = 0;
  Eigen::Vector2d c = Eigen::Vector2d::Zero();
  for (std::size_t i = 0; i < poly.size(); ++i) {
    const Eigen::Vector2d &p = poly[i], &n = poly[(i + 1) % poly.size()];
    const double cross = p.x() * n.y() - p.y() * n.x();
    area2 += cross;
    c += cross * (p + n);
  }
  if (std::abs(area2) >= 1e-12) return c / (3 * area2);
  c.setZero();
  for (const auto& p : poly) c += p;
  return poly.empty() ? c : Eigen::Vector2d(c / static_cast<double>(poly.size()));
}

double wrap_degrees(double deg) { return deg - 360.0 * std::floor((deg + 180.0) / 360.0); }

}  // namespace caps
