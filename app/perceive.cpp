#include "app/perceive.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cmath>
#include <cstdlib>
#include <iostream>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <spdlog/spdlog.h>

#include "app/bench.h"
#include "app/frame_io.h"
#include "app/scoring.h"
#include "common/check.h"
#include "common/paths.h"
#include "perception/parts.h"

namespace toolbench::app {
namespace {

nlohmann::json Vec3(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }

const toollib::ToolModel* FindModel(const std::vector<toollib::ToolModel>& library, const std::string& name) {
  for (const auto& model : library) {
    if (model.name == name) return &model;
  }
  return nullptr;
}

/// Short label of an analysed tool for the images: the model, "unknown", or the status.
std::string Label(const perception::ToolAnalysis& a) {
  if (a.status != perception::AnalysisStatus::kOk && a.model.empty()) return perception::ToString(a.status);
  std::string label = a.known ? a.model : "unknown";
  if (a.status != perception::AnalysisStatus::kOk) {
    label.append(1, ' ');
    label.append(perception::ToString(a.status));
  }
  return label;
}

void PutLabel(cv::Mat& bgr, const std::string& text, cv::Point at) {
  at.y = std::max(at.y, 14);
  cv::putText(bgr, text, at, cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(0, 0, 0), 3);
  cv::putText(bgr, text, at, cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(255, 255, 255), 1);
}

void WriteImage(const std::filesystem::path& path, const cv::Mat& image) {
  if (!cv::imwrite(path.string(), image)) throw std::runtime_error(Cat("cannot write '", path.string(), "'"));
}

/// Segments drawn over the colour image: contour (green: analysed, red: not), box and label.
cv::Mat DrawSegments(const RgbdFrame& frame, const perception::FrameAnalysis& analysis) {
  cv::Mat bgr;
  cv::cvtColor(frame.rgb, bgr, cv::COLOR_RGB2BGR);
  for (size_t i = 0; i < analysis.segments.size(); ++i) {
    const bool ok = analysis.tools[i].status == perception::AnalysisStatus::kOk;
    std::vector<std::vector<cv::Point>> contours;
    cv::findContours(analysis.segments[i].mask.clone(), contours, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_SIMPLE);
    cv::drawContours(bgr, contours, -1, ok ? cv::Scalar(0, 220, 0) : cv::Scalar(0, 0, 255), 2);
    cv::rectangle(bgr, analysis.segments[i].roi, cv::Scalar(255, 255, 255), 1);
    PutLabel(bgr, std::to_string(i) + " " + Label(analysis.tools[i]), analysis.segments[i].roi.tl() + cv::Point(2, -4));
  }
  return bgr;
}

/// Pixel of a point given in R, or nothing when it is behind the camera.
std::optional<cv::Point2d> Project(const RgbdFrame& frame, const Eigen::Vector3d& p_R) {
  const Eigen::Vector3d p_C = frame.X_RC.inverse() * p_R;
  if (p_C.z() <= 1e-3) return std::nullopt;
  const CameraIntrinsics& k = frame.intrinsics;
  return cv::Point2d(k.fx * p_C.x() / p_C.z() + k.cx, k.fy * p_C.y() / p_C.z() + k.cy);
}

/// Each handle projected into the image: its graspable length along the axis (yellow), the two
/// sides of its cylinder (thin), the centre (dot) and an arrow from the centre toward the
/// effector (cyan), labelled with the segment index.
cv::Mat DrawHandles(const RgbdFrame& frame, const perception::FrameAnalysis& analysis) {
  cv::Mat bgr;
  cv::cvtColor(frame.rgb, bgr, cv::COLOR_RGB2BGR);
  for (size_t i = 0; i < analysis.tools.size(); ++i) {
    const perception::ToolAnalysis& a = analysis.tools[i];
    if (a.handle.part < 0 || a.handle.length <= 0.0) continue;
    const perception::Handle& h = a.handle;
    const Eigen::Vector3d half = 0.5 * h.length * h.axis;
    const Eigen::Vector3d side = h.radius * h.X_FH.linear().col(0);
    const auto c = Project(frame, h.center), lo = Project(frame, h.center - half), hi = Project(frame, h.center + half);
    const auto tip = Project(frame, h.center + 0.5 * h.length * h.axis + 0.05 * h.axis);
    if (!c || !lo || !hi || !tip) continue;
    for (const double s : {-1.0, 1.0}) {
      const auto a0 = Project(frame, h.center - half + s * side), a1 = Project(frame, h.center + half + s * side);
      if (a0 && a1) cv::line(bgr, *a0, *a1, cv::Scalar(0, 200, 255), 1, cv::LINE_AA);
    }
    cv::line(bgr, *lo, *hi, cv::Scalar(0, 230, 255), 3, cv::LINE_AA);
    cv::arrowedLine(bgr, *hi, *tip, cv::Scalar(255, 255, 0), 2, cv::LINE_AA, 0, 0.3);
    cv::circle(bgr, *c, 4, cv::Scalar(0, 0, 255), cv::FILLED, cv::LINE_AA);
    PutLabel(bgr, std::to_string(i) + " " + Label(a), cv::Point(static_cast<int>(c->x) + 8, static_cast<int>(c->y)));
  }
  return bgr;
}

/// The object cloud (grey), the fitted library model's samples and the axes of X_RT.
void WriteFitPly(const std::filesystem::path& path, const perception::ObjectCloud& cloud,
                 const perception::ToolAnalysis& analysis, const perception::RecognitionResult& recognition,
                 const perception::ToolAnalyzer& analyzer) {
  std::vector<Eigen::Vector3f> points;
  std::vector<Eigen::Matrix<unsigned char, 3, 1>> colours;
  auto add = [&](const Eigen::Vector3f& p, unsigned char r, unsigned char g, unsigned char b) {
    points.push_back(p);
    colours.emplace_back(r, g, b);
  };
  for (Eigen::Index k = 0; k < cloud.p_R.cols(); ++k) add(cloud.p_R.col(k), 160, 160, 160);
  if (recognition.status == perception::FitStatus::kOk) {
    const std::vector<std::string> names = analyzer.recognizer().model_names();
    const auto it = std::find(names.begin(), names.end(), recognition.model);
    TOOLBENCH_DEMAND(it != names.end());
    const Eigen::Matrix3Xf& model_T =
        analyzer.recognizer().fitter(static_cast<int>(it - names.begin())).samples().points;
    const Eigen::Isometry3f X_RT = recognition.fit.X_RT.cast<float>();
    for (Eigen::Index k = 0; k < model_T.cols(); ++k) {
      if (analysis.known) {
        add(X_RT * Eigen::Vector3f(model_T.col(k)), 230, 110, 30);
      } else {
        add(X_RT * Eigen::Vector3f(model_T.col(k)), 210, 60, 210);
      }
    }
  }
  if (analysis.status == perception::AnalysisStatus::kOk || analysis.known) {
    constexpr int kAxisPoints = 50;  // 1 mm apart
    for (int axis = 0; axis < 3; ++axis) {
      for (int k = 0; k <= kAxisPoints; ++k) {
        const Eigen::Vector3d p = analysis.X_RT * (0.001 * k * Eigen::Vector3d::Unit(axis));
        add(p.cast<float>(), axis == 0 ? 255 : 0, axis == 1 ? 255 : 0, axis == 2 ? 255 : 0);
      }
    }
  }
  Eigen::Matrix3Xf p(3, static_cast<Eigen::Index>(points.size()));
  Eigen::Matrix<unsigned char, 3, Eigen::Dynamic> c(3, static_cast<Eigen::Index>(points.size()));
  for (size_t k = 0; k < points.size(); ++k) {
    p.col(static_cast<Eigen::Index>(k)) = points[k];
    c.col(static_cast<Eigen::Index>(k)) = colours[k];
  }
  WritePointCloudPly(path, p, c);
}

/// The score of every true tool against the analysis nearest its handle (ground truth, after
/// perception is done).
nlohmann::json ScoreJson(const nlohmann::json& truth, const std::vector<toollib::ToolModel>& scene_library,
                         const perception::FrameAnalysis& analysis) {
  nlohmann::json score;
  score["segments"] = analysis.segments.size();
  score["tools_in_scene"] = truth["tools"].size();
  score["tools"] = nlohmann::json::array();
  double sum = 0.0;
  for (const auto& true_tool : truth["tools"]) {
    const toollib::ToolModel* model = FindModel(scene_library, true_tool["name"].get<std::string>());
    TOOLBENCH_DEMAND(model != nullptr);
    Eigen::Matrix4d M;
    for (int r = 0; r < 4; ++r) {
      for (int c = 0; c < 4; ++c) M(r, c) = true_tool["X_RT"]["matrix"][r][c];
    }
    const Eigen::Isometry3d X_RT_true(M);
    const Eigen::Vector3d handle_true = X_RT_true * model->handle.center;
    nlohmann::json entry{{"name", true_tool["name"]}, {"cell", true_tool["cell"]}};
    // Association by position: the analysed tool whose handle is nearest the true handle.
    int best = -1;
    double best_distance = 1e9;
    for (size_t i = 0; i < analysis.tools.size(); ++i) {
      const perception::ToolAnalysis& a = analysis.tools[i];
      if (a.status != perception::AnalysisStatus::kOk) continue;
      const double d = (a.handle.center - handle_true).norm();
      if (d < best_distance) {
        best_distance = d;
        best = static_cast<int>(i);
      }
    }
    if (best < 0) {
      entry["missed"] = true;
      entry["score"] = 0.0;
      entry["verdict"] = "not_found";
      score["tools"].push_back(entry);
      continue;
    }
    const perception::ToolAnalysis& a = analysis.tools[static_cast<size_t>(best)];
    const toollib::ToolModel* fitted = FindModel(scene_library, a.model);
    const CellScore cell = ScoreCell(a, *model, X_RT_true, fitted != nullptr ? fitted->family : "");
    entry["segment"] = best;
    entry["recognised_as"] = a.known ? a.model : "unknown";
    entry["closest_model"] = a.model;
    entry["recognition_correct"] = a.known && cell.recognised;
    entry["family_correct"] = a.known && cell.family_recognised;
    entry["confidence"] = a.confidence;
    entry["score"] = cell.score;
    entry["verdict"] = cell.verdict;
    entry["handle_error_m"] = cell.handle_error_m;
    entry["axis_error_deg"] = cell.axis_error_deg;
    entry["effector_error_deg"] = cell.effector_error_deg;
    sum += cell.score;
    score["tools"].push_back(entry);
  }
  score["mean_score"] = truth["tools"].empty() ? 0.0 : sum / static_cast<double>(truth["tools"].size());
  return score;
}

}  // namespace

nlohmann::json ToolAnalysisJson(const perception::ToolAnalysis& a) {
  nlohmann::json j;
  j["segment"] = a.segment;
  j["status"] = perception::ToString(a.status);
  j["reason"] = a.reason;
  j["roi"] = {a.roi.x, a.roi.y, a.roi.width, a.roi.height};
  j["model"] = a.model;
  j["known"] = a.known;
  j["confidence"] = a.confidence;
  j["X_RT"] = PoseJson(a.X_RT);
  j["fit_error_m"] = a.fit_error;
  j["parts"] = nlohmann::json::array();
  for (const perception::Part& p : a.parts) {
    j["parts"].push_back({{"points", p.points.cols()},
                          {"fit_error", p.fit_error},
                          {"cylinder_score", p.cylinder_score},
                          {"superquadric", {{"size_m", Vec3(p.sq.size)},
                                            {"e1", p.sq.e1},
                                            {"e2", p.sq.e2},
                                            {"X_RS", PoseJson(p.sq.pose)}}}});
  }
  const perception::Handle& h = a.handle;
  j["handle"] = {{"part", h.part},         {"center_R", Vec3(h.center)}, {"axis_R", Vec3(h.axis)},
                 {"radius_m", h.radius},   {"length_m", h.length},       {"X_RH", PoseJson(h.X_FH)}};
  const perception::ToolFeatures& f = a.features;
  j["features"] = {{"total_length_m", f.total_length},
                   {"handle_length_m", f.handle_length},
                   {"handle_radius_m", f.handle_radius},
                   {"effector_center_T", Vec3(f.effector_center)},
                   {"effector_size_T", Vec3(f.effector_size)},
                   {"effector_protrusion_m", f.effector_protrusion}};
  return j;
}

nlohmann::json FrameAnalysisJson(const perception::FrameAnalysis& frame) {
  TOOLBENCH_DEMAND(frame.tools.size() == frame.segments.size() && frame.times.size() == frame.segments.size() &&
                   frame.recognition.size() == frame.segments.size() && frame.clouds.size() == frame.segments.size());
  nlohmann::json out;
  out["tools"] = nlohmann::json::array();
  for (size_t i = 0; i < frame.tools.size(); ++i) {
    nlohmann::json j = ToolAnalysisJson(frame.tools[i]);
    const perception::StageTimes& t = frame.times[i];
    j["ms"] = {{"segmentation", t.segmentation_ms}, {"cloud", t.cloud_ms}, {"classification", t.classification_ms},
               {"recognition", t.recognition_ms},   {"shape", t.shape_ms}, {"total", t.total_ms}};
    const perception::ToolSegment& s = frame.segments[i];
    j["segment_area_px"] = s.area_px;
    j["segment_mean_hue_deg"] = s.mean_hue_deg;
    j["segment_median_depth_m"] = s.median_depth;
    const perception::ObjectCloud& c = frame.clouds[i];
    j["cloud"] = {{"points", c.p_R.cols()},       {"masked_pixels", c.masked_pixels},
                  {"valid_depth", c.valid_depth}, {"plane_points", c.plane_points},
                  {"outliers", c.outlier_points}, {"reason", c.reason}};
    j["candidates"] = nlohmann::json::array();
    for (const perception::ModelScore& m : frame.recognition[i].scores) {
      if (!m.fitted) continue;
      j["candidates"].push_back({{"model", m.model}, {"prior", m.prior}, {"score_m", m.score}, {"posterior", m.posterior}});
    }
    out["tools"].push_back(std::move(j));
  }
  return out;
}

std::filesystem::path DefaultClassifierPath() { return AssetsDir() / "models" / "tool_classifier.yml.gz"; }

namespace {

// DefaultAnalyzerOptions' shape cache directory (see its comment).
std::filesystem::path DefaultShapeCacheDir() {
  if (const char* dir = std::getenv("TOOLBENCH_CACHE_DIR"); dir != nullptr && *dir != 0) {
    return std::filesystem::path(dir) / "shapes";
  }
  if (const char* dir = std::getenv("XDG_CACHE_HOME"); dir != nullptr && *dir != 0) {
    return std::filesystem::path(dir) / "toolbench" / "shapes";
  }
  if (const char* home = std::getenv("HOME"); home != nullptr && *home != 0) {
    return std::filesystem::path(home) / ".cache" / "toolbench" / "shapes";
  }
  return {};
}

}  // namespace

perception::AnalyzerOptions DefaultAnalyzerOptions() {
  perception::AnalyzerOptions options;
  options.classifier_file = DefaultClassifierPath();
  options.shape_cache_dir = DefaultShapeCacheDir();
  options.shape_segmentations = AssetsDir() / "models" / "library_segmentation.json";
  return options;
}

void WriteLibrarySegmentations(const std::vector<toollib::ToolModel>& library, const std::filesystem::path& out) {
  const perception::ShapeOptions options = DefaultAnalyzerOptions().shape;
  perception::ShapeSegmentations segmentations;
  std::string failed;
  for (const toollib::ToolModel& model : library) {
    const auto start = std::chrono::steady_clock::now();
    perception::ShapeSegmentation seg = perception::SegmentModelShape(model, options);
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (seg.status != perception::ShapeStatus::kOk) {
      failed += Cat(failed.empty() ? "" : "; ", model.name, ": ", seg.reason);
      continue;
    }
    std::printf("%-14s %d parts, %zu samples%s (%.1f s)\n", model.name.c_str(), seg.num_labels, seg.labels.size(),
                seg.mesh_fallback ? ", from the library mesh" : "", s);
    segmentations.emplace(perception::ShapeCacheKey(model, options), std::move(seg));
  }
  if (!failed.empty()) throw std::runtime_error(Cat("segmentation failed for ", failed, "; nothing written"));
  perception::WriteShapeSegmentations(out, segmentations);
  std::printf("wrote %zu segmentations to %s\n", segmentations.size(), out.string().c_str());
}

int RunPerceive(const SceneRequest& request, const std::filesystem::path& out_dir, const CaptureOptions& capture_options,
                const PerceiveOptions& options) {
  if (options.user_tools_unknown && request.extra_tool_dirs.empty()) {
    ThrowInvalid("perceive: --user-tools-unknown needs at least one --tool-dir");
  }
  if (!options.classifier.empty() && !std::filesystem::is_regular_file(options.classifier)) {
    ThrowInvalid("perceive: classifier file '", options.classifier.string(), "' does not exist (--classifier; "
                 "--no-classifier recognises without one)");
  }
  sim::GlContext gl;
  const Capture capture = CaptureFrame(request, capture_options, gl);
  WriteFrame(out_dir, capture.frame, CaptureMetadata(capture, request, capture_options));
  const nlohmann::json truth = GroundTruthJson(capture);
  WriteTextFile(out_dir / "ground_truth.json", truth.dump(2) + "\n");

  // ---- Perception: from here on only the frame and the robot's library are used. ----
  std::vector<toollib::ToolModel> library =
      options.user_tools_unknown ? LoadLibraries(capture.scene.spec, {}) : capture.scene.library;
  perception::AnalyzerOptions analyzer_options = DefaultAnalyzerOptions();
  analyzer_options.classifier_file = options.classifier;
  std::unique_ptr<perception::ToolAnalyzer> analyzer;
  try {
    analyzer = std::make_unique<perception::ToolAnalyzer>(library, analyzer_options);
  } catch (const std::invalid_argument& e) {
    if (request.extra_tool_dirs.empty() || options.classifier.empty()) throw;
    ThrowInvalid("perceive: ", e.what(),
                 " (user tools from --tool-dir: add --no-classifier to recognise them by fit alone, or "
                 "--user-tools-unknown to analyse them as unknown tools)");
  }
  const perception::FrameAnalysis analysis = analyzer->Analyze(capture.frame);
  const RgbdFrame& frame = capture.frame;

  nlohmann::json json = FrameAnalysisJson(analysis);
  json["classifier"] = options.classifier.empty() ? "none (extent pre-selection)" : options.classifier.string();
  json["library"] = analyzer->recognizer().model_names();
  json["user_tools_unknown"] = options.user_tools_unknown;
  json["library_preparation_ms"] = analyzer->preparation_ms();
  json["segments"] = analysis.segments.size();
  json["reason"] = analysis.reason;
  for (size_t i = 0; i < analysis.tools.size(); ++i) {
    const perception::ToolAnalysis& a = analysis.tools[i];
    const perception::ToolSegment& segment = analysis.segments[i];
    const std::string n = std::to_string(i);
    nlohmann::json files = nlohmann::json::array();
    auto written = [&](const std::string& name) {
      files.push_back(name);
      return out_dir / name;
    };
    WriteImage(written("mask_" + n + ".png"), segment.mask);
    cv::Mat roi_bgr;
    cv::cvtColor(frame.rgb(segment.roi), roi_bgr, cv::COLOR_RGB2BGR);
    WriteImage(written("roi_" + n + ".png"), roi_bgr);
    if (analysis.clouds[i].p_R.cols() > 0) {
      WriteFitPly(written("tool_" + n + "_fit.ply"), analysis.clouds[i], a, analysis.recognition[i], *analyzer);
    }
    if (!a.parts.empty()) {
      perception::WritePartsPly(written("tool_" + n + "_parts.ply"), a.parts, a.handle.part);
      perception::WriteSuperquadricsPly(written("tool_" + n + "_superquadrics.ply"), a.parts, a.handle.part);
    }
    json["tools"][i]["files"] = files;
  }
  WriteJson(out_dir / "analysis.json", json);
  WriteImage(out_dir / "segments.png", DrawSegments(frame, analysis));
  WriteImage(out_dir / "handles.png", DrawHandles(frame, analysis));

  // ---- Evaluation against ground truth (after perception is done). ----
  WriteJson(out_dir / "score.json", ScoreJson(truth, capture.scene.library, analysis));
  int ok = 0;
  for (const perception::ToolAnalysis& a : analysis.tools) ok += a.status == perception::AnalysisStatus::kOk ? 1 : 0;
  spdlog::info("perceive: seed {}, {} segment(s) ({} analysed) for {} tool(s), written to {}", request.seed,
               analysis.segments.size(), ok, truth["tools"].size(), out_dir.string());
  std::cout << out_dir.string() << "\n";
  return 0;
}

}  // namespace toolbench::app
