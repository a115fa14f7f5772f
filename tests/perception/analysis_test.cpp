// ToolAnalyzer and its stages on bad input: an empty mask, all-NaN depth, a cloud of three
// points, a library model file missing, mismatched image sizes. Each gives a clear
// std::invalid_argument naming the input, or an analysis entry with a non-kOk status and a
// reason; never a crash.
#include "perception/analysis.h"

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "common/paths.h"
#include "perception/model_fit.h"
#include "perception/object_cloud.h"
#include "perception/parts.h"
#include "perception/segmentation.h"
#include "perception/superquadric.h"
#include "toollib/tool_model.h"

namespace toolbench::perception {
namespace {

using ::testing::AllOf;
using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

constexpr float kBoardDepth = 1.0f;  // [m]
constexpr float kToolDepth = 0.97f;  // [m]

const std::vector<toollib::ToolModel>& TwoTools() {
  static const std::vector<toollib::ToolModel> tools = {
      toollib::LoadToolModel(AssetsDir() / "tools" / "hoe_1.json"),
      toollib::LoadToolModel(AssetsDir() / "tools" / "stick_1.json")};
  return tools;
}

AnalyzerOptions QuickOptions() {
  AnalyzerOptions options;  // no classifier, shapes in memory only
  options.recognition.fit.model_points = 500;
  return options;
}

// A light grey board at 1 m seen straight on, with one red bar 3 cm in front of it.
RgbdFrame BoardWithBar() {
  RgbdFrame frame;
  frame.intrinsics = CameraIntrinsics{640, 480, 500.0, 500.0, 319.5, 239.5};
  frame.rgb = cv::Mat(480, 640, CV_8UC3, cv::Scalar(190, 190, 190));
  frame.depth = cv::Mat(480, 640, CV_32FC1, cv::Scalar(kBoardDepth));
  frame.rgb(cv::Rect(200, 230, 240, 14)).setTo(cv::Scalar(210, 30, 30));
  frame.depth(cv::Rect(200, 230, 240, 14)).setTo(kToolDepth);
  frame.X_RC.linear() = Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()).toRotationMatrix();
  frame.X_RC.translation() = Eigen::Vector3d(0.0, 0.0, 1.0);
  return frame;
}

TEST(ToolAnalyzerBadInputTest, MalformedFramesAreNamed) {
  const ToolAnalyzer analyzer(TwoTools(), QuickOptions());
  RgbdFrame empty;
  EXPECT_THAT([&] { analyzer.Analyze(empty); }, ThrowsMessage<std::invalid_argument>(HasSubstr("frame.rgb")));

  RgbdFrame small_depth = BoardWithBar();
  small_depth.depth = cv::Mat(240, 320, CV_32FC1, cv::Scalar(1.0f));
  EXPECT_THAT([&] { analyzer.Analyze(small_depth); },
              ThrowsMessage<std::invalid_argument>(AllOf(HasSubstr("frame.depth"), HasSubstr("320x240"))));

  RgbdFrame no_depth = BoardWithBar();
  no_depth.depth = cv::Mat();
  EXPECT_THAT([&] { analyzer.Analyze(no_depth); }, ThrowsMessage<std::invalid_argument>(HasSubstr("frame.depth")));

  RgbdFrame half_intrinsics = BoardWithBar();
  half_intrinsics.intrinsics.width = 320;
  EXPECT_THAT([&] { analyzer.Analyze(half_intrinsics); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("frame.intrinsics 320x480")));
  // ... also when the frame shows no tool, so nothing downstream would have looked.
  half_intrinsics.rgb.setTo(cv::Scalar(190, 190, 190));
  EXPECT_THAT([&] { analyzer.Analyze(half_intrinsics); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("frame.intrinsics 320x480")));

  RgbdFrame nan_pose = BoardWithBar();
  nan_pose.X_RC.translation().x() = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THAT([&] { analyzer.Analyze(nan_pose); }, ThrowsMessage<std::invalid_argument>(HasSubstr("frame.X_RC")));
}

TEST(ToolAnalyzerBadInputTest, AllNanDepthGivesNoCloudWithAReason) {
  const ToolAnalyzer analyzer(TwoTools(), QuickOptions());
  RgbdFrame frame = BoardWithBar();
  frame.depth.setTo(std::numeric_limits<float>::quiet_NaN());
  const FrameAnalysis analysis = analyzer.Analyze(frame);
  ASSERT_EQ(analysis.tools.size(), 1u);  // the bar is still seen in colour
  EXPECT_EQ(analysis.tools[0].status, AnalysisStatus::kNoCloud);
  EXPECT_THAT(analysis.tools[0].reason, HasSubstr("depth"));
  EXPECT_EQ(analysis.recognition[0].status, FitStatus::kTooFewPoints);
  EXPECT_EQ(analysis.clouds[0].valid_depth, 0);
  EXPECT_EQ(analysis.tools[0].handle.part, -1);
}

TEST(ToolAnalyzerBadInputTest, EmptyMaskAndEmptyFrameAreResultsWithReasons) {
  // The stage: a mask that selects nothing.
  const RgbdFrame frame = BoardWithBar();
  const ObjectCloud cloud = ExtractObjectCloud(frame, cv::Mat::zeros(480, 640, CV_8UC1), {});
  EXPECT_EQ(cloud.status, CloudStatus::kEmptyMask);
  EXPECT_FALSE(cloud.reason.empty());
  EXPECT_THAT([&] { ExtractObjectCloud(frame, cv::Mat(), {}); }, ThrowsMessage<std::invalid_argument>(HasSubstr("mask")));
  // The pipeline: nothing segmented is an empty analysis that says why.
  const ToolAnalyzer analyzer(TwoTools(), QuickOptions());
  RgbdFrame board = BoardWithBar();
  board.rgb.setTo(cv::Scalar(190, 190, 190));
  const FrameAnalysis analysis = analyzer.Analyze(board);
  EXPECT_TRUE(analysis.tools.empty());
  EXPECT_THAT(analysis.reason, HasSubstr("no tool segmented"));
}

TEST(ToolAnalyzerBadInputTest, FlatPatchIsOnePartNotACrash) {
  // Every SDF ray of a flat patch misses, so all SDF values are equal; CGAL's k-means seeding
  // then recursed in boost::random until the stack overflowed (the flat top of a synthetic
  // bar, seen by the camera above, crashed ToolAnalyzer::Analyze that way).
  SurfaceSamples patch;
  patch.points.resize(3, 20 * 6);
  patch.normals.resize(3, 20 * 6);
  for (int i = 0; i < 20; ++i) {
    for (int j = 0; j < 6; ++j) {
      patch.points.col(i * 6 + j) << 0.01f * static_cast<float>(i), 0.01f * static_cast<float>(j), 0.0f;
      patch.normals.col(i * 6 + j) << 0.0f, 0.0f, 1.0f;
    }
  }
  const PartsResult parts = SegmentParts(patch, ShapeOptions{});
  ASSERT_EQ(parts.status, ShapeStatus::kOk) << parts.reason;
  EXPECT_EQ(parts.parts.size(), 1u);
}

TEST(ToolAnalyzerBadInputTest, ThreePointsAreTooFewForEveryStage) {
  // A segment whose depth has only three readings: no cloud, with the count in the reason.
  const ToolAnalyzer analyzer(TwoTools(), QuickOptions());
  RgbdFrame frame = BoardWithBar();
  frame.depth(cv::Rect(200, 230, 240, 14)).setTo(0.0f);
  frame.depth.at<float>(236, 300) = kToolDepth;
  frame.depth.at<float>(236, 301) = kToolDepth;
  frame.depth.at<float>(237, 300) = kToolDepth;
  const FrameAnalysis analysis = analyzer.Analyze(frame);
  ASSERT_EQ(analysis.tools.size(), 1u);
  EXPECT_EQ(analysis.tools[0].status, AnalysisStatus::kNoCloud);
  EXPECT_FALSE(analysis.tools[0].reason.empty());

  // Each later stage given a cloud of three points directly.
  const Eigen::Matrix3Xf three = Eigen::Matrix3Xf::Identity(3, 3);
  const RecognitionResult recognition = analyzer.recognizer().Recognize(three, Eigen::Vector3d(0, 0, 1));
  EXPECT_EQ(recognition.status, FitStatus::kTooFewPoints);
  EXPECT_THAT(recognition.reason, HasSubstr("3 points"));
  const ModelShape shape = AnalyzeObservedShape(three, Eigen::Vector3d(0, 0, 1), ShapeOptions{});
  EXPECT_EQ(shape.status, ShapeStatus::kTooFewPoints);
  EXPECT_THAT(shape.reason, HasSubstr("3 points"));
  const SuperquadricFit sq = FitSuperquadric(three, SuperquadricOptions{});
  EXPECT_EQ(sq.status, SuperquadricStatus::kTooFewPoints);
  EXPECT_THAT(sq.reason, HasSubstr("3 points"));
  const Handle handle = ChooseHandle({}, ShapeOptions{});
  EXPECT_EQ(handle.part, -1);
}

TEST(ToolAnalyzerBadInputTest, MissingLibraryFilesAreNamed) {
  EXPECT_THAT([] { ToolAnalyzer({}, AnalyzerOptions{}); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("library is empty")));

  // A classifier file that is not there, and one made for another library.
  AnalyzerOptions missing = QuickOptions();
  missing.classifier_file = "/nonexistent/tool_classifier.yml.gz";
  EXPECT_THAT([&] { ToolAnalyzer(TwoTools(), missing); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("/nonexistent/tool_classifier.yml.gz")));
  AnalyzerOptions shipped = QuickOptions();
  shipped.classifier_file = AssetsDir() / "models" / "tool_classifier.yml.gz";
  EXPECT_THAT([&] { ToolAnalyzer(TwoTools(), shipped); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("library mismatch")));

  // A model the analyzer does not have.
  const ToolAnalyzer analyzer(TwoTools(), QuickOptions());
  EXPECT_THAT([&] { analyzer.PrepareShapes({"spoon_9"}); }, ThrowsMessage<std::invalid_argument>(HasSubstr("spoon_9")));

  // A library folder whose sidecar names a mesh file that is missing.
  const std::filesystem::path dir = std::filesystem::path(::testing::TempDir()) / "analysis_test_missing_mesh";
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  toollib::ToolModel hoe = TwoTools()[0];
  hoe.name = "lost_hoe";
  toollib::SaveToolModel(hoe, dir);
  std::filesystem::remove(dir / "lost_hoe.stl");
  EXPECT_THAT([&] { toollib::LoadToolLibrary(dir); }, ThrowsMessage<std::invalid_argument>(HasSubstr("lost_hoe.stl")));
  std::filesystem::remove_all(dir);
}

TEST(ToolAnalyzerBadInputTest, BadOptionsAreNamed) {
  AnalyzerOptions options = QuickOptions();
  options.max_known_fit_error = 0.0;
  EXPECT_THAT([&] { ToolAnalyzer(TwoTools(), options); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("max_known_fit_error = 0")));
  options = QuickOptions();
  options.min_known_confidence = 1.5;
  EXPECT_THAT([&] { ToolAnalyzer(TwoTools(), options); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("min_known_confidence = 1.5")));
}

}  // namespace
}  // namespace toolbench::perception
