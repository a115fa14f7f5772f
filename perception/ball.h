#pragma once

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <string>

#include "common/types.h"

namespace toolbench::perception {

/// Configuration of DetectBall. Colours in HSV with hue in degrees and S, V in
/// [0, 1].
struct BallDetectionOptions {
  double hue_center_deg = 0.0;      // the ball's hue (red) [deg], [0, 360)
  double hue_tolerance_deg = 20.0;  // accepted circular distance from hue_center_deg [deg], (0, 180]
  double min_saturation = 0.5;      // (0, 1)
  double min_value = 0.2;           // [0, 1)
  int min_area_px = 30;             // smaller blobs are ignored [px], > 0
  double expected_radius = 0.035;   // [m], > 0
  double radius_tolerance = 0.35;   // accepted relative radius error of the fitted sphere, (0, 1)
  double max_rms_error = 0.004;     // accepted RMS distance of the points to the sphere [m], > 0
  double min_depth = 0.05;          // depth readings outside [min_depth, max_depth] are ignored [m]
  double max_depth = 4.0;           // [m], > min_depth
  void Validate() const;            // throws std::invalid_argument naming the field and value
};

/// Outcome of DetectBall (an expected failure is a result, not an exception).
enum class BallStatus {
  kFound,
  kNotSeen,   // no blob of the ball's colour
  kNoSphere,  // blobs of the colour, but none fits a sphere of the expected
              // radius
};

/// Where the ball is.
struct BallDetection {
  BallStatus status = BallStatus::kNotSeen;
  std::string reason;                              // empty when kFound
  Eigen::Vector3d p_RB = Eigen::Vector3d::Zero();  // ball centre in the root frame R [m]
  double radius = 0.0;                             // fitted radius [m]
  double rms_error = 0.0;                          // RMS point-to-sphere distance [m]
  int points = 0;                                  // 3D points used by the fit
  cv::Rect roi;                                    // the blob's bounding box [px]
};

/// Finds the ball in an RGB-D frame: blobs of its colour, each blob's depth
/// back-projected and moved to R with frame.X_RC, a sphere fitted to each
/// (algebraic least squares, then Gauss-Newton on the geometric distance); the
/// blob whose sphere has the expected radius and the smallest RMS error wins.
/// Only the visible cap is seen, which the geometric refinement handles. Throws
/// std::invalid_argument for a frame whose rgb is not CV_8UC3 or whose depth is
/// not CV_32FC1 of the same size, or for bad options.
BallDetection DetectBall(const RgbdFrame& frame, const BallDetectionOptions& options);

/// Sphere through 3 x N points (N >= 4): algebraic fit refined by Gauss-Newton
/// on the geometric distance. Returns false when the points are degenerate
/// (coplanar or too few).
bool FitSphere(const Eigen::Matrix3Xd& points, Eigen::Vector3d& center, double& radius, double& rms_error);

}  // namespace toolbench::perception
