// Scenes composed from assets loaded once (what a bench's episodes share) are the scenes that
// LoadScene composes from files loaded for each.
#include "app/scene_setup.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "common/paths.h"

namespace toolbench::app {
namespace {

using ::testing::AllOf;
using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

TEST(ComposeFromAssets, ComposesTheSceneThatLoadSceneComposes) {
  const SceneAssets assets = LoadSceneAssets({}, {});
  EXPECT_EQ(assets.scene_file, sim::DefaultScenePath());
  for (std::uint64_t seed : {1u, 2u, 7u}) {
    SceneRequest request;
    request.seed = seed;
    const LoadedScene loaded = LoadScene(request);
    const LoadedScene composed = ComposeFromAssets(request, assets);
    EXPECT_EQ(composed.composed.mjcf, loaded.composed.mjcf) << "seed " << seed;
    EXPECT_EQ(composed.library.size(), loaded.library.size());
  }
  // Named tools and cells, too.
  SceneRequest request;
  request.tools = {"hoe_1", "rake_2"};
  request.cells = {"pos1", "rot2"};
  EXPECT_EQ(ComposeFromAssets(request, assets).composed.mjcf, LoadScene(request).composed.mjcf);
}

TEST(ComposeFromAssets, RefusesAssetsLoadedForAnotherScene) {
  const SceneAssets assets = LoadSceneAssets({}, {});
  SceneRequest other_file;
  other_file.scene_file = ScenesDir() / "noslip_always.json";
  EXPECT_THAT([&] { ComposeFromAssets(other_file, assets); },
              ThrowsMessage<std::invalid_argument>(AllOf(HasSubstr("noslip_always.json"), HasSubstr("default.json"))));
  SceneRequest user_tools;
  user_tools.extra_tool_dirs = {"/tmp/my_tools"};
  EXPECT_THAT([&] { ComposeFromAssets(user_tools, assets); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("user tool folder")));
}

}  // namespace
}  // namespace toolbench::app
