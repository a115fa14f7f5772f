#include "perception/held_tool.h"

#include <cmath>
#include <limits>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "common/paths.h"
#include "toollib/tool_model.h"

namespace toolbench::perception {
namespace {

using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

// A synthetic RGB-D frame of one tool at X_RT (camera at the origin of R looking along +z_R, the
// OpenCV convention): dense surface samples z-buffered into the depth image and painted magenta
// on a grey background. What the helmet camera sees of a held tool, without the hand.
RgbdFrame RenderTool(const toollib::ToolModel& tool, const Eigen::Isometry3d& X_RT) {
  RgbdFrame frame;
  frame.intrinsics = CameraIntrinsics{640, 480, 525.0, 525.0, 319.5, 239.5};
  frame.rgb = cv::Mat(480, 640, CV_8UC3, cv::Scalar(128, 128, 128));
  frame.depth = cv::Mat::zeros(480, 640, CV_32FC1);
  const SurfaceSamples dense = SampleSurface(tool.mesh, 200000, 5);
  for (Eigen::Index i = 0; i < dense.points.cols(); ++i) {
    const Eigen::Vector3d p = X_RT * dense.points.col(i).cast<double>();
    const Eigen::Vector3d n = X_RT.linear() * dense.normals.col(i).cast<double>();
    if (n.dot(-p) <= 0 || p.z() <= 0.05) continue;
    const int u = static_cast<int>(std::lround(525.0 * p.x() / p.z() + 319.5));
    const int v = static_cast<int>(std::lround(525.0 * p.y() / p.z() + 239.5));
    for (int dv = 0; dv <= 1; ++dv) {
      for (int du = 0; du <= 1; ++du) {
        if (u + du < 0 || u + du >= 640 || v + dv < 0 || v + dv >= 480) continue;
        float& d = frame.depth.at<float>(v + dv, u + du);
        if (d == 0.0F || p.z() < d) {
          d = static_cast<float>(p.z());
          frame.rgb.at<cv::Vec3b>(v + dv, u + du) = cv::Vec3b(220, 30, 200);
        }
      }
    }
  }
  return frame;
}

struct HeldScene {
  toollib::ToolModel tool = toollib::LoadToolModel(AssetsDir() / "tools" / "hook_1.json");
  Eigen::Isometry3d X_RT = Eigen::Isometry3d::Identity();
  Eigen::Vector3d p_R_grasp;  // the handle centre: where the hand holds it
  HeldScene() {
    // The tool across the view, 0.6 m ahead, the hook seen from the side.
    // Handle axis z_T across the image (+x_R), the hook's working side x_T down it (+y_R).
    X_RT.linear() = (Eigen::AngleAxisd(-0.3, Eigen::Vector3d::UnitX()) *
                     Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitY()) *
                     Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitZ()))
                        .toRotationMatrix();
    X_RT.translation() = Eigen::Vector3d(-0.2, 0.05, 0.6);
    p_R_grasp = X_RT * tool.handle.center;
  }
  // The pose the grasp planned: the truth turned about the grasp centre (the tool pivoted).
  Eigen::Isometry3d Pivoted(double angle, const Eigen::Vector3d& axis) const {
    Eigen::Isometry3d turn = Eigen::Isometry3d::Identity();
    turn.linear() = Eigen::AngleAxisd(angle, axis.normalized()).toRotationMatrix();
    turn.translation() = p_R_grasp - turn.linear() * p_R_grasp;
    return turn * X_RT;
  }
};

double AngleDeg(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b) {
  return Eigen::AngleAxisd(a.linear() * b.linear().transpose()).angle() * 180.0 / M_PI;
}

TEST(EstimateHeldTool, RecoversAToolThatPivotedInTheGrip) {
  const HeldScene scene;
  const RgbdFrame frame = RenderTool(scene.tool, scene.X_RT);
  const Eigen::Isometry3d prior = scene.Pivoted(35.0 * M_PI / 180.0, Eigen::Vector3d(0.3, 1.0, 0.2));
  ASSERT_NEAR(AngleDeg(prior, scene.X_RT), 35.0, 0.1);
  const HeldToolEstimate e = EstimateHeldTool(frame, scene.tool, prior, scene.p_R_grasp);
  ASSERT_TRUE(e.ok) << e.reason << " (global fit " << e.global_fit_error_m * 1000 << " mm, from the prior "
                    << e.prior_fit_error_m * 1000 << " mm, " << e.points << " points, estimate "
                    << AngleDeg(e.X_RT, scene.X_RT) << " deg from the truth)";
  EXPECT_EQ(e.segments, 1);
  EXPECT_LT(AngleDeg(e.X_RT, scene.X_RT), 2.0);
  EXPECT_LT((e.X_RT * scene.tool.effector.center - scene.X_RT * scene.tool.effector.center).norm(), 0.005);
  EXPECT_NEAR(e.correction_deg, 35.0, 2.5);
  EXPECT_LT(e.axis_offset_m, 0.005);
}

TEST(EstimateHeldTool, KeepsThePriorWhenNothingTouchesTheHand) {
  const HeldScene scene;
  const RgbdFrame frame = RenderTool(scene.tool, scene.X_RT);
  // The hand 30 cm away from any tool pixel: the tool in view is another one.
  const Eigen::Vector3d far_hand = scene.p_R_grasp + Eigen::Vector3d(0.0, 0.3, 0.0);
  const HeldToolEstimate e = EstimateHeldTool(frame, scene.tool, scene.X_RT, far_hand);
  EXPECT_FALSE(e.ok);
  EXPECT_THAT(e.reason, HasSubstr("within 5 cm of the hand"));
  EXPECT_TRUE(e.X_RT.isApprox(scene.X_RT));
}

TEST(EstimateHeldTool, RejectsACorrectionBeyondItsLimit) {
  const HeldScene scene;
  const RgbdFrame frame = RenderTool(scene.tool, scene.X_RT);
  HeldToolOptions options;
  options.max_correction_rad = 20.0 * M_PI / 180.0;
  const Eigen::Isometry3d prior = scene.Pivoted(35.0 * M_PI / 180.0, Eigen::Vector3d::UnitY());
  const HeldToolEstimate e = EstimateHeldTool(frame, scene.tool, prior, scene.p_R_grasp, options);
  EXPECT_FALSE(e.ok);
  EXPECT_THAT(e.reason, HasSubstr("turns the tool by"));
}

TEST(EstimateHeldTool, PutsTheHandBackOnTheHandleWhenTheFitHasItBeyondTheEnd) {
  // A stick held at its far end, 20 cm from the handle's centre along the axis (beyond the
  // handle's half-length 13.5 cm plus max_axis_offset_m): the view cannot say where along a
  // stick the hand is, the grasp can. The prior has the hand at the handle's centre.
  const toollib::ToolModel stick = toollib::LoadToolModel(AssetsDir() / "tools" / "stick_1.json");
  const HeldScene scene;  // its pose across the view
  const Eigen::Vector3d a = scene.X_RT.linear() * stick.handle.axis;
  const Eigen::Vector3d p_R_grasp = scene.X_RT * stick.handle.center + 0.2 * a;
  Eigen::Isometry3d prior = scene.X_RT;
  prior.translation() += 0.2 * a;
  const RgbdFrame frame = RenderTool(stick, scene.X_RT);
  const HeldToolEstimate e = EstimateHeldTool(frame, stick, prior, p_R_grasp);
  ASSERT_TRUE(e.ok) << e.reason;
  EXPECT_NEAR(e.slide_corrected_m, 0.2, 0.01) << "the fit found the stick where it is, the hand beyond its handle";
  EXPECT_NEAR((p_R_grasp - e.X_RT * stick.handle.center).dot(a), 0.0, 0.01);
  EXPECT_LT(AngleDeg(e.X_RT, scene.X_RT), 2.0);
  // Held on its handle, nothing is put back.
  const HeldToolEstimate on_handle = EstimateHeldTool(frame, stick, scene.X_RT, scene.X_RT * stick.handle.center);
  ASSERT_TRUE(on_handle.ok) << on_handle.reason;
  EXPECT_EQ(on_handle.slide_corrected_m, 0.0);
}

TEST(EstimateHeldTool, RejectsBadInput) {
  const HeldScene scene;
  const RgbdFrame frame = RenderTool(scene.tool, scene.X_RT);
  Eigen::Isometry3d nan_prior = scene.X_RT;
  nan_prior.translation().x() = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THAT([&] { EstimateHeldTool(frame, scene.tool, nan_prior, scene.p_R_grasp); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("X_RT_prior")));
  HeldToolOptions bad;
  bad.hand_gap_m = 0.0;
  EXPECT_THAT([&] { EstimateHeldTool(frame, scene.tool, scene.X_RT, scene.p_R_grasp, bad); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("hand_gap_m")));
  RgbdFrame no_depth = frame;
  no_depth.depth = cv::Mat();
  EXPECT_THROW(EstimateHeldTool(no_depth, scene.tool, scene.X_RT, scene.p_R_grasp), std::invalid_argument);
}

}  // namespace
}  // namespace toolbench::perception
