#pragma once

#include <string>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "common/types.h"
#include "perception/model_fit.h"
#include "perception/object_cloud.h"
#include "perception/segmentation.h"
#include "toollib/tool_model.h"

namespace toolbench::perception {

/// Configuration of EstimateHeldTool.
struct HeldToolOptions {
  SegmentationOptions segmentation;
  /// The tool is seen in the air: no support plane is removed (a flat blade would be), only
  /// statistical outliers.
  ObjectCloudOptions cloud = [] {
    ObjectCloudOptions o;
    o.max_planes = 0;
    return o;
  }();
  ModelFitOptions fit;
  /// A segment belongs to the held tool when one of its points lies within this distance of the
  /// grasp centre [m], > 0: the handle runs through the hand, so every visible piece of the held
  /// tool (the hand may cut it in two) touches the hand's neighbourhood; tools elsewhere do not.
  double hand_gap_m = 0.05;
  /// Plausibility of the estimate against the prior (the pose the grasp planned): the handle
  /// axis must pass within max_axis_offset_m [m] (> 0) of the grasp centre (the hand holds it),
  /// and the estimate may turn the tool by at most max_correction_rad [rad] (in (0, pi]) from
  /// the prior (a tool hangs from the grip; it does not turn over); fit_error at most
  /// max_fit_error_m [m] (> 0). 5 cm: a tool put into the open hand (the hand-over) lies on the
  /// palm, its handle axis 3-4 cm from the grasp centre (3 cm rejected a fit 1.4 mm off whose
  /// rotation matched the truth within 0.05 deg).
  double max_axis_offset_m = 0.05;
  double max_correction_rad = 75.0 * M_PI / 180.0;
  double max_fit_error_m = 0.006;
  /// Two fits are made: the model fitter's global search, and its refinement started from the
  /// prior. The prior's is kept when its mean error is at most prior_fit_slack (>= 1) times the
  /// global one's plus prior_fit_margin_m [m] (>= 0): a partial view of a tool fits some poses
  /// turned end over end almost as well, and the grasp knows which end is which.
  double prior_fit_slack = 1.2;
  double prior_fit_margin_m = 0.0005;
  void Validate() const;  // throws std::invalid_argument naming the field and its value
};

/// What EstimateHeldTool found.
struct HeldToolEstimate {
  bool ok = false;         // X_RT is a plausible fit; otherwise keep the prior
  std::string reason;      // why not ok (empty when ok)
  Eigen::Isometry3d X_RT = Eigen::Isometry3d::Identity();  // fitted tool pose in R (also when not ok, if fitted)
  int segments = 0;        // segments taken for the held tool
  int points = 0;          // observed points fitted
  double fit_error_m = 0.0;       // mean observed-to-model distance [m]
  double global_fit_error_m = 0.0;  // of the global search's fit [m]
  double prior_fit_error_m = 0.0;   // of the refinement from the prior [m]
  bool from_prior = false;          // the refinement from the prior was kept
  double correction_deg = 0.0;    // rotation from the prior to the estimate [deg]
  double correction_m = 0.0;      // displacement of the tool origin from the prior [m]
  double axis_offset_m = 0.0;     // distance of the grasp centre from the fitted handle axis [m]
  /// How far the fit had slid the tool along its handle axis past the hand, undone [m] (0 = the
  /// grasp centre lay on the handle: within its half-length plus max_axis_offset_m of its centre).
  double slide_corrected_m = 0.0;
  cv::Mat mask;                   // union of the held tool's segments (CV_8UC1), for pictures
};

/// Estimates the pose of a tool held in the hand from one RGB-D frame (the tool turned toward the
/// camera): the tool may have pivoted or slipped in the grip while it was lifted, so the pose the
/// grasp planned (X_RT_prior) is only a prior. Segments the saturated-colour regions
/// (SegmentTools), keeps those that touch the hand (within hand_gap_m of p_R_grasp, the grasp
/// centre in R from forward kinematics of the encoders), back-projects them with frame.X_RC, fits
/// the recognised library `model` to their points (ModelFitter: global candidate search, ICP and
/// the depth-image check, and the same refinement from the prior; HeldToolOptions says which is
/// kept), and checks the result against the prior (HeldToolOptions). Never reads
/// simulator state. Returns ok = false with a reason when nothing plausible is seen.
/// Throws std::invalid_argument for bad options, images that do not match their intrinsics, or a
/// non-finite prior or grasp centre.
HeldToolEstimate EstimateHeldTool(const RgbdFrame& frame, const toollib::ToolModel& model,
                                  const Eigen::Isometry3d& X_RT_prior, const Eigen::Vector3d& p_R_grasp,
                                  const HeldToolOptions& options = {});

}  // namespace toolbench::perception
