#pragma once

#include <vector>

#include <opencv2/core.hpp>

#include "common/types.h"

namespace toolbench::perception {

/// One tool found in the image.
struct ToolSegment {
  cv::Mat mask;                    // CV_8UC1, full image size, 255 = this tool's pixels
  cv::Rect roi;                    // bounding box of the mask [px]
  double area_px = 0.0;            // number of mask pixels
  cv::Vec3d mean_rgb{0, 0, 0};     // mean colour inside the mask (R, G, B), 0-255
  double mean_hue_deg = 0.0;       // circular mean hue inside the mask [deg], [0, 360)
  double median_depth = 0.0;       // median depth inside the mask [m]; 0 when no pixel has depth
};

/// Configuration of SegmentTools. Colours are judged in HSV with S and V in [0, 1] and hue in
/// degrees.
struct SegmentationOptions {
  // Thesis Alg. 1: a band around the image's own background colour. The background here is
  // light board, dark floor and black sky at once, so the band is taken on saturation, which
  // shading hardly changes: a pixel whose S is below max(min_saturation, mean + background_band
  // * stddev of the unsaturated pixels' S) is background.
  double background_band = 3.0;      // half-width of the band [standard deviations], > 0
  double min_saturation = 0.45;      // tools are saturated: S below this is background, (0, 1)
  double min_value = 0.18;           // V below this (deep shadow, black) is background, [0, 1)
  // Colours that cover a large part of the image (the brown table) are background too: a
  // hue bin (10 deg wide) holding more than this fraction of all pixels is dropped.
  double dominant_hue_fraction = 0.12;  // (0, 1]
  // Depth: pixels with depth this much closer/farther than a 4-neighbour are cut apart, so that
  // touching tools at different heights, or a tool lying over another, separate.
  bool use_depth = true;             // false: colour only (the thesis)
  double depth_edge = 0.012;         // depth jump that separates two surfaces [m], > 0
  // Hue clusters: a blob whose hue histogram has two modes this far apart is split by hue
  // (touching tools of different colours).
  double hue_split_deg = 30.0;       // (0, 180]
  double min_mode_fraction = 0.08;   // a hue mode must hold this fraction of the blob, (0, 0.5]
  // Morphology, thesis Alg. 1 with a 3x3 kernel: opening (erode, dilate) then closing.
  int open_iterations = 1;           // erosions then dilations of the opening, >= 0
  int close_iterations = 2;          // dilations then erosions of the closing, >= 0
  int min_area_px = 150;             // smaller segments are noise [px], > 0
  // Occlusion: two segments of the same hue (within merge_hue_deg) whose gap is covered by a
  // nearer segment, or (with depth) whose gap is not behind them (the ledge lip in front of a
  // lying tool, a washed-out highlight on it; not the board between two tools), are one partly
  // occluded tool and are merged.
  double merge_hue_deg = 12.0;       // [deg], >= 0; 0 disables merging
  int merge_gap_px = 40;             // largest gap bridged [px], >= 0
  void Validate() const;             // throws std::invalid_argument naming the field and value
};

/// Finds the tools in an RGB-D frame (thesis Alg. 1, made robust): a colour mask (saturated
/// beyond the background band, bright enough, not a dominant scene colour), 3x3 opening and closing, depth
/// discontinuities cut, connected components, hue-cluster splitting, small-blob removal and a
/// merge of same-coloured pieces separated by an occluder. Segments are ordered by decreasing
/// area. Shadows on the board stay unsaturated and are rejected by the saturation test.
/// Precondition: frame.rgb is CV_8UC3 (RGB); frame.depth, when not empty, is CV_32FC1 of the
/// same size (metres, 0 = no return). Throws std::invalid_argument naming the argument
/// otherwise, or for bad options. Returns an empty vector when no tool is seen.
std::vector<ToolSegment> SegmentTools(const RgbdFrame& frame, const SegmentationOptions& options);

}  // namespace toolbench::perception
