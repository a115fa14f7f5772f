#include "perception/recognition_features.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Eigenvalues>
#include <opencv2/imgproc.hpp>

#include "common/check.h"

namespace toolbench::perception {
namespace {

constexpr int kMinFeaturePoints = 10;

// q-quantile (q in [0, 1]) of `values`; reorders them.
double Quantile(std::vector<double>& values, double q) {
  if (values.empty()) return 0.0;
  const auto k = static_cast<std::ptrdiff_t>(std::lround(q * static_cast<double>(values.size() - 1)));
  std::nth_element(values.begin(), values.begin() + k, values.end());
  return values[static_cast<std::size_t>(k)];
}

float SignedLog(double h) {
  if (std::abs(h) < 1e-30) return 30.0f;
  return static_cast<float>(-std::copysign(1.0, h) * std::log10(std::abs(h)));
}

}  // namespace

void RecognitionFeatureOptions::Validate() const {
  if (profile_bins < 2 || profile_bins > 32) {
    ThrowInvalid("RecognitionFeatureOptions::Validate: profile_bins = ", profile_bins, " (expected in [2, 32])");
  }
  if (max_points < kMinFeaturePoints) {
    ThrowInvalid("RecognitionFeatureOptions::Validate: max_points = ", max_points, " (expected >= ",
                 kMinFeaturePoints, ")");
  }
}

std::vector<std::string> RecognitionFeatureNames(const RecognitionFeatureOptions& options) {
  options.Validate();
  std::vector<std::string> names = {"length", "width", "thickness", "width_over_length", "thickness_over_width"};
  for (const char* profile : {"radius_", "offset_", "fraction_"}) {
    for (int k = 0; k < options.profile_bins; ++k) names.push_back(profile + std::to_string(k));
  }
  for (const char* name : {"radius_max", "radius_median", "head_radius_over_tail", "mask_area", "mask_solidity",
                           "mask_rect_fill", "mask_rect_aspect", "hu_1", "hu_2"}) {
    names.emplace_back(name);
  }
  return names;
}

std::vector<float> ComputeRecognitionFeatures(const Eigen::Matrix3Xf& p_R, const cv::Mat& mask,
                                              const CameraIntrinsics& intrinsics, double median_depth,
                                              const RecognitionFeatureOptions& options) {
  const char* f = "ComputeRecognitionFeatures: ";
  options.Validate();
  if (p_R.cols() < kMinFeaturePoints) {
    ThrowInvalid(f, "argument p_R has ", p_R.cols(), " points (expected >= ", kMinFeaturePoints, ")");
  }
  if (!p_R.allFinite()) ThrowInvalid(f, "argument p_R has a non-finite coordinate (expected finite points)");
  if (mask.empty() || mask.type() != CV_8UC1) {
    ThrowInvalid(f, "argument mask is empty or not CV_8UC1 (type ", mask.type(), ")");
  }
  if (mask.cols != intrinsics.width || mask.rows != intrinsics.height) {
    ThrowInvalid(f, "argument mask is ", mask.cols, "x", mask.rows, " (expected the intrinsics' ", intrinsics.width,
                 "x", intrinsics.height, ")");
  }
  if (!(intrinsics.fx > 0) || !(intrinsics.fy > 0)) {
    ThrowInvalid(f, "argument intrinsics has focal lengths ", intrinsics.fx, ", ", intrinsics.fy, " (expected > 0)");
  }
  if (!(median_depth > 0) || !std::isfinite(median_depth)) {
    ThrowInvalid(f, "argument median_depth = ", median_depth, " (expected a finite depth > 0 [m])");
  }
  const int bins = options.profile_bins;

  // ---- 3D: principal frame of an evenly subsampled cloud. ----
  const Eigen::Index n = std::min<Eigen::Index>(p_R.cols(), options.max_points);
  Eigen::Matrix3Xd p(3, n);
  const double stride = static_cast<double>(p_R.cols()) / static_cast<double>(n);
  for (Eigen::Index i = 0; i < n; ++i) p.col(i) = p_R.col(static_cast<Eigen::Index>(i * stride)).cast<double>();
  const Eigen::Vector3d centroid = p.rowwise().mean();
  const Eigen::Matrix3Xd centred = p.colwise() - centroid;
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(centred * centred.transpose() / static_cast<double>(n));
  Eigen::Matrix3d axes;
  for (int i = 0; i < 3; ++i) axes.col(i) = solver.eigenvectors().col(2 - i);  // largest variance first
  const Eigen::Matrix3Xd local = axes.transpose() * centred;

  std::vector<double> extents(3);
  std::vector<double> lo(3);
  for (int a = 0; a < 3; ++a) {
    std::vector<double> values(static_cast<std::size_t>(n));
    for (Eigen::Index i = 0; i < n; ++i) values[static_cast<std::size_t>(i)] = local(a, i);
    lo[static_cast<std::size_t>(a)] = Quantile(values, 0.02);
    extents[static_cast<std::size_t>(a)] = Quantile(values, 0.98) - lo[static_cast<std::size_t>(a)];
  }
  const double length = std::max(extents[0], 1e-6);

  // Per point: position along the main axis in [0, 1] and distance to the main axis.
  std::vector<double> t(static_cast<std::size_t>(n));
  std::vector<double> radius(static_cast<std::size_t>(n));
  double head_sum[2] = {0, 0};
  int head_count[2] = {0, 0};
  for (Eigen::Index i = 0; i < n; ++i) {
    const auto s = static_cast<std::size_t>(i);
    t[s] = std::clamp((local(0, i) - lo[0]) / length, 0.0, 1.0);
    radius[s] = local.col(i).tail<2>().norm();
    const int half = t[s] < 0.5 ? 0 : 1;
    head_sum[half] += radius[s];
    ++head_count[half];
  }
  const double mean_first = head_count[0] > 0 ? head_sum[0] / head_count[0] : 0.0;
  const double mean_second = head_count[1] > 0 ? head_sum[1] / head_count[1] : 0.0;
  // Canonical direction: the wider half first, so a tool turned end over end reads the same.
  const bool reverse = mean_second > mean_first;
  std::vector<std::vector<double>> bin_radius(static_cast<std::size_t>(bins));
  std::vector<Eigen::Vector2d> bin_sum(static_cast<std::size_t>(bins), Eigen::Vector2d::Zero());
  for (Eigen::Index i = 0; i < n; ++i) {
    const auto s = static_cast<std::size_t>(i);
    const double u = reverse ? 1.0 - t[s] : t[s];
    const int k = std::min(bins - 1, static_cast<int>(u * bins));
    bin_radius[static_cast<std::size_t>(k)].push_back(radius[s]);
    bin_sum[static_cast<std::size_t>(k)] += local.col(i).tail<2>();
  }

  std::vector<float> out;
  out.reserve(static_cast<std::size_t>(5 + 3 * bins + 9));
  out.push_back(static_cast<float>(extents[0]));
  out.push_back(static_cast<float>(extents[1]));
  out.push_back(static_cast<float>(extents[2]));
  out.push_back(static_cast<float>(extents[1] / length));
  out.push_back(static_cast<float>(extents[2] / std::max(extents[1], 1e-6)));
  std::vector<float> offsets;
  std::vector<float> fractions;
  for (int k = 0; k < bins; ++k) {
    auto& r = bin_radius[static_cast<std::size_t>(k)];
    const double count = static_cast<double>(r.size());
    fractions.push_back(static_cast<float>(count / static_cast<double>(n)));
    offsets.push_back(r.empty() ? 0.0f : static_cast<float>((bin_sum[static_cast<std::size_t>(k)] / count).norm()));
    out.push_back(static_cast<float>(Quantile(r, 0.9)));
  }
  out.insert(out.end(), offsets.begin(), offsets.end());
  out.insert(out.end(), fractions.begin(), fractions.end());
  std::vector<double> all_radius = radius;
  const double radius_max = Quantile(all_radius, 0.98);
  const double radius_median = Quantile(all_radius, 0.5);
  out.push_back(static_cast<float>(radius_max));
  out.push_back(static_cast<float>(radius_median));
  const double head = std::max(mean_first, mean_second);
  const double tail = std::min(mean_first, mean_second);
  out.push_back(static_cast<float>(head / std::max(tail, 1e-6)));

  // ---- 2D: mask shape, made metric with the segment's depth. ----
  const cv::Rect box = cv::boundingRect(mask);
  if (box.area() == 0) ThrowInvalid(f, "argument mask has no set pixel");
  const cv::Mat roi = mask(box);
  const double area_px = cv::countNonZero(roi);
  const double metres_per_px_sq = (median_depth / intrinsics.fx) * (median_depth / intrinsics.fy);
  std::vector<cv::Point> pixels;
  cv::findNonZero(roi, pixels);
  std::vector<cv::Point> hull;
  cv::convexHull(pixels, hull);
  // Pixel centres: a hull through them misses half a pixel all round, so compare with the
  // area of the hull grown by that border (perimeter / 2) plus the corners.
  const double hull_area = cv::contourArea(hull) + 0.5 * cv::arcLength(hull, true) + 1.0;
  const cv::RotatedRect rect = cv::minAreaRect(pixels);
  const double side_a = rect.size.width + 1.0;
  const double side_b = rect.size.height + 1.0;
  const cv::Moments moments = cv::moments(roi, true);
  double hu[7];
  cv::HuMoments(moments, hu);
  out.push_back(static_cast<float>(area_px * metres_per_px_sq));
  out.push_back(static_cast<float>(std::min(1.0, area_px / hull_area)));
  out.push_back(static_cast<float>(std::min(1.0, area_px / (side_a * side_b))));
  out.push_back(static_cast<float>(std::max(side_a, side_b) / std::min(side_a, side_b)));
  out.push_back(SignedLog(hu[0]));
  out.push_back(SignedLog(hu[1]));
  TOOLBENCH_DEMAND(out.size() == RecognitionFeatureNames(options).size());
  return out;
}

}  // namespace toolbench::perception
