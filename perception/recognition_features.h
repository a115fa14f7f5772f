#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "common/types.h"

namespace toolbench::perception {

/// Version of the feature definition below. A classifier file stores the version it was trained
/// on; loading a file of another version fails (its numbers would mean something else).
inline constexpr int kRecognitionFeatureVersion = 1;

/// Configuration of ComputeRecognitionFeatures.
struct RecognitionFeatureOptions {
  int profile_bins = 8;     // slices along the main axis for the profiles, in [2, 32]
  int max_points = 1500;    // the cloud is subsampled evenly (by index) to at most this many
                            // points before the statistics, >= 10
  void Validate() const;    // throws std::invalid_argument naming the field and its value
};

/// Pose-invariant description of one segmented tool, used to tell library models apart
/// regardless of where on the rack and how it lies (colour is never used: tools are coloured by
/// their index in the scene, not by model). All lengths are metric [m] or ratios, so they do not
/// depend on distance to the camera. In the order of RecognitionFeatureNames():
///
/// From the 3D object cloud p_R (root frame; every quantity below is invariant to a rigid motion
/// of the cloud). Extents are robust (2nd to 98th percentile of the coordinates) so a few
/// stray points do not change them:
///   length, width, thickness   extents along the principal axes, largest first [m]
///   width_over_length, thickness_over_width   ratios of the above
///   radius_<k>      k = 0..bins-1: 90th percentile of the distance of the points in slice k to
///                   the main axis (a line through the centroid) [m]. Rotation about the main
///                   axis does not change it.
///   offset_<k>      distance of slice k's centroid from the main axis [m]: large at one-sided
///                   heads (hook, L-stick), small at symmetric ones (hoe blade seen face-on, rake)
///   fraction_<k>    fraction of the points in slice k (how the visible surface is distributed)
///                   The slices run from the end whose half has the larger mean radius ("head")
///                   to the other end, which makes the three profiles invariant to the tool
///                   being turned end over end (rot2).
///   radius_max, radius_median   of the per-point distances to the main axis [m]
///   head_radius_over_tail       mean radius of the head half over the tail half (>= 1)
/// From the 2D mask (metric through the median depth z of the segment, 1 px ~ z / f metres):
///   mask_area       pixel count * (z/fx)(z/fy) [m^2]: the tool's projected area
///   mask_solidity   area / convex hull area, in (0, 1]: low for hooks, rakes, L-sticks
///   mask_rect_fill  area / minimum-area rectangle area, in (0, 1]
///   mask_rect_aspect  long / short side of the minimum-area rectangle (>= 1)
///   hu_1, hu_2      -sign(h) log10 |h| of the first two Hu moments (rotation, scale invariant)
std::vector<std::string> RecognitionFeatureNames(const RecognitionFeatureOptions& options);

/// Computes the features described at RecognitionFeatureNames for one tool: `p_R` is its object
/// cloud (3 x N, root frame R [m], N >= 10), `mask` its segment mask (CV_8UC1, non-zero = tool,
/// of the size in `intrinsics`), `median_depth` the segment's median depth [m] (> 0).
/// Throws std::invalid_argument naming the argument for fewer than 10 points, non-finite
/// points, a mask of the wrong type or size or without any set pixel, a non-positive depth or
/// focal length, or bad options.
std::vector<float> ComputeRecognitionFeatures(const Eigen::Matrix3Xf& p_R, const cv::Mat& mask,
                                              const CameraIntrinsics& intrinsics, double median_depth,
                                              const RecognitionFeatureOptions& options);

}  // namespace toolbench::perception
