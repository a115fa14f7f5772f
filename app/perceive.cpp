#include "app/perceive.h"

#include <chrono>
#include <cmath>
#include <iostream>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <spdlog/spdlog.h>

#include "app/bench.h"
#include "app/frame_io.h"
#include "common/paths.h"
#include "perception/model_fit.h"
#include "perception/object_cloud.h"
#include "perception/segmentation.h"

namespace toolbench::app {
namespace {

using Clock = std::chrono::steady_clock;

double Ms(Clock::time_point since) {
  return std::chrono::duration<double, std::milli>(Clock::now() - since).count();
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

int RunPerceive(const SceneRequest& request, const std::filesystem::path& out_dir,
                const CaptureOptions& options) {
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
  const double prepare_ms = Ms(t);
  t = Clock::now();
  const std::vector<perception::ToolSegment> segments = perception::SegmentTools(frame, {});
  const double segment_ms = Ms(t);

  nlohmann::json analysis;
  analysis["library_preparation_ms"] = prepare_ms;
  analysis["segmentation_ms"] = segment_ms;
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
    const perception::ObjectCloud cloud = perception::ExtractObjectCloud(frame, segment.mask, {});
    const double cloud_ms = Ms(t);
    tool["cloud"] = {{"points", cloud.p_R.cols()},       {"masked_pixels", cloud.masked_pixels},
                     {"valid_depth", cloud.valid_depth}, {"plane_points", cloud.plane_points},
                     {"outliers", cloud.outlier_points}, {"reason", cloud.reason}};
    tool["ms"] = {{"cloud", cloud_ms}};
    perception::RecognitionResult result;
    if (cloud.status != perception::CloudStatus::kOk) {
      result.reason = cloud.reason;
      tool["status"] = "no_cloud";
      tool["reason"] = cloud.reason;
      labels.push_back("?");
    } else {
      t = Clock::now();
      result = recognizer.Recognize(cloud.p_R, frame.X_RC.translation());
      tool["ms"]["recognition_and_fit"] = Ms(t);
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
    const Eigen::Vector3d handle_true = X_RT_true * model->handle.center;
    const Eigen::Vector3d axis_true = X_RT_true.linear().col(2);
    nlohmann::json entry{{"name", true_tool["name"]}, {"cell", true_tool["cell"]}};
    double best = 1e9;
    for (size_t i = 0; i < results.size(); ++i) {
      if (results[i].status != perception::FitStatus::kOk) continue;
      const toollib::ToolModel* fitted = FindModel(library, results[i].model);
      const Eigen::Vector3d handle = results[i].fit.X_RT * fitted->handle.center;
      const double error = (handle - handle_true).norm();
      if (error < best) {
        best = error;
        const Eigen::Vector3d axis = results[i].fit.X_RT.linear().col(2);
        entry["segment"] = i;
        entry["recognised_as"] = results[i].model;
        entry["recognition_correct"] = results[i].model == true_tool["name"];
        entry["handle_error_m"] = error;
        entry["axis_error_deg"] = std::acos(std::clamp(axis.dot(axis_true), -1.0, 1.0)) * 180.0 / M_PI;
      }
    }
    if (best > 1e8) entry["missed"] = true;
    score["tools"].push_back(entry);
  }
  WriteJson(out_dir / "score.json", score);
  spdlog::info("perceive: seed {}, {} segment(s) for {} tool(s), written to {}", request.seed,
               segments.size(), truth["tools"].size(), out_dir.string());
  std::cout << out_dir.string() << "\n";
  return 0;
}

}  // namespace toolbench::app
