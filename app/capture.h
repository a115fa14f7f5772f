#pragma once

#include <filesystem>
#include <memory>
#include <string>

#include <nlohmann/json.hpp>

#include "app/scene_setup.h"
#include "common/types.h"
#include "sim/renderer.h"
#include "sim/world.h"

namespace toolbench::app {

/// How to take the picture.
struct CaptureOptions {
  bool noise = true;              // sensor noise model on
  bool look_at_table = false;     // look at the table instead of the rack
  std::string camera = "helmet";  // "helmet" (the robot's sensor) or a fixed camera: "overview", "side", "rack_close"
};

/// A scene after settling and turning to look, with one frame from the chosen camera.
struct Capture {
  LoadedScene scene;
  std::unique_ptr<sim::World> world;
  RgbdFrame frame;                 // X_RC from encoder forward kinematics (helmet camera)
  LookResult look;
  Eigen::Vector3d target_R = Eigen::Vector3d::Zero();  // the gaze target
  bool settled = false;            // tools and ball came to rest before the robot moved
  double tool_drift_m = 0.0;       // largest tool displacement from settling to capture [m]
};

/// Loads and composes the scene, lets it settle, turns torso and head to the rack (thesis
/// Fig. 5.4) with the right arm out of view, and renders one frame (noise seeded from the
/// request's seed). Throws std::invalid_argument for bad requests and std::runtime_error when
/// the simulation becomes unstable.
Capture CaptureFrame(const SceneRequest& request, const CaptureOptions& options, sim::GlContext& gl);

/// Camera metadata for camera.json: seed, joints, gaze outcome.
nlohmann::json CaptureMetadata(const Capture& capture, const SceneRequest& request,
                               const CaptureOptions& options);

/// Ground truth for ground_truth.json (scoring only): X_WR, every tool's X_RT and cell, ball.
nlohmann::json GroundTruthJson(const Capture& capture);

}  // namespace toolbench::app
