#include "common/geometry.h"

#include <gtest/gtest.h>

namespace toolbench {
namespace {

constexpr double kTol = 1e-12;

TEST(GeometryTest, RpyRoundTrip) {
  const Eigen::Vector3d rpy(0.3, -0.7, 2.1);
  EXPECT_TRUE(RpyFromRotation(RotationFromRpy(rpy)).isApprox(rpy, kTol));
}

TEST(GeometryTest, RpyIsFixedAxisRollPitchYaw) {
  // URDF: R = Rz(yaw) Ry(pitch) Rx(roll); a pure yaw of 90 deg maps x to y.
  const Eigen::Matrix3d R = RotationFromRpy(Eigen::Vector3d(0, 0, M_PI / 2));
  EXPECT_TRUE((R * Eigen::Vector3d::UnitX()).isApprox(Eigen::Vector3d::UnitY(), kTol));
}

TEST(GeometryTest, RotationAngleBetween) {
  const Eigen::Matrix3d A = AxisAngle(Eigen::Vector3d(1, 2, 3), 0.4);
  const Eigen::Matrix3d B = A * AxisAngle(Eigen::Vector3d(0, 1, 0), 0.25);
  EXPECT_NEAR(RotationAngleBetween(A, B), 0.25, 1e-9);
}

}  // namespace
}  // namespace toolbench
