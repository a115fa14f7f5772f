#include "perception/model_fit.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "common/paths.h"
#include "common/rng.h"
#include "toollib/tool_model.h"

namespace toolbench::perception {
namespace {

using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

constexpr double kPositionTol = 0.005;               // [m]
constexpr double kAngleTol = 3.0 * M_PI / 180.0;     // [rad]
constexpr double kNoise = 0.001;                     // depth-like noise on the synthetic view [m]

toollib::ToolModel LoadTool(const std::string& name) {
  return toollib::LoadToolModel(AssetsDir() / "tools" / (name + ".json"));
}

// Two disjoint triangles, areas 0.5 and 1.5 m^2.
toollib::TriangleMesh TwoTriangles() {
  toollib::TriangleMesh mesh;
  mesh.vertices.resize(3, 6);
  mesh.vertices << 0, 1, 0, 0, 3, 0,  //
      0, 0, 1, 0, 0, 1,               //
      0, 0, 0, 1, 1, 1;
  mesh.faces.resize(3, 2);
  mesh.faces << 0, 3, 1, 4, 2, 5;
  return mesh;
}

// A one-sided noisy view of a tool at pose X_RT, seen from p_R_camera: dense surface samples
// whose normal faces the camera, with isotropic noise. Not the model samples (other seed).
Eigen::Matrix3Xf PartialView(const toollib::ToolModel& tool, const Eigen::Isometry3d& X_RT,
                             const Eigen::Vector3d& p_R_camera, std::uint64_t seed) {
  const SurfaceSamples dense = SampleSurface(tool.mesh, 6000, seed);
  Rng rng(seed + 7);
  std::vector<Eigen::Vector3f> kept;
  for (Eigen::Index i = 0; i < dense.points.cols(); ++i) {
    const Eigen::Vector3d p = X_RT * dense.points.col(i).cast<double>();
    const Eigen::Vector3d n = X_RT.linear() * dense.normals.col(i).cast<double>();
    if (n.dot(p_R_camera - p) <= 0) continue;
    const Eigen::Vector3d noise(StandardNormal(rng), StandardNormal(rng), StandardNormal(rng));
    kept.push_back((p + kNoise * noise).cast<float>());
  }
  Eigen::Matrix3Xf out(3, static_cast<Eigen::Index>(kept.size()));
  for (std::size_t i = 0; i < kept.size(); ++i) out.col(static_cast<Eigen::Index>(i)) = kept[i];
  return out;
}

double AngleBetween(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) {
  return Eigen::AngleAxisd(a.transpose() * b).angle();
}

TEST(SampleSurfaceTest, AreaWeightedAndReproducible) {
  const toollib::TriangleMesh mesh = TwoTriangles();
  const SurfaceSamples s = SampleSurface(mesh, 20000, 42);
  ASSERT_EQ(s.points.cols(), 20000);
  int on_big = 0;
  for (Eigen::Index i = 0; i < s.points.cols(); ++i) {
    const float z = s.points(2, i);
    ASSERT_TRUE(z == 0.0f || z == 1.0f) << z;  // on one of the two triangle planes
    on_big += z == 1.0f ? 1 : 0;
    EXPECT_NEAR(s.normals.col(i).norm(), 1.0, 1e-5);
  }
  // Area ratio 3:1 -> 75 % of the samples on the big triangle (binomial sigma 0.3 %).
  EXPECT_NEAR(on_big / 20000.0, 0.75, 0.015);
  const SurfaceSamples again = SampleSurface(mesh, 20000, 42);
  EXPECT_EQ(s.points, again.points);
  const SurfaceSamples other = SampleSurface(mesh, 20000, 43);
  EXPECT_NE(s.points, other.points);
}

TEST(SampleSurfaceTest, UniformInsideATriangle) {
  // Uniform in the unit right triangle: mean of x and y is 1/3 each.
  toollib::TriangleMesh mesh = TwoTriangles();
  mesh.faces.conservativeResize(3, 1);
  const SurfaceSamples s = SampleSurface(mesh, 20000, 5);
  EXPECT_NEAR(s.points.row(0).mean(), 1.0 / 3.0, 0.01);
  EXPECT_NEAR(s.points.row(1).mean(), 1.0 / 3.0, 0.01);
  EXPECT_LE((s.points.row(0) + s.points.row(1)).maxCoeff(), 1.0f + 1e-6f);
}

TEST(SampleSurfaceTest, RejectsBadInput) {
  EXPECT_THAT([] { SampleSurface(TwoTriangles(), 0, 1); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("count = 0")));
  EXPECT_THAT([] { SampleSurface(toollib::TriangleMesh{}, 10, 1); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("no faces")));
  toollib::TriangleMesh bad = TwoTriangles();
  bad.faces(0, 0) = 17;
  EXPECT_THAT([&] { SampleSurface(bad, 10, 1); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("face index")));
}

class ModelFitTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    hoe_ = new toollib::ToolModel(LoadTool("hoe_2"));
    fitter_ = new ModelFitter(*hoe_, ModelFitOptions{});
  }
  static void TearDownTestSuite() {
    delete fitter_;
    delete hoe_;
  }
  static toollib::ToolModel* hoe_;
  static ModelFitter* fitter_;
};
toollib::ToolModel* ModelFitTest::hoe_ = nullptr;
ModelFitter* ModelFitTest::fitter_ = nullptr;

// A tool leaning on a board in front of a camera 0.8 m away, as on the rack.
Eigen::Isometry3d BasePose() {
  Eigen::Isometry3d X_RT = Eigen::Isometry3d::Identity();
  X_RT.linear() = (Eigen::AngleAxisd(0.4, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(-1.2, Eigen::Vector3d::UnitX()))
                      .toRotationMatrix();
  X_RT.translation() = Eigen::Vector3d(-0.1, 0.5, -0.05);
  return X_RT;
}

TEST_F(ModelFitTest, RecoversPoseFromPartialNoisyViewIncludingFlips) {
  const Eigen::Vector3d camera(0.1, 0.0, 0.4);
  // The base pose and the 180-degree flips about each tool axis, and a quarter turn about the
  // main axis (Table 5.3 rot cases): the principal-axes guess is wrong by 180 deg for some.
  const std::vector<Eigen::Matrix3d> turns = {
      Eigen::Matrix3d::Identity(),
      Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()).toRotationMatrix(),
      Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitY()).toRotationMatrix(),
      Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitZ()).toRotationMatrix(),
      Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitZ()).toRotationMatrix()};
  int initial_guess_flipped = 0;
  for (std::size_t k = 0; k < turns.size(); ++k) {
    Eigen::Isometry3d X_RT = BasePose();
    X_RT.linear() = X_RT.linear() * turns[k];
    const Eigen::Matrix3Xf view = PartialView(*hoe_, X_RT, camera, 100 + k);
    const ModelFitResult fit = fitter_->Fit(view, camera);
    ASSERT_EQ(fit.status, FitStatus::kOk) << fit.reason;
    const double position_error = (fit.X_RT * hoe_->handle.center - X_RT * hoe_->handle.center).norm();
    const double angle_error = AngleBetween(fit.X_RT.linear(), X_RT.linear());
    EXPECT_LT(position_error, kPositionTol) << "case " << k << " best " << fit.candidates[fit.best_candidate].label;
    EXPECT_LT(angle_error, kAngleTol) << "case " << k << " best " << fit.candidates[fit.best_candidate].label;
    EXPECT_LT(fit.fit_error, 3 * kNoise);
    ASSERT_EQ(fit.candidates.size(), 8u);
    if (AngleBetween(fit.candidates[0].X_RT_initial.linear(), X_RT.linear()) > M_PI / 2) ++initial_guess_flipped;
  }
  EXPECT_GE(initial_guess_flipped, 1) << "no case exercised a flipped principal-axes guess";
}

TEST_F(ModelFitTest, FitIsDeterministic) {
  const Eigen::Vector3d camera(0.1, 0.0, 0.4);
  const Eigen::Matrix3Xf view = PartialView(*hoe_, BasePose(), camera, 3);
  const ModelFitResult a = fitter_->Fit(view, camera);
  const ModelFitResult b = fitter_->Fit(view, camera);
  EXPECT_TRUE(a.X_RT.matrix() == b.X_RT.matrix());
  EXPECT_EQ(a.fit_error, b.fit_error);
}

TEST_F(ModelFitTest, FitIsSearchThenRefine) {
  const Eigen::Vector3d camera(0.1, 0.0, 0.4);
  const Eigen::Matrix3Xf view = PartialView(*hoe_, BasePose(), camera, 5);
  const ModelFitResult search = fitter_->Search(view, camera);
  ASSERT_EQ(search.status, FitStatus::kOk);
  EXPECT_EQ(search.candidates.size(), 8u);
  EXPECT_EQ(search.X_RT.matrix(), search.candidates[static_cast<std::size_t>(search.best_candidate)].X_RT.matrix());
  const ModelFitResult refined = fitter_->Refine(view, camera, search);
  const ModelFitResult fit = fitter_->Fit(view, camera);
  EXPECT_TRUE(refined.X_RT.matrix() == fit.X_RT.matrix());
  EXPECT_EQ(refined.score, fit.score);
  // The refinement does not make the fit worse than the search left it.
  EXPECT_LE(refined.fit_error, search.fit_error + 1e-4);
  ModelFitResult other = search;
  other.model = "rake_1";
  EXPECT_THAT([&] { fitter_->Refine(view, camera, other); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("'rake_1'")));
  EXPECT_THAT([&] { fitter_->Refine(view, camera, search, 5, 10); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("max_observed_points = 5")));
}

TEST_F(ModelFitTest, BadInput) {
  const ModelFitResult three = fitter_->Fit(Eigen::Matrix3Xf::Ones(3, 3));
  EXPECT_EQ(three.status, FitStatus::kTooFewPoints);
  EXPECT_THAT(three.reason, HasSubstr("3 points"));
  Eigen::Matrix3Xf nan_cloud = Eigen::Matrix3Xf::Zero(3, 50);
  nan_cloud(1, 7) = std::numeric_limits<float>::quiet_NaN();
  EXPECT_THAT([&] { fitter_->Fit(nan_cloud); }, ThrowsMessage<std::invalid_argument>(HasSubstr("non-finite")));
  ModelFitOptions options;
  options.max_iterations = 0;
  EXPECT_THAT([&] { ModelFitter(*hoe_, options); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("max_iterations = 0")));
  options = ModelFitOptions{};
  options.spin_steps = 0;
  EXPECT_THAT([&] { ModelFitter(*hoe_, options); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("spin_steps = 0")));
  RecognitionOptions recognition;
  recognition.classifier_mass = 1.5;
  EXPECT_THAT([&] { recognition.Validate(); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("classifier_mass = 1.5")));
}

TEST(ToolRecognizerTest, PicksTheObservedModel) {
  const std::vector<toollib::ToolModel> library = {LoadTool("hoe_2"), LoadTool("rake_1"), LoadTool("hook_3")};
  RecognitionOptions options;
  options.fit.model_points = 1500;  // fewer points than the defaults keep this test under 1 s
  options.fit.max_observed_points = 400;
  options.fit.coarse_points = 150;
  const ToolRecognizer recognizer(library, options);
  const Eigen::Vector3d camera(0.1, 0.0, 0.4);
  for (const std::string name : {"rake_1"}) {
    const auto& tool = *std::find_if(library.begin(), library.end(), [&](const auto& t) { return t.name == name; });
    const RecognitionResult r = recognizer.Recognize(PartialView(tool, BasePose(), camera, 9), camera);
    ASSERT_EQ(r.status, FitStatus::kOk) << r.reason;
    EXPECT_EQ(r.model, name);
    EXPECT_GT(r.confidence, 0.5);
    EXPECT_EQ(r.scores.size(), library.size());
  }
  EXPECT_EQ(recognizer.Recognize(Eigen::Matrix3Xf::Zero(3, 2)).status, FitStatus::kTooFewPoints);

  // With a classifier prior: only the likely models are verified, the probability combines.
  const Eigen::Matrix3Xf rake_view = PartialView(library[1], BasePose(), camera, 9);
  const RecognitionResult sure = recognizer.Recognize(rake_view, camera, {0.02, 0.97, 0.01});
  ASSERT_EQ(sure.status, FitStatus::kOk) << sure.reason;
  EXPECT_EQ(sure.model, "rake_1");
  EXPECT_FALSE(sure.scores[0].fitted);
  EXPECT_TRUE(sure.scores[1].fitted);
  EXPECT_NEAR(sure.confidence, 0.97, 1e-9);  // one verified model holding 97 % of the prior
  // Below classifier_mass, but the rest are stray votes under min_classifier_probability.
  const RecognitionResult stray = recognizer.Recognize(rake_view, camera, {0.04, 0.92, 0.04});
  EXPECT_FALSE(stray.scores[0].fitted);
  EXPECT_FALSE(stray.scores[2].fitted);
  EXPECT_EQ(stray.model, "rake_1");
  // Two close candidates: both verified, the fit decides against the (wrong) favourite.
  const RecognitionResult close = recognizer.Recognize(rake_view, camera, {0.55, 0.44, 0.01});
  EXPECT_TRUE(close.scores[0].fitted);
  EXPECT_TRUE(close.scores[1].fitted);
  EXPECT_FALSE(close.scores[2].fitted);
  EXPECT_EQ(close.model, "rake_1");
  EXPECT_THAT([&] { recognizer.Recognize(rake_view, camera, {0.5, 0.5}); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("prior has 2 entries")));
  EXPECT_THAT([&] { recognizer.Recognize(rake_view, camera, {0.5, -0.1, 0.6}); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("prior[1] = -0.1")));
  EXPECT_EQ(recognizer.model_names(), (std::vector<std::string>{"hoe_2", "rake_1", "hook_3"}));
}

}  // namespace
}  // namespace toolbench::perception
