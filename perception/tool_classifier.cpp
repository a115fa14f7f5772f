#include "perception/tool_classifier.h"

#include <algorithm>
#include <cmath>
#include <set>

#include <opencv2/core.hpp>
#include <opencv2/ml.hpp>

#include "common/check.h"
#include "perception/recognition_features.h"

namespace toolbench::perception {
namespace {

constexpr const char* kFormat = "toolbench_tool_classifier";

std::string Join(const std::vector<std::string>& names) {
  std::string out;
  for (const auto& n : names) out += (out.empty() ? "" : ", ") + n;
  return out.empty() ? "none" : out;
}

}  // namespace

void ToolClassifierOptions::Validate() const {
  const char* f = "ToolClassifierOptions::Validate: ";
  if (trees <= 0) ThrowInvalid(f, "trees = ", trees, " (expected > 0)");
  if (max_depth < 1 || max_depth > 64) ThrowInvalid(f, "max_depth = ", max_depth, " (expected in [1, 64])");
  if (min_sample_count < 1) ThrowInvalid(f, "min_sample_count = ", min_sample_count, " (expected >= 1)");
  if (active_vars < 0) ThrowInvalid(f, "active_vars = ", active_vars, " (expected >= 0)");
}

struct ToolClassifier::Impl {
  std::vector<std::string> model_names;
  std::vector<std::string> feature_names;
  cv::Ptr<cv::ml::RTrees> forest;
};

ToolClassifier::ToolClassifier() : impl_(std::make_unique<Impl>()) {}
ToolClassifier::~ToolClassifier() = default;
ToolClassifier::ToolClassifier(ToolClassifier&&) noexcept = default;
ToolClassifier& ToolClassifier::operator=(ToolClassifier&&) noexcept = default;

const std::vector<std::string>& ToolClassifier::model_names() const { return impl_->model_names; }
const std::vector<std::string>& ToolClassifier::feature_names() const { return impl_->feature_names; }

ToolClassifier ToolClassifier::Train(const ToolDataset& data, const ToolClassifierOptions& options) {
  const char* f = "ToolClassifier::Train: ";
  options.Validate();
  if (data.model_names.size() < 2) {
    ThrowInvalid(f, "data.model_names has ", data.model_names.size(), " names (expected >= 2 classes)");
  }
  if (data.features.rows() == 0) ThrowInvalid(f, "data.features has no samples (expected >= 1 row)");
  if (static_cast<std::size_t>(data.features.rows()) != data.labels.size()) {
    ThrowInvalid(f, "data.features has ", data.features.rows(), " rows but data.labels has ", data.labels.size());
  }
  if (static_cast<std::size_t>(data.features.cols()) != data.feature_names.size()) {
    ThrowInvalid(f, "data.features has ", data.features.cols(), " columns but data.feature_names has ",
                 data.feature_names.size());
  }
  if (!data.features.allFinite()) ThrowInvalid(f, "data.features has a non-finite entry");
  for (std::size_t i = 0; i < data.labels.size(); ++i) {
    if (data.labels[i] < 0 || data.labels[i] >= static_cast<int>(data.model_names.size())) {
      ThrowInvalid(f, "data.labels[", i, "] = ", data.labels[i], " (expected in [0, ", data.model_names.size(), "))");
    }
  }
  const int rows = static_cast<int>(data.features.rows());
  const int cols = static_cast<int>(data.features.cols());
  cv::Mat samples(rows, cols, CV_32F);
  cv::Mat responses(rows, 1, CV_32S);
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < cols; ++c) samples.at<float>(r, c) = data.features(r, c);
    responses.at<int>(r, 0) = data.labels[static_cast<std::size_t>(r)];
  }
  // Integer responses make OpenCV treat the problem as classification.
  cv::Ptr<cv::ml::TrainData> train = cv::ml::TrainData::create(samples, cv::ml::ROW_SAMPLE, responses);
  ToolClassifier out;
  out.impl_->model_names = data.model_names;
  out.impl_->feature_names = data.feature_names;
  out.impl_->forest = cv::ml::RTrees::create();
  cv::ml::RTrees& forest = *out.impl_->forest;
  forest.setMaxDepth(options.max_depth);
  forest.setMinSampleCount(options.min_sample_count);
  forest.setActiveVarCount(options.active_vars);
  forest.setCalculateVarImportance(false);
  forest.setUseSurrogates(false);
  forest.setCVFolds(0);
  forest.setTermCriteria(cv::TermCriteria(cv::TermCriteria::MAX_ITER, options.trees, 0.0));
  // RTrees bootstraps with cv::theRNG() (thread-local global state): seed it for this call only.
  cv::RNG& global = cv::theRNG();
  const cv::RNG saved = global;
  global = cv::RNG(options.seed);
  const bool trained = forest.train(train);
  global = saved;
  if (!trained) ThrowInvalid(f, "OpenCV RTrees training failed on ", rows, " samples");
  return out;
}

void ToolClassifier::Save(const std::filesystem::path& path) const {
  try {
    cv::FileStorage fs(path.string(), cv::FileStorage::WRITE);
    if (!fs.isOpened()) ThrowInvalid("ToolClassifier::Save: cannot open '", path.string(), "' for writing");
    fs << "format" << kFormat;
    fs << "feature_version" << kRecognitionFeatureVersion;
    fs << "model_names" << impl_->model_names;
    fs << "feature_names" << impl_->feature_names;
    fs << "forest" << "{";
    impl_->forest->write(fs);
    fs << "}";
    fs.release();
  } catch (const cv::Exception& e) {
    ThrowInvalid("ToolClassifier::Save: writing '", path.string(), "' failed: ", e.what());
  }
}

ToolClassifier ToolClassifier::Load(const std::filesystem::path& path) {
  const std::string where = "ToolClassifier::Load: '" + path.string() + "' ";
  if (!std::filesystem::is_regular_file(path)) ThrowInvalid(where, "does not exist or is not a file");
  ToolClassifier out;
  try {
    cv::FileStorage fs(path.string(), cv::FileStorage::READ);
    if (!fs.isOpened()) ThrowInvalid(where, "cannot be read as an OpenCV FileStorage file");
    std::string format;
    fs["format"] >> format;
    if (format != kFormat) ThrowInvalid(where, "is not a tool classifier (format '", format, "', expected '", kFormat, "')");
    int version = -1;
    fs["feature_version"] >> version;
    if (version != kRecognitionFeatureVersion) {
      ThrowInvalid(where, "was trained on feature version ", version, " but this build computes version ",
                   kRecognitionFeatureVersion, "; retrain it (toolbench train-recognizer)");
    }
    fs["model_names"] >> out.impl_->model_names;
    fs["feature_names"] >> out.impl_->feature_names;
    if (out.impl_->model_names.size() < 2) ThrowInvalid(where, "lists ", out.impl_->model_names.size(), " model names");
    if (out.impl_->feature_names.empty()) ThrowInvalid(where, "lists no feature names");
    const cv::FileNode node = fs["forest"];
    if (node.empty()) ThrowInvalid(where, "has no 'forest' section");
    out.impl_->forest = cv::ml::RTrees::create();
    out.impl_->forest->read(node);
  } catch (const cv::Exception& e) {
    ThrowInvalid(where, "is corrupt: ", e.what());
  }
  const cv::ml::RTrees& forest = *out.impl_->forest;
  if (!forest.isTrained() || forest.getRoots().empty()) ThrowInvalid(where, "is corrupt: the forest has no trees");
  if (forest.getVarCount() != static_cast<int>(out.impl_->feature_names.size())) {
    ThrowInvalid(where, "is corrupt: the forest expects ", forest.getVarCount(), " features but ",
                 out.impl_->feature_names.size(), " are named");
  }
  return out;
}

std::vector<double> ToolClassifier::Predict(const std::vector<float>& features) const {
  if (features.size() != impl_->feature_names.size()) {
    ThrowInvalid("ToolClassifier::Predict: argument features has ", features.size(), " entries (expected ",
                 impl_->feature_names.size(), ")");
  }
  for (std::size_t i = 0; i < features.size(); ++i) {
    if (!std::isfinite(features[i])) {
      ThrowInvalid("ToolClassifier::Predict: argument features[", i, "] (", impl_->feature_names[i],
                   ") is not finite");
    }
  }
  const cv::Mat sample(1, static_cast<int>(features.size()), CV_32F, const_cast<float*>(features.data()));
  cv::Mat votes;
  impl_->forest->getVotes(sample, votes, 0);
  // Row 0 holds the class labels (only classes seen in training), row 1 the vote counts.
  std::vector<double> probability(impl_->model_names.size(), 0.0);
  double total = 0.0;
  for (int c = 0; c < votes.cols; ++c) {
    const int label = votes.at<int>(0, c);
    const double count = votes.at<int>(1, c);
    TOOLBENCH_DEMAND(label >= 0 && label < static_cast<int>(probability.size()));
    probability[static_cast<std::size_t>(label)] += count;
    total += count;
  }
  TOOLBENCH_DEMAND(total > 0);
  for (double& p : probability) p /= total;
  return probability;
}

void ToolClassifier::RequireLibrary(const std::vector<std::string>& library) const {
  const std::set<std::string> mine(impl_->model_names.begin(), impl_->model_names.end());
  const std::set<std::string> theirs(library.begin(), library.end());
  if (mine == theirs && theirs.size() == library.size()) return;
  std::vector<std::string> missing;  // in the library, unknown to the classifier
  std::vector<std::string> extra;    // known to the classifier, not in the library
  std::set_difference(theirs.begin(), theirs.end(), mine.begin(), mine.end(), std::back_inserter(missing));
  std::set_difference(mine.begin(), mine.end(), theirs.begin(), theirs.end(), std::back_inserter(extra));
  ThrowInvalid("ToolClassifier: library mismatch: the classifier was trained on ", mine.size(),
               " models, the library has ", library.size(), " names; not in the classifier: ", Join(missing),
               "; not in the library: ", Join(extra), ". Retrain it (toolbench train-recognizer)");
}

std::vector<double> ToolClassifier::PredictForLibrary(const std::vector<float>& features,
                                                      const std::vector<std::string>& library) const {
  RequireLibrary(library);
  const std::vector<double> mine = Predict(features);
  std::vector<double> out(library.size(), 0.0);
  for (std::size_t i = 0; i < library.size(); ++i) {
    const auto it = std::find(impl_->model_names.begin(), impl_->model_names.end(), library[i]);
    out[i] = mine[static_cast<std::size_t>(it - impl_->model_names.begin())];
  }
  return out;
}

}  // namespace toolbench::perception
