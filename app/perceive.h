#pragma once

#include <filesystem>

#include "app/capture.h"
#include "app/scene_setup.h"

#include "perception/analysis.h"

namespace toolbench::app {

/// `toolbench perceive`: captures a frame of the rack (as `render`), runs perception on it
/// (segmentation, object clouds, recognition and model fit) and writes, besides the frame files:
///   analysis.json  one entry per segmented tool: segment, cloud counts or the reason it failed,
///                  recognised model and confidence, X_RT, handle centre and axis in R, and the
///                  per-stage times [ms]
///   segments.png   the image with each segment's contour, box and label
///   tool_<i>.ply   the object cloud (grey) with the fitted model's samples (colour), in R
///   score.json     evaluation against ground truth (never read by perception)
/// `classifier_path` names a ToolClassifier file (the learned recogniser, whose probabilities
/// pick the models to verify); empty = no classifier, the extent-based pre-selection.
/// Returns 0 when perception ran (even if some tools were not recognised: they are recorded
/// with their reason). Throws std::invalid_argument for bad requests, a missing or corrupt
/// classifier file, or a classifier trained for another library.
int RunPerceive(const SceneRequest& request, const std::filesystem::path& out_dir, const CaptureOptions& options,
                const std::filesystem::path& classifier_path);

/// The shipped classifier: assets/models/tool_classifier.yml.gz.
std::filesystem::path DefaultClassifierPath();

/// Where shape analyses of library models are kept between runs: $TOOLBENCH_CACHE_DIR/shapes,
/// else $XDG_CACHE_HOME/toolbench/shapes, else $HOME/.cache/toolbench/shapes, else empty
/// (memory only). The files are keyed by mesh and option hashes, so they never go stale.
std::filesystem::path DefaultShapeCacheDir();

/// The perception pipeline as the app runs it: defaults, the shipped classifier and the shape
/// cache on disk.
perception::AnalyzerOptions DefaultAnalyzerOptions();

}  // namespace toolbench::app
