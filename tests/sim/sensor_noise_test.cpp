#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "sim/renderer.h"

namespace toolbench::sim {
namespace {

using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

CameraIntrinsics Intrinsics() {
  CameraIntrinsics K;
  K.width = 160;
  K.height = 120;
  K.fx = K.fy = 108;
  K.cx = 79.5;
  K.cy = 59.5;
  return K;
}

TEST(SensorNoiseTest, PlaneNoiseMatchesTheRmsModel) {
  const CameraIntrinsics K = Intrinsics();
  cv::Mat rgb(K.height, K.width, CV_8UC3, cv::Scalar(100, 100, 100));
  cv::Mat depth(K.height, K.width, CV_32FC1, cv::Scalar(1.0f));
  DepthNoiseOptions options;
  options.quantization = 0.0;
  ApplySensorNoise(rgb, depth, K, options, 42);
  cv::Scalar mean, stddev;
  cv::meanStdDev(depth, mean, stddev, depth > 0);
  const double expected = 1.0 * options.subpixel_rms / (K.fx * options.baseline);  // z^2 s / (f B)
  EXPECT_NEAR(mean[0], 1.0, 3 * expected / std::sqrt(depth.total()) + 1e-6);
  EXPECT_NEAR(stddev[0], expected, 0.1 * expected);
}

TEST(SensorNoiseTest, SameSeedSameImagesOtherSeedOtherImages) {
  const CameraIntrinsics K = Intrinsics();
  auto run = [&](std::uint64_t seed) {
    cv::Mat rgb(K.height, K.width, CV_8UC3, cv::Scalar(100, 100, 100));
    cv::Mat depth(K.height, K.width, CV_32FC1, cv::Scalar(0.8f));
    ApplySensorNoise(rgb, depth, K, {}, seed);
    return depth;
  };
  EXPECT_EQ(cv::norm(run(1), run(1), cv::NORM_INF), 0.0);
  EXPECT_GT(cv::norm(run(1), run(2), cv::NORM_INF), 0.0);
}

TEST(SensorNoiseTest, DropsOutOfRangeAndFarSideOfEdges) {
  const CameraIntrinsics K = Intrinsics();
  cv::Mat rgb(K.height, K.width, CV_8UC3, cv::Scalar(0, 0, 0));
  cv::Mat depth(K.height, K.width, CV_32FC1, cv::Scalar(1.0f));
  depth(cv::Rect(0, 0, 80, 120)).setTo(0.5f);  // near half: an occlusion edge at column 80
  depth.at<float>(5, 5) = 0.1f;                // closer than Min-Z
  DepthNoiseOptions options;
  options.edge_dropout = 1.0;
  ApplySensorNoise(rgb, depth, K, options, 3);
  EXPECT_EQ(depth.at<float>(5, 5), 0.0f);
  EXPECT_EQ(depth.at<float>(60, 80), 0.0f);   // far side of the edge
  EXPECT_GT(depth.at<float>(60, 79), 0.0f);   // near side kept
}

TEST(SensorNoiseTest, RejectsBadOptionsAndImages) {
  const CameraIntrinsics K = Intrinsics();
  cv::Mat rgb(K.height, K.width, CV_8UC3);
  cv::Mat depth(K.height, K.width, CV_32FC1, cv::Scalar(1.0f));
  DepthNoiseOptions bad;
  bad.baseline = 0;
  EXPECT_THAT([&] { ApplySensorNoise(rgb, depth, K, bad, 1); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("baseline")));
  cv::Mat wrong(10, 10, CV_32FC1);
  EXPECT_THAT([&] { ApplySensorNoise(rgb, wrong, K, {}, 1); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("one size")));
}

}  // namespace
}  // namespace toolbench::sim
