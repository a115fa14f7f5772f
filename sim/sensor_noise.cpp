#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include <opencv2/imgproc.hpp>

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
  // Gaussian variates come from a table of 65536 standard normals drawn from the seed, indexed
  // by 16 random bits: four per 64-bit draw. Exact Box-Muller per pixel and channel cost ~50 ms
  // a frame; this costs a few.
  // Per-pixel random bits come from a counter-based hash (SplitMix64 of seed and pixel index):
  // as reproducible as the engine and several times cheaper than mt19937_64 per pixel.
  constexpr int kTableBits = 12;
  constexpr std::uint64_t kMask = (1u << kTableBits) - 1;
  std::vector<float> normal(1u << kTableBits);
  {
    // Standardised: exactly zero mean and unit variance, so the table adds no bias.
    std::vector<double> draws(normal.size());
    double mean = 0.0, var = 0.0;
    for (double& v : draws) mean += (v = StandardNormal(rng));
    mean /= draws.size();
    for (double v : draws) var += (v - mean) * (v - mean);
    const double inv_std = 1.0 / std::sqrt(var / draws.size());
    for (size_t i = 0; i < draws.size(); ++i) normal[i] = static_cast<float>((draws[i] - mean) * inv_std);
  }
  constexpr std::uint64_t kBits16 = 0xffff;
  constexpr double kUnit16 = 1.0 / 65536.0;
  const std::uint64_t stream = rng();
  const auto pixel_bits = [stream](std::uint64_t index) {
    std::uint64_t z = stream + 0x9e3779b97f4a7c15ull * (index + 1);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
  };

  const int W = depth.cols;
  const int H = depth.rows;
  const cv::Mat ideal = depth.clone();
  // Nearest depth in each 3x3 neighbourhood (no-return pixels ignored), one vectorised pass.
  cv::Mat nearest_map;
  {
    cv::Mat z_inf = ideal.clone();
    z_inf.setTo(std::numeric_limits<float>::max(), ideal <= 0.0f);
    cv::erode(z_inf, nearest_map, cv::Mat::ones(3, 3, CV_8U), cv::Point(-1, -1), 1,
              cv::BORDER_REPLICATE);
  }
  const double cos_grazing = std::cos(options.grazing_angle_deg * M_PI / 180.0);
  const double cos_soft = std::cos((options.grazing_angle_deg - 10.0) * M_PI / 180.0);
  const double sigma_scale = options.subpixel_rms / (K.fx * options.baseline);
  const double inv_quantization = options.quantization > 0 ? 1.0 / options.quantization : 0.0;
  for (int r = 0; r < H; ++r) {
    float* out = depth.ptr<float>(r);
    const float* z_row = ideal.ptr<float>(r);
    for (int c = 0; c < W; ++c) {
      const std::uint64_t bits = pixel_bits(static_cast<std::uint64_t>(r) * W + c);
      const double z = z_row[c];
      if (z <= 0.0) continue;
      if (z < options.min_range || z > options.max_range) {
        out[c] = 0.0f;
        continue;
      }
      const double u_edge = static_cast<double>(bits & kBits16) * kUnit16;
      const double u_graze = static_cast<double>((bits >> 16) & kBits16) * kUnit16;
      const double gauss = normal[(bits >> 32) & kMask];
      if (r > 0 && c > 0 && r < H - 1 && c < W - 1) {
        const float* up = ideal.ptr<float>(r - 1);
        const float* down = ideal.ptr<float>(r + 1);
        // Occlusion edges: the far side of a depth jump is often lost by stereo matching.
        const double nearest = nearest_map.ptr<float>(r)[c];
        if (z - nearest > options.edge_jump && u_edge < options.edge_dropout) {
          out[c] = 0.0f;
          continue;
        }
        // Grazing surfaces: no texture survives foreshortening; dropout probability rises over
        // the last 10 degrees before the limit. With P(u, v) = z(u, v) ray(u, v), the normal is
        // dP/du x dP/dv and its component along the ray is z^2 / (fx fy) (a closed form).
        const double zl = z_row[c - 1], zr = z_row[c + 1], zu = up[c], zd = down[c];
        const auto same = [&](double zn) { return zn > 0 && std::abs(zn - z) < options.edge_jump; };
        if (same(zl) && same(zr) && same(zu) && same(zd)) {
          const double rx = (c - K.cx) / K.fx, ry = (r - K.cy) / K.fy;
          const double z_u = (zr - zl) / 2.0, z_v = (zd - zu) / 2.0;
          // dP/du = z_u (rx, ry, 1) + (z / fx, 0, 0); dP/dv = z_v (rx, ry, 1) + (0, z / fy, 0).
          const double ax = z_u * rx + z / K.fx, ay = z_u * ry, az = z_u;
          const double bx = z_v * rx, by = z_v * ry + z / K.fy, bz = z_v;
          const double nx = ay * bz - az * by, ny = az * bx - ax * bz, nz = ax * by - ay * bx;
          // cos^2 of the viewing angle, compared without square roots (this runs per pixel).
          const double n2 = nx * nx + ny * ny + nz * nz;
          const double dot = nx * rx + ny * ry + nz;
          const double cos2 = dot * dot / (n2 * (rx * rx + ry * ry + 1.0));
          if (n2 > 0 && cos2 < cos_soft * cos_soft) {
            const double cos_view = std::sqrt(cos2);
            if (cos_view < cos_grazing ||
                u_graze < (cos_soft - cos_view) / std::max(1e-9, cos_soft - cos_grazing)) {
              out[c] = 0.0f;
              continue;
            }
          }
        }
      }
      double noisy = z + z * z * sigma_scale * gauss;
      if (options.quantization > 0) {
        noisy = std::nearbyint(noisy * inv_quantization) * options.quantization;
      }
      out[c] = static_cast<float>(std::max(0.0, noisy));
    }
  }
  if (options.rgb_sigma > 0) {
    const float sigma = static_cast<float>(options.rgb_sigma);
    for (int r = 0; r < H; ++r) {
      unsigned char* px = rgb.ptr<unsigned char>(r);
      for (int i = 0; i < 3 * W; i += 4) {
        std::uint64_t bits = pixel_bits((static_cast<std::uint64_t>(H + r) * 3 * W) + i);
        for (int k = 0; k < 4 && i + k < 3 * W; ++k, bits >>= 16) {
          const float v = px[i + k] + sigma * normal[bits & kMask] + 0.5f;
          px[i + k] = static_cast<unsigned char>(std::clamp(v, 0.0f, 255.0f));
        }
      }
    }
  }
}

}  // namespace toolbench::sim
