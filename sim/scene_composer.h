#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Geometry>

#include "robot/robot_description.h"
#include "sim/scene_spec.h"
#include "toollib/tool_model.h"

namespace toolbench::sim {

/// The Table 5.3 cells (shared/design.md): pos1..pos3 = three places along the rack, tool
/// upright and unrotated; rot0..rot3 at the central place: rot0 unrotated, rot1 = 90 deg about
/// the vertical (effector turns toward the robot), rot2 = 180 deg about the rack normal (upside
/// down), rot3 = 90 deg about the rack normal (lying across, effector up).
inline constexpr std::string_view kCellNames[] = {"pos1", "pos2", "pos3", "rot0",
                                                  "rot1", "rot2", "rot3"};

/// The extended protocol's cells (design.md: the full 3 x 4 cross product): every place pos1..pos3
/// with every rotation rot0..rot3, "pos<i>_rot<j>". pos<i>_rot0 is the pose of pos<i>, and
/// pos2_rot<j> that of rot<j>. A tool too long to lie across (rot3) at an end place is moved
/// toward the centre until it fits on the rack.
inline constexpr std::string_view kExtendedCellNames[] = {
    "pos1_rot0", "pos1_rot1", "pos1_rot2", "pos1_rot3", "pos2_rot0", "pos2_rot1",
    "pos2_rot2", "pos2_rot3", "pos3_rot0", "pos3_rot1", "pos3_rot2", "pos3_rot3"};

/// True when `cell` is one of kCellNames or kExtendedCellNames.
bool IsCellName(std::string_view cell);

/// Where one tool goes.
struct ToolPlacement {
  std::string tool;    // library model name
  std::string cell;    // one of kCellNames or kExtendedCellNames
  double offset = 0;   // extra shift along the rack x_K [m]
  double spin = 0;     // extra rotation about the tool's own axis z_T [rad], toward the robot
};

/// The random choices of one scene, fixed before composing.
struct ScenePlan {
  std::uint64_t seed = 0;
  std::vector<ToolPlacement> tools;
  Eigen::Vector2d ball_xy = Eigen::Vector2d::Zero();  // ball centre (x, y) in R [m]
};

/// Draws a plan from `seed`: the ball position, and (when `requested` is empty) 1..3 distinct
/// tools from `spec.tools.choices` (or all of `library_names`) in distinct places with small
/// jitter. With `requested` non-empty those placements are used as given. Throws
/// std::invalid_argument naming an unknown tool or cell, or two tools in one place.
ScenePlan PlanScene(const SceneSpec& spec, const std::vector<std::string>& library_names,
                    std::uint64_t seed, const std::vector<ToolPlacement>& requested);

/// A tool as composed into the scene.
struct PlacedTool {
  std::string name;   // library model name
  std::string cell;   // Table 5.3 cell
  std::string body;   // MuJoCo body name ("tool/<name>")
  Eigen::Isometry3d X_RT = Eigen::Isometry3d::Identity();  // pose as placed (before settling)
};

/// The composed MJCF and what it contains.
struct ComposedScene {
  std::string mjcf;                 // complete, loadable by MuJoCo 2.2.2 (absolute asset paths)
  ScenePlan plan;
  std::vector<PlacedTool> tools;
  Eigen::Isometry3d X_WR = Eigen::Isometry3d::Identity();  // robot root in world
  Eigen::Isometry3d X_RK = Eigen::Isometry3d::Identity();  // rack frame in robot root
  std::string ball_body = "ball";
  /// The fixed third-person cameras (for looking at what happens, not for perception) by name,
  /// "overview", "side" and "rack_close": each one's OpenCV optical frame in R. Calibrated
  /// extrinsics, like cameras on tripods.
  std::map<std::string, Eigen::Isometry3d> X_R_fixed_cameras;
};

/// Optical (OpenCV) frame of a camera at `p_eye` looking at `p_target`, image up toward +z.
Eigen::Isometry3d LookAtFrame(const Eigen::Vector3d& p_eye, const Eigen::Vector3d& p_target);

/// Pose of the rack frame K in the robot root R.
Eigen::Isometry3d RackPose(const RackSpec& rack);

/// Pose of a tool's model frame in the rack frame for a cell, before the tool is pushed onto
/// the ledge and against the board (rotation only, origin at the slot).
Eigen::Isometry3d CellPose(const RackSpec& rack, std::string_view cell);

/// A box of the scene's fixed furniture (table top and legs; rack board, ledge, rail, stop and
/// posts), exactly as ComposeScene writes it (MJCF geom name, pose and size).
struct FixtureBox {
  std::string name;                                         // geom name, e.g. "rack_ledge"
  Eigen::Isometry3d X_RB = Eigen::Isometry3d::Identity();   // box centre and axes in R
  Eigen::Vector3d half = Eigen::Vector3d::Zero();           // half extents [m]
};

/// The table's and the rack's boxes of `spec` in the robot root R: what the robot knows of its
/// workspace from the scene file (by calibration, like the table height), not the tools on it.
/// Throws std::invalid_argument when the spec is invalid.
std::vector<FixtureBox> FixtureBoxes(const SceneSpec& spec);

/// Builds the MJCF: robot (from the URDF, with position servos and the helmet camera), table,
/// rack, ball and the planned tools resting on the ledge against the board. Robot geoms collide
/// with the world and tools only. Throws std::invalid_argument when a planned tool is not in
/// `library`.
ComposedScene ComposeScene(const SceneSpec& spec, const robot::RobotDescription& robot,
                           const std::vector<toollib::ToolModel>& library, const ScenePlan& plan);

}  // namespace toolbench::sim
