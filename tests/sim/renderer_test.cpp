#include "sim/renderer.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace toolbench::sim {
namespace {

using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

// A camera 1 m above the floor looking straight down at a 0.20 x 0.10 x 0.05 m box.
constexpr const char* kBoxScene = R"(
<mujoco>
  <statistic extent="1"/>
  <visual><global offwidth="640" offheight="480"/><quality offsamples="0"/><map znear="0.01" zfar="50"/></visual>
  <worldbody>
    <light directional="true" pos="0 0 3" dir="0 0 -1"/>
    <geom type="plane" size="2 2 0.1" rgba="0.5 0.5 0.5 1"/>
    <geom name="box" type="box" size="0.10 0.05 0.025" pos="0.05 0.02 0.025" rgba="0.8 0.2 0.2 1"/>
    <camera name="down" pos="0 0 1" quat="1 0 0 0" fovy="58"/>
  </worldbody>
</mujoco>)";

std::unique_ptr<GlContext> MakeContext() {
  try {
    return std::make_unique<GlContext>();
  } catch (const std::exception&) {
    return nullptr;
  }
}

TEST(RendererTest, IdealDepthMatchesPlaneAndBoxWithinOneMillimetre) {
  auto gl = MakeContext();
  if (!gl) GTEST_SKIP() << "no OSMesa context available";
  World world(kBoxScene, "box scene");
  RendererOptions options;
  options.camera = "down";
  options.noise.enabled = false;
  Renderer renderer(*gl, world, options);
  const RgbdFrame frame = renderer.Render(world, 0);
  const CameraIntrinsics& K = frame.intrinsics;
  EXPECT_NEAR(K.fy, 240.0 / std::tan(29.0 * M_PI / 180.0), 1e-9);
  // The MuJoCo camera at identity looks along world -z with image-up = world +y, so the OpenCV
  // frame is (x, -y, -z): world point = (x_C, -y_C, 1 - z_C).
  double box_x_min = 1e9, box_x_max = -1e9, box_y_min = 1e9, box_y_max = -1e9;
  int plane_points = 0, box_points = 0;
  for (int v = 0; v < K.height; ++v) {
    for (int u = 0; u < K.width; ++u) {
      const double z = frame.depth.at<float>(v, u);
      ASSERT_GT(z, 0.0);
      const double x_w = (u - K.cx) / K.fx * z;
      const double y_w = -(v - K.cy) / K.fy * z;
      const double h = 1.0 - z;
      const bool on_box = std::abs(x_w - 0.05) < 0.1 - 0.004 && std::abs(y_w - 0.02) < 0.05 - 0.004;
      const bool off_box = std::abs(x_w - 0.05) > 0.1 + 0.004 || std::abs(y_w - 0.02) > 0.05 + 0.004;
      if (on_box) {
        ASSERT_NEAR(h, 0.05, 1e-3) << "box top at pixel " << u << "," << v;
        ++box_points;
      } else if (off_box) {
        ASSERT_NEAR(h, 0.0, 1e-3) << "floor at pixel " << u << "," << v;
        ++plane_points;
      }
      if (h > 0.025) {
        box_x_min = std::min(box_x_min, x_w);
        box_x_max = std::max(box_x_max, x_w);
        box_y_min = std::min(box_y_min, y_w);
        box_y_max = std::max(box_y_max, y_w);
      }
    }
  }
  EXPECT_GT(box_points, 3000);
  EXPECT_GT(plane_points, 100000);
  // The box outline, to within one pixel (0.95 m / 433 px = 2.2 mm).
  const double pixel = 0.95 / K.fx;
  EXPECT_NEAR(box_x_min, -0.05, pixel);
  EXPECT_NEAR(box_x_max, 0.15, pixel);
  EXPECT_NEAR(box_y_min, -0.03, pixel);
  EXPECT_NEAR(box_y_max, 0.07, pixel);
  // The red box shows in the colour image where depth says it is.
  const cv::Vec3b centre = frame.rgb.at<cv::Vec3b>(static_cast<int>(K.cy - 0.02 * K.fy / 0.95),
                                                    static_cast<int>(K.cx + 0.05 * K.fx / 0.95));
  EXPECT_GT(centre[0], centre[1] + 50);
  EXPECT_GT(centre[0], centre[2] + 50);
}

TEST(RendererTest, SameSeedSameFrameOtherSeedOtherNoise) {
  auto gl = MakeContext();
  if (!gl) GTEST_SKIP() << "no OSMesa context available";
  World world(kBoxScene, "box scene");
  RendererOptions options;
  options.camera = "down";
  Renderer renderer(*gl, world, options);
  const RgbdFrame a = renderer.Render(world, 5);
  const RgbdFrame b = renderer.Render(world, 5);
  const RgbdFrame c = renderer.Render(world, 6);
  EXPECT_EQ(cv::norm(a.depth, b.depth, cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(a.rgb, b.rgb, cv::NORM_INF), 0.0);
  EXPECT_GT(cv::norm(a.depth, c.depth, cv::NORM_INF), 0.0);
}

TEST(RendererTest, UnknownCameraIsNamed) {
  auto gl = MakeContext();
  if (!gl) GTEST_SKIP() << "no OSMesa context available";
  World world(kBoxScene, "box scene");
  RendererOptions options;
  options.camera = "wrist";
  EXPECT_THAT([&] { Renderer(*gl, world, options); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("wrist")));
}

}  // namespace
}  // namespace toolbench::sim
