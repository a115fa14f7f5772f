// Scenes composed from assets loaded once (what a bench's episodes share) are the scenes that
// LoadScene composes from files loaded for each.
#include "app/scene_setup.h"

#include <algorithm>

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

// The hand may hold a shovel on its neck past the handle, not a stick on its other end (the
// effector: the same bar, but the part that works) nor a hook on its thinner shaft; either way the
// handle's own free slide stays, and the choke that GraspToolForAction and the hand-over use (away
// from the effector) does not move.
TEST(GripSlide, ReachesPastTheHandleWhereTheToolStaysABarUpToItsEffector) {
  const SceneAssets assets = LoadSceneAssets({}, {});
  const robot::RobotDescription& desc = assets.robot;
  int necks = 0;
  for (const toollib::ToolModel& tool : assets.library) {
    SCOPED_TRACE(tool.name);
    const double free = FreeHandleSlide(desc, tool.handle.length);
    const control::HandleSlide slide = GripSlide(desc, tool, tool.handle);
    EXPECT_DOUBLE_EQ(slide.min_m, -free);  // library handles end at the tool's butt
    EXPECT_GE(slide.max_m, free);
    if (tool.family == "shovel") {
      necks += slide.max_m > free + 0.005;
    } else if (tool.family == "stick" || tool.family == "hook" || tool.family == "hammer") {
      EXPECT_LT(slide.max_m, free + 0.006);
    }
  }
  EXPECT_GE(necks, 3);
  // Without the effector in the way, a stick's whole length: the bar to its other end.
  const auto stick = std::find_if(assets.library.begin(), assets.library.end(),
                                  [](const toollib::ToolModel& t) { return t.family == "stick"; });
  ASSERT_NE(stick, assets.library.end());
  toollib::ToolModel bare = *stick;
  bare.effector.center = bare.handle.center - 0.1 * bare.handle.axis;  // inside the handle's butt half
  bare.effector.axis = Eigen::Vector3d::UnitX();
  bare.effector.radius = 0.0;
  bare.effector.length = 0.001;
  EXPECT_NEAR(GripSlide(desc, bare, bare.handle).max_m,
              bare.total_length - bare.handle.center.z() - desc.grasp.length / 2 - 0.01, 1e-9);
  // A handle thicker than any bar on the mesh keeps its free slide.
  toollib::ToolModel odd = assets.library.front();
  odd.handle.radius = 0.2;
  EXPECT_EQ(GripSlide(desc, odd, odd.handle),
            control::HandleSlide::Symmetric(FreeHandleSlide(desc, odd.handle.length)));
}

}  // namespace
}  // namespace toolbench::app
