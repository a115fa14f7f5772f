// Rendered end to end: segment the tools, cut their clouds and fit the library model, scored
// against simulator ground truth (tests only; perception itself never sees it). Prints the
// per-case errors and the per-stage timings.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "app/scene_setup.h"
#include "perception/model_fit.h"
#include "perception/object_cloud.h"
#include "perception/segmentation.h"
#include "sim/renderer.h"

namespace toolbench::perception {
namespace {

constexpr double kHandleTol = 0.02;                  // handle centre [m]
constexpr double kAxisTol = 15.0 * M_PI / 180.0;     // main axis [rad]

struct Case {
  std::string tool;
  std::string cell;
};

std::string CaseName(const ::testing::TestParamInfo<Case>& info) { return info.param.tool + "_" + info.param.cell; }

// gtest prints parameters in test listings; without this it dumps the struct's bytes.
void PrintTo(const Case& c, std::ostream* os) { *os << c.tool << " in " << c.cell; }

class PerceptionPipelineTest : public ::testing::TestWithParam<Case> {
 protected:
  static void SetUpTestSuite() {
    try {
      gl_ = new sim::GlContext();
    } catch (const std::exception&) {
      gl_ = nullptr;
    }
  }
  static void TearDownTestSuite() {
    delete gl_;
    gl_ = nullptr;
  }
  static sim::GlContext* gl_;
};
sim::GlContext* PerceptionPipelineTest::gl_ = nullptr;

double Milliseconds(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - since).count();
}

TEST_P(PerceptionPipelineTest, OneSegmentAndHandlePoseWithinTolerance) {
  if (gl_ == nullptr) GTEST_SKIP() << "no OSMesa context available";
  const Case& c = GetParam();
  app::SceneRequest request;
  request.seed = 1;
  request.tools = {c.tool};
  request.cells = {c.cell};
  const app::LoadedScene scene = app::LoadScene(request);
  sim::World world(scene.composed.mjcf, "perception_test");
  sim::SimRobot robot(world);
  world.SettleFreeBodies(scene.spec.physics.settle_time);
  const app::LookResult look = app::LookAt(robot, scene.robot, app::RackViewTarget(scene.spec));
  ASSERT_TRUE(look.motion.reached);
  sim::RendererOptions render_options;
  render_options.noise.enabled = true;
  sim::Renderer renderer(*gl_, world, render_options);
  RgbdFrame frame = renderer.Render(world, 1);
  frame.X_RC = app::CameraPoseFromEncoders(scene.robot, robot);
  const Eigen::Isometry3d X_RT_true =
      scene.composed.X_WR.inverse() * world.ground_truth().Pose(scene.composed.tools.at(0).body);
  const auto& model = *std::find_if(scene.library.begin(), scene.library.end(),
                                    [&](const toollib::ToolModel& t) { return t.name == c.tool; });

  auto start = std::chrono::steady_clock::now();
  const std::vector<ToolSegment> segments = SegmentTools(frame, SegmentationOptions{});
  const double segment_ms = Milliseconds(start);
  if (segments.size() != 1u) {
    const std::string path = ::testing::TempDir() + "perception_" + c.tool + "_" + c.cell + "_rgb.png";
    cv::Mat bgr;
    cv::cvtColor(frame.rgb, bgr, cv::COLOR_RGB2BGR);
    cv::imwrite(path, bgr);
    ADD_FAILURE() << "frame written to " << path;
    for (const ToolSegment& s : segments) {
      std::printf("[segment] roi %d %d %dx%d area %.0f hue %.1f depth %.3f\n", s.roi.x, s.roi.y, s.roi.width,
                  s.roi.height, s.area_px, s.mean_hue_deg, s.median_depth);
    }
  }
  ASSERT_EQ(segments.size(), 1u) << c.tool << " in " << c.cell;

  start = std::chrono::steady_clock::now();
  const ObjectCloud cloud = ExtractObjectCloud(frame, segments[0].mask, ObjectCloudOptions{});
  const double cloud_ms = Milliseconds(start);
  ASSERT_EQ(cloud.status, CloudStatus::kOk) << cloud.reason;

  start = std::chrono::steady_clock::now();
  const ModelFitter fitter(model, ModelFitOptions{});
  const double sample_ms = Milliseconds(start);
  start = std::chrono::steady_clock::now();
  const Eigen::Vector3d p_R_camera = frame.X_RC.translation();
  const ModelFitResult fit = fitter.Fit(cloud.p_R, p_R_camera);
  const double fit_ms = Milliseconds(start);
  ASSERT_EQ(fit.status, FitStatus::kOk) << fit.reason;

  // Errors modulo the tool's rotational symmetry (a stick turned end over end is the same
  // stick, with its handle centre elsewhere): the smaller of the two readings counts.
  std::vector<Eigen::Isometry3d> truths = {X_RT_true};
  if (std::find(model.symmetries.begin(), model.symmetries.end(), "rot_x_180") != model.symmetries.end()) {
    Eigen::Isometry3d flip = Eigen::Isometry3d::Identity();
    flip.linear() = Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()).toRotationMatrix();
    flip.translation() = Eigen::Vector3d(0, 0, model.total_length);
    truths.push_back(X_RT_true * flip);
  }
  double handle_error = 1e9;
  double axis_error = 1e9;
  for (const Eigen::Isometry3d& truth : truths) {
    const double h = (fit.X_RT * model.handle.center - truth * model.handle.center).norm();
    const double a = std::acos(std::clamp((fit.X_RT.linear() * model.handle.axis).dot(truth.linear() * model.handle.axis), -1.0, 1.0));
    if (h < handle_error) {
      handle_error = h;
      axis_error = a;
    }
  }
  std::printf("[pipeline] %-9s %-4s segments %zu area %6.0f px cloud %5ld pts (planes %d, plane pts %d, outliers %d) "
              "best %-8s fit_error %.2f mm unexplained %.2f | handle %.1f mm axis %.1f deg | "
              "ms: segment %.1f cloud %.1f sample %.1f fit %.1f\n",
              c.tool.c_str(), c.cell.c_str(), segments.size(), segments[0].area_px, cloud.p_R.cols(),
              cloud.planes_found, cloud.plane_points, cloud.outlier_points,
              fit.candidates[static_cast<std::size_t>(fit.best_candidate)].label.c_str(), fit.fit_error * 1e3,
              fit.unexplained, handle_error * 1e3, axis_error * 180 / M_PI, segment_ms, cloud_ms, sample_ms, fit_ms);
  // The thesis's configuration on the same cloud, for comparison (reported, not required).
  ModelFitOptions baseline_options;
  baseline_options.metric = IcpMetric::kPointToPoint;
  baseline_options.try_flips = false;
  baseline_options.visible_rounds = 0;
  start = std::chrono::steady_clock::now();
  const ModelFitResult baseline = ModelFitter(model, baseline_options).Fit(cloud.p_R);
  const double baseline_ms = Milliseconds(start);
  double baseline_handle = 1e9;
  double baseline_axis = 1e9;
  for (const Eigen::Isometry3d& truth : truths) {
    const double h = (baseline.X_RT * model.handle.center - truth * model.handle.center).norm();
    if (h < baseline_handle) {
      baseline_handle = h;
      baseline_axis = std::acos(std::clamp(
          (baseline.X_RT.linear() * model.handle.axis).dot(truth.linear() * model.handle.axis), -1.0, 1.0));
    }
  }
  std::printf("[baseline] %-9s %-4s thesis ICP (point-to-point, no flips): handle %.1f mm axis %.1f deg (%.1f ms)\n",
              c.tool.c_str(), c.cell.c_str(), baseline_handle * 1e3, baseline_axis * 180 / M_PI, baseline_ms);

  // Recognition over the whole library (a baseline, reported, not required yet).
  const ToolRecognizer recognizer(scene.library, RecognitionOptions{});
  start = std::chrono::steady_clock::now();
  const RecognitionResult recognition = recognizer.Recognize(cloud.p_R, p_R_camera);
  const double recognize_ms = Milliseconds(start);
  std::printf("[recognition] %-9s %-4s -> %-9s confidence %.2f (%.1f ms)\n", c.tool.c_str(), c.cell.c_str(),
              recognition.model.c_str(), recognition.confidence, recognize_ms);
  for (const ModelScore& s : recognition.scores) {
    if (s.fitted) std::printf("[recognition]    %-9s extent %.2f score %.2f mm\n", s.model.c_str(), s.extent_distance, s.score * 1e3);
  }
  EXPECT_LT(handle_error, kHandleTol) << c.tool << " in " << c.cell;
  EXPECT_LT(axis_error, kAxisTol) << c.tool << " in " << c.cell;
}

std::vector<Case> AllCases() {
  std::vector<Case> cases;
  for (const char* tool : {"hoe_2", "hook_3", "rake_1", "stick_2", "spatula_1"}) {
    for (const char* cell : {"pos2", "rot1", "rot2", "rot3"}) cases.push_back({tool, cell});
  }
  return cases;
}

INSTANTIATE_TEST_SUITE_P(Table53, PerceptionPipelineTest, ::testing::ValuesIn(AllCases()), CaseName);

}  // namespace
}  // namespace toolbench::perception
