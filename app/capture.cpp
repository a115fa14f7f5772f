#include "app/capture.h"

#include <stdexcept>

#include <spdlog/spdlog.h>

#include "app/frame_io.h"
#include "common/rng.h"

namespace toolbench::app {

Capture CaptureFrame(const SceneRequest& request, const CaptureOptions& options, sim::GlContext& gl) {
  Capture capture;
  capture.scene = LoadScene(request);
  capture.world = std::make_unique<sim::World>(capture.scene.composed.mjcf,
                                               "scene seed " + std::to_string(request.seed));
  sim::World& world = *capture.world;
  sim::SimRobot robot(world);
  capture.settled = world.SettleFreeBodies(capture.scene.spec.physics.settle_time);
  if (!capture.settled) {
    spdlog::warn("tools still moving after {} s of settling", capture.scene.spec.physics.settle_time);
  }
  const sim::GroundTruth settled = world.ground_truth();
  const sim::SceneSpec& spec = capture.scene.spec;
  capture.target_R = options.look_at_table
                         ? Eigen::Vector3d(spec.table.center.x(), spec.table.center.y(), spec.table.top_z)
                         : RackViewTarget(spec);
  capture.look = LookAt(robot, capture.scene.robot, capture.target_R);
  if (!world.status().ok) throw std::runtime_error("simulation became unstable: " + world.status().message);

  sim::RendererOptions render_options;
  render_options.noise.enabled = options.noise;
  render_options.camera = options.camera;
  sim::Renderer renderer(gl, world, render_options);
  capture.frame = renderer.Render(world, DeriveSeed(request.seed, "sensor_noise"));
  // The helmet camera's pose comes from encoder forward kinematics, as on the robot; the other
  // cameras are fixed in the world with calibrated extrinsics.
  capture.frame.X_RC = options.camera == "helmet" ? CameraPoseFromEncoders(capture.scene.robot, robot)
                                                  : capture.scene.composed.X_R_fixed_cameras.at(options.camera);
  const sim::GroundTruth now = world.ground_truth();
  for (const auto& placed : capture.scene.composed.tools) {
    capture.tool_drift_m = std::max(capture.tool_drift_m, (now.Pose(placed.body).translation() -
                                                           settled.Pose(placed.body).translation()).norm());
  }
  return capture;
}

nlohmann::json CaptureMetadata(const Capture& capture, const SceneRequest& request,
                               const CaptureOptions& options) {
  nlohmann::json extra;
  extra["seed"] = request.seed;
  extra["camera"] = options.camera;
  extra["noise"] = options.noise;
  extra["joints"] = nlohmann::json::object();
  const auto& names = capture.world->actuated_joints();
  const Eigen::VectorXd q = capture.world->JointPositions();
  for (size_t i = 0; i < names.size(); ++i) extra["joints"][names[i]] = q[static_cast<Eigen::Index>(i)];
  extra["gaze"] = {{"target_R", {capture.target_R.x(), capture.target_R.y(), capture.target_R.z()}},
                   {"converged", capture.look.gaze.converged},
                   {"error_deg", capture.look.gaze.error_deg},
                   {"motion_reached", capture.look.motion.reached}};
  return extra;
}

nlohmann::json GroundTruthJson(const Capture& capture) {
  const sim::GroundTruth truth = capture.world->ground_truth();
  const Eigen::Isometry3d X_RW = capture.scene.composed.X_WR.inverse();
  nlohmann::json gt;
  gt["note"] = "simulator ground truth: for scoring and debugging, never an input to perception";
  gt["X_WR"] = PoseJson(capture.scene.composed.X_WR);
  gt["tools"] = nlohmann::json::array();
  for (const auto& placed : capture.scene.composed.tools) {
    gt["tools"].push_back({{"name", placed.name}, {"cell", placed.cell},
                           {"X_RT", PoseJson(X_RW * truth.Pose(placed.body))}});
  }
  gt["ball_R"] = PoseJson(X_RW * truth.Pose("ball"))["position"];
  gt["tool_drift_since_settled_m"] = capture.tool_drift_m;
  gt["settled"] = capture.settled;
  return gt;
}

}  // namespace toolbench::app
