#include "app/held_tool_view.h"

#include <vector>

#include <opencv2/imgproc.hpp>

#include "app/scene_setup.h"

namespace toolbench::app {
namespace {

// Draws every k-th mesh vertex of `model` at X_RT as a dot.
void DrawModel(cv::Mat& bgr, const RgbdFrame& frame, const toollib::ToolModel& model, const Eigen::Isometry3d& X_RT,
               const cv::Scalar& colour) {
  const Eigen::Isometry3d X_CT = frame.X_RC.inverse() * X_RT;
  const CameraIntrinsics& K = frame.intrinsics;
  const Eigen::Index step = std::max<Eigen::Index>(1, model.mesh.vertices.cols() / 1500);
  for (Eigen::Index v = 0; v < model.mesh.vertices.cols(); v += step) {
    const Eigen::Vector3d p = X_CT * model.mesh.vertices.col(v).cast<double>();
    if (p.z() <= 0.01) continue;
    cv::circle(bgr, cv::Point2d(K.fx * p.x() / p.z() + K.cx, K.fy * p.y() / p.z() + K.cy), 1, colour, -1);
  }
}

}  // namespace

HeldToolView InspectHeldTool(RobotInterface& robot, const robot::RobotDescription& desc,
                             const std::function<RgbdFrame()>& see, const toollib::ToolModel& model,
                             const Eigen::Isometry3d& X_PT_prior, const perception::HeldToolOptions& options) {
  auto palm = [&] { return PalmPoseFromEncoders(desc, robot); };
  // The middle of the tool's mesh, where the prior puts it.
  const Eigen::Vector3d p_T_middle =
      0.5 * (model.mesh.vertices.rowwise().minCoeff() + model.mesh.vertices.rowwise().maxCoeff()).cast<double>();
  HeldToolView view;
  view.X_PT = X_PT_prior;
  view.gaze_converged = LookWithNeck(robot, desc, palm() * X_PT_prior * p_T_middle).gaze.converged;
  const RgbdFrame frame = see();
  const Eigen::Isometry3d X_RP = palm();  // after the look (the torso may have turned)
  view.X_RP = X_RP;
  const Eigen::Isometry3d X_RT_prior = X_RP * X_PT_prior;
  view.estimate = perception::EstimateHeldTool(frame, model, X_RT_prior, X_RP * desc.grasp.center, options);
  if (view.estimate.ok) view.X_PT = X_RP.inverse() * view.estimate.X_RT;
  cv::cvtColor(frame.rgb, view.picture, cv::COLOR_RGB2BGR);
  if (!view.estimate.mask.empty()) {
    std::vector<std::vector<cv::Point>> contours;
    cv::findContours(view.estimate.mask.clone(), contours, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_SIMPLE);
    cv::drawContours(view.picture, contours, -1, cv::Scalar(255, 0, 255), 1);
  }
  DrawModel(view.picture, frame, model, X_RT_prior, cv::Scalar(0, 255, 255));
  if (view.estimate.points > 0) {
    DrawModel(view.picture, frame, model, view.estimate.X_RT,
              view.estimate.ok ? cv::Scalar(0, 255, 0) : cv::Scalar(0, 0, 255));
  }
  return view;
}

}  // namespace toolbench::app
