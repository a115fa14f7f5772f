// The ball on the table, seen from the table observation pose in rendered,
// noisy frames.
#include <gtest/gtest.h>

#include "app/capture.h"
#include "perception/ball.h"
#include "sim/renderer.h"

namespace toolbench::perception {
namespace {

TEST(BallSceneTest, BallFoundWithinFiveMillimetresAcrossSeeds) {
  std::unique_ptr<sim::GlContext> gl;
  try {
    gl = std::make_unique<sim::GlContext>();
  } catch (const std::exception& e) {
    GTEST_SKIP() << "no OSMesa context: " << e.what();
  }
  for (std::uint64_t seed : {1, 2, 3}) {
    app::SceneRequest request;
    request.seed = seed;
    app::CaptureOptions options;
    options.look_at_table = true;
    const app::Capture capture = app::CaptureFrame(request, options, *gl);
    const BallDetection ball = DetectBall(capture.frame, {});
    ASSERT_EQ(ball.status, BallStatus::kFound) << "seed " << seed << ": " << ball.reason;
    const Eigen::Vector3d truth =
        capture.scene.composed.X_WR.inverse() * capture.world->ground_truth().Pose("ball").translation();
    EXPECT_LT((ball.p_RB - truth).norm(), 0.005) << "seed " << seed;
    EXPECT_NEAR(ball.radius, capture.scene.spec.ball.radius, 0.005) << "seed " << seed;
  }
}

}  // namespace
}  // namespace toolbench::perception
