#include "perception/segmentation.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <numeric>

#include <opencv2/imgproc.hpp>
#include <spdlog/spdlog.h>

#include "common/check.h"
#include "perception/internal/log.h"

namespace toolbench::perception {
namespace {

constexpr int kHueBins = 36;  // 10-degree bins
constexpr double kHueBinDeg = 360.0 / kHueBins;

double HueDistance(double a, double b) {
  const double d = std::fmod(std::abs(a - b), 360.0);
  return std::min(d, 360.0 - d);
}

int HueBin(float hue) { return std::clamp(static_cast<int>(hue / kHueBinDeg), 0, kHueBins - 1); }

// Circular mean hue [deg] of the pixels of `mask`.
double MeanHue(const cv::Mat& hsv, const cv::Mat& mask) {
  double sx = 0.0;
  double sy = 0.0;
  for (int v = 0; v < mask.rows; ++v) {
    const unsigned char* m = mask.ptr<unsigned char>(v);
    const cv::Vec3f* p = hsv.ptr<cv::Vec3f>(v);
    for (int u = 0; u < mask.cols; ++u) {
      if (m[u] == 0) continue;
      const double h = p[u][0] * M_PI / 180.0;
      sx += std::cos(h);
      sy += std::sin(h);
    }
  }
  const double deg = std::atan2(sy, sx) * 180.0 / M_PI;
  return deg < 0 ? deg + 360.0 : deg;
}

// Hue modes of a blob: local maxima of the circularly smoothed histogram holding at least
// min_fraction of the pixels (summed over the peak's +-1 bins), strongest first.
std::vector<double> HueModes(const std::array<double, kHueBins>& histogram, double total, double min_fraction) {
  std::array<double, kHueBins> smooth{};
  for (int i = 0; i < kHueBins; ++i) {
    smooth[i] = histogram[(i + kHueBins - 1) % kHueBins] + histogram[i] + histogram[(i + 1) % kHueBins];
  }
  std::vector<std::pair<double, double>> peaks;  // (mass, hue)
  for (int i = 0; i < kHueBins; ++i) {
    const double left = smooth[(i + kHueBins - 1) % kHueBins];
    const double right = smooth[(i + 1) % kHueBins];
    if (smooth[i] >= left && smooth[i] > right && smooth[i] >= min_fraction * total) {
      peaks.emplace_back(smooth[i], (i + 0.5) * kHueBinDeg);
    }
  }
  std::sort(peaks.begin(), peaks.end(), [](const auto& a, const auto& b) { return a.first > b.first; });
  std::vector<double> modes;
  for (const auto& peak : peaks) modes.push_back(peak.second);
  return modes;
}

double MedianDepth(const cv::Mat& depth, const cv::Mat& mask) {
  if (depth.empty()) return 0.0;
  std::vector<float> values;
  for (int v = 0; v < mask.rows; ++v) {
    const unsigned char* m = mask.ptr<unsigned char>(v);
    const float* d = depth.ptr<float>(v);
    for (int u = 0; u < mask.cols; ++u) {
      if (m[u] != 0 && std::isfinite(d[u]) && d[u] > 0) values.push_back(d[u]);
    }
  }
  if (values.empty()) return 0.0;
  std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(values.size() / 2), values.end());
  return values[values.size() / 2];
}

// Pixels on either side of a depth jump larger than `jump` (4-neighbourhood), 255 = edge.
cv::Mat DepthEdges(const cv::Mat& depth, double jump) {
  cv::Mat edges = cv::Mat::zeros(depth.size(), CV_8UC1);
  auto valid = [](float z) { return std::isfinite(z) && z > 0; };
  for (int v = 0; v < depth.rows; ++v) {
    const float* d = depth.ptr<float>(v);
    const float* below = v + 1 < depth.rows ? depth.ptr<float>(v + 1) : nullptr;
    unsigned char* e = edges.ptr<unsigned char>(v);
    unsigned char* e_below = below != nullptr ? edges.ptr<unsigned char>(v + 1) : nullptr;
    for (int u = 0; u < depth.cols; ++u) {
      if (!valid(d[u])) continue;
      if (u + 1 < depth.cols && valid(d[u + 1]) && std::abs(d[u] - d[u + 1]) > jump) e[u] = e[u + 1] = 255;
      if (below != nullptr && valid(below[u]) && std::abs(d[u] - below[u]) > jump) e[u] = e_below[u] = 255;
    }
  }
  return edges;
}

struct Piece {
  cv::Mat mask;
  double hue = 0.0;
  double depth = 0.0;
  int area = 0;
};

// Connected components of `mask` as separate masks, each at least min_area pixels.
std::vector<cv::Mat> Components(const cv::Mat& mask, int min_area) {
  cv::Mat labels;
  cv::Mat stats;
  cv::Mat centroids;
  const int count = cv::connectedComponentsWithStats(mask, labels, stats, centroids, 8, CV_32S);
  std::vector<cv::Mat> out;
  for (int label = 1; label < count; ++label) {
    if (stats.at<int>(label, cv::CC_STAT_AREA) < min_area) continue;
    out.push_back(labels == label);
  }
  return out;
}

// The pixels on the straight line between the closest points of two masks (3 px wide),
// excluding the masks themselves.
cv::Mat GapPath(const cv::Mat& a, const cv::Mat& b) {
  const auto closest_to = [](const cv::Mat& from, const cv::Mat& to) {
    cv::Mat distance;
    cv::distanceTransform(~from, distance, cv::DIST_L2, 3);
    double min_value = 0.0;
    cv::Point location;
    cv::minMaxLoc(distance, &min_value, nullptr, &location, nullptr, to);
    return location;
  };
  const cv::Point on_b = closest_to(a, b);
  const cv::Point on_a = closest_to(b, a);
  cv::Mat path = cv::Mat::zeros(a.size(), CV_8UC1);
  cv::line(path, on_a, on_b, cv::Scalar(255), 3);
  return path & ~a & ~b;
}

}  // namespace

void SegmentationOptions::Validate() const {
  const char* f = "SegmentationOptions::Validate: ";
  if (!(background_band > 0)) ThrowInvalid(f, "background_band = ", background_band, " (expected > 0)");
  if (!(min_saturation > 0 && min_saturation < 1)) {
    ThrowInvalid(f, "min_saturation = ", min_saturation, " (expected in (0, 1))");
  }
  if (!(min_value >= 0 && min_value < 1)) ThrowInvalid(f, "min_value = ", min_value, " (expected in [0, 1))");
  if (!(dominant_hue_fraction > 0 && dominant_hue_fraction <= 1)) {
    ThrowInvalid(f, "dominant_hue_fraction = ", dominant_hue_fraction, " (expected in (0, 1])");
  }
  if (!(depth_edge > 0)) ThrowInvalid(f, "depth_edge = ", depth_edge, " (expected > 0)");
  if (!(hue_split_deg > 0 && hue_split_deg <= 180)) {
    ThrowInvalid(f, "hue_split_deg = ", hue_split_deg, " (expected in (0, 180])");
  }
  if (!(min_mode_fraction > 0 && min_mode_fraction <= 0.5)) {
    ThrowInvalid(f, "min_mode_fraction = ", min_mode_fraction, " (expected in (0, 0.5])");
  }
  if (open_iterations < 0) ThrowInvalid(f, "open_iterations = ", open_iterations, " (expected >= 0)");
  if (close_iterations < 0) ThrowInvalid(f, "close_iterations = ", close_iterations, " (expected >= 0)");
  if (min_area_px <= 0) ThrowInvalid(f, "min_area_px = ", min_area_px, " (expected > 0)");
  if (!(merge_hue_deg >= 0)) ThrowInvalid(f, "merge_hue_deg = ", merge_hue_deg, " (expected >= 0)");
  if (merge_gap_px < 0) ThrowInvalid(f, "merge_gap_px = ", merge_gap_px, " (expected >= 0)");
}

std::vector<ToolSegment> SegmentTools(const RgbdFrame& frame, const SegmentationOptions& options) {
  if (frame.rgb.empty() || frame.rgb.type() != CV_8UC3) {
    ThrowInvalid("SegmentTools: frame.rgb must be a non-empty CV_8UC3 image (got ",
                 frame.rgb.empty() ? "empty" : "another type", ")");
  }
  const bool have_depth = options.use_depth && !frame.depth.empty();
  if (!frame.depth.empty() && (frame.depth.type() != CV_32FC1 || frame.depth.size() != frame.rgb.size())) {
    ThrowInvalid("SegmentTools: frame.depth must be CV_32FC1 of the rgb size ", frame.rgb.cols, "x", frame.rgb.rows,
                 " (got ", frame.depth.cols, "x", frame.depth.rows, " type ", frame.depth.type(), ")");
  }
  options.Validate();

  cv::Mat rgb_float;
  frame.rgb.convertTo(rgb_float, CV_32FC3, 1.0 / 255.0);
  cv::Mat hsv;
  cv::cvtColor(rgb_float, hsv, cv::COLOR_RGB2HSV);  // H [0, 360), S, V [0, 1]

  // Background colour model from the image itself (thesis: a band around the mean colour). A
  // band in RGB fails here: the background is light board, dark floor and black sky at once,
  // so its RGB spread covers the tools too. Shading changes value but hardly saturation, so the
  // band is taken on saturation: mean + background_band * stddev of the unsaturated pixels.
  std::vector<cv::Mat> channels;
  cv::split(hsv, channels);
  cv::Mat unsaturated = channels[1] < options.min_saturation;
  cv::Scalar bg_mean;
  cv::Scalar bg_std;
  cv::meanStdDev(channels[1], bg_mean, bg_std, unsaturated);
  const double saturation_limit =
      std::max(options.min_saturation, std::min(0.95, bg_mean[0] + options.background_band * bg_std[0]));

  // Dominant scene hues (the table) among the saturated pixels.
  std::array<double, kHueBins> scene_hues{};
  for (int v = 0; v < hsv.rows; ++v) {
    const cv::Vec3f* p = hsv.ptr<cv::Vec3f>(v);
    for (int u = 0; u < hsv.cols; ++u) {
      if (p[u][1] >= saturation_limit && p[u][2] >= options.min_value) scene_hues[HueBin(p[u][0])] += 1.0;
    }
  }
  const double total_pixels = static_cast<double>(hsv.total());
  std::array<bool, kHueBins> dominant{};
  for (int i = 0; i < kHueBins; ++i) dominant[i] = scene_hues[i] > options.dominant_hue_fraction * total_pixels;

  cv::Mat colour_mask = cv::Mat::zeros(hsv.size(), CV_8UC1);
  for (int v = 0; v < hsv.rows; ++v) {
    const cv::Vec3f* p = hsv.ptr<cv::Vec3f>(v);
    unsigned char* m = colour_mask.ptr<unsigned char>(v);
    for (int u = 0; u < hsv.cols; ++u) {
      const bool tool_colour =
          p[u][1] >= saturation_limit && p[u][2] >= options.min_value && !dominant[HueBin(p[u][0])];
      m[u] = tool_colour ? 255 : 0;
    }
  }

  // Thesis morphology: 3x3 opening removes specks, closing fills holes.
  const cv::Mat kernel = cv::getStructuringElement(cv::MORPH_RECT, cv::Size(3, 3));
  cv::Mat cleaned;
  cv::morphologyEx(colour_mask, cleaned, cv::MORPH_OPEN, kernel, cv::Point(-1, -1), options.open_iterations);
  cv::morphologyEx(cleaned, cleaned, cv::MORPH_CLOSE, kernel, cv::Point(-1, -1), options.close_iterations);

  cv::Mat cut = cleaned.clone();
  if (have_depth) cut.setTo(0, DepthEdges(frame.depth, options.depth_edge));

  // Components, then hue-cluster splitting of each.
  std::vector<Piece> pieces;
  for (const cv::Mat& blob : Components(cut, options.min_area_px)) {
    std::array<double, kHueBins> histogram{};
    double total = 0.0;
    for (int v = 0; v < blob.rows; ++v) {
      const unsigned char* m = blob.ptr<unsigned char>(v);
      const cv::Vec3f* p = hsv.ptr<cv::Vec3f>(v);
      const unsigned char* c = colour_mask.ptr<unsigned char>(v);
      for (int u = 0; u < blob.cols; ++u) {
        if (m[u] != 0 && c[u] != 0) {
          histogram[HueBin(p[u][0])] += 1.0;
          total += 1.0;
        }
      }
    }
    std::vector<double> modes = HueModes(histogram, total, options.min_mode_fraction);
    // Keep only modes far enough from every stronger mode.
    std::vector<double> kept;
    for (double mode : modes) {
      bool far = true;
      for (double k : kept) far = far && HueDistance(mode, k) >= options.hue_split_deg;
      if (far) kept.push_back(mode);
    }
    std::vector<cv::Mat> parts;
    if (kept.size() <= 1) {
      parts.push_back(blob);
    } else {
      std::vector<cv::Mat> by_mode(kept.size());
      for (cv::Mat& m : by_mode) m = cv::Mat::zeros(blob.size(), CV_8UC1);
      for (int v = 0; v < blob.rows; ++v) {
        const unsigned char* m = blob.ptr<unsigned char>(v);
        const cv::Vec3f* p = hsv.ptr<cv::Vec3f>(v);
        for (int u = 0; u < blob.cols; ++u) {
          if (m[u] == 0) continue;
          std::size_t nearest = 0;
          for (std::size_t k = 1; k < kept.size(); ++k) {
            if (HueDistance(p[u][0], kept[k]) < HueDistance(p[u][0], kept[nearest])) nearest = k;
          }
          by_mode[nearest].at<unsigned char>(v, u) = 255;
        }
      }
      for (cv::Mat& m : by_mode) {
        cv::morphologyEx(m, m, cv::MORPH_OPEN, kernel);
        for (cv::Mat& c : Components(m, options.min_area_px)) parts.push_back(c);
      }
    }
    for (cv::Mat& part : parts) {
      Piece piece;
      piece.mask = part;
      piece.area = cv::countNonZero(part);
      piece.hue = MeanHue(hsv, part);
      piece.depth = have_depth ? MedianDepth(frame.depth, part) : 0.0;
      pieces.push_back(std::move(piece));
    }
  }

  // Merge pieces of one tool split by an occluder: same hue, close in the image, and the pixels
  // between them belong to a nearer piece (or, without depth, to some other piece).
  if (options.merge_hue_deg > 0 && options.merge_gap_px > 0 && pieces.size() > 1) {
    const cv::Mat reach = cv::getStructuringElement(
        cv::MORPH_ELLIPSE, cv::Size(2 * options.merge_gap_px + 1, 2 * options.merge_gap_px + 1));
    bool merged = true;
    while (merged) {
      merged = false;
      for (std::size_t a = 0; a < pieces.size() && !merged; ++a) {
        cv::Mat grown_a;
        cv::dilate(pieces[a].mask, grown_a, reach);
        for (std::size_t b = a + 1; b < pieces.size() && !merged; ++b) {
          if (HueDistance(pieces[a].hue, pieces[b].hue) > options.merge_hue_deg) continue;
          if (cv::countNonZero(grown_a & pieces[b].mask) == 0) continue;
          cv::Mat grown_b;
          cv::dilate(pieces[b].mask, grown_b, reach);
          const cv::Mat between = grown_a & grown_b;
          bool occluded = false;
          for (std::size_t c = 0; c < pieces.size() && !occluded; ++c) {
            if (c == a || c == b) continue;
            const bool nearer = !have_depth || (pieces[c].depth > 0 && pieces[c].depth < pieces[a].depth &&
                                                pieces[c].depth < pieces[b].depth);
            occluded = nearer && cv::countNonZero(between & pieces[c].mask) > 0;
          }
          if (!occluded && have_depth) {
            // The gap may hold no tool at all: the ledge lip in front of a lying tool, or a
            // specular highlight that washed the colour out. Then the pixels on the shortest
            // path between the pieces are nearer than both, or at the same depth; a gap behind
            // them is the board between two tools of one colour. No depth at all on the gap
            // (sensor dropouts) is no evidence of a board behind.
            const cv::Mat gap = GapPath(pieces[a].mask, pieces[b].mask);
            const double gap_depth = MedianDepth(frame.depth, gap);
            occluded = gap_depth <= 0 ||
                       gap_depth < std::min(pieces[a].depth, pieces[b].depth) + 0.5 * options.depth_edge;
          }
          if (!occluded) continue;
          pieces[a].mask |= pieces[b].mask;
          pieces[a].area += pieces[b].area;
          pieces[a].hue = MeanHue(hsv, pieces[a].mask);
          pieces[a].depth = have_depth ? MedianDepth(frame.depth, pieces[a].mask) : 0.0;
          pieces.erase(pieces.begin() + static_cast<std::ptrdiff_t>(b));
          merged = true;
        }
      }
    }
  }

  // Give back the pixels the depth cut removed: each joins the piece that reaches it first
  // (one 3x3 dilation inside the cleaned colour mask).
  std::vector<ToolSegment> segments;
  cv::Mat claimed = cv::Mat::zeros(cleaned.size(), CV_8UC1);
  for (const Piece& piece : pieces) claimed |= piece.mask;
  for (Piece& piece : pieces) {
    cv::Mat grown;
    cv::dilate(piece.mask, grown, kernel);
    cv::Mat extra = grown & cleaned & ~claimed;
    piece.mask |= extra;
    claimed |= extra;
  }
  for (const Piece& piece : pieces) {
    ToolSegment segment;
    segment.mask = piece.mask;
    segment.roi = cv::boundingRect(piece.mask);
    segment.area_px = cv::countNonZero(piece.mask);
    const cv::Scalar mean = cv::mean(frame.rgb, piece.mask);
    segment.mean_rgb = cv::Vec3d(mean[0], mean[1], mean[2]);
    segment.mean_hue_deg = MeanHue(hsv, piece.mask);
    segment.median_depth = frame.depth.empty() ? 0.0 : MedianDepth(frame.depth, piece.mask);
    segments.push_back(std::move(segment));
  }
  std::stable_sort(segments.begin(), segments.end(),
                   [](const ToolSegment& a, const ToolSegment& b) { return a.area_px > b.area_px; });
  internal::Logger()->debug("segmentation: {} tool segments", segments.size());
  return segments;
}

}  // namespace toolbench::perception
