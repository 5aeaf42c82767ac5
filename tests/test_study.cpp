// Studies made of closures: measured against constant thickness.
#include <gtest/gtest.h>

#include <cmath>

#include "caps/core/error.hpp"
#include "caps/core/units.hpp"
#include "caps/plan/procedures.hpp"
#include "caps/study/compare.hpp"
#include "cylinder_model.hpp"

using namespace caps;
using namespace caps::closure;
using namespace caps::study;
using caps_test::constant_cylinder;
using caps_test::cylinder;

TEST(Compare, ConstantEqualsMeasuredWhenTheThicknessIsConstant) {
  const auto ellipse = plan::layout_procedure("ellipse", {{"length", 20.0}, {"width", 6.0}});
  SimulateOptions o;
  o.surface.size_mm = 2.0;
  o.surface.extent_mm = 20.0;
  // Thickness 5 mm everywhere: the median under the wound is 5 mm and both sides are one problem.
  const PatientModel flat = constant_cylinder();
  const Comparison same = compare_thickness(flat, plan::place_procedure(ellipse, flat, 0, 0, 90), 0, o);
  EXPECT_NEAR(same.constant_thickness_mm, 5.0, 1e-6);
  EXPECT_NEAR(same.measured_summary.closing_force_n, same.constant_summary.closing_force_n, 1e-9);
  EXPECT_NEAR(same.measured_summary.max_displacement_mm, same.constant_summary.max_displacement_mm, 1e-9);
  EXPECT_GT(same.measured_summary.closing_force_n, 0.0);
  // Thickness varying under the wound (3 to 9 mm across it): the results differ, and the summary
  // reports the measured range.
  const PatientModel varying = cylinder([](double theta, double) { return 6.0 + 3.0 * std::sin(theta * kPi / 180 * 10); });
  const Comparison diff = compare_thickness(varying, plan::place_procedure(ellipse, varying, 0, 0, 90), 0, o);
  EXPECT_LT(diff.measured_summary.thickness_min_mm, diff.constant_thickness_mm);
  EXPECT_GT(diff.measured_summary.thickness_max_mm, diff.constant_thickness_mm);
  EXPECT_GT(std::abs(diff.measured_summary.strain_energy_mj - diff.constant_summary.strain_energy_mj),
            1e-3 * diff.constant_summary.strain_energy_mj);
  EXPECT_EQ(diff.measured_summary.elements, diff.constant_summary.elements);  // the same mesh
  EXPECT_THROW(compare_thickness(flat, plan::place_procedure(ellipse, flat, 0, 0, 90), -1, o), InvalidInput);
}
