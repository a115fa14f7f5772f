#include "perception/tool_classifier.h"

#include <algorithm>
#include <cmath>
#include <fstream>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "common/paths.h"
#include "common/rng.h"
#include "perception/model_fit.h"
#include "perception/recognition_features.h"
#include "toollib/tool_model.h"

namespace toolbench::perception {
namespace {

using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

constexpr double kNoise = 0.001;  // [m]

toollib::ToolModel LoadTool(const std::string& name) {
  return toollib::LoadToolModel(AssetsDir() / "tools" / (name + ".json"));
}

CameraIntrinsics TestIntrinsics() {
  CameraIntrinsics k;
  k.width = 320;
  k.height = 240;
  k.fx = k.fy = 280.0;
  k.cx = 159.5;
  k.cy = 119.5;
  return k;
}

// A noisy one-sided view of `tool` at X_CT in front of a camera at the origin of C (OpenCV
// frame), and its mask (the projected points, closed like a segmentation mask).
struct View {
  Eigen::Matrix3Xf p_C;
  cv::Mat mask;
  double median_depth = 0.0;
};

View MakeView(const toollib::ToolModel& tool, const Eigen::Isometry3d& X_CT, std::uint64_t seed) {
  const SurfaceSamples dense = SampleSurface(tool.mesh, 6000, seed);
  Rng rng(seed + 7);
  const CameraIntrinsics k = TestIntrinsics();
  View view;
  view.mask = cv::Mat::zeros(k.height, k.width, CV_8UC1);
  std::vector<Eigen::Vector3f> kept;
  std::vector<double> depths;
  for (Eigen::Index i = 0; i < dense.points.cols(); ++i) {
    const Eigen::Vector3d p = X_CT * dense.points.col(i).cast<double>();
    const Eigen::Vector3d n = X_CT.linear() * dense.normals.col(i).cast<double>();
    if (n.dot(-p) <= 0) continue;
    const Eigen::Vector3d noise(StandardNormal(rng), StandardNormal(rng), StandardNormal(rng));
    kept.push_back((p + kNoise * noise).cast<float>());
    depths.push_back(p.z());
    const int u = static_cast<int>(std::lround(k.fx * p.x() / p.z() + k.cx));
    const int v = static_cast<int>(std::lround(k.fy * p.y() / p.z() + k.cy));
    if (u >= 0 && v >= 0 && u < k.width && v < k.height) view.mask.at<unsigned char>(v, u) = 255;
  }
  cv::morphologyEx(view.mask, view.mask, cv::MORPH_CLOSE, cv::Mat::ones(3, 3, CV_8U));
  view.p_C.resize(3, static_cast<Eigen::Index>(kept.size()));
  for (std::size_t i = 0; i < kept.size(); ++i) view.p_C.col(static_cast<Eigen::Index>(i)) = kept[i];
  std::nth_element(depths.begin(), depths.begin() + static_cast<std::ptrdiff_t>(depths.size() / 2), depths.end());
  view.median_depth = depths[depths.size() / 2];
  return view;
}

// A random pose on a rack-like board 0.7 m in front of the camera: main axis roughly vertical
// or horizontal in the image, upside down or not, turned about its axis up to 90 deg.
Eigen::Isometry3d RandomPose(Rng& rng) {
  Eigen::Isometry3d X_CT = Eigen::Isometry3d::Identity();
  const double in_plane = UniformReal(rng, -0.3, 0.3) + (UniformInt(rng, 0, 3) * M_PI / 2);
  const double spin = UniformReal(rng, 0.0, M_PI / 2);
  X_CT.linear() = (Eigen::AngleAxisd(in_plane, Eigen::Vector3d::UnitZ()) *
                   Eigen::AngleAxisd(-M_PI / 2 + UniformReal(rng, -0.3, 0.3), Eigen::Vector3d::UnitX()) *
                   Eigen::AngleAxisd(spin, Eigen::Vector3d::UnitZ()))
                      .toRotationMatrix();
  X_CT.translation() = Eigen::Vector3d(UniformReal(rng, -0.05, 0.05), UniformReal(rng, -0.05, 0.05), 0.7);
  X_CT.translation() -= X_CT.linear() * Eigen::Vector3d(0, 0, 0.15);  // roughly centre the tool
  return X_CT;
}

class ToolClassifierTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    library_ = new std::vector<toollib::ToolModel>{LoadTool("hoe_2"), LoadTool("rake_1"), LoadTool("hook_3"),
                                                   LoadTool("stick_2")};
    train_ = new ToolDataset(MakeData(20, 100));
    test_ = new ToolDataset(MakeData(8, 5000));
  }
  static void TearDownTestSuite() {
    delete library_;
    delete train_;
    delete test_;
  }
  static ToolDataset MakeData(int per_model, std::uint64_t seed) {
    const RecognitionFeatureOptions options;
    ToolDataset data;
    for (const auto& m : *library_) data.model_names.push_back(m.name);
    data.feature_names = RecognitionFeatureNames(options);
    data.features.resize(per_model * static_cast<int>(library_->size()), static_cast<Eigen::Index>(data.feature_names.size()));
    Rng rng(seed);
    int row = 0;
    for (int i = 0; i < per_model; ++i) {
      for (std::size_t m = 0; m < library_->size(); ++m) {
        const View view = MakeView((*library_)[m], RandomPose(rng), seed + static_cast<std::uint64_t>(row));
        const std::vector<float> f =
            ComputeRecognitionFeatures(view.p_C, view.mask, TestIntrinsics(), view.median_depth, options);
        for (std::size_t c = 0; c < f.size(); ++c) data.features(row, static_cast<Eigen::Index>(c)) = f[c];
        data.labels.push_back(static_cast<int>(m));
        ++row;
      }
    }
    return data;
  }
  static std::vector<float> Row(const ToolDataset& data, int r) {
    std::vector<float> out(static_cast<std::size_t>(data.features.cols()));
    for (Eigen::Index c = 0; c < data.features.cols(); ++c) out[static_cast<std::size_t>(c)] = data.features(r, c);
    return out;
  }
  static std::vector<toollib::ToolModel>* library_;
  static ToolDataset* train_;
  static ToolDataset* test_;
};
std::vector<toollib::ToolModel>* ToolClassifierTest::library_ = nullptr;
ToolDataset* ToolClassifierTest::train_ = nullptr;
ToolDataset* ToolClassifierTest::test_ = nullptr;

TEST_F(ToolClassifierTest, FeaturesIgnoreRigidMotionOfTheCloud) {
  Rng rng(3);
  const View view = MakeView((*library_)[0], RandomPose(rng), 11);
  RecognitionFeatureOptions options;
  options.max_points = 100000;  // no subsampling: it picks other points once the order changes
  const std::vector<float> a = ComputeRecognitionFeatures(view.p_C, view.mask, TestIntrinsics(), view.median_depth, options);
  Eigen::Isometry3f X = Eigen::Isometry3f::Identity();
  X.linear() = Eigen::AngleAxisf(2.0f, Eigen::Vector3f(0.3f, -0.5f, 0.8f).normalized()).toRotationMatrix();
  X.translation() = Eigen::Vector3f(0.4f, -1.0f, 0.2f);
  // Reversing the point order too: the slices must not depend on it.
  const Eigen::Matrix3Xf moved = (X * view.p_C.rowwise().reverse().colwise().homogeneous()).eval();
  const std::vector<float> b = ComputeRecognitionFeatures(moved, view.mask, TestIntrinsics(), view.median_depth, options);
  ASSERT_EQ(a.size(), b.size());
  const std::vector<std::string> names = RecognitionFeatureNames(options);
  for (std::size_t i = 0; i < a.size(); ++i) EXPECT_NEAR(a[i], b[i], 2e-3 + 0.02 * std::abs(a[i])) << names[i];
}

TEST_F(ToolClassifierTest, FeaturesRejectBadInput) {
  const CameraIntrinsics k = TestIntrinsics();
  const cv::Mat mask = cv::Mat::ones(k.height, k.width, CV_8UC1);
  const Eigen::Matrix3Xf cloud = Eigen::Matrix3Xf::Ones(3, 50);
  EXPECT_THAT([&] { ComputeRecognitionFeatures(Eigen::Matrix3Xf::Ones(3, 5), mask, k, 0.7, {}); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("p_R has 5 points")));
  EXPECT_THAT([&] { ComputeRecognitionFeatures(cloud, cv::Mat::ones(10, 10, CV_8UC1), k, 0.7, {}); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("mask is 10x10")));
  EXPECT_THAT([&] { ComputeRecognitionFeatures(cloud, mask, k, -1.0, {}); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("median_depth = -1")));
  RecognitionFeatureOptions options;
  options.profile_bins = 1;
  EXPECT_THAT([&] { ComputeRecognitionFeatures(cloud, mask, k, 0.7, options); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("profile_bins = 1")));
}

TEST_F(ToolClassifierTest, LearnsToolsFromSyntheticViewsAndIsDeterministic) {
  ToolClassifierOptions options;
  options.trees = 30;
  const ToolClassifier a = ToolClassifier::Train(*train_, options);
  const ToolClassifier b = ToolClassifier::Train(*train_, options);
  int correct = 0;
  for (int r = 0; r < test_->features.rows(); ++r) {
    const std::vector<double> pa = a.Predict(Row(*test_, r));
    const std::vector<double> pb = b.Predict(Row(*test_, r));
    EXPECT_EQ(pa, pb) << "row " << r;
    double sum = 0.0;
    for (double p : pa) sum += p;
    EXPECT_NEAR(sum, 1.0, 1e-9);
    const auto best = std::max_element(pa.begin(), pa.end()) - pa.begin();
    if (best == test_->labels[static_cast<std::size_t>(r)]) ++correct;
  }
  // Four clearly different tools in unseen poses.
  EXPECT_GE(correct, static_cast<int>(0.85 * static_cast<double>(test_->features.rows())))
      << correct << " of " << test_->features.rows();
}

TEST_F(ToolClassifierTest, SaveLoadRoundTripAndErrors) {
  ToolClassifierOptions options;
  options.trees = 10;
  const ToolClassifier trained = ToolClassifier::Train(*train_, options);
  const std::filesystem::path path = std::filesystem::path(::testing::TempDir()) / "tool_classifier_test.yml.gz";
  trained.Save(path);
  const ToolClassifier loaded = ToolClassifier::Load(path);
  EXPECT_EQ(loaded.model_names(), train_->model_names);
  EXPECT_EQ(loaded.feature_names(), train_->feature_names);
  for (int r = 0; r < test_->features.rows(); ++r) EXPECT_EQ(trained.Predict(Row(*test_, r)), loaded.Predict(Row(*test_, r)));

  // Library order does not matter; a different set of names is an error naming them.
  std::vector<std::string> shuffled = {"stick_2", "hook_3", "hoe_2", "rake_1"};
  const std::vector<double> p = loaded.PredictForLibrary(Row(*test_, 0), shuffled);
  EXPECT_EQ(p[0], loaded.Predict(Row(*test_, 0))[3]);
  EXPECT_THAT([&] { loaded.RequireLibrary({"stick_2", "hook_3", "hoe_2", "shovel_1"}); },
              ThrowsMessage<std::invalid_argument>(AllOf(HasSubstr("shovel_1"), HasSubstr("rake_1"))));
  EXPECT_THAT([&] { loaded.Predict({1.0f, 2.0f}); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("features has 2 entries")));

  EXPECT_THAT([&] { ToolClassifier::Load("/nonexistent/model.yml.gz"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("/nonexistent/model.yml.gz")));
  const std::filesystem::path corrupt = std::filesystem::path(::testing::TempDir()) / "corrupt_classifier.yml";
  std::ofstream(corrupt) << "%YAML:1.0\nformat: toolbench_tool_classifier\nfeature_version: "
                         << kRecognitionFeatureVersion << "\nmodel_names: [a, b]\nfeature_names: [x]\nforest: { ";
  EXPECT_THAT([&] { ToolClassifier::Load(corrupt); }, ThrowsMessage<std::invalid_argument>(HasSubstr("corrupt")));
  const std::filesystem::path other = std::filesystem::path(::testing::TempDir()) / "other.yml";
  std::ofstream(other) << "%YAML:1.0\nformat: something_else\n";
  EXPECT_THAT([&] { ToolClassifier::Load(other); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("not a tool classifier")));
}

TEST_F(ToolClassifierTest, TrainRejectsBadData) {
  ToolDataset data = *train_;
  data.labels[0] = 7;
  EXPECT_THAT([&] { ToolClassifier::Train(data, {}); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("data.labels[0] = 7")));
  ToolClassifierOptions options;
  options.trees = 0;
  EXPECT_THAT([&] { ToolClassifier::Train(*train_, options); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("trees = 0")));
}

// The committed classifier (assets/models, made by `toolbench train-recognizer`) loads and
// covers exactly the committed tool library.
TEST(ShippedToolClassifierTest, LoadsAndMatchesTheLibrary) {
  const ToolClassifier classifier = ToolClassifier::Load(AssetsDir() / "models" / "tool_classifier.yml.gz");
  std::vector<std::string> names;
  for (const auto& entry : std::filesystem::directory_iterator(AssetsDir() / "tools")) {
    if (entry.path().extension() == ".json") names.push_back(toollib::LoadToolModel(entry.path()).name);
  }
  ASSERT_FALSE(names.empty());
  EXPECT_NO_THROW(classifier.RequireLibrary(names));
  EXPECT_EQ(classifier.feature_names(), RecognitionFeatureNames(RecognitionFeatureOptions{}));
}

}  // namespace
}  // namespace toolbench::perception
