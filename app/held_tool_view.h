#pragma once

#include <functional>

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "common/robot_interface.h"
#include "common/types.h"
#include "perception/held_tool.h"
#include "robot/robot_description.h"
#include "toollib/tool_model.h"

namespace toolbench::app {

/// What looking at the tool in the hand gave.
struct HeldToolView {
  perception::HeldToolEstimate estimate;
  /// The tool in the palm to plan with: the estimate's when it is plausible, else the prior.
  Eigen::Isometry3d X_PT = Eigen::Isometry3d::Identity();
  cv::Mat picture;  // BGR: the frame with the held tool's mask, the prior (yellow) and the estimate (green)
  Eigen::Isometry3d X_RP = Eigen::Isometry3d::Identity();  // the palm (encoders) when the frame was taken
  bool gaze_converged = false;
};

/// Looks at the tool held in the right hand and estimates how it sits there (the grip may have
/// let it pivot while it was lifted): turns the head (neck only) toward where the prior X_PT_prior (the
/// grasp's plan) puts the tool's centre, takes one frame with `see` (which must set the camera
/// pose from the encoders), and fits the recognised `model` to the held tool's points
/// (perception::EstimateHeldTool). Sensors only: encoders and images.
HeldToolView InspectHeldTool(RobotInterface& robot, const robot::RobotDescription& desc,
                             const std::function<RgbdFrame()>& see, const toollib::ToolModel& model,
                             const Eigen::Isometry3d& X_PT_prior, const perception::HeldToolOptions& options = {});

}  // namespace toolbench::app
