#include <algorithm>
#include <cmath>

#include "common/check.h"
#include "common/rng.h"
#include "sim/renderer.h"

namespace toolbench::sim {

void DepthNoiseOptions::Validate() const {
  auto require = [](bool ok, const char* field, double value, const char* expected) {
    if (!ok) ThrowInvalid("DepthNoiseOptions: ", field, " = ", value, ", expected ", expected);
  };
  require(subpixel_rms >= 0, "subpixel_rms", subpixel_rms, ">= 0");
  require(baseline > 0, "baseline", baseline, "> 0");
  require(quantization >= 0, "quantization", quantization, ">= 0");
  require(min_range >= 0, "min_range", min_range, ">= 0");
  require(max_range > min_range, "max_range", max_range, "> min_range");
  require(grazing_angle_deg > 0 && grazing_angle_deg <= 90, "grazing_angle_deg",
          grazing_angle_deg, "in (0, 90]");
  require(edge_jump > 0, "edge_jump", edge_jump, "> 0");
  require(edge_dropout >= 0 && edge_dropout <= 1, "edge_dropout", edge_dropout, "in [0, 1]");
  require(rgb_sigma >= 0, "rgb_sigma", rgb_sigma, ">= 0");
}

void ApplySensorNoise(cv::Mat& rgb, cv::Mat& depth, const CameraIntrinsics& K,
                      const DepthNoiseOptions& options, std::uint64_t seed) {
  options.Validate();
  if (depth.type() != CV_32FC1 || rgb.type() != CV_8UC3 || depth.size() != rgb.size()) {
    ThrowInvalid("ApplySensorNoise: expected CV_8UC3 rgb and CV_32FC1 depth of one size");
  }
  if (depth.cols != K.width || depth.rows != K.height) {
    ThrowInvalid("ApplySensorNoise: image ", depth.cols, "x", depth.rows,
                 " does not match the intrinsics ", K.width, "x", K.height);
  }
  Rng rng(seed);
  const int W = depth.cols;
  const int H = depth.rows;
  const cv::Mat ideal = depth.clone();
  const double cos_grazing = std::cos(options.grazing_angle_deg * M_PI / 180.0);
  auto point = [&](int r, int c) {
    const double z = ideal.at<float>(r, c);
    return Eigen::Vector3d((c - K.cx) * z / K.fx, (r - K.cy) * z / K.fy, z);
  };
  for (int r = 0; r < H; ++r) {
    float* out = depth.ptr<float>(r);
    for (int c = 0; c < W; ++c) {
      const double z = ideal.at<float>(r, c);
      // Draw the same number of variates for every pixel, so the stream stays aligned.
      const double u_edge = UniformReal(rng, 0.0, 1.0);
      const double u_graze = UniformReal(rng, 0.0, 1.0);
      const double gauss = StandardNormal(rng);
      if (z <= 0.0) continue;
      if (z < options.min_range || z > options.max_range) {
        out[c] = 0.0f;
        continue;
      }
      if (r > 0 && c > 0 && r < H - 1 && c < W - 1) {
        // Occlusion edges: the far side of a depth jump is often lost by stereo matching.
        double nearest = z;
        for (int dr = -1; dr <= 1; ++dr) {
          for (int dc = -1; dc <= 1; ++dc) {
            const double zn = ideal.at<float>(r + dr, c + dc);
            if (zn > 0.0) nearest = std::min(nearest, zn);
          }
        }
        if (z - nearest > options.edge_jump && u_edge < options.edge_dropout) {
          out[c] = 0.0f;
          continue;
        }
        // Grazing surfaces: no texture survives foreshortening; dropout probability rises over
        // the last 10 degrees before the limit.
        const double zl = ideal.at<float>(r, c - 1), zr = ideal.at<float>(r, c + 1);
        const double zu = ideal.at<float>(r - 1, c), zd = ideal.at<float>(r + 1, c);
        const auto same_surface = [&](double zn) { return zn > 0 && std::abs(zn - z) < options.edge_jump; };
        if (same_surface(zl) && same_surface(zr) && same_surface(zu) && same_surface(zd)) {
          const Eigen::Vector3d n =
              (point(r, c + 1) - point(r, c - 1)).cross(point(r + 1, c) - point(r - 1, c));
          const Eigen::Vector3d ray = point(r, c).normalized();
          if (n.norm() > 0) {
            const double cos_view = std::abs(n.normalized().dot(ray));
            const double cos_soft = std::cos((options.grazing_angle_deg - 10.0) * M_PI / 180.0);
            if (cos_view < cos_grazing) {
              out[c] = 0.0f;
              continue;
            }
            if (cos_view < cos_soft &&
                u_graze < (cos_soft - cos_view) / std::max(1e-9, cos_soft - cos_grazing)) {
              out[c] = 0.0f;
              continue;
            }
          }
        }
      }
      const double sigma = z * z * options.subpixel_rms / (K.fx * options.baseline);
      double noisy = z + sigma * gauss;
      if (options.quantization > 0) {
        noisy = std::round(noisy / options.quantization) * options.quantization;
      }
      out[c] = static_cast<float>(std::max(0.0, noisy));
    }
  }
  if (options.rgb_sigma > 0) {
    for (int r = 0; r < H; ++r) {
      unsigned char* px = rgb.ptr<unsigned char>(r);
      for (int i = 0; i < 3 * W; ++i) {
        const double v = px[i] + options.rgb_sigma * StandardNormal(rng);
        px[i] = static_cast<unsigned char>(std::clamp(std::lround(v), 0L, 255L));
      }
    }
  }
}

}  // namespace toolbench::sim
