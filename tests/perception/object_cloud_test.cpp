#include "perception/object_cloud.h"

#include <limits>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace toolbench::perception {
namespace {

using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

constexpr float kBoardDepth = 1.0f;   // [m]
constexpr float kToolDepth = 0.97f;   // a 3 cm thick tool lying on the board [m]
constexpr double kTol = 1e-4;         // [m]

// A fronto-parallel board at 1 m with a 60x20 px box 3 cm in front of it; camera 1 m above R's
// origin, looking down -z_R.
RgbdFrame BoardWithBox() {
  RgbdFrame frame;
  frame.intrinsics = CameraIntrinsics{640, 480, 500.0, 500.0, 319.5, 239.5};
  frame.rgb = cv::Mat(480, 640, CV_8UC3, cv::Scalar(200, 200, 200));
  frame.depth = cv::Mat(480, 640, CV_32FC1, cv::Scalar(kBoardDepth));
  frame.depth(cv::Rect(300, 200, 60, 20)).setTo(kToolDepth);
  frame.X_RC.linear() = Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()).toRotationMatrix();
  frame.X_RC.translation() = Eigen::Vector3d(0.0, 0.0, 1.0);
  return frame;
}

cv::Mat BoxMask(int grow) {
  cv::Mat mask = cv::Mat::zeros(480, 640, CV_8UC1);
  mask(cv::Rect(300 - grow, 200 - grow, 60 + 2 * grow, 20 + 2 * grow)).setTo(255);
  return mask;
}

TEST(ObjectCloudTest, KeepsTheToolDropsTheBoard) {
  const RgbdFrame frame = BoardWithBox();
  // The mask bleeds 3 px onto the board, as a 2D segmentation does at the edges.
  const ObjectCloud cloud = ExtractObjectCloud(frame, BoxMask(3), ObjectCloudOptions{});
  ASSERT_EQ(cloud.status, CloudStatus::kOk) << cloud.reason;
  EXPECT_EQ(cloud.planes_found, 1);
  EXPECT_EQ(cloud.masked_pixels, 66 * 26);
  EXPECT_EQ(cloud.plane_points, 66 * 26 - 60 * 20);
  EXPECT_EQ(cloud.p_R.cols() + cloud.outlier_points, 60 * 20);
  // Camera at z_R = 1 looking down: the box top is at z_R = 1 - 0.97.
  EXPECT_NEAR(cloud.p_R.row(2).minCoeff(), 1.0 - kToolDepth, kTol);
  EXPECT_NEAR(cloud.p_R.row(2).maxCoeff(), 1.0 - kToolDepth, kTol);
  // Pixel (300, 200) back-projects to x_C = 0.97 (300 - 319.5) / 500; x_R = x_C, y_R = -y_C.
  // The statistical filter may drop the box's corner pixels (fewer neighbours): allow 1 px.
  constexpr double kPixel = kToolDepth / 500.0;
  EXPECT_NEAR(cloud.p_R.row(0).minCoeff(), kToolDepth * (300 - 319.5) / 500.0, kPixel + kTol);
  EXPECT_NEAR(cloud.p_R.row(1).maxCoeff(), -kToolDepth * (200 - 239.5) / 500.0, kPixel + kTol);
  // On a noise-free grid the border pixels are the statistical outliers (fewer neighbours).
  EXPECT_LT(cloud.outlier_points, 60 * 20 / 5);
}

TEST(ObjectCloudTest, ExpectedFailuresAreResults) {
  RgbdFrame frame = BoardWithBox();
  const ObjectCloud empty = ExtractObjectCloud(frame, cv::Mat::zeros(480, 640, CV_8UC1), {});
  EXPECT_EQ(empty.status, CloudStatus::kEmptyMask);
  EXPECT_THAT(empty.reason, HasSubstr("no pixel"));
  EXPECT_EQ(empty.p_R.cols(), 0);

  RgbdFrame zero = BoardWithBox();
  zero.depth.setTo(0.0f);
  const ObjectCloud no_depth = ExtractObjectCloud(zero, BoxMask(0), {});
  EXPECT_EQ(no_depth.status, CloudStatus::kNoDepth);
  EXPECT_THAT(no_depth.reason, HasSubstr("1200 masked pixels"));

  RgbdFrame nan = BoardWithBox();
  nan.depth.setTo(std::numeric_limits<float>::quiet_NaN());
  EXPECT_EQ(ExtractObjectCloud(nan, BoxMask(0), {}).status, CloudStatus::kNoDepth);

  cv::Mat three = cv::Mat::zeros(480, 640, CV_8UC1);
  three(cv::Rect(310, 210, 3, 1)).setTo(255);
  ObjectCloudOptions no_planes;  // else the 3-pixel ROI sees only the box top, a "support"
  no_planes.max_planes = 0;
  const ObjectCloud tiny = ExtractObjectCloud(frame, three, no_planes);
  EXPECT_EQ(tiny.status, CloudStatus::kTooFewPoints);
  EXPECT_THAT(tiny.reason, HasSubstr("3 points left"));
}

TEST(ObjectCloudTest, BadInputThrows) {
  const RgbdFrame frame = BoardWithBox();
  EXPECT_THAT([&] { ExtractObjectCloud(frame, cv::Mat::zeros(10, 10, CV_8UC1), {}); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("mask")));
  RgbdFrame no_depth = frame;
  no_depth.depth = cv::Mat();
  EXPECT_THAT([&] { ExtractObjectCloud(no_depth, BoxMask(0), {}); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("frame.depth")));
  ObjectCloudOptions options;
  options.plane_distance = -1;
  EXPECT_THAT([&] { ExtractObjectCloud(frame, BoxMask(0), options); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("plane_distance = -1")));
}

TEST(ObjectCloudTest, BackProjectMaskIsPinhole) {
  const RgbdFrame frame = BoardWithBox();
  cv::Mat one = cv::Mat::zeros(480, 640, CV_8UC1);
  one.at<unsigned char>(100, 50) = 255;  // row v = 100, column u = 50
  const Eigen::Matrix3Xf p_C = BackProjectMask(frame, one, 0.05, 4.0);
  ASSERT_EQ(p_C.cols(), 1);
  EXPECT_NEAR(p_C(0, 0), kBoardDepth * (50 - 319.5) / 500.0, 1e-6);
  EXPECT_NEAR(p_C(1, 0), kBoardDepth * (100 - 239.5) / 500.0, 1e-6);
  EXPECT_NEAR(p_C(2, 0), kBoardDepth, 1e-6);
}

}  // namespace
}  // namespace toolbench::perception
