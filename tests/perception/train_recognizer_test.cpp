// Rendered: the training-data collector of `toolbench train-recognizer` labels the segments of
// random rack scenes, and training on them is reproducible from the seed.
#include "app/train_recognizer.h"

#include <algorithm>
#include <memory>

#include <gtest/gtest.h>

namespace toolbench::app {
namespace {

TEST(TrainRecognizerTest, SameSeedsSameDatasetSamePredictions) {
  std::unique_ptr<sim::GlContext> gl;
  try {
    gl = std::make_unique<sim::GlContext>();
  } catch (const std::exception& e) {
    GTEST_SKIP() << "no OSMesa context available: " << e.what();
  }
  const perception::RecognitionFeatureOptions features;
  std::vector<std::vector<LabelledSample>> runs(2);
  std::vector<std::string> library;
  for (int run = 0; run < 2; ++run) {
    for (int i = 0; i < 3; ++i) {
      SceneRequest request;
      request.seed = TrainingSceneSeed(7, false, i);
      if (library.empty()) {
        for (const auto& m : LoadScene(request).library) library.push_back(m.name);
      }
      const CollectStats stats = CollectSamples(request, *gl, features, runs[static_cast<std::size_t>(run)]);
      EXPECT_GE(stats.segments, 1) << "seed " << request.seed;
    }
  }
  ASSERT_GE(runs[0].size(), 3u);
  ASSERT_EQ(runs[0].size(), runs[1].size());
  for (std::size_t k = 0; k < runs[0].size(); ++k) {
    EXPECT_EQ(runs[0][k].label, runs[1][k].label);
    EXPECT_EQ(runs[0][k].features, runs[1][k].features) << "sample " << k;
    // The label is a library model and the scene really holds it.
    EXPECT_NE(std::find(library.begin(), library.end(), runs[0][k].label), library.end());
  }
  // Held-out seeds are a different stream.
  EXPECT_NE(TrainingSceneSeed(7, false, 0), TrainingSceneSeed(7, true, 0));

  perception::ToolClassifierOptions options;
  options.trees = 20;
  const perception::ToolClassifier a = perception::ToolClassifier::Train(MakeDataset(runs[0], library, features), options);
  const perception::ToolClassifier b = perception::ToolClassifier::Train(MakeDataset(runs[1], library, features), options);
  for (const LabelledSample& s : runs[0]) {
    const std::vector<double> pa = a.PredictForLibrary(s.features, library);
    EXPECT_EQ(pa, b.PredictForLibrary(s.features, library));
    // Training samples are recognised by the forest trained on them.
    EXPECT_EQ(library[static_cast<std::size_t>(std::max_element(pa.begin(), pa.end()) - pa.begin())], s.label);
  }
}

}  // namespace
}  // namespace toolbench::app
