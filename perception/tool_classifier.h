#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace toolbench::perception {

/// Configuration of ToolClassifier::Train (a random forest, OpenCV's cv::ml::RTrees).
struct ToolClassifierOptions {
  int trees = 60;            // trees in the forest, > 0
  int max_depth = 14;        // depth cap of each tree, in [1, 64]
  int min_sample_count = 2;  // a node with fewer samples is not split, >= 1
  int active_vars = 0;       // features tried at each split; 0 = sqrt(feature count), >= 0
  std::uint64_t seed = 1;    // seed of the bootstrap draws
  void Validate() const;     // throws std::invalid_argument naming the field and its value
};

/// Labelled feature vectors (one row per segmented tool) for training.
struct ToolDataset {
  std::vector<std::string> model_names;    // the classes, in library order
  std::vector<std::string> feature_names;  // RecognitionFeatureNames() of the features' options
  Eigen::MatrixXf features;                // samples x features
  std::vector<int> labels;                 // per sample, index into model_names
};

/// A learned tool recogniser: a random forest over the pose-invariant features of
/// recognition_features.h, giving a probability per library model (the fraction of tree votes).
/// Deterministic: OpenCV's forest draws its bootstrap samples from the thread's cv::theRNG(),
/// which Train seeds from options.seed for the duration of training (and then restores), and
/// its split variables from a generator of its own with a fixed seed; so the same dataset and
/// seed give the same forest and predictions.
/// The file written by Save stores, besides the forest, the model names (classes), the feature
/// names and kRecognitionFeatureVersion, so that a classifier never meets a library or a
/// feature definition it was not trained for without saying so.
class ToolClassifier {
 public:
  /// Trains on `data`. Throws std::invalid_argument for bad options, an empty dataset, features
  /// and labels of different lengths, a label outside [0, model_names.size()), a feature count
  /// that differs from feature_names, non-finite features, or fewer than 2 model names.
  static ToolClassifier Train(const ToolDataset& data, const ToolClassifierOptions& options);

  /// Reads a file written by Save. Throws std::invalid_argument naming the path when it is
  /// missing, unreadable, not a toolbench classifier, of another feature version, or corrupt.
  static ToolClassifier Load(const std::filesystem::path& path);

  ~ToolClassifier();
  ToolClassifier(ToolClassifier&&) noexcept;
  ToolClassifier& operator=(ToolClassifier&&) noexcept;

  /// Writes the forest and its metadata (OpenCV FileStorage; a ".yml.gz" path is compressed).
  /// Throws std::invalid_argument naming the path when it cannot be written.
  void Save(const std::filesystem::path& path) const;

  /// Probability of each class (model_names() order), summing to 1. Throws
  /// std::invalid_argument when `features` has the wrong length or a non-finite entry.
  std::vector<double> Predict(const std::vector<float>& features) const;

  /// Probabilities re-ordered to `library` (model names in library order). Throws
  /// std::invalid_argument listing the differences when the library and the classifier's
  /// classes are not the same set of names (the classifier must be retrained for that library).
  std::vector<double> PredictForLibrary(const std::vector<float>& features,
                                        const std::vector<std::string>& library) const;

  /// Throws std::invalid_argument (see PredictForLibrary) unless `library` holds exactly the
  /// classifier's model names, in any order.
  void RequireLibrary(const std::vector<std::string>& library) const;

  const std::vector<std::string>& model_names() const;    // the classes
  const std::vector<std::string>& feature_names() const;  // the expected features, in order

 private:
  ToolClassifier();
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace toolbench::perception
