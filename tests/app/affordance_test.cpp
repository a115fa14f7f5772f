#include "app/affordance.h"

#include <cmath>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "common/rng.h"

namespace toolbench::app {
namespace {

using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

std::filesystem::path TempDir(const std::string& name) {
  const auto dir = std::filesystem::temp_directory_path() / ("toolbench_affordance_" + name);
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

std::string ReadAll(const std::filesystem::path& p) {
  std::ifstream in(p);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

/// A synthetic exploration: 6 families x 4 tools, each at 4 in-hand rolls, one action. The
/// effector protrudes sideways by a family-specific amount (plus per-tool variation); the ball
/// moves along the action by 0.2 m x min(1, protrusion / 4 cm), less when the working side faces
/// away (the roll), plus noise. Features are built as AffordanceFeatures lays them out.
std::vector<AffordanceSample> SyntheticExploration(std::uint64_t seed, const std::string& action = "pull") {
  Rng rng(seed);
  const double family_protrusion[] = {0.0, 0.01, 0.025, 0.04, 0.06, 0.08};
  std::vector<AffordanceSample> out;
  for (int fam = 0; fam < 6; ++fam) {
    for (int k = 0; k < 4; ++k) {
      const double protrusion = family_protrusion[fam] * (0.8 + 0.1 * k);
      const double length = 0.45 + 0.03 * k + UniformReal(rng, -0.01, 0.01);
      for (int r = 0; r < 3; ++r) {
        const double roll = r * M_PI * 2 / 3;
        Eigen::VectorXd x = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(AffordanceFeatureNames().size()));
        x[0] = length;                       // total_length
        x[1] = 0.2;                          // handle_length
        x[2] = 0.015;                        // handle_radius
        x[3] = protrusion / 2;               // effector_x_T
        x[4] = length - 0.03;                // effector_z_T
        x[5] = protrusion + 0.02;            // effector_size_x
        x[6] = 0.03;                         // effector_size_y
        x[7] = 0.05;                         // effector_size_z
        x[8] = protrusion;                   // effector_protrusion
        x[9] = protrusion > 0 ? 0.04 : 0.0;  // sq sizes
        x[10] = protrusion > 0 ? 0.02 : 0.0;
        x[11] = protrusion > 0 ? 0.01 : 0.0;
        x[12] = 0.5;
        x[13] = 1.0;
        x[14] = 0.0;                         // effector in G
        x[15] = 0.0;
        x[16] = length - 0.2;
        x[17] = std::cos(roll);              // working side in G
        x[18] = std::sin(roll);
        x[19] = 0.0;
        AffordanceSample s;
        s.tool = "fam" + std::to_string(fam) + "_" + std::to_string(k);
        s.family = "fam" + std::to_string(fam);
        s.action = action;
        s.x = x;
        s.displacement_m = 0.2 * std::min(1.0, protrusion / 0.04) * (0.75 + 0.25 * std::cos(roll)) +
                           0.01 * StandardNormal(rng);
        out.push_back(s);
      }
    }
  }
  return out;
}

TEST(AffordanceFeaturesTest, LaysOutShapeAndInHandPose) {
  perception::Part handle, head;
  handle.points = Eigen::Matrix3Xf::Zero(3, 100);
  head.points = Eigen::Matrix3Xf::Zero(3, 40);
  head.sq.size = Eigen::Vector3d(0.01, 0.05, 0.02);
  head.sq.e1 = 0.3;
  head.sq.e2 = 0.9;
  perception::ToolFeatures f;
  f.total_length = 0.5;
  f.effector_center = Eigen::Vector3d(0.04, 0.0, 0.45);
  f.effector_protrusion = 0.05;
  Eigen::Isometry3d X_TH = Eigen::Isometry3d::Identity();
  X_TH.translation() = Eigen::Vector3d(0, 0, 0.1);
  const Eigen::Isometry3d X_GT = HeldToolPose(X_TH, M_PI / 2);
  const Eigen::VectorXd x = AffordanceFeatures({handle, head}, 0, f, X_GT);
  ASSERT_EQ(static_cast<std::size_t>(x.size()), AffordanceFeatureNames().size());
  constexpr double kTol = 1e-12;
  EXPECT_NEAR(x[0], 0.5, kTol);
  EXPECT_NEAR(x[8], 0.05, kTol);
  EXPECT_NEAR(x[9], 0.05, kTol);  // semi-axes sorted decreasing
  EXPECT_NEAR(x[10], 0.02, kTol);
  EXPECT_NEAR(x[11], 0.01, kTol);
  EXPECT_NEAR(x[12], 0.3, kTol);
  // Rolled by 90 deg about z_G: the working side +x_T lies along +y_G; the effector 0.35 m up
  // the handle axis from the grasp centre and 4 cm toward +y_G.
  EXPECT_TRUE(x.segment<3>(17).isApprox(Eigen::Vector3d::UnitY(), 1e-12));
  EXPECT_TRUE(x.segment<3>(14).isApprox(Eigen::Vector3d(0.0, 0.04, 0.35), 1e-12));
  // A one-part tool (a stick): no effector superquadric.
  const Eigen::VectorXd stick = AffordanceFeatures({handle}, 0, f, X_GT);
  EXPECT_EQ(stick.segment<3>(9), Eigen::Vector3d::Zero());
  EXPECT_THAT([&] { AffordanceFeatures({handle}, 1, f, X_GT); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("handle_part = 1")));
}

TEST(AffordanceModelTest, FitsTrainingDataAndSavesLoadsIdentically) {
  const std::vector<AffordanceSample> data = SyntheticExploration(1);
  AffordanceModel model = AffordanceModel::Train(data);
  model.info = {{"seed", 1}};
  EXPECT_EQ(model.actions(), std::vector<std::string>{"pull"});
  EXPECT_EQ(model.samples("pull"), static_cast<int>(data.size()));
  double abs_error = 0;
  for (const AffordanceSample& s : data) abs_error += std::abs(model.Predict("pull", s.x).displacement_m - s.displacement_m);
  EXPECT_LT(abs_error / static_cast<double>(data.size()), 0.02);

  const auto dir = TempDir("roundtrip");
  model.Save(dir / "a.json");
  const AffordanceModel loaded = AffordanceModel::Load(dir / "a.json");
  EXPECT_EQ(loaded.info["seed"], 1);
  for (const AffordanceSample& s : data) {
    EXPECT_NEAR(loaded.Predict("pull", s.x).displacement_m, model.Predict("pull", s.x).displacement_m, 1e-9);
  }
  loaded.Save(dir / "b.json");
  EXPECT_EQ(ReadAll(dir / "a.json"), ReadAll(dir / "b.json"));
  // Training is deterministic: the same data give the same bytes.
  AffordanceModel again = AffordanceModel::Train(data);
  again.info = {{"seed", 1}};
  again.Save(dir / "c.json");
  EXPECT_EQ(ReadAll(dir / "a.json"), ReadAll(dir / "c.json"));

  EXPECT_THAT([&] { model.Predict("push", data[0].x); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("'push' was not explored (the model knows: pull)")));
  EXPECT_THAT([&] { model.Predict("pull", Eigen::VectorXd::Zero(3)); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("x has 3 features")));
}

TEST(AffordanceModelTest, LoadRejectsMissingAndMalformedFilesByName) {
  const auto dir = TempDir("malformed");
  EXPECT_THAT([&] { AffordanceModel::Load(dir / "none.json"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("none.json': cannot open")));
  auto write = [&](const std::string& name, const std::string& text) {
    std::ofstream(dir / name) << text;
    return dir / name;
  };
  EXPECT_THAT([&] { AffordanceModel::Load(write("bad.json", "{not json")); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("bad.json': not JSON")));
  EXPECT_THAT([&] { AffordanceModel::Load(write("other.json", R"({"format": "something"})")); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("format is not 'toolbench-affordance-gp'")));
  AffordanceModel model = AffordanceModel::Train(SyntheticExploration(2));
  model.Save(dir / "good.json");
  nlohmann::json j = nlohmann::json::parse(ReadAll(dir / "good.json"));
  nlohmann::json names = j;
  names["feature_names"][0] = "colour";
  EXPECT_THAT([&] { AffordanceModel::Load(write("names.json", names.dump())); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("feature_names differ")));
  nlohmann::json rows = j;
  rows["actions"]["pull"]["targets"].erase(0);
  EXPECT_THAT([&] { AffordanceModel::Load(write("rows.json", rows.dump())); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("must have the same, non-zero length")));
  nlohmann::json missing = j;
  missing["actions"]["pull"].erase("noise_var");
  EXPECT_THAT([&] { AffordanceModel::Load(write("missing.json", missing.dump())); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("missing.json'")));
}

TEST(AffordanceModelTest, TrainRejectsTooFewSamples) {
  std::vector<AffordanceSample> data = SyntheticExploration(3);
  data.resize(1);
  EXPECT_THAT([&] { AffordanceModel::Train(data); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("action 'pull' has 1 sample")));
  EXPECT_THAT([&] { AffordanceModel::Train({}); }, ThrowsMessage<std::invalid_argument>(HasSubstr("no samples")));
}

TEST(HeldOutTest, ModelBeatsTheMeanOnHeldOutToolsAndFamilies) {
  std::vector<AffordanceSample> data = SyntheticExploration(4, "pull");
  for (AffordanceSample s : SyntheticExploration(5, "push")) {
    s.displacement_m = 0.05 + 0.5 * s.displacement_m;  // another action, another scale
    data.push_back(s);
  }
  for (HoldOut by : {HoldOut::kTool, HoldOut::kFamily}) {
    const HeldOutReport r = EvaluateHeldOut(data, by);
    ASSERT_EQ(r.per_action.size(), 2u);
    EXPECT_EQ(r.overall.samples, static_cast<int>(data.size()));
    EXPECT_EQ(r.overall.groups, by == HoldOut::kTool ? 24 : 6);
    for (const HeldOutScore& s : r.per_action) {
      EXPECT_LT(s.mae_model_m, 0.7 * s.mae_mean_m) << s.action;
      EXPECT_LT(s.rmse_model_m, s.rmse_mean_m) << s.action;
      // Unseen tools are ranked: strongly within known families, clearly across families.
      EXPECT_GT(s.group_correlation, by == HoldOut::kTool ? 0.8 : 0.5) << s.action;
    }
  }
  const nlohmann::json j = HeldOutJson(EvaluateHeldOut(data, HoldOut::kFamily));
  EXPECT_EQ(j["held_out"], "family");
  EXPECT_LT(j["overall"]["mae_ratio"].get<double>(), 0.7);
}

TEST(HeldOutTest, MeanBaselineIsTheTrainingFoldMean) {
  // Two tools, one action, targets constant per tool: leaving tool a out, the mean predicts b's
  // value (0.3) for a's targets (0.1), and the reverse; the error is 0.2 either way.
  std::vector<AffordanceSample> data;
  for (int i = 0; i < 4; ++i) {
    AffordanceSample s;
    s.tool = i < 2 ? "a" : "b";
    s.family = s.tool;
    s.action = "pull";
    s.x = Eigen::VectorXd::Constant(static_cast<Eigen::Index>(AffordanceFeatureNames().size()), i < 2 ? 0.0 : 1.0);
    s.displacement_m = i < 2 ? 0.1 : 0.3;
    data.push_back(s);
  }
  const HeldOutReport r = EvaluateHeldOut(data, HoldOut::kTool);
  EXPECT_NEAR(r.overall.mae_mean_m, 0.2, 1e-12);
  EXPECT_NEAR(r.overall.rmse_mean_m, 0.2, 1e-12);
  EXPECT_EQ(r.overall.groups, 2);
  data.resize(2);
  EXPECT_THAT([&] { EvaluateHeldOut(data, HoldOut::kTool); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("1 tool group(s)")));
}

TEST(ReadAffordanceSamplesTest, KeepsLabelledTrialsAndNamesBadLines) {
  const auto dir = TempDir("read");
  const std::vector<double> x(AffordanceFeatureNames().size(), 0.1);
  nlohmann::json good = {{"id", "hoe_1/pull/r0/b0"},
                         {"ok", true},
                         {"result",
                          {{"tool", "hoe_1"},
                           {"family", "hoe"},
                           {"action", "pull"},
                           {"labelled", true},
                           {"features", x},
                           {"displacement_along_m", 0.12}}}};
  nlohmann::json unlabelled = good;
  unlabelled["result"]["labelled"] = false;
  nlohmann::json crashed = {{"ok", false}, {"error", "signal 11"}};
  {
    std::ofstream out(dir / "results.jsonl");
    out << good.dump() << "\n" << unlabelled.dump() << "\n" << crashed.dump() << "\n\n";
  }
  const std::vector<AffordanceSample> samples = ReadAffordanceSamples(dir / "results.jsonl");
  ASSERT_EQ(samples.size(), 1u);
  EXPECT_EQ(samples[0].tool, "hoe_1");
  EXPECT_DOUBLE_EQ(samples[0].displacement_m, 0.12);
  nlohmann::json short_features = good;
  short_features["result"]["features"] = {1.0, 2.0};
  {
    std::ofstream out(dir / "bad.jsonl");
    out << good.dump() << "\n" << short_features.dump() << "\n";
  }
  EXPECT_THAT([&] { ReadAffordanceSamples(dir / "bad.jsonl"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("bad.jsonl:2: features has 2 values")));
  EXPECT_THAT([&] { ReadAffordanceSamples(dir / "nothing.jsonl"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("cannot open")));
}

}  // namespace
}  // namespace toolbench::app
