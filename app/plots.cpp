#include "app/plots.h"

#include <plplot/plplot.h>
#include <plplot/plstream.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "common/check.h"

namespace toolbench::app {
namespace {

// Colour map 0: 0 = background, 1 = text and axes, 2 = grid, 3.. = series (the "tab10" colours).
constexpr int kInk = 1;
constexpr int kGrid = 2;
constexpr int kFirstSeries = 3;
constexpr PLINT kRed[] = {255, 0, 215, 31, 255, 44, 214, 148, 140, 127};
constexpr PLINT kGreen[] = {255, 0, 215, 119, 127, 160, 39, 103, 86, 127};
constexpr PLINT kBlue[] = {255, 0, 215, 180, 14, 44, 40, 189, 75, 127};
constexpr int kColours = static_cast<int>(std::size(kRed));

// Character heights (PLplot's schr scale): axis text and labels, titles, value labels. PLplot
// scales text with the page width; PngPage undoes that, so that one unit of scale is about
// 20 px on every page (measured on rendered 1200 px wide charts), and text is on average 0.62
// character heights wide per character.
constexpr double kTextScale = 0.9;
constexpr double kTitleScale = 1.05;
constexpr double kValueScale = 0.75;
constexpr double kPxPerScale = 20.0;
constexpr double kCharWidth = 0.62;
constexpr double kReferenceWidthPx = 1200;

int SeriesColour(size_t s) { return kFirstSeries + static_cast<int>(s) % (kColours - kFirstSeries); }

// '#' starts a PLplot escape sequence; a literal one is written "##".
std::string Text(const std::string& s) {
  std::string out;
  for (char c : s) {
    out += c;
    if (c == '#') out += '#';
  }
  return out;
}

void RequirePngDevice(const std::string& what) {
  int n = 128;
  std::vector<const char*> menu(static_cast<size_t>(n)), names(static_cast<size_t>(n));
  const char** menu_ptr = menu.data();
  const char** names_ptr = names.data();
  plgDevs(&menu_ptr, &names_ptr, &n);
  for (int i = 0; i < n; ++i) {
    if (names_ptr[i] != nullptr && std::string(names_ptr[i]) == "pngcairo") return;
  }
  ThrowInvalid(what, ": PLplot has no 'pngcairo' device; install plplot-driver-cairo (scripts/setup.sh)");
}

void CheckSize(const std::string& what, int width, int height) {
  if (width < 200 || width > 4000 || height < 200 || height > 4000) {
    ThrowInvalid(what, ": image size ", width, " x ", height, " px (expected 200..4000 each)");
  }
}

/// A PLplot stream writing one PNG page of width x height pixels, white background.
class PngPage {
 public:
  PngPage(const std::filesystem::path& png, int width, int height) : unit_(kReferenceWidthPx / width) {
    if (png.has_parent_path()) std::filesystem::create_directories(png.parent_path());
    stream_.sdev("pngcairo");
    stream_.sfnam(png.c_str());
    stream_.spage(90, 90, width, height, 0, 0);
    stream_.scmap0(kRed, kGreen, kBlue, kColours);
    stream_.init();
    TextSize(kTextScale);
  }
  /// Character height in units of about kPxPerScale px, whatever the page size.
  void TextSize(double scale) { stream_.schr(0, scale * unit_); }
  plstream& operator*() { return stream_; }
  plstream* operator->() { return &stream_; }

 private:
  double unit_;
  plstream stream_;
};

void Rect(plstream& pls, double x0, double x1, double y0, double y1, int colour) {
  const PLFLT x[] = {x0, x1, x1, x0};
  const PLFLT y[] = {y0, y0, y1, y1};
  pls.col0(colour);
  pls.fill(4, x, y);
  const PLFLT xo[] = {x0, x1, x1, x0, x0};
  const PLFLT yo[] = {y0, y0, y1, y1, y0};
  pls.col0(kInk);
  pls.width(0.5);
  pls.line(5, xo, yo);
  pls.width(1.0);
}

/// Horizontal grid lines at the y axis's major ticks, then the frame and its numbers on top.
void Axes(plstream& pls, const char* xopt) {
  pls.col0(kGrid);
  pls.box("", 0, 0, "g", 0, 0);
  pls.col0(kInk);
  pls.box(xopt, 0, 0, "bcnstv", 0, 0);
}


}  // namespace

void WriteBarChartPng(const BarChart& chart, const std::filesystem::path& png) {
  const std::string what = "WriteBarChartPng('" + chart.title + "')";
  if (chart.value_decimals < 0 || chart.value_decimals > 6) {
    ThrowInvalid(what, ": value_decimals = ", chart.value_decimals, " (expected 0..6)");
  }
  if (chart.categories.empty()) ThrowInvalid(what, ": no categories");
  if (chart.series.empty()) ThrowInvalid(what, ": no series");
  CheckSize(what, chart.width_px, chart.height_px);
  const size_t n = chart.categories.size();
  double data_max = chart.y_min;
  for (const BarSeries& s : chart.series) {
    if (s.values.size() != n) {
      ThrowInvalid(what, ": series '", s.label, "' has ", s.values.size(), " values for ", n, " categories");
    }
    if (!(s.low.empty() && s.high.empty()) && (s.low.size() != n || s.high.size() != n)) {
      ThrowInvalid(what, ": series '", s.label, "' has ", s.low.size(), " low and ", s.high.size(),
                   " high interval ends for ", n, " categories (expected none or one each)");
    }
    for (size_t i = 0; i < n; ++i) {
      if (std::isfinite(s.values[i])) data_max = std::max(data_max, s.values[i]);
      if (!s.high.empty() && std::isfinite(s.high[i])) data_max = std::max(data_max, s.high[i]);
    }
  }
  RequirePngDevice(what);
  const double y_max = std::isfinite(chart.y_max) ? chart.y_max : (data_max > chart.y_min ? data_max * 1.1 : chart.y_min + 1);
  if (!(y_max > chart.y_min)) ThrowInvalid(what, ": y range ", chart.y_min, "..", y_max, " is empty");

  // Category names are written vertically when they do not fit side by side; the bottom margin
  // makes room for them and the axis label.
  size_t longest = 0;
  for (const std::string& c : chart.categories) longest = std::max(longest, c.size());
  const double char_px = kPxPerScale * kTextScale;
  const double slot_px = 0.88 * chart.width_px / static_cast<double>(n);
  const bool vertical = kCharWidth * static_cast<double>(longest) * char_px > 0.95 * slot_px;
  const double label_chars = vertical ? kCharWidth * static_cast<double>(longest) + 2.2 : 2.0;
  const double char_frac = char_px / chart.height_px;  // one character height as a page fraction
  const double bottom = std::min(0.6, (label_chars + 3.4) * char_frac);
  const bool legend = chart.series.size() > 1 || !chart.series.front().label.empty();
  const double top = 1.0 - (legend ? 4.2 : 2.6) * char_frac;

  PngPage page(png, chart.width_px, chart.height_px);
  plstream& pls = *page;
  pls.adv(0);
  const double left = std::min(0.2, 7.0 * char_px / chart.width_px);
  pls.vpor(left, 0.98, bottom, top);
  pls.wind(0, static_cast<double>(n), chart.y_min, y_max);
  Axes(pls, "bc");

  const double group = 0.8;
  const double bar = group / static_cast<double>(chart.series.size());
  for (size_t s = 0; s < chart.series.size(); ++s) {
    const BarSeries& series = chart.series[s];
    for (size_t i = 0; i < n; ++i) {
      const double v = series.values[i];
      if (!std::isfinite(v)) continue;
      const double x0 = static_cast<double>(i) + (1 - group) / 2 + bar * static_cast<double>(s);
      Rect(pls, x0, x0 + bar, chart.y_min, std::clamp(v, chart.y_min, y_max), SeriesColour(s));
      double label_y = v;
      if (!series.low.empty() && std::isfinite(series.low[i]) && std::isfinite(series.high[i])) {
        const PLFLT x[] = {x0 + bar / 2};
        const PLFLT lo[] = {series.low[i]};
        const PLFLT hi[] = {series.high[i]};
        pls.col0(kInk);
        pls.width(1.5);
        pls.erry(1, x, lo, hi);
        pls.width(1.0);
        label_y = series.high[i];
      }
      if (chart.value_labels) {
        // Above the bar or its interval, by one label height (PLplot centres text vertically).
        const double label_h = kPxPerScale * kValueScale / (chart.height_px * (top - bottom)) * (y_max - chart.y_min);
        pls.col0(kInk);
        page.TextSize(kValueScale);
        pls.ptex(x0 + bar / 2, label_y + 1.2 * label_h, 1, 0, 0.5, fmt::format("{:.{}f}", v, chart.value_decimals).c_str());
        page.TextSize(kTextScale);
      }
    }
  }
  pls.col0(kInk);
  for (size_t i = 0; i < n; ++i) {
    const double pos = (static_cast<double>(i) + 0.5) / static_cast<double>(n);
    if (vertical) {
      pls.mtex("bv", 0.7, pos, 1.0, Text(chart.categories[i]).c_str());
    } else {
      pls.mtex("b", 1.6, pos, 0.5, Text(chart.categories[i]).c_str());
    }
  }
  pls.mtex("b", label_chars + 1.2, 0.5, 0.5, Text(chart.x_label).c_str());
  pls.mtex("l", 4.0, 0.5, 0.5, Text(chart.y_label).c_str());
  page.TextSize(kTitleScale);
  pls.mtex("t", legend ? 2.4 : 1.0, 0.5, 0.5, Text(chart.title).c_str());
  page.TextSize(kTextScale);
  if (legend) {
    // Entries side by side, centred, each as wide as its text.
    const double viewport_px = chart.width_px * (0.98 - left);
    std::vector<double> widths;
    double total = 0;
    for (const BarSeries& series : chart.series) {
      widths.push_back(kCharWidth * char_px * static_cast<double>(series.label.size() + 5) / viewport_px);
      total += widths.back();
    }
    double pos = 0.5 - total / 2;
    for (size_t s = 0; s < chart.series.size(); ++s) {
      pls.col0(SeriesColour(s));
      pls.mtex("t", 0.8, pos, 0.0, Text("■ " + chart.series[s].label).c_str());
      pos += widths[s];
    }
  }
}

void WriteHistogramsPng(const std::vector<Histogram>& panels, const std::filesystem::path& png, int columns,
                        int panel_width_px, int panel_height_px) {
  const std::string what = "WriteHistogramsPng('" + png.filename().string() + "')";
  if (panels.empty()) ThrowInvalid(what, ": no panels");
  if (columns < 1) ThrowInvalid(what, ": columns = ", columns, " (expected >= 1)");
  for (const Histogram& h : panels) {
    if (h.bins < 1) ThrowInvalid(what, ": panel '", h.title, "' has bins = ", h.bins, " (expected >= 1)");
  }
  columns = std::min<int>(columns, static_cast<int>(panels.size()));
  const int rows = (static_cast<int>(panels.size()) + columns - 1) / columns;
  CheckSize(what, panel_width_px * columns, panel_height_px * rows);
  RequirePngDevice(what);

  // One page, a viewport per panel (PLplot's subpages would rescale the text).
  const int width = panel_width_px * columns, height = panel_height_px * rows;
  PngPage page(png, width, height);
  plstream& pls = *page;
  pls.adv(0);
  const double char_px = kPxPerScale * kTextScale;
  for (size_t k = 0; k < panels.size(); ++k) {
    const Histogram& h = panels[k];
    const int column = static_cast<int>(k) % columns, row = static_cast<int>(k) / columns;
    const double x0 = static_cast<double>(column) / columns, y1 = 1.0 - static_cast<double>(row) / rows;
    pls.vpor(x0 + 6.5 * char_px / width, x0 + 1.0 / columns - 2.0 * char_px / width,
             y1 - 1.0 / rows + 5.0 * char_px / height, y1 - 3.0 * char_px / height);
    std::vector<double> values;
    for (double v : h.values) {
      if (std::isfinite(v)) values.push_back(v);
    }
    if (values.empty()) {
      pls.wind(0, 1, 0, 1);
      pls.col0(kInk);
      pls.box("bc", 0, 0, "bc", 0, 0);
      pls.ptex(0.5, 0.5, 1, 0, 0.5, "no data");
    } else {
      double lo = *std::min_element(values.begin(), values.end());
      double hi = *std::max_element(values.begin(), values.end());
      if (hi - lo < 1e-12 * std::max(1.0, std::abs(hi))) {  // one value: a bin around it
        lo -= 0.05 * std::max(1.0, std::abs(lo));
        hi += 0.05 * std::max(1.0, std::abs(hi));
      }
      const double bin = (hi - lo) / h.bins;
      std::vector<int> counts(static_cast<size_t>(h.bins), 0);
      for (double v : values) ++counts[static_cast<size_t>(std::clamp(static_cast<int>((v - lo) / bin), 0, h.bins - 1))];
      const int most = *std::max_element(counts.begin(), counts.end());
      pls.wind(lo, hi, 0, most * 1.15);
      Axes(pls, "bcnst");
      for (int b = 0; b < h.bins; ++b) {
        if (counts[static_cast<size_t>(b)] == 0) continue;
        Rect(pls, lo + b * bin, lo + (b + 1) * bin, 0, counts[static_cast<size_t>(b)], SeriesColour(0));
      }
    }
    pls.col0(kInk);
    pls.mtex("b", 2.8, 0.5, 0.5, Text(h.x_label).c_str());
    pls.mtex("l", 3.2, 0.5, 0.5, Text(h.y_label).c_str());
    page.TextSize(kTitleScale);
    pls.mtex("t", 0.8, 0.5, 0.5, Text(h.title).c_str());
    page.TextSize(kTextScale);
  }
}

}  // namespace toolbench::app
