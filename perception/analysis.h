#pragma once

#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "common/types.h"
#include "perception/model_fit.h"
#include "perception/object_cloud.h"
#include "perception/parts.h"
#include "perception/segmentation.h"
#include "perception/tool_analysis.h"
#include "toollib/tool_model.h"

namespace toolbench::perception {

/// Configuration of the whole per-frame pipeline (thesis Alg. 1-5).
struct AnalyzerOptions {
  SegmentationOptions segmentation;
  ObjectCloudOptions cloud;
  RecognitionOptions recognition;
  /// Learned tool classifier (ToolClassifier file, e.g. assets/models/tool_classifier.yml.gz);
  /// its probabilities pick the models the recogniser fits. Empty: no classifier (models are
  /// pre-selected by principal extents).
  std::filesystem::path classifier_file;
  ShapeOptions shape;                     // parts, superquadrics and handle choice
  bool cache_shapes = true;               // analyse each library model's shape once (false: every time)
  std::filesystem::path shape_cache_dir;  // shape analyses on disk, shared by runs; empty = memory only
  /// Recorded segmentations of the library models (ReadShapeSegmentations, e.g.
  /// assets/models/library_segmentation.json): with them a model's analysis is the same in every
  /// process (ShapeSegmentation says why it would not be). Empty: segment each model anew.
  std::filesystem::path shape_segmentations;
  /// A tool is taken for the recognised library model only when the recogniser's confidence is
  /// at least min_known_confidence, in [0, 1], and the fit's mean error at most
  /// max_known_fit_error [m], > 0; otherwise it is analysed as an unknown tool from its cloud.
  double min_known_confidence = 0.3;
  double max_known_fit_error = 0.006;
  /// Scale check: a tool is not the recognised model when more than max_outside_fraction, in
  /// (0, 1], of its observed points lie outside the model's bounding box (in T, at the fitted
  /// pose) grown by outside_margin_m [m], >= 0, on every side. Partial views only ever shrink
  /// the observed extent, so a larger tool that ICP fits well locally (a library tool scaled by
  /// 1.3 fits within the fit-error limit) is caught by its overhang. 1 = off.
  double max_outside_fraction = 0.05;
  double outside_margin_m = 0.012;
  void Validate() const;  // throws std::invalid_argument naming the field

  /// The thesis's configuration (chapter 4) as the baseline to compare against:
  /// point-to-point ICP with 500 iterations and the thesis's epsilons on 4000
  /// model points, principal-axes initialisation only (no flip candidates), no
  /// visible-surface scoring rounds, no depth-image check of the turn about the handle; parts,
  /// superquadrics and handle computed for every tool, every time (no shape cache); no scale
  /// check.
  static AnalyzerOptions Thesis();
};

/// Wall time of each stage for one tool [ms]. Segmentation runs once per frame;
/// its time is shared equally among the frame's tools.
struct StageTimes {
  double segmentation_ms = 0.0;
  double cloud_ms = 0.0;
  double classification_ms = 0.0;  // recognition features and the classifier
  double recognition_ms = 0.0;     // classification/ranking, model fit and refinement
  double shape_ms = 0.0;           // parts, superquadrics and handle placed in R
  double total_ms = 0.0;
};

/// What one frame gave.
struct FrameAnalysis {
  std::vector<ToolSegment> segments;           // every 2D segment, by decreasing area
  std::vector<ToolAnalysis> tools;             // one per segment, same order
  std::vector<StageTimes> times;               // one per segment, same order
  std::vector<RecognitionResult> recognition;  // one per segment (status kTooFewPoints when no cloud)
  std::vector<ObjectCloud> clouds;             // one per segment
  std::string reason;  // why no tool was found when `segments` is empty, else empty
};

/// The perception pipeline of one robot: RGB-D frame (and the camera pose from
/// encoder FK that the frame carries) -> one ToolAnalysis per tool, in the root
/// frame R. Construction prepares the library once (model sampling, search
/// structures); Analyze can then be called for many frames. Never reads
/// anything but the frame and the library.
class ToolAnalyzer {
 public:
  /// Throws std::invalid_argument for bad options, an empty/unusable library, or a classifier
  /// file that is missing, corrupt or made for another library.
  ToolAnalyzer(std::vector<toollib::ToolModel> library, const AnalyzerOptions& options);
  ~ToolAnalyzer();
  ToolAnalyzer(ToolAnalyzer&&) noexcept;
  ToolAnalyzer& operator=(ToolAnalyzer&&) noexcept;

  /// Segments the frame, extracts each tool's cloud, recognises and fits it,
  /// and places its handle. Tools whose cloud or fit fails are still reported,
  /// with a status and reason (e.g. kNoCloud for a tool without usable depth); a frame without
  /// any tool gives no entries and a FrameAnalysis::reason. Throws std::invalid_argument for a
  /// malformed frame (empty or non-CV_8UC3 rgb, depth of another size or type, intrinsics that
  /// do not match the images: see SegmentTools, ExtractObjectCloud).
  FrameAnalysis Analyze(const RgbdFrame& frame) const;

  /// Analyses (or loads from the shape cache) the shapes of the named library models now, so
  /// that Analyze does not pay for them (and forked processes inherit them). No effect without
  /// the shape cache. Throws std::invalid_argument for an unknown name.
  void PrepareShapes(const std::vector<std::string>& models) const;

  /// The library, in the order the recogniser uses.
  const std::vector<toollib::ToolModel>& library() const;
  /// The recogniser (for display of model samples).
  const ToolRecognizer& recognizer() const;
  /// Wall time of the construction (library preparation) [ms].
  double preparation_ms() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Handle frame H in T of a library model's sidecar handle: origin at its
/// centre, z_H along its axis, x_H the component of +x_T perpendicular to it
/// (the effector's working side).
Eigen::Isometry3d SidecarHandleFrame(const toollib::ToolModel& model);

/// Human-readable name of an AnalysisStatus ("ok", "no_cloud", ...).
const char* ToString(AnalysisStatus status);

}  // namespace toolbench::perception
