// End to end: compose, settle, turn to look, render, back-project with the encoder-FK camera pose.
#include <algorithm>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "app/capture.h"
#include "app/frame_io.h"
#include "app/scene_setup.h"
#include "sim/renderer.h"

namespace toolbench::app {
namespace {

std::unique_ptr<sim::GlContext> MakeContext() {
  try {
    return std::make_unique<sim::GlContext>();
  } catch (const std::exception&) {
    return nullptr;
  }
}

Capture Render(sim::GlContext& gl, const SceneRequest& request, bool look_at_table, bool noise) {
  CaptureOptions options;
  options.look_at_table = look_at_table;
  options.noise = noise;
  Capture capture = CaptureFrame(request, options, gl);
  EXPECT_TRUE(capture.look.gaze.converged);
  EXPECT_TRUE(capture.look.motion.reached) << capture.look.motion.worst_joint << " " << capture.look.motion.max_error;
  return capture;
}

TEST(RenderPipelineTest, TablePlaneFromEncoderPoseWithinOneMillimetre) {
  auto gl = MakeContext();
  if (!gl) GTEST_SKIP() << "no OSMesa context available";
  SceneRequest request;
  request.seed = 2;
  const Capture r = Render(*gl, request, true, false);
  const sim::TableSpec& table = r.scene.spec.table;
  Eigen::Matrix3Xf p_R;
  Eigen::Matrix<unsigned char, 3, Eigen::Dynamic> colour;
  BackProject(r.frame, p_R, colour);
  const Eigen::Vector3d ball = r.scene.composed.X_WR.inverse() * r.world->ground_truth().Pose("ball").translation();
  std::vector<double> errors;
  for (Eigen::Index i = 0; i < p_R.cols(); ++i) {
    const Eigen::Vector3d p = p_R.col(i).cast<double>();
    const bool inside = std::abs(p.x() - table.center.x()) < table.size.x() / 2 - 0.02 &&
                        std::abs(p.y() - table.center.y()) < table.size.y() / 2 - 0.02;
    const bool near_ball = (p.head<2>() - ball.head<2>()).norm() < 0.06;
    if (inside && !near_ball && std::abs(p.z() - table.top_z) < 0.05) errors.push_back(std::abs(p.z() - table.top_z));
  }
  ASSERT_GT(errors.size(), 20000u);
  std::sort(errors.begin(), errors.end());
  EXPECT_LT(errors[errors.size() / 2], 1e-3);
  EXPECT_LT(errors[errors.size() * 99 / 100], 1e-3);
}

TEST(RenderPipelineTest, RackViewShowsEveryTool) {
  auto gl = MakeContext();
  if (!gl) GTEST_SKIP() << "no OSMesa context available";
  SceneRequest request;
  request.seed = 1;
  const Capture r = Render(*gl, request, false, true);
  // Every tool's origin (handle butt) and its effector centre project inside the image, in
  // front of the camera, and the depth there is the tool's (not the board behind it).
  const CameraIntrinsics& K = r.frame.intrinsics;
  for (const auto& placed : r.scene.composed.tools) {
    const Eigen::Isometry3d X_RT = r.scene.composed.X_WR.inverse() * r.world->ground_truth().Pose(placed.body);
    const auto& model = *std::find_if(r.scene.library.begin(), r.scene.library.end(),
                                      [&](const auto& t) { return t.name == placed.name; });
    for (const Eigen::Vector3d& p_T : {model.handle.center, model.effector.center}) {
      const Eigen::Vector3d p_C = r.frame.X_RC.inverse() * (X_RT * p_T);
      ASSERT_GT(p_C.z(), 0.1) << placed.name;
      const double u = K.fx * p_C.x() / p_C.z() + K.cx;
      const double v = K.fy * p_C.y() / p_C.z() + K.cy;
      EXPECT_TRUE(u > 0 && u < K.width - 1 && v > 0 && v < K.height - 1)
          << placed.name << " in " << placed.cell << " at pixel " << u << ", " << v;
    }
  }
}

}  // namespace
}  // namespace toolbench::app
