#include "app/train_recognizer.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <iomanip>
#include <map>

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include "app/bench.h"
#include "app/capture.h"
#include "common/check.h"
#include "common/rng.h"
#include "perception/model_fit.h"
#include "perception/object_cloud.h"
#include "perception/segmentation.h"

namespace toolbench::app {
namespace {

constexpr double kLabelDistance = 0.01;   // a cloud point within this of a tool's surface is explained [m]
constexpr double kLabelFraction = 0.8;    // fraction of explained points needed for a label
constexpr int kLabelPoints = 200;         // cloud points checked per segment
constexpr int kLabelSamples = 1500;       // surface samples per ground-truth tool

void WriteCsv(const std::filesystem::path& path, const std::vector<LabelledSample>& samples,
              const std::vector<std::string>& feature_names) {
  std::ofstream out(path);
  if (!out) ThrowInvalid("train-recognizer: cannot write '", path.string(), "'");
  out << "seed,segment,cell,label";
  for (const auto& name : feature_names) out << ',' << name;
  out << '\n';
  out << std::setprecision(9);
  for (const LabelledSample& s : samples) {
    out << s.seed << ',' << s.segment << ',' << s.cell << ',' << s.label;
    for (float v : s.features) out << ',' << v;
    out << '\n';
  }
}

}  // namespace

std::uint64_t TrainingSceneSeed(std::uint64_t seed, bool heldout, int index) {
  return DeriveSeed(seed, (heldout ? "heldout/" : "train/") + std::to_string(index));
}

CollectStats CollectSamples(const SceneRequest& request, sim::GlContext& gl,
                            const perception::RecognitionFeatureOptions& features,
                            std::vector<LabelledSample>& samples) {
  CaptureOptions options;
  const Capture capture = CaptureFrame(request, options, gl);
  const RgbdFrame& frame = capture.frame;
  CollectStats stats;

  // Perception, as `perceive` runs it.
  const std::vector<perception::ToolSegment> segments = perception::SegmentTools(frame, {});
  stats.segments = static_cast<int>(segments.size());

  // Ground truth (offline supervision only): each placed tool's surface in R.
  const sim::GroundTruth truth = capture.world->ground_truth();
  const Eigen::Isometry3d X_RW = capture.scene.composed.X_WR.inverse();
  struct TrueTool {
    std::string name;
    std::string cell;
    Eigen::Matrix3Xf surface_R;
  };
  std::vector<TrueTool> tools;
  for (const auto& placed : capture.scene.composed.tools) {
    const auto it = std::find_if(capture.scene.library.begin(), capture.scene.library.end(),
                                 [&](const toollib::ToolModel& m) { return m.name == placed.name; });
    TOOLBENCH_DEMAND(it != capture.scene.library.end());
    const Eigen::Isometry3f X_RT = (X_RW * truth.Pose(placed.body)).cast<float>();
    const perception::SurfaceSamples surface = perception::SampleSurface(it->mesh, kLabelSamples, 1);
    tools.push_back({placed.name, placed.cell, (X_RT * surface.points.colwise().homogeneous()).eval()});
  }

  for (std::size_t i = 0; i < segments.size(); ++i) {
    const perception::ObjectCloud cloud = perception::ExtractObjectCloud(frame, segments[i].mask, {});
    if (cloud.status != perception::CloudStatus::kOk || cloud.p_R.cols() < 10) {
      ++stats.no_cloud;
      continue;
    }
    // Which ground-truth tool explains the cloud?
    const Eigen::Index n = cloud.p_R.cols();
    const int checked = static_cast<int>(std::min<Eigen::Index>(n, kLabelPoints));
    int best = -1;
    double best_fraction = 0.0;
    for (std::size_t t = 0; t < tools.size(); ++t) {
      int explained = 0;
      for (int k = 0; k < checked; ++k) {
        const Eigen::Vector3f p = cloud.p_R.col(static_cast<Eigen::Index>(k * static_cast<double>(n) / checked));
        const float d2 = (tools[t].surface_R.colwise() - p).colwise().squaredNorm().minCoeff();
        if (d2 < kLabelDistance * kLabelDistance) ++explained;
      }
      const double fraction = static_cast<double>(explained) / checked;
      if (fraction > best_fraction) {
        best_fraction = fraction;
        best = static_cast<int>(t);
      }
    }
    if (best < 0 || best_fraction < kLabelFraction) {
      ++stats.unlabelled;
      continue;
    }
    LabelledSample sample;
    sample.seed = request.seed;
    sample.segment = static_cast<int>(i);
    sample.cell = tools[static_cast<std::size_t>(best)].cell;
    sample.label = tools[static_cast<std::size_t>(best)].name;
    sample.features = perception::ComputeRecognitionFeatures(cloud.p_R, segments[i].mask, frame.intrinsics,
                                                             segments[i].median_depth, features);
    samples.push_back(std::move(sample));
  }
  return stats;
}

perception::ToolDataset MakeDataset(const std::vector<LabelledSample>& samples,
                                    const std::vector<std::string>& library,
                                    const perception::RecognitionFeatureOptions& features) {
  perception::ToolDataset data;
  data.model_names = library;
  data.feature_names = perception::RecognitionFeatureNames(features);
  data.features.resize(static_cast<Eigen::Index>(samples.size()), static_cast<Eigen::Index>(data.feature_names.size()));
  for (std::size_t r = 0; r < samples.size(); ++r) {
    const auto it = std::find(library.begin(), library.end(), samples[r].label);
    if (it == library.end()) ThrowInvalid("MakeDataset: sample label '", samples[r].label, "' is not in the library");
    if (samples[r].features.size() != data.feature_names.size()) {
      ThrowInvalid("MakeDataset: sample ", r, " has ", samples[r].features.size(), " features (expected ",
                   data.feature_names.size(), ")");
    }
    data.labels.push_back(static_cast<int>(it - library.begin()));
    for (std::size_t c = 0; c < samples[r].features.size(); ++c) {
      data.features(static_cast<Eigen::Index>(r), static_cast<Eigen::Index>(c)) = samples[r].features[c];
    }
  }
  return data;
}

int RunTrainRecognizer(const TrainRecognizerRequest& request) {
  if (request.scenes <= 0) ThrowInvalid("train-recognizer: --scenes = ", request.scenes, " (expected > 0)");
  if (request.heldout_scenes < 0) {
    ThrowInvalid("train-recognizer: --heldout = ", request.heldout_scenes, " (expected >= 0)");
  }
  if (request.out_dir.empty()) ThrowInvalid("train-recognizer: --out is empty (expected a folder)");
  request.classifier.Validate();
  request.features.Validate();
  std::filesystem::create_directories(request.out_dir);
  const int heldout = request.heldout_scenes > 0 ? request.heldout_scenes : std::max(1, request.scenes / 4);

  const auto start = std::chrono::steady_clock::now();
  sim::GlContext gl;
  std::vector<LabelledSample> train;
  std::vector<LabelledSample> test;
  CollectStats totals;
  std::vector<std::string> library;
  for (int pass = 0; pass < 2; ++pass) {
    const bool is_heldout = pass == 1;
    const int count = is_heldout ? heldout : request.scenes;
    for (int i = 0; i < count; ++i) {
      SceneRequest scene;
      scene.seed = TrainingSceneSeed(request.seed, is_heldout, i);
      if (library.empty()) {
        for (const auto& m : LoadScene(scene).library) library.push_back(m.name);
      }
      const CollectStats stats = CollectSamples(scene, gl, request.features, is_heldout ? test : train);
      totals.segments += stats.segments;
      totals.no_cloud += stats.no_cloud;
      totals.unlabelled += stats.unlabelled;
      if ((i + 1) % 25 == 0) {
        spdlog::info("train-recognizer: {} {}/{} scenes, {} samples", is_heldout ? "held-out" : "training", i + 1,
                     count, (is_heldout ? test : train).size());
      }
    }
  }
  const double collect_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const std::vector<std::string> feature_names = perception::RecognitionFeatureNames(request.features);
  WriteCsv(request.out_dir / "dataset.csv", train, feature_names);
  WriteCsv(request.out_dir / "heldout.csv", test, feature_names);

  const auto train_start = std::chrono::steady_clock::now();
  const perception::ToolClassifier classifier =
      perception::ToolClassifier::Train(MakeDataset(train, library, request.features), request.classifier);
  const double train_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - train_start).count();
  const std::filesystem::path model_path = request.out_dir / "tool_classifier.yml.gz";
  classifier.Save(model_path);

  // Held-out evaluation.
  int top1 = 0;
  int top3 = 0;
  std::map<std::string, std::pair<int, int>> per_model;  // correct, total
  std::map<std::string, int> confusions;                  // "truth -> predicted"
  std::vector<double> predict_us;
  nlohmann::json predictions = nlohmann::json::array();
  for (const LabelledSample& s : test) {
    const auto t0 = std::chrono::steady_clock::now();
    const std::vector<double> p = classifier.PredictForLibrary(s.features, library);
    predict_us.push_back(std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - t0).count());
    std::vector<std::size_t> order(p.size());
    for (std::size_t k = 0; k < order.size(); ++k) order[k] = k;
    std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return p[a] > p[b]; });
    const std::string& predicted = library[order[0]];
    const bool correct = predicted == s.label;
    bool in_top3 = false;
    for (std::size_t k = 0; k < std::min<std::size_t>(3, order.size()); ++k) in_top3 |= library[order[k]] == s.label;
    top1 += correct ? 1 : 0;
    top3 += in_top3 ? 1 : 0;
    auto& entry = per_model[s.label];
    entry.first += correct ? 1 : 0;
    entry.second += 1;
    if (!correct) ++confusions[s.label + " -> " + predicted];
    predictions.push_back({{"seed", s.seed}, {"segment", s.segment}, {"cell", s.cell}, {"label", s.label},
                           {"predicted", predicted}, {"probability", p[order[0]]}});
  }
  nlohmann::json report;
  report["command"] = Cat("toolbench train-recognizer --seed ", request.seed, " --scenes ", request.scenes,
                          " --heldout ", heldout, " --out ", request.out_dir.string());
  report["seed"] = request.seed;
  report["training_scenes"] = request.scenes;
  report["heldout_scenes"] = heldout;
  report["training_samples"] = train.size();
  report["heldout_samples"] = test.size();
  report["segments"] = totals.segments;
  report["segments_without_cloud"] = totals.no_cloud;
  report["segments_unlabelled"] = totals.unlabelled;
  report["models"] = library;
  report["feature_names"] = feature_names;
  report["feature_version"] = perception::kRecognitionFeatureVersion;
  report["classifier"] = {{"type", "opencv RTrees"},
                          {"trees", request.classifier.trees},
                          {"max_depth", request.classifier.max_depth},
                          {"min_sample_count", request.classifier.min_sample_count},
                          {"active_vars", request.classifier.active_vars}};
  const double n_test = std::max<double>(1.0, static_cast<double>(test.size()));
  report["heldout_top1_accuracy"] = top1 / n_test;
  report["heldout_top3_accuracy"] = top3 / n_test;
  report["per_model"] = nlohmann::json::object();
  for (const auto& [name, counts] : per_model) {
    report["per_model"][name] = {{"correct", counts.first}, {"total", counts.second}};
  }
  report["confusions"] = confusions;
  report["predict_us_median"] = Percentile(predict_us, 50);
  report["collect_s"] = collect_s;
  report["train_s"] = train_s;
  report["heldout_predictions"] = predictions;
  WriteJson(request.out_dir / "training_report.json", report);
  spdlog::info("train-recognizer: {} training / {} held-out samples, held-out top-1 {:.3f} top-3 {:.3f}, model {}",
               train.size(), test.size(), top1 / n_test, top3 / n_test, model_path.string());
  return 0;
}

}  // namespace toolbench::app
