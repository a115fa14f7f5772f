#include "app/perceive.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <ctime>
#include <iostream>
#include <optional>

#include <spdlog/spdlog.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "app/bench.h"
#include "app/frame_io.h"
#include "common/paths.h"
#include "perception/model_fit.h"
#include "perception/object_cloud.h"
#include "perception/recognition_features.h"
#include "perception/segmentation.h"
#include "perception/tool_classifier.h"

namespace toolbench::app {
namespace {

using Clock = std::chrono::steady_clock;

double Ms(Clock::time_point since) { return std::chrono::duration<double, std::milli>(Clock::now() - since).count(); }

// CPU time of the process (all threads) [ms]: unlike wall time, it does not grow when other
// processes share the cores, so it measures the work itself.
double ProcessCpuMs() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return 1e3 * static_cast<double>(ts.tv_sec) + 1e-6 * static_cast<double>(ts.tv_nsec);
}

nlohmann::json Vec3(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }

const toollib::ToolModel* FindModel(const std::vector<toollib::ToolModel>& library, const std::string& name) {
  for (const auto& model : library) {
    if (model.name == name) return &model;
  }
  return nullptr;
}

/// Segments drawn over the colour image: contour, box and index.
cv::Mat DrawSegments(const RgbdFrame& frame, const std::vector<perception::ToolSegment>& segments,
                     const std::vector<std::string>& labels) {
  cv::Mat bgr;
  cv::cvtColor(frame.rgb, bgr, cv::COLOR_RGB2BGR);
  for (size_t i = 0; i < segments.size(); ++i) {
    std::vector<std::vector<cv::Point>> contours;
    cv::findContours(segments[i].mask.clone(), contours, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_SIMPLE);
    cv::drawContours(bgr, contours, -1, cv::Scalar(0, 255, 0), 2);
    cv::rectangle(bgr, segments[i].roi, cv::Scalar(255, 255, 255), 1);
    cv::putText(bgr, std::to_string(i) + " " + labels[i], segments[i].roi.tl() + cv::Point(2, -4),
                cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(0, 0, 0), 2);
    cv::putText(bgr, std::to_string(i) + " " + labels[i], segments[i].roi.tl() + cv::Point(2, -4),
                cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(255, 255, 255), 1);
  }
  return bgr;
}

}  // namespace

std::filesystem::path DefaultClassifierPath() { return AssetsDir() / "models" / "tool_classifier.yml.gz"; }

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

perception::AnalyzerOptions DefaultAnalyzerOptions() {
  perception::AnalyzerOptions options;
  options.classifier_file = DefaultClassifierPath();
  options.shape_cache_dir = DefaultShapeCacheDir();
  return options;
}

int RunPerceive(const SceneRequest& request, const std::filesystem::path& out_dir, const CaptureOptions& options,
                const std::filesystem::path& classifier_path) {
  std::optional<perception::ToolClassifier> classifier;
  if (!classifier_path.empty()) classifier = perception::ToolClassifier::Load(classifier_path);
  sim::GlContext gl;
  const Capture capture = CaptureFrame(request, options, gl);
  WriteFrame(out_dir, capture.frame, CaptureMetadata(capture, request, options));
  const nlohmann::json truth = GroundTruthJson(capture);
  WriteTextFile(out_dir / "ground_truth.json", truth.dump(2) + "\n");

  // ---- Perception: from here on only the frame and the library are used. ----
  const std::vector<toollib::ToolModel>& library = capture.scene.library;
  const RgbdFrame& frame = capture.frame;
  auto t = Clock::now();
  const perception::ToolRecognizer recognizer(library, perception::RecognitionOptions{});
  const std::vector<std::string> names = recognizer.model_names();
  if (classifier) classifier->RequireLibrary(names);
  const double prepare_ms = Ms(t);
  t = Clock::now();
  double cpu = ProcessCpuMs();
  const std::vector<perception::ToolSegment> segments = perception::SegmentTools(frame, {});
  const double segment_ms = Ms(t);
  const double segment_cpu_ms = ProcessCpuMs() - cpu;

  nlohmann::json analysis;
  analysis["library_preparation_ms"] = prepare_ms;
  analysis["segmentation_ms"] = segment_ms;
  analysis["segmentation_cpu_ms"] = segment_cpu_ms;
  analysis["classifier"] = classifier ? classifier_path.string() : "none (extent pre-selection)";
  analysis["tools"] = nlohmann::json::array();
  std::vector<std::string> labels;
  std::vector<perception::RecognitionResult> results;
  for (size_t i = 0; i < segments.size(); ++i) {
    const perception::ToolSegment& segment = segments[i];
    nlohmann::json tool;
    tool["segment"] = {{"roi", {segment.roi.x, segment.roi.y, segment.roi.width, segment.roi.height}},
                       {"area_px", segment.area_px},
                       {"mean_hue_deg", segment.mean_hue_deg},
                       {"median_depth_m", segment.median_depth}};
    t = Clock::now();
    const double tool_cpu_start = ProcessCpuMs();
    const perception::ObjectCloud cloud = perception::ExtractObjectCloud(frame, segment.mask, {});
    const double cloud_ms = Ms(t);
    const double cloud_cpu_ms = ProcessCpuMs() - tool_cpu_start;
    tool["cloud"] = {{"points", cloud.p_R.cols()},       {"masked_pixels", cloud.masked_pixels},
                     {"valid_depth", cloud.valid_depth}, {"plane_points", cloud.plane_points},
                     {"outliers", cloud.outlier_points}, {"reason", cloud.reason}};
    tool["ms"] = {{"cloud", cloud_ms}};
    tool["cpu_ms"] = {{"cloud", cloud_cpu_ms}};
    perception::RecognitionResult result;
    if (cloud.status != perception::CloudStatus::kOk) {
      result.reason = cloud.reason;
      tool["status"] = "no_cloud";
      tool["reason"] = cloud.reason;
      labels.push_back("?");
    } else {
      std::vector<double> prior;
      if (classifier) {
        t = Clock::now();
        cpu = ProcessCpuMs();
        const std::vector<float> features =
            perception::ComputeRecognitionFeatures(cloud.p_R, segment.mask, frame.intrinsics, segment.median_depth, {});
        prior = classifier->PredictForLibrary(features, names);
        tool["ms"]["features"] = Ms(t);
        tool["cpu_ms"]["features"] = ProcessCpuMs() - cpu;
      }
      t = Clock::now();
      cpu = ProcessCpuMs();
      perception::FitView view;
      view.depth = frame.depth;
      view.mask = segment.mask;
      view.intrinsics = frame.intrinsics;
      view.X_RC = frame.X_RC;
      result = recognizer.Recognize(cloud.p_R, frame.X_RC.translation(), prior, view);
      tool["ms"]["recognition_and_fit"] = Ms(t);
      tool["cpu_ms"]["recognition_and_fit"] = ProcessCpuMs() - cpu;
      tool["candidates"] = nlohmann::json::array();
      for (const perception::ModelScore& s : result.scores) {
        if (!s.fitted) continue;
        tool["candidates"].push_back(
            {{"model", s.model}, {"prior", s.prior}, {"score_m", s.score}, {"posterior", s.posterior}});
      }
      if (result.status != perception::FitStatus::kOk) {
        tool["status"] = "not_recognised";
        tool["reason"] = result.reason;
        labels.push_back("?");
      } else {
        const toollib::ToolModel* model = FindModel(library, result.model);
        tool["status"] = "ok";
        tool["model"] = result.model;
        tool["confidence"] = result.confidence;
        tool["fit_error_m"] = result.fit.fit_error;
        tool["view_turn"] = result.fit.view_turn;
        tool["view_violation"] = result.fit.violation;
        tool["X_RT"] = PoseJson(result.fit.X_RT);
        tool["handle"] = {{"center_R", Vec3(result.fit.X_RT * model->handle.center)},
                          {"axis_R", Vec3(result.fit.X_RT.linear() * model->handle.axis)},
                          {"radius_m", model->handle.radius},
                          {"length_m", model->handle.length}};
        labels.push_back(result.model);
        // Object cloud (grey) and the fitted model's samples (tool colour) in one PLY.
        const perception::ModelFitter* fitter = nullptr;
        for (size_t m = 0; m < library.size(); ++m) {
          if (library[m].name == result.model) fitter = &recognizer.fitter(static_cast<int>(m));
        }
        const Eigen::Matrix3Xf model_R =
            (result.fit.X_RT.cast<float>() * fitter->samples().points.colwise().homogeneous()).eval();
        Eigen::Matrix3Xf points(3, cloud.p_R.cols() + model_R.cols());
        points << cloud.p_R, model_R;
        Eigen::Matrix<unsigned char, 3, Eigen::Dynamic> colour(3, points.cols());
        colour.leftCols(cloud.p_R.cols()).setConstant(160);
        for (Eigen::Index c = 0; c < model_R.cols(); ++c) {
          colour.col(cloud.p_R.cols() + c) << 230, 60, 30;
        }
        WritePointCloudPly(out_dir / ("tool_" + std::to_string(i) + ".ply"), points, colour);
      }
    }
    results.push_back(result);
    analysis["tools"].push_back(tool);
  }
  WriteJson(out_dir / "analysis.json", analysis);
  cv::imwrite((out_dir / "segments.png").string(), DrawSegments(frame, segments, labels));

  // ---- Evaluation against ground truth (after perception is done). ----
  nlohmann::json score;
  score["segments"] = segments.size();
  score["tools_in_scene"] = truth["tools"].size();
  score["tools"] = nlohmann::json::array();
  for (const auto& true_tool : truth["tools"]) {
    const toollib::ToolModel* model = FindModel(library, true_tool["name"]);
    Eigen::Matrix4d M;
    for (int r = 0; r < 4; ++r) {
      for (int c = 0; c < 4; ++c) M(r, c) = true_tool["X_RT"]["matrix"][r][c];
    }
    const Eigen::Isometry3d X_RT_true(M);
    // A tool symmetric end over end (a stick) is equally right either way up.
    std::vector<Eigen::Isometry3d> truths = {X_RT_true};
    if (std::find(model->symmetries.begin(), model->symmetries.end(), "rot_x_180") != model->symmetries.end()) {
      Eigen::Isometry3d flip = Eigen::Isometry3d::Identity();
      flip.linear() = Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()).toRotationMatrix();
      flip.translation() = Eigen::Vector3d(0, 0, model->total_length);
      truths.push_back(X_RT_true * flip);
    }
    nlohmann::json entry{{"name", true_tool["name"]}, {"cell", true_tool["cell"]}};
    double best = 1e9;
    for (size_t i = 0; i < results.size(); ++i) {
      if (results[i].status != perception::FitStatus::kOk) continue;
      const toollib::ToolModel* fitted = FindModel(library, results[i].model);
      const Eigen::Vector3d handle = results[i].fit.X_RT * fitted->handle.center;
      for (const Eigen::Isometry3d& truth : truths) {
        const double error = (handle - truth * model->handle.center).norm();
        if (error >= best) continue;
        best = error;
        const Eigen::Vector3d axis = results[i].fit.X_RT.linear().col(2);
        // The effector protrudes along +x_T: it faces the right way when x_T agrees.
        const Eigen::Vector3d effector = results[i].fit.X_RT.linear().col(0);
        entry["segment"] = i;
        entry["recognised_as"] = results[i].model;
        entry["recognition_correct"] = results[i].model == true_tool["name"];
        entry["confidence"] = results[i].confidence;
        entry["handle_error_m"] = error;
        entry["axis_error_deg"] = std::acos(std::clamp(axis.dot(truth.linear().col(2)), -1.0, 1.0)) * 180.0 / M_PI;
        // A tool of any spin about its axis (a stick) has no effector direction to get wrong.
        const bool any_spin =
            std::find(model->symmetries.begin(), model->symmetries.end(), "rot_z_any") != model->symmetries.end();
        if (!any_spin) {
          entry["effector_error_deg"] =
              std::acos(std::clamp(effector.dot(truth.linear().col(0)), -1.0, 1.0)) * 180.0 / M_PI;
        }
      }
    }
    if (best > 1e8) entry["missed"] = true;
    score["tools"].push_back(entry);
  }
  WriteJson(out_dir / "score.json", score);
  spdlog::info("perceive: seed {}, {} segment(s) for {} tool(s), written to {}", request.seed, segments.size(),
               truth["tools"].size(), out_dir.string());
  std::cout << out_dir.string() << "\n";
  return 0;
}

}  // namespace toolbench::app
