#include "perception/held_tool.h"

#include <cmath>
#include <cstdlib>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "common/check.h"

namespace toolbench::perception {
namespace {

// Rotations of T that map the model onto itself ("rot_<axis>_<deg|any>" symmetries of the sidecar),
// the identity first: an estimate and its symmetric twins describe the same held tool.
std::vector<Eigen::Matrix3d> SymmetryRotations(const toollib::ToolModel& model) {
  std::vector<Eigen::Matrix3d> out{Eigen::Matrix3d::Identity()};
  for (const std::string& s : model.symmetries) {
    if (s.size() < 7 || s.rfind("rot_", 0) != 0 || s[5] != '_') continue;
    const char axis = s[4];
    if (axis != 'x' && axis != 'y' && axis != 'z') continue;
    // "any": symmetric under every turn about the axis (a stick), sampled every 5 deg.
    const double deg = s.substr(6) == "any" ? 5.0 : std::atof(s.c_str() + 6);
    if (!(deg > 0 && deg < 360)) continue;
    const Eigen::Vector3d a = axis == 'x' ? Eigen::Vector3d::UnitX()
                              : axis == 'y' ? Eigen::Vector3d::UnitY()
                                            : Eigen::Vector3d::UnitZ();
    const size_t n = out.size();
    for (double t = deg; t < 360 - 1e-6; t += deg) {
      const Eigen::Matrix3d R = Eigen::AngleAxisd(t * M_PI / 180.0, a).toRotationMatrix();
      for (size_t i = 0; i < n; ++i) out.push_back(out[i] * R);
    }
  }
  return out;
}

}  // namespace

void HeldToolOptions::Validate() const {
  segmentation.Validate();
  cloud.Validate();
  fit.Validate();
  auto fail = [](const char* field, double value, const char* expected) {
    ThrowInvalid("HeldToolOptions: ", field, " = ", value, " (expected ", expected, ")");
  };
  if (!(hand_gap_m > 0)) fail("hand_gap_m", hand_gap_m, "> 0");
  if (!(max_axis_offset_m > 0)) fail("max_axis_offset_m", max_axis_offset_m, "> 0");
  if (!(max_correction_rad > 0 && max_correction_rad <= M_PI)) fail("max_correction_rad", max_correction_rad, "in (0, pi]");
  if (!(max_fit_error_m > 0)) fail("max_fit_error_m", max_fit_error_m, "> 0");
  if (!(prior_fit_slack >= 1)) fail("prior_fit_slack", prior_fit_slack, ">= 1");
  if (!(prior_fit_margin_m >= 0)) fail("prior_fit_margin_m", prior_fit_margin_m, ">= 0");
}

HeldToolEstimate EstimateHeldTool(const RgbdFrame& frame, const toollib::ToolModel& model,
                                  const Eigen::Isometry3d& X_RT_prior, const Eigen::Vector3d& p_R_grasp,
                                  const HeldToolOptions& options) {
  options.Validate();
  if (!X_RT_prior.matrix().allFinite() || !p_R_grasp.allFinite()) {
    ThrowInvalid("EstimateHeldTool: X_RT_prior or p_R_grasp = (", p_R_grasp.transpose(), ") is not finite");
  }
  if (!frame.X_RC.matrix().allFinite()) ThrowInvalid("EstimateHeldTool: frame.X_RC is not finite");
  HeldToolEstimate out;
  out.X_RT = X_RT_prior;
  const std::vector<ToolSegment> segments = SegmentTools(frame, options.segmentation);
  cv::Mat mask = cv::Mat::zeros(frame.rgb.rows, frame.rgb.cols, CV_8UC1);
  const Eigen::Isometry3d X_CR = frame.X_RC.inverse();
  for (const ToolSegment& segment : segments) {
    const Eigen::Matrix3Xf p_C = BackProjectMask(frame, segment.mask, options.cloud.min_depth, options.cloud.max_depth);
    const Eigen::Vector3f p_C_grasp = (X_CR * p_R_grasp).cast<float>();
    bool touches = false;
    for (Eigen::Index i = 0; i < p_C.cols() && !touches; ++i) {
      touches = (p_C.col(i) - p_C_grasp).norm() <= options.hand_gap_m;
    }
    if (!touches) continue;
    mask |= segment.mask;
    ++out.segments;
  }
  out.mask = mask;
  if (out.segments == 0) {
    out.reason = Cat("no segment of saturated colour within ", options.hand_gap_m * 100, " cm of the hand (",
                     segments.size(), " segments in view)");
    return out;
  }
  const ObjectCloud cloud = ExtractObjectCloud(frame, mask, options.cloud);
  if (cloud.status != CloudStatus::kOk) {
    out.reason = "held tool cloud: " + cloud.reason;
    return out;
  }
  out.points = static_cast<int>(cloud.p_R.cols());
  FitView view;
  view.depth = frame.depth;
  view.mask = mask;
  view.intrinsics = frame.intrinsics;
  view.X_RC = frame.X_RC;
  const ModelFitter fitter(model, options.fit);
  const std::optional<Eigen::Vector3d> p_R_camera = frame.X_RC.translation();
  ModelFitResult fit = fitter.Fit(cloud.p_R, p_R_camera, view);
  if (fit.status != FitStatus::kOk) {
    out.reason = "fit: " + fit.reason;
    return out;
  }
  // The same refinement started from the prior: the global search knows nothing of how the tool
  // was grasped, and may settle on a pose turned end over end that fits a partial view about as
  // well. The prior's refinement wins unless the global one fits clearly better.
  ModelFitResult from_prior;
  from_prior.status = FitStatus::kOk;
  from_prior.model = model.name;
  from_prior.X_RT = X_RT_prior;
  from_prior.candidates.push_back({"prior", X_RT_prior, X_RT_prior, 0.0, 0.0, 0.0, false});
  from_prior.best_candidate = 0;
  from_prior = fitter.Refine(cloud.p_R, p_R_camera, std::move(from_prior), view);
  out.global_fit_error_m = fit.fit_error;
  out.prior_fit_error_m = from_prior.fit_error;
  if (from_prior.fit_error <= options.prior_fit_slack * fit.fit_error + options.prior_fit_margin_m) {
    fit = std::move(from_prior);
    out.from_prior = true;
  }
  // The symmetric twin of the fit nearest the prior.
  double best = std::numeric_limits<double>::infinity();
  for (const Eigen::Matrix3d& S : SymmetryRotations(model)) {
    Eigen::Isometry3d X = fit.X_RT;
    X.linear() = fit.X_RT.linear() * S;
    X.translation() = fit.X_RT.translation();
    const double angle = Eigen::AngleAxisd(X.linear() * X_RT_prior.linear().transpose()).angle();
    if (angle < best) {
      best = angle;
      out.X_RT = X;
    }
  }
  out.fit_error_m = fit.fit_error;
  out.correction_deg = best * 180.0 / M_PI;
  const Eigen::Vector3d a = (out.X_RT.linear() * model.handle.axis).normalized();
  // The hand holds the handle: a fit that puts the grasp centre beyond the handle's end has slid
  // along the tool's axis, which a partial view of a tool straight along it (a stick) leaves
  // open. The fitted turn is kept and the grasp centre put back where the prior had it along the
  // handle (stick_1 handed over: 33 cm slid, effector 35 cm off; the turn was right within 12 deg).
  const double along = (p_R_grasp - out.X_RT * model.handle.center).dot(a);
  if (std::abs(along) > model.handle.length / 2 + options.max_axis_offset_m) {
    const Eigen::Vector3d a_prior = (X_RT_prior.linear() * model.handle.axis).normalized();
    const double along_prior = (p_R_grasp - X_RT_prior * model.handle.center).dot(a_prior);
    out.slide_corrected_m = along - along_prior;
    out.X_RT.translation() += out.slide_corrected_m * a;
  }
  out.correction_m = (out.X_RT.translation() - X_RT_prior.translation()).norm();
  const Eigen::Vector3d c = out.X_RT * model.handle.center;
  const Eigen::Vector3d d = p_R_grasp - c;
  out.axis_offset_m = (d - d.dot(a) * a).norm();
  if (fit.fit_error > options.max_fit_error_m) {
    out.reason = Cat("fit error ", fit.fit_error * 1000, " mm > ", options.max_fit_error_m * 1000, " mm");
  } else if (best > options.max_correction_rad) {
    out.reason = Cat("the fit turns the tool by ", out.correction_deg, " deg from the grasp's pose (more than ",
                     options.max_correction_rad * 180 / M_PI, " deg)");
  } else if (out.axis_offset_m > options.max_axis_offset_m) {
    out.reason = Cat("the fitted handle axis passes ", out.axis_offset_m * 100, " cm from the hand (more than ",
                     options.max_axis_offset_m * 100, " cm)");
  } else {
    out.ok = true;
  }
  return out;
}

}  // namespace toolbench::perception
