#pragma once

#include <string>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "common/types.h"

namespace toolbench::perception {

/// Configuration of ExtractObjectCloud (thesis Alg. 2 and 3, plus outlier removal).
struct ObjectCloudOptions {
  int roi_margin_px = 12;          // the plane is fitted on the mask's bounding box grown by this
                                   // margin, so that it sees the board around the tool [px], >= 0
  double min_depth = 0.05;         // depth readings outside [min_depth, max_depth] are ignored [m], > 0
  double max_depth = 4.0;          // [m], > min_depth
  int max_planes = 2;              // support planes (board, ledge, table) removed at most, >= 0
  double plane_distance = 0.003;   // RANSAC inlier distance; mask points closer to a found plane
                                   // are removed [m], > 0. Small, because flat blades lie on the board
  int max_plane_points = 4000;     // RANSAC runs on an even subsample of at most this many ROI
                                   // points (all object points are still tested), >= 100
  int plane_iterations = 500;      // RANSAC iterations per plane (PCL, fixed seed), > 0
  double min_plane_fraction = 0.15;  // a plane must hold this fraction of the ROI points to count
                                     // as support, in (0, 1]
  int outlier_neighbours = 20;     // StatisticalOutlierRemoval mean_k, > 0; 0 disables the filter
  double outlier_stddev = 2.0;     // StatisticalOutlierRemoval stddev multiplier, > 0
  int min_points = 30;             // fewer object points than this -> kTooFewPoints, >= 4
  void Validate() const;           // throws std::invalid_argument naming the field and value
};

/// Why a cloud is empty (an expected failure is a result, not an exception).
enum class CloudStatus {
  kOk,
  kEmptyMask,     // the mask selects no pixel
  kNoDepth,       // every masked pixel has depth 0, NaN, infinite or outside [min, max]
  kTooFewPoints,  // fewer than min_points survive plane and outlier removal
};

/// The 3D points of one tool.
struct ObjectCloud {
  CloudStatus status = CloudStatus::kEmptyMask;
  std::string reason;          // human-readable cause when status != kOk, else empty
  Eigen::Matrix3Xf p_R;        // 3 x N tool points in the robot root frame R [m]; empty unless kOk
  int masked_pixels = 0;       // pixels selected by the mask
  int valid_depth = 0;         // of those, pixels with a usable depth
  int plane_points = 0;        // removed as lying on a support plane
  int outlier_points = 0;      // removed by the statistical outlier filter
  int planes_found = 0;        // support planes found around the mask
};

/// Back-projects the depth inside `mask` with the pinhole model (thesis Alg. 2), moves it to R
/// with frame.X_RC, removes points on the support planes found by RANSAC around the mask (thesis
/// Alg. 3; PCL SACSegmentation, plane model, deterministic) and statistical outliers.
/// `mask` is CV_8U of the depth image's size, non-zero = tool.
/// Throws std::invalid_argument for an empty or non-CV_32FC1 depth, a mask of another size or
/// type, intrinsics that do not match the image or have non-positive focal lengths, or bad options.
ObjectCloud ExtractObjectCloud(const RgbdFrame& frame, const cv::Mat& mask, const ObjectCloudOptions& options);

/// Back-projects every pixel of `mask` with a usable depth to the camera frame C (OpenCV
/// convention) [m], no filtering; the helper ExtractObjectCloud starts from. Same preconditions.
Eigen::Matrix3Xf BackProjectMask(const RgbdFrame& frame, const cv::Mat& mask, double min_depth, double max_depth);

}  // namespace toolbench::perception
