#include "perception/object_cloud.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include <opencv2/imgproc.hpp>
#include <pcl/ModelCoefficients.h>
#include <pcl/console/print.h>
#include <pcl/filters/statistical_outlier_removal.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>
#include <pcl/sample_consensus/method_types.h>
#include <pcl/sample_consensus/model_types.h>
#include <pcl/segmentation/sac_segmentation.h>
#include <spdlog/spdlog.h>

#include "common/check.h"
#include "perception/internal/log.h"

namespace toolbench::perception {
namespace {

void CheckFrame(const RgbdFrame& frame, const cv::Mat& mask, const char* function) {
  if (frame.depth.empty() || frame.depth.type() != CV_32FC1) {
    ThrowInvalid(function, ": frame.depth must be a non-empty CV_32FC1 image (got ",
                 frame.depth.empty() ? "empty" : "another type", ")");
  }
  if (mask.size() != frame.depth.size() || mask.type() != CV_8UC1) {
    ThrowInvalid(function, ": argument mask must be CV_8UC1 of size ", frame.depth.cols, "x", frame.depth.rows,
                 " (got ", mask.cols, "x", mask.rows, " type ", mask.type(), ")");
  }
  const CameraIntrinsics& K = frame.intrinsics;
  if (K.width != frame.depth.cols || K.height != frame.depth.rows || !(K.fx > 0) || !(K.fy > 0)) {
    ThrowInvalid(function, ": frame.intrinsics ", K.width, "x", K.height, " fx ", K.fx, " fy ", K.fy,
                 " do not describe the ", frame.depth.cols, "x", frame.depth.rows, " depth image");
  }
}

bool UsableDepth(float z, double min_depth, double max_depth) {
  return std::isfinite(z) && z >= min_depth && z <= max_depth;
}

Eigen::Vector3f Unproject(const CameraIntrinsics& K, int u, int v, float z) {
  // Thesis Alg. 2 (pinhole model, pixel-index coordinates).
  return {static_cast<float>(z * (u - K.cx) / K.fx), static_cast<float>(z * (v - K.cy) / K.fy), z};
}

}  // namespace

void ObjectCloudOptions::Validate() const {
  const char* f = "ObjectCloudOptions::Validate: ";
  if (roi_margin_px < 0) ThrowInvalid(f, "roi_margin_px = ", roi_margin_px, " (expected >= 0)");
  if (!(min_depth > 0)) ThrowInvalid(f, "min_depth = ", min_depth, " (expected > 0)");
  if (!(max_depth > min_depth)) ThrowInvalid(f, "max_depth = ", max_depth, " (expected > min_depth ", min_depth, ")");
  if (max_plane_points < 100) ThrowInvalid(f, "max_plane_points = ", max_plane_points, " (expected >= 100)");
  if (max_planes < 0) ThrowInvalid(f, "max_planes = ", max_planes, " (expected >= 0)");
  if (!(plane_distance > 0)) ThrowInvalid(f, "plane_distance = ", plane_distance, " (expected > 0)");
  if (plane_iterations <= 0) ThrowInvalid(f, "plane_iterations = ", plane_iterations, " (expected > 0)");
  if (!(min_plane_fraction > 0 && min_plane_fraction <= 1)) {
    ThrowInvalid(f, "min_plane_fraction = ", min_plane_fraction, " (expected in (0, 1])");
  }
  if (outlier_neighbours < 0) ThrowInvalid(f, "outlier_neighbours = ", outlier_neighbours, " (expected >= 0)");
  if (!(outlier_stddev > 0)) ThrowInvalid(f, "outlier_stddev = ", outlier_stddev, " (expected > 0)");
  if (min_points < 4) ThrowInvalid(f, "min_points = ", min_points, " (expected >= 4)");
}

Eigen::Matrix3Xf BackProjectMask(const RgbdFrame& frame, const cv::Mat& mask, double min_depth, double max_depth) {
  CheckFrame(frame, mask, "BackProjectMask");
  std::vector<Eigen::Vector3f> points;
  for (int v = 0; v < mask.rows; ++v) {
    const unsigned char* m = mask.ptr<unsigned char>(v);
    const float* d = frame.depth.ptr<float>(v);
    for (int u = 0; u < mask.cols; ++u) {
      if (m[u] != 0 && UsableDepth(d[u], min_depth, max_depth)) points.push_back(Unproject(frame.intrinsics, u, v, d[u]));
    }
  }
  Eigen::Matrix3Xf out(3, static_cast<Eigen::Index>(points.size()));
  for (std::size_t i = 0; i < points.size(); ++i) out.col(static_cast<Eigen::Index>(i)) = points[i];
  return out;
}

ObjectCloud ExtractObjectCloud(const RgbdFrame& frame, const cv::Mat& mask, const ObjectCloudOptions& options) {
  CheckFrame(frame, mask, "ExtractObjectCloud");
  options.Validate();
  pcl::console::setVerbosityLevel(pcl::console::L_ERROR);
  ObjectCloud result;
  result.masked_pixels = cv::countNonZero(mask);
  if (result.masked_pixels == 0) {
    result.status = CloudStatus::kEmptyMask;
    result.reason = "the mask selects no pixel";
    return result;
  }

  // Object points (inside the mask) and ROI points (the grown bounding box, which mostly sees
  // the board, ledge or table around the tool, so RANSAC finds the support there).
  const cv::Rect roi = cv::boundingRect(mask);
  const cv::Rect grown = cv::Rect(roi.x - options.roi_margin_px, roi.y - options.roi_margin_px,
                                  roi.width + 2 * options.roi_margin_px, roi.height + 2 * options.roi_margin_px) &
                         cv::Rect(0, 0, mask.cols, mask.rows);
  std::vector<Eigen::Vector3f> roi_points;
  std::vector<char> roi_points_in_mask;
  std::vector<Eigen::Vector3f> object;
  for (int v = grown.y; v < grown.br().y; ++v) {
    const unsigned char* m = mask.ptr<unsigned char>(v);
    const float* d = frame.depth.ptr<float>(v);
    for (int u = grown.x; u < grown.br().x; ++u) {
      if (!UsableDepth(d[u], options.min_depth, options.max_depth)) continue;
      const Eigen::Vector3f p_C = Unproject(frame.intrinsics, u, v, d[u]);
      roi_points.push_back(p_C);
      roi_points_in_mask.push_back(m[u] != 0 ? 1 : 0);
      if (m[u] != 0) object.push_back(p_C);
    }
  }
  // RANSAC counts inliers over every point in every iteration: an even subsample of the ROI
  // finds the same support planes at a fraction of the cost (a long tool lying across the
  // view has a ROI of 50k+ points). Every object point is still tested against the planes.
  auto roi_cloud = std::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
  std::vector<char> roi_in_mask;
  const std::size_t stride = std::max<std::size_t>(
      1, (roi_points.size() + static_cast<std::size_t>(options.max_plane_points) - 1) /
             static_cast<std::size_t>(options.max_plane_points));
  for (std::size_t i = 0; i < roi_points.size(); i += stride) {
    roi_cloud->push_back(pcl::PointXYZ(roi_points[i].x(), roi_points[i].y(), roi_points[i].z()));
    roi_in_mask.push_back(roi_points_in_mask[i]);
  }
  result.valid_depth = static_cast<int>(object.size());
  if (object.empty()) {
    result.status = CloudStatus::kNoDepth;
    result.reason = Cat("none of the ", result.masked_pixels, " masked pixels has a depth in [", options.min_depth,
                        ", ", options.max_depth, "] m (all zero, NaN or out of range)");
    return result;
  }

  // Thesis Alg. 3, repeated for up to max_planes supports. A plane counts as support only when
  // most of its inliers lie outside the mask; otherwise it is the tool's own flat face.
  std::vector<Eigen::Vector4f> planes;
  std::vector<char> removed(roi_cloud->size(), 0);
  for (int k = 0; k < options.max_planes; ++k) {
    auto remaining = std::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
    std::vector<std::size_t> back;
    for (std::size_t i = 0; i < roi_cloud->size(); ++i) {
      if (removed[i] == 0) {
        remaining->push_back((*roi_cloud)[i]);
        back.push_back(i);
      }
    }
    if (remaining->size() < 3) break;
    pcl::SACSegmentation<pcl::PointXYZ> sac(/*random=*/false);
    sac.setOptimizeCoefficients(true);
    sac.setModelType(pcl::SACMODEL_PLANE);
    sac.setMethodType(pcl::SAC_RANSAC);
    sac.setDistanceThreshold(options.plane_distance);
    sac.setMaxIterations(options.plane_iterations);
    sac.setInputCloud(remaining);
    pcl::PointIndices inliers;
    pcl::ModelCoefficients coefficients;
    sac.segment(inliers, coefficients);
    // PCL reports failure by printing and leaving the output empty: turn that into a stop.
    if (inliers.indices.empty() || coefficients.values.size() != 4) break;
    const double fraction = static_cast<double>(inliers.indices.size()) / static_cast<double>(roi_cloud->size());
    std::size_t in_mask = 0;
    for (int i : inliers.indices) in_mask += roi_in_mask[back[static_cast<std::size_t>(i)]];
    if (fraction < options.min_plane_fraction || 2 * in_mask > inliers.indices.size()) break;
    for (int i : inliers.indices) removed[back[static_cast<std::size_t>(i)]] = 1;
    Eigen::Vector4f plane(coefficients.values[0], coefficients.values[1], coefficients.values[2],
                          coefficients.values[3]);
    plane /= plane.head<3>().norm();
    planes.push_back(plane);
  }
  result.planes_found = static_cast<int>(planes.size());

  auto kept = std::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
  for (const Eigen::Vector3f& p : object) {
    bool on_plane = false;
    for (const Eigen::Vector4f& plane : planes) {
      on_plane = on_plane || std::abs(plane.head<3>().dot(p) + plane.w()) < options.plane_distance;
    }
    if (on_plane) {
      ++result.plane_points;
    } else {
      kept->push_back(pcl::PointXYZ(p.x(), p.y(), p.z()));
    }
  }

  pcl::PointCloud<pcl::PointXYZ> filtered;
  if (options.outlier_neighbours > 0 && static_cast<int>(kept->size()) > options.outlier_neighbours) {
    pcl::StatisticalOutlierRemoval<pcl::PointXYZ> sor;
    sor.setInputCloud(kept);
    sor.setMeanK(options.outlier_neighbours);
    sor.setStddevMulThresh(options.outlier_stddev);
    sor.filter(filtered);
  } else {
    filtered = *kept;
  }
  result.outlier_points = static_cast<int>(kept->size() - filtered.size());
  if (static_cast<int>(filtered.size()) < options.min_points) {
    result.status = CloudStatus::kTooFewPoints;
    result.reason = Cat(filtered.size(), " points left after removing ", result.plane_points, " plane and ",
                        result.outlier_points, " outlier points (need >= ", options.min_points, ")");
    return result;
  }
  const Eigen::Matrix3f R_RC = frame.X_RC.linear().cast<float>();
  const Eigen::Vector3f p_RC = frame.X_RC.translation().cast<float>();
  result.p_R.resize(3, static_cast<Eigen::Index>(filtered.size()));
  for (std::size_t i = 0; i < filtered.size(); ++i) {
    result.p_R.col(static_cast<Eigen::Index>(i)) = R_RC * filtered[i].getVector3fMap() + p_RC;
  }
  result.status = CloudStatus::kOk;
  internal::Logger()->debug("object cloud: {} px, {} depth, {} on {} planes, {} outliers, {} kept",
                            result.masked_pixels, result.valid_depth, result.plane_points, result.planes_found,
                            result.outlier_points, result.p_R.cols());
  return result;
}

}  // namespace toolbench::perception
