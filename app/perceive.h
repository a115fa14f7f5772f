#pragma once

#include <filesystem>

#include <nlohmann/json_fwd.hpp>

#include "app/capture.h"
#include "app/scene_setup.h"

#include "perception/analysis.h"

namespace toolbench::app {

/// How `toolbench perceive` runs perception.
struct PerceiveOptions {
  /// ToolClassifier file (the learned recogniser, whose probabilities pick the models to
  /// verify); empty = no classifier, the extent-based pre-selection.
  std::filesystem::path classifier = {};
  /// true: the user tools of the request (extra_tool_dirs) are put on the rack but left out of
  /// perception's library, so that they are analysed as unknown tools from their clouds (and the
  /// shipped classifier, trained on the asset library, still matches). false: they join it.
  bool user_tools_unknown = false;
};

/// `toolbench perceive`: captures a frame of the rack (as `render`: rgb.png, depth.png,
/// camera.json, cloud.ply, ground_truth.json), runs the perception pipeline the episode runs
/// (perception::ToolAnalyzer with DefaultAnalyzerOptions: segmentation, object cloud,
/// classifier + model fit, parts, superquadrics, handle; unknown tools analysed from their
/// clouds) and writes, so that a person can look at every step:
///   analysis.json              FrameAnalysisJson: one full ToolAnalysis per segment (status and
///                              reason, roi, model, known, confidence, X_RT, fit error, parts
///                              with their superquadrics, handle with X_RH, features in T,
///                              per-stage times [ms]), its cloud counts and the fitted candidates,
///                              plus the library, the classifier and the files written per tool
///   segments.png               the image with each segment's contour, box and label
///   mask_<i>.png, roi_<i>.png  segment i's mask (0/255, full image) and its RGB crop (the box)
///   tool_<i>_fit.ply           the object cloud (grey) with the fitted library model's samples
///                              (orange when known; magenta: the closest model of an unknown
///                              tool) and the axes of X_RT (x red, y green, z blue, 5 cm), in R
///   tool_<i>_parts.ply         the parts' points, one colour each, the handle part blue, in R
///   tool_<i>_superquadrics.ply a triangle mesh of each part's superquadric, coloured as the
///                              parts, in R
///   handles.png                each handle (centre, graspable length along its axis, an arrow
///                              toward the effector) projected into the image
///   score.json                 evaluation against ground truth (never read by perception)
/// Files of a stage a tool did not reach (no cloud, no parts) are not written; analysis.json
/// lists each tool's files. Returns 0 when perception ran (even if some tools were not
/// analysed: they are recorded with their reason). Throws std::invalid_argument for bad
/// requests, a missing or corrupt classifier file, or a classifier trained for another library
/// (with user tools from --tool-dir in the library, the message names --no-classifier and
/// --user-tools-unknown as ways out), --user-tools-unknown without a --tool-dir, and
/// std::runtime_error when a file cannot be written.
int RunPerceive(const SceneRequest& request, const std::filesystem::path& out_dir, const CaptureOptions& capture,
                const PerceiveOptions& options);

/// JSON form of one tool's analysis (all poses as PoseJson, positions in R [m], features in T):
/// {segment, status, reason, roi [x, y, w, h px], model, known, confidence, X_RT, fit_error_m,
///  parts: [{points, fit_error, cylinder_score, superquadric: {size_m, e1, e2, X_RS}}],
///  handle: {part, center_R, axis_R, radius_m, length_m, X_RH},
///  features: {total_length_m, handle_length_m, handle_radius_m, effector_center_T,
///             effector_size_T, effector_protrusion_m}}.
nlohmann::json ToolAnalysisJson(const perception::ToolAnalysis& analysis);

/// JSON form of a whole frame's analysis: {"tools": [...]}, one entry per segment: the
/// ToolAnalysisJson plus "ms" (StageTimes), "segment_area_px", "cloud" (point counts and the
/// cloud's reason) and "candidates" (the library models the recogniser verified, with prior,
/// score [m] and posterior).
nlohmann::json FrameAnalysisJson(const perception::FrameAnalysis& frame);

/// The shipped classifier: assets/models/tool_classifier.yml.gz.
std::filesystem::path DefaultClassifierPath();

/// The perception pipeline as the app runs it: defaults, the shipped classifier, the shipped
/// segmentations of the library models' shape analyses (assets/models/library_segmentation.json,
/// perception::ShapeSegmentation) and the shape cache on disk, where analyses of library models
/// are kept between runs: $TOOLBENCH_CACHE_DIR/shapes, else $XDG_CACHE_HOME/toolbench/shapes,
/// else $HOME/.cache/toolbench/shapes, else none (memory only). The cache's files are keyed by
/// mesh and option hashes, so they never go stale.
perception::AnalyzerOptions DefaultAnalyzerOptions();

/// Segments every model of `library` anew (perception::SegmentModelShape under
/// DefaultAnalyzerOptions().shape), one line per model on stdout, and writes the segmentations
/// to `out` (perception::WriteShapeSegmentations): what assets/models/library_segmentation.json
/// is made with. Throws std::runtime_error naming the models whose segmentation failed (nothing
/// is written then) or the file that cannot be written.
void WriteLibrarySegmentations(const std::vector<toollib::ToolModel>& library, const std::filesystem::path& out);

}  // namespace toolbench::app
