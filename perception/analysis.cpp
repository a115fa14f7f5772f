#include "perception/analysis.h"

#include <chrono>
#include <cmath>
#include <utility>

#include "common/check.h"
#include "perception/parts.h"
#include "perception/recognition_features.h"
#include "perception/tool_classifier.h"

namespace toolbench::perception {
namespace {

using Clock = std::chrono::steady_clock;

double Ms(Clock::time_point since) { return std::chrono::duration<double, std::milli>(Clock::now() - since).count(); }

/// Unit vector perpendicular to `axis`, as close to `preferred` as possible.
Eigen::Vector3d PerpendicularTowards(const Eigen::Vector3d& axis, const Eigen::Vector3d& preferred) {
  Eigen::Vector3d x = preferred - preferred.dot(axis) * axis;
  if (x.norm() < 1e-9) x = axis.unitOrthogonal();
  return x.normalized();
}

}  // namespace

void AnalyzerOptions::Validate() const {
  segmentation.Validate();
  cloud.Validate();
  recognition.Validate();
  if (!(max_known_fit_error > 0.0)) {
    ThrowInvalid("AnalyzerOptions: max_known_fit_error = ", max_known_fit_error, " (expected > 0)");
  }
  if (!(min_known_confidence >= 0.0 && min_known_confidence <= 1.0)) {
    ThrowInvalid("AnalyzerOptions: min_known_confidence = ", min_known_confidence, " (expected in [0, 1])");
  }
  if (!(max_outside_fraction > 0.0 && max_outside_fraction <= 1.0)) {
    ThrowInvalid("AnalyzerOptions: max_outside_fraction = ", max_outside_fraction, " (expected in (0, 1])");
  }
  if (!(outside_margin_m >= 0.0)) {
    ThrowInvalid("AnalyzerOptions: outside_margin_m = ", outside_margin_m, " (expected >= 0)");
  }
}

AnalyzerOptions AnalyzerOptions::Thesis() {
  AnalyzerOptions options;
  ModelFitOptions& fit = options.recognition.fit;
  fit.metric = IcpMetric::kPointToPoint;
  fit.model_points = 4000;
  fit.max_iterations = 500;
  fit.transformation_epsilon = 1e-9;
  fit.euclidean_fitness_epsilon = 1e-6;
  fit.try_flips = false;
  fit.visible_rounds = 0;
  fit.view_spin_steps = 0;  // no depth-image check of the turn about the handle
  options.cache_shapes = false;  // reconstruction, SDF and superquadrics for every tool, every time
  options.max_outside_fraction = 1.0;  // the thesis has no unknown tools: no scale check
  return options;
}

namespace {

/// Fraction of the points p_R (3 x N, in R) that lie outside the bounding box of `model`'s mesh
/// (in T, placed at X_RT) grown by margin on every side; 0 for no points.
double FractionOutsideModel(const Eigen::Matrix3Xf& p_R, const toollib::ToolModel& model, const Eigen::Isometry3d& X_RT,
                            double margin) {
  if (p_R.cols() == 0 || model.mesh.vertices.cols() == 0) return 0.0;
  const Eigen::Vector3d lo = model.mesh.vertices.rowwise().minCoeff().array() - margin;
  const Eigen::Vector3d hi = model.mesh.vertices.rowwise().maxCoeff().array() + margin;
  const Eigen::Isometry3d X_TR = X_RT.inverse();
  Eigen::Index outside = 0;
  for (Eigen::Index i = 0; i < p_R.cols(); ++i) {
    const Eigen::Vector3d p_T = X_TR * p_R.col(i).cast<double>();
    if ((p_T.array() < lo.array()).any() || (p_T.array() > hi.array()).any()) ++outside;
  }
  return static_cast<double>(outside) / static_cast<double>(p_R.cols());
}

}  // namespace

Eigen::Isometry3d SidecarHandleFrame(const toollib::ToolModel& model) {
  const Eigen::Vector3d z = model.handle.axis.normalized();
  const Eigen::Vector3d x = PerpendicularTowards(z, Eigen::Vector3d::UnitX());
  Eigen::Isometry3d X_TH = Eigen::Isometry3d::Identity();
  X_TH.linear().col(0) = x;
  X_TH.linear().col(1) = z.cross(x);
  X_TH.linear().col(2) = z;
  X_TH.translation() = model.handle.center;
  return X_TH;
}

const char* ToString(AnalysisStatus status) {
  switch (status) {
    case AnalysisStatus::kOk:
      return "ok";
    case AnalysisStatus::kNoCloud:
      return "no_cloud";
    case AnalysisStatus::kNoFit:
      return "no_fit";
    case AnalysisStatus::kNoHandle:
      return "no_handle";
  }
  return "unknown";
}

struct ToolAnalyzer::Impl {
  std::vector<toollib::ToolModel> library;
  AnalyzerOptions options;
  std::unique_ptr<ToolRecognizer> recognizer;
  std::optional<ToolClassifier> classifier;
  std::vector<std::string> model_names;
  double preparation_ms = 0.0;

  const toollib::ToolModel* Find(const std::string& name) const {
    for (const auto& model : library) {
      if (model.name == name) return &model;
    }
    return nullptr;
  }

  mutable ShapeCache shapes;  // per library model, filled as models are recognised

  /// Parts, superquadrics, handle (Alg. 5) and features of a recognised library model, analysed
  /// once in T (cached, unless the options ask to redo it every time as the thesis did) and
  /// placed with the fitted pose.
  void PlaceShape(const toollib::ToolModel& model, ToolAnalysis& out) const {
    const ModelShape shape =
        options.cache_shapes ? shapes.Get(model, options.shape) : AnalyzeModelShape(model, options.shape);
    Adopt(TransformShape(shape, out.X_RT), out);
  }

  /// Copies a shape in R into the analysis (status kNoHandle when no part is a handle).
  static void Adopt(const ModelShape& shape, ToolAnalysis& out) {
    out.parts = shape.parts;
    out.handle = shape.handle;
    out.features = shape.features;
    if (shape.status != ShapeStatus::kOk) {
      out.status = AnalysisStatus::kNoHandle;
      out.reason = "shape analysis failed: " + shape.reason;
    } else if (shape.handle.part < 0) {
      out.status = AnalysisStatus::kNoHandle;
      out.reason = "no part resembles the 32 x 80 mm cylinder the hand holds";
    } else {
      out.status = AnalysisStatus::kOk;
    }
  }
};

ToolAnalyzer::ToolAnalyzer(std::vector<toollib::ToolModel> library, const AnalyzerOptions& options)
    : impl_(std::make_unique<Impl>()) {
  options.Validate();
  if (library.empty()) ThrowInvalid("ToolAnalyzer: the tool library is empty");
  const auto start = Clock::now();
  impl_->library = std::move(library);
  impl_->options = options;
  impl_->shapes = ShapeCache(options.shape_cache_dir, options.shape_segmentations.empty()
                                                         ? ShapeSegmentations{}
                                                         : ReadShapeSegmentations(options.shape_segmentations));
  impl_->recognizer = std::make_unique<ToolRecognizer>(impl_->library, options.recognition);
  impl_->model_names = impl_->recognizer->model_names();
  if (!options.classifier_file.empty()) {
    impl_->classifier = ToolClassifier::Load(options.classifier_file);
    impl_->classifier->RequireLibrary(impl_->model_names);
  }
  impl_->preparation_ms = Ms(start);
}

ToolAnalyzer::~ToolAnalyzer() = default;
ToolAnalyzer::ToolAnalyzer(ToolAnalyzer&&) noexcept = default;
ToolAnalyzer& ToolAnalyzer::operator=(ToolAnalyzer&&) noexcept = default;

void ToolAnalyzer::PrepareShapes(const std::vector<std::string>& models) const {
  for (const std::string& name : models) {
    const toollib::ToolModel* model = impl_->Find(name);
    if (model == nullptr) ThrowInvalid("ToolAnalyzer::PrepareShapes: unknown model '", name, "'");
    if (impl_->options.cache_shapes) impl_->shapes.Get(*model, impl_->options.shape);
  }
}

const std::vector<toollib::ToolModel>& ToolAnalyzer::library() const { return impl_->library; }
const ToolRecognizer& ToolAnalyzer::recognizer() const { return *impl_->recognizer; }
double ToolAnalyzer::preparation_ms() const { return impl_->preparation_ms; }

FrameAnalysis ToolAnalyzer::Analyze(const RgbdFrame& frame) const {
  FrameAnalysis out;
  auto t = Clock::now();
  out.segments = SegmentTools(frame, impl_->options.segmentation);  // checks the images
  const double segmentation_ms = Ms(t);
  // The stages after segmentation check these too, but only when a tool was found: a bad
  // camera model must not pass unnoticed on a frame that happens to show none.
  if (frame.depth.empty()) {
    ThrowInvalid("ToolAnalyzer::Analyze: frame.depth is empty (expected CV_32FC1 of the rgb size ", frame.rgb.cols,
                 "x", frame.rgb.rows, ")");
  }
  const CameraIntrinsics& k = frame.intrinsics;
  if (k.width != frame.rgb.cols || k.height != frame.rgb.rows || !(k.fx > 0) || !(k.fy > 0)) {
    ThrowInvalid("ToolAnalyzer::Analyze: frame.intrinsics ", k.width, "x", k.height, " fx ", k.fx, " fy ", k.fy,
                 " do not describe the ", frame.rgb.cols, "x", frame.rgb.rows, " images (expected the image size and "
                 "positive focal lengths)");
  }
  if (!frame.X_RC.matrix().allFinite()) ThrowInvalid("ToolAnalyzer::Analyze: frame.X_RC is not finite");
  if (out.segments.empty()) {
    out.reason = Cat("no tool segmented: no region of saturated colour (S >= ",
                     impl_->options.segmentation.min_saturation, ", V >= ", impl_->options.segmentation.min_value,
                     ") of at least ", impl_->options.segmentation.min_area_px, " px");
  }
  const std::optional<Eigen::Vector3d> p_R_camera = frame.X_RC.translation();
  for (size_t i = 0; i < out.segments.size(); ++i) {
    const ToolSegment& segment = out.segments[i];
    StageTimes times;
    times.segmentation_ms = segmentation_ms / static_cast<double>(out.segments.size());
    ToolAnalysis analysis;
    analysis.segment = static_cast<int>(i);
    analysis.roi = segment.roi;

    t = Clock::now();
    ObjectCloud cloud = ExtractObjectCloud(frame, segment.mask, impl_->options.cloud);
    times.cloud_ms = Ms(t);
    RecognitionResult recognition;
    if (cloud.status != CloudStatus::kOk) {
      analysis.status = AnalysisStatus::kNoCloud;
      analysis.reason = cloud.reason;
      recognition.reason = cloud.reason;
    } else {
      std::vector<double> prior;
      if (impl_->classifier) {
        t = Clock::now();
        const std::vector<float> features =
            ComputeRecognitionFeatures(cloud.p_R, segment.mask, frame.intrinsics, segment.median_depth, {});
        prior = impl_->classifier->PredictForLibrary(features, impl_->model_names);
        times.classification_ms = Ms(t);
      }
      t = Clock::now();
      FitView view;
      view.depth = frame.depth;
      view.mask = segment.mask;
      view.intrinsics = frame.intrinsics;
      view.X_RC = frame.X_RC;
      recognition = impl_->recognizer->Recognize(cloud.p_R, p_R_camera, prior, view);
      times.recognition_ms = Ms(t);
      if (recognition.status != FitStatus::kOk) {
        analysis.status = AnalysisStatus::kNoFit;
        analysis.reason = recognition.reason;
      } else {
        t = Clock::now();
        const toollib::ToolModel* model = impl_->Find(recognition.model);
        TOOLBENCH_DEMAND(model != nullptr);
        analysis.model = recognition.model;
        analysis.confidence = recognition.confidence;
        analysis.X_RT = recognition.fit.X_RT;
        analysis.fit_error = recognition.fit.fit_error;
        const double outside =
            FractionOutsideModel(cloud.p_R, *model, recognition.fit.X_RT, impl_->options.outside_margin_m);
        const bool fits_model = recognition.fit.fit_error <= impl_->options.max_known_fit_error &&
                                outside <= impl_->options.max_outside_fraction;
        analysis.known = recognition.confidence >= impl_->options.min_known_confidence && fits_model;
        // The confidence is the probability that the tool is `model`: none when its geometry says
        // it is not (too poor a fit, or larger than the model).
        if (!fits_model) analysis.confidence = 0.0;
        if (analysis.known) {
          impl_->PlaceShape(*model, analysis);
        } else {
          // Not a library tool (or not one we are sure of): analyse what was seen. The pose is
          // the frame estimated from the observed handle, the confidence stays low.
          const ModelShape shape = AnalyzeObservedShape(cloud.p_R, frame.X_RC.translation(), impl_->options.shape);
          analysis.X_RT = shape.X_FT;
          Impl::Adopt(shape, analysis);
          if (analysis.status == AnalysisStatus::kOk) {
            analysis.reason =
                Cat("unknown tool (closest library model ", recognition.model, ", classifier confidence ",
                    recognition.confidence, ", fit error ", recognition.fit.fit_error * 1000, " mm, ", 100 * outside,
                    " % of the points outside the model): analysed from the observed cloud");
          }
        }
        times.shape_ms = Ms(t);
      }
    }
    times.total_ms =
        times.segmentation_ms + times.cloud_ms + times.classification_ms + times.recognition_ms + times.shape_ms;
    out.tools.push_back(std::move(analysis));
    out.times.push_back(times);
    out.recognition.push_back(std::move(recognition));
    out.clouds.push_back(std::move(cloud));
  }
  return out;
}

}  // namespace toolbench::perception
