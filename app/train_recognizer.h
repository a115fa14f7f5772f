#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "app/scene_setup.h"
#include "perception/recognition_features.h"
#include "perception/tool_classifier.h"
#include "sim/renderer.h"

namespace toolbench::app {

/// One segmented tool of a rendered training scene, with its features and ground-truth label.
struct LabelledSample {
  std::uint64_t seed = 0;           // scene seed
  int segment = 0;                  // index of the segment in the frame
  std::string cell;                 // the labelled tool's Table 5.3 cell (from the scene plan)
  std::string label;                // library model name the segment belongs to (ground truth)
  std::vector<float> features;      // perception::ComputeRecognitionFeatures
};

/// What CollectSamples did with one scene's segments.
struct CollectStats {
  int segments = 0;     // segments found
  int no_cloud = 0;     // segments whose object cloud failed
  int unlabelled = 0;   // segments no ground-truth tool explains (merged or spurious segments)
};

/// Renders the scene of `request` (random tools and cells from its seed), runs segmentation and
/// object-cloud extraction exactly as perception does, computes the recognition features and
/// labels each segment with the ground-truth tool whose posed surface explains its cloud (at
/// least 80 % of its points within 1 cm; offline supervision, the only place ground truth is
/// read). Appends to `samples`. Throws as CaptureFrame.
CollectStats CollectSamples(const SceneRequest& request, sim::GlContext& gl,
                            const perception::RecognitionFeatureOptions& features,
                            std::vector<LabelledSample>& samples);

/// `toolbench train-recognizer`.
struct TrainRecognizerRequest {
  std::uint64_t seed = 1;          // master seed: training scenes use seeds derived from it
  int scenes = 200;                // training scenes, > 0
  int heldout_scenes = 0;          // held-out scenes (disjoint seeds); 0 = scenes / 4
  std::filesystem::path out_dir;   // dataset.csv, heldout.csv, tool_classifier.yml.gz,
                                   // training_report.json
  perception::ToolClassifierOptions classifier;
  perception::RecognitionFeatureOptions features;
};

/// Scene seeds of a training run: training scene i uses DeriveSeed(seed, "train/" + i), held-out
/// scene i uses DeriveSeed(seed, "heldout/" + i) (disjoint streams, so disjoint poses).
std::uint64_t TrainingSceneSeed(std::uint64_t seed, bool heldout, int index);

/// Collects the training and held-out samples, writes them as CSV, trains the classifier on the
/// training set, reports its accuracy on the held-out set (top-1, top-3, per model, confusions)
/// in training_report.json and saves the classifier. Returns 0. Throws std::invalid_argument
/// for bad requests.
int RunTrainRecognizer(const TrainRecognizerRequest& request);

/// The samples as a ToolDataset over `library` (labels are indices into it).
perception::ToolDataset MakeDataset(const std::vector<LabelledSample>& samples,
                                    const std::vector<std::string>& library,
                                    const perception::RecognitionFeatureOptions& features);

}  // namespace toolbench::app
