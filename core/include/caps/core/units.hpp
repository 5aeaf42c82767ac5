#pragma once
/// @brief Strong unit types for scalars at API boundaries. Kernels unwrap them to double.
///
/// Lengths are millimetres in the patient LPS frame; angles at the API are degrees;
/// CT values are Hounsfield units; fem/ works in mm-N-MPa-s.

namespace caps {

struct Millimetres {
  double value;
};
struct Degrees {
  double value;
};
struct Hounsfield {
  double value;
};
struct Megapascals {
  double value;
};

constexpr Millimetres operator""_mm(long double v) { return {static_cast<double>(v)}; }
constexpr Degrees operator""_deg(long double v) { return {static_cast<double>(v)}; }
constexpr Hounsfield operator""_HU(long double v) { return {static_cast<double>(v)}; }
constexpr Megapascals from_kilopascals(double kpa) { return {kpa * 1e-3}; }

constexpr double kPi = 3.14159265358979323846;
constexpr double deg_to_rad(double deg) { return deg * kPi / 180.0; }
constexpr double rad_to_deg(double rad) { return rad * 180.0 / kPi; }

}  // namespace caps
