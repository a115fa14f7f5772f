#include "perception/ball.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "common/rng.h"

namespace toolbench::perception {
namespace {

/// A 320x240 frame looking at a ball of radius r centred at c_C (camera frame)
/// in front of a grey wall at 1.2 m, with Gaussian depth noise of sigma [m].
RgbdFrame SphereFrame(const Eigen::Vector3d& c_C, double r, double sigma, std::uint64_t seed,
                      const cv::Vec3b& colour = {230, 25, 25}) {
  RgbdFrame frame;
  frame.intrinsics = {320, 240, 260.0, 260.0, 159.5, 119.5};
  frame.rgb = cv::Mat(240, 320, CV_8UC3, cv::Scalar(120, 120, 120));
  frame.depth = cv::Mat(240, 320, CV_32FC1, cv::Scalar(1.2f));
  Rng rng(seed);
  for (int v = 0; v < 240; ++v) {
    for (int u = 0; u < 320; ++u) {
      const Eigen::Vector3d ray = Eigen::Vector3d((u - 159.5) / 260.0, (v - 119.5) / 260.0, 1.0);
      // |t ray - c|^2 = r^2, nearest root; depth is t (z of the ray is 1).
      const double a = ray.squaredNorm(), b = -2 * ray.dot(c_C), cc = c_C.squaredNorm() - r * r;
      const double disc = b * b - 4 * a * cc;
      if (disc < 0) continue;
      const double t = (-b - std::sqrt(disc)) / (2 * a);
      frame.depth.at<float>(v, u) = static_cast<float>(t + sigma * StandardNormal(rng));
      frame.rgb.at<cv::Vec3b>(v, u) = colour;
    }
  }
  return frame;
}

TEST(BallTest, FitSphereRecoversACapExactly) {
  const Eigen::Vector3d c(0.1, -0.2, 0.8);
  Eigen::Matrix3Xd p(3, 200);
  Rng rng(3);
  for (int i = 0; i < 200; ++i) {
    // Points on the half facing -z only (what a camera sees).
    Eigen::Vector3d d(StandardNormal(rng), StandardNormal(rng), -std::fabs(StandardNormal(rng)));
    p.col(i) = c + 0.035 * d.normalized();
  }
  Eigen::Vector3d center;
  double radius = 0, rms = 0;
  ASSERT_TRUE(FitSphere(p, center, radius, rms));
  EXPECT_LT((center - c).norm(), 1e-6);
  EXPECT_NEAR(radius, 0.035, 1e-6);
  EXPECT_LT(rms, 1e-6);
}

TEST(BallTest, FitSphereRejectsDegeneratePoints) {
  Eigen::Vector3d center;
  double radius = 0, rms = 0;
  EXPECT_FALSE(FitSphere(Eigen::Matrix3Xd::Random(3, 3), center, radius, rms));
  Eigen::Matrix3Xd plane = Eigen::Matrix3Xd::Random(3, 50);
  plane.row(2).setZero();
  EXPECT_FALSE(FitSphere(plane, center, radius, rms));
}

TEST(BallTest, DetectsTheBallInANoisyFrameAndMovesItToTheRootFrame) {
  const Eigen::Vector3d c_C(0.05, 0.02, 0.7);
  RgbdFrame frame = SphereFrame(c_C, 0.035, 0.001, 7);
  frame.X_RC = Eigen::Translation3d(0.1, 0.2, 0.3) * Eigen::AngleAxisd(0.5, Eigen::Vector3d::UnitY());
  const BallDetection ball = DetectBall(frame, {});
  ASSERT_EQ(ball.status, BallStatus::kFound) << ball.reason;
  EXPECT_LT((ball.p_RB - frame.X_RC * c_C).norm(), 0.003);
  EXPECT_NEAR(ball.radius, 0.035, 0.004);
  EXPECT_GT(ball.points, 100);
}

TEST(BallTest, ABallTouchingARodOfTheSameColourIsStillFound) {
  const Eigen::Vector3d c_C(0.0, 0.0, 0.7);
  RgbdFrame frame = SphereFrame(c_C, 0.035, 0.0005, 3);
  // A red rod lying against the ball, 2 cm thick, from its side to the image edge.
  for (int v = 112; v < 128; ++v) {
    for (int u = 0; u < 150; ++u) {
      frame.rgb.at<cv::Vec3b>(v, u) = {230, 25, 25};
      frame.depth.at<float>(v, u) = 0.72f;
    }
  }
  const BallDetection ball = DetectBall(frame, {});
  ASSERT_EQ(ball.status, BallStatus::kFound) << ball.reason;
  EXPECT_LT((ball.p_RB - c_C).norm(), 0.003);
}

TEST(BallTest, WrongColourOrWrongSizeIsReportedWithAReason) {
  const BallDetection green = DetectBall(SphereFrame({0, 0, 0.7}, 0.035, 0.0, 1, {25, 230, 25}), {});
  EXPECT_EQ(green.status, BallStatus::kNotSeen);
  EXPECT_FALSE(green.reason.empty());
  const BallDetection big = DetectBall(SphereFrame({0, 0, 0.9}, 0.10, 0.0, 1), {});
  EXPECT_EQ(big.status, BallStatus::kNoSphere);
  EXPECT_NE(big.reason.find("radius"), std::string::npos) << big.reason;
}

TEST(BallTest, NaNDepthAndBadFramesDoNotCrash) {
  RgbdFrame frame = SphereFrame({0, 0, 0.7}, 0.035, 0.0, 1);
  frame.depth.setTo(std::numeric_limits<float>::quiet_NaN());
  const BallDetection none = DetectBall(frame, {});
  EXPECT_NE(none.status, BallStatus::kFound);
  RgbdFrame empty;
  EXPECT_THROW(DetectBall(empty, {}), std::invalid_argument);
  BallDetectionOptions bad;
  bad.expected_radius = -1;
  EXPECT_THROW(DetectBall(frame, bad), std::invalid_argument);
}

}  // namespace
}  // namespace toolbench::perception
