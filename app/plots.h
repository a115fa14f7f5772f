#pragma once

#include <filesystem>
#include <limits>
#include <string>
#include <vector>

namespace toolbench::app {

/// One series of a bar chart: one value per category, optionally with an interval per value.
struct BarSeries {
  std::string label;           // legend entry (a chart with one unlabelled series has no legend)
  std::vector<double> values;  // one per category; NaN = no bar
  /// Interval per category (e.g. a 95 % confidence interval), drawn as an error bar; both empty
  /// (no error bars) or both of the size of `values`, with low <= value <= high.
  std::vector<double> low;
  std::vector<double> high;
};

/// A bar chart; several series give grouped bars (side by side within each category).
struct BarChart {
  std::string title;
  std::string x_label;                  // what the categories are
  std::string y_label;                  // with its unit, e.g. "success rate [%]"
  std::vector<std::string> categories;  // one group of bars each, left to right
  std::vector<BarSeries> series;        // >= 1
  double y_min = 0.0;                                        // axis range
  double y_max = std::numeric_limits<double>::quiet_NaN();   // NaN = from the data (+10 %)
  bool value_labels = false;            // print each bar's value above it (few bars only)
  int value_decimals = 0;               // decimals of those values, 0..6
  int width_px = 1200;                  // image size [px], 200..4000
  int height_px = 700;                  // [px], 200..4000
};

/// A histogram of a sample.
struct Histogram {
  std::string title;
  std::string x_label;           // with its unit, e.g. "wall time [s]"
  std::string y_label = "count";
  std::vector<double> values;    // the sample (non-finite values are ignored)
  int bins = 20;                 // >= 1
};

/// Writes a bar chart as a PNG (PLplot, cairo device; folders are created). Throws
/// std::invalid_argument naming the chart and the problem: no categories or series, a series
/// whose size differs from the categories, intervals of the wrong size, a bad image size, or no
/// PNG device (plplot-driver-cairo missing).
void WriteBarChartPng(const BarChart& chart, const std::filesystem::path& png);

/// Writes histograms as one PNG, `columns` panels per row (>= 1); same errors as above, plus an
/// empty panel list or bins < 1. A panel whose sample is empty says "no data".
void WriteHistogramsPng(const std::vector<Histogram>& panels, const std::filesystem::path& png, int columns = 2,
                        int panel_width_px = 600, int panel_height_px = 380);

}  // namespace toolbench::app
