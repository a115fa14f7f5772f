#include "perception/segmentation.h"

#include <algorithm>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace toolbench::perception {
namespace {

using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

// Colours (RGB) as in the rendered scenes: saturated tools on a light grey board.
const cv::Scalar kBoard(190, 190, 190);
const cv::Scalar kShadow(110, 110, 110);
const cv::Scalar kTable(120, 75, 40);
const cv::Scalar kRed(210, 30, 30);
const cv::Scalar kBlue(30, 60, 210);
const cv::Scalar kGreen(40, 180, 40);
const cv::Scalar kPurple(140, 40, 170);

void Paint(RgbdFrame& frame, const cv::Rect& r, const cv::Scalar& colour, float depth) {
  frame.rgb(r).setTo(colour);
  frame.depth(r).setTo(depth);
}

// Board at 1 m with a shadow, a table strip, and three hard cases:
//  A: red and blue bars touching end to end (hue split),
//  B: two red bars touching side by side at different heights (depth split),
//  C: a green bar crossed by a nearer purple bar (occlusion: one green tool, two pieces).
RgbdFrame HardScene() {
  RgbdFrame frame;
  frame.intrinsics = CameraIntrinsics{640, 480, 500.0, 500.0, 319.5, 239.5};
  frame.rgb = cv::Mat(480, 640, CV_8UC3, kBoard);
  frame.depth = cv::Mat(480, 640, CV_32FC1, cv::Scalar(1.0f));
  Paint(frame, cv::Rect(100, 50, 100, 100), kShadow, 1.0f);
  Paint(frame, cv::Rect(0, 380, 640, 100), kTable, 0.9f);
  Paint(frame, cv::Rect(50, 200, 200, 15), kRed, 0.98f);     // A
  Paint(frame, cv::Rect(250, 200, 150, 15), kBlue, 0.98f);   // A
  Paint(frame, cv::Rect(420, 60, 180, 15), kRed, 0.98f);     // B, lower
  Paint(frame, cv::Rect(420, 75, 180, 15), kRed, 0.95f);     // B, upper
  Paint(frame, cv::Rect(100, 300, 250, 15), kGreen, 0.98f);  // C
  Paint(frame, cv::Rect(200, 260, 15, 100), kPurple, 0.94f);  // C, occluder
  return frame;
}

const ToolSegment* Containing(const std::vector<ToolSegment>& segments, cv::Point p) {
  for (const ToolSegment& s : segments) {
    if (s.mask.at<unsigned char>(p) != 0) return &s;
  }
  return nullptr;
}

TEST(SegmentationTest, SplitsTouchingToolsAndMergesOccludedOnes) {
  const RgbdFrame frame = HardScene();
  const std::vector<ToolSegment> segments = SegmentTools(frame, SegmentationOptions{});
  ASSERT_EQ(segments.size(), 6u);
  for (const ToolSegment& s : segments) {
    EXPECT_EQ(s.mask.type(), CV_8UC1);
    EXPECT_EQ(s.mask.size(), frame.rgb.size());
    EXPECT_EQ(s.area_px, cv::countNonZero(s.mask));
  }
  // A: hue split at the colour boundary.
  const ToolSegment* red = Containing(segments, {100, 207});
  const ToolSegment* blue = Containing(segments, {300, 207});
  ASSERT_TRUE(red != nullptr && blue != nullptr);
  EXPECT_NE(red, blue);
  EXPECT_NEAR(blue->roi.x, 250, 2);
  EXPECT_NEAR(blue->roi.width, 150, 3);
  EXPECT_NEAR(blue->area_px, 150 * 15, 150);
  EXPECT_GT(red->mean_rgb[0], 180);
  EXPECT_LT(red->mean_rgb[2], 60);
  EXPECT_NEAR(blue->median_depth, 0.98, 1e-6);
  // B: depth split.
  EXPECT_NE(Containing(segments, {500, 65}), Containing(segments, {500, 85}));
  // C: the two green pieces are one tool; the purple occluder is another.
  const ToolSegment* green_left = Containing(segments, {120, 307});
  const ToolSegment* green_right = Containing(segments, {300, 307});
  ASSERT_NE(green_left, nullptr);
  EXPECT_EQ(green_left, green_right);
  EXPECT_NE(Containing(segments, {207, 280}), green_left);
  // Shadow and table are background.
  EXPECT_EQ(Containing(segments, {150, 100}), nullptr);
  EXPECT_EQ(Containing(segments, {320, 450}), nullptr);
}

TEST(SegmentationTest, ColourOnlyCannotSplitSameColourTools) {
  SegmentationOptions options;
  options.use_depth = false;
  const std::vector<ToolSegment> segments = SegmentTools(HardScene(), options);
  EXPECT_EQ(segments.size(), 5u);
}

TEST(SegmentationTest, EmptyBoardHasNoTools) {
  RgbdFrame frame = HardScene();
  frame.rgb.setTo(kBoard);
  EXPECT_TRUE(SegmentTools(frame, {}).empty());
}

TEST(SegmentationTest, BadInputThrows) {
  RgbdFrame frame = HardScene();
  RgbdFrame no_rgb = frame;
  no_rgb.rgb = cv::Mat();
  EXPECT_THAT([&] { SegmentTools(no_rgb, {}); }, ThrowsMessage<std::invalid_argument>(HasSubstr("frame.rgb")));
  RgbdFrame small_depth = frame;
  small_depth.depth = cv::Mat(10, 10, CV_32FC1, cv::Scalar(1.0f));
  EXPECT_THAT([&] { SegmentTools(small_depth, {}); }, ThrowsMessage<std::invalid_argument>(HasSubstr("frame.depth")));
  SegmentationOptions options;
  options.min_area_px = 0;
  EXPECT_THAT([&] { SegmentTools(frame, options); }, ThrowsMessage<std::invalid_argument>(HasSubstr("min_area_px")));
}

}  // namespace
}  // namespace toolbench::perception
