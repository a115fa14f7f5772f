#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "control/gaze.h"
#include "control/motion.h"
#include "control/skills.h"
#include "robot/robot_description.h"
#include "sim/scene_composer.h"
#include "sim/scene_spec.h"
#include "sim/world.h"
#include "toollib/tool_model.h"

namespace toolbench::app {

/// What the user asked for on the command line.
struct SceneRequest {
  std::filesystem::path scene_file;  // empty = scenes/default.json
  std::uint64_t seed = 1;
  std::vector<std::string> tools;                      // empty = drawn from the seed
  std::vector<std::string> cells;                      // one per tool, or empty
  std::vector<std::filesystem::path> extra_tool_dirs;  // user tools (mesh + sidecar)
};

/// Everything loaded and composed for one scene.
struct LoadedScene {
  sim::SceneSpec spec;
  robot::RobotDescription robot;
  std::vector<toollib::ToolModel> library;
  sim::ComposedScene composed;
};

/// The files a scene is composed from: the scene file, the robot and the tool library (assets
/// plus user folders). Every scene of a run shares them: a sweep loads them once (~0.1 s, most of
/// it the library's meshes) and composes each of its scenes from them.
struct SceneAssets {
  std::filesystem::path scene_file;                    // the file loaded (never empty)
  std::vector<std::filesystem::path> extra_tool_dirs;  // as requested
  sim::SceneSpec spec;
  robot::RobotDescription robot;
  std::vector<toollib::ToolModel> library;
};

/// Loads the scene file (empty = scenes/default.json), the robot and the tool library (a name
/// defined twice is an error). Throws std::invalid_argument naming the bad input.
SceneAssets LoadSceneAssets(const std::filesystem::path& scene_file,
                            const std::vector<std::filesystem::path>& extra_tool_dirs);

/// Composes the request's scene from `assets`, which must have been loaded for its scene file
/// and user tool folders (else std::invalid_argument). Tools without cells get pos1, pos2, pos3
/// in order (a single tool gets pos2). Throws std::invalid_argument naming the bad input.
LoadedScene ComposeFromAssets(const SceneRequest& request, SceneAssets assets);

/// LoadSceneAssets for the request, then ComposeFromAssets.
LoadedScene LoadScene(const SceneRequest& request);

/// Loads every tool folder of the scene plus `extra_dirs`; throws on duplicates or bad files.
std::vector<toollib::ToolModel> LoadLibraries(const sim::SceneSpec& spec,
                                              const std::vector<std::filesystem::path>& extra_dirs);

/// Joint vector in the robot model's q order from encoder readings named `names`. Joints the
/// encoders do not cover keep their HomeQ value. Throws on an encoder of an unknown joint.
Eigen::VectorXd ModelQ(const robot::RobotDescription& robot, const std::vector<std::string>& names,
                       const Eigen::VectorXd& encoders);

/// Camera pose in the root frame from the encoders (forward kinematics of the URDF): the only
/// camera pose perception may use.
Eigen::Isometry3d CameraPoseFromEncoders(const robot::RobotDescription& robot, const RobotInterface& interface);

/// Palm frame pose in the root frame from the encoders (forward kinematics of the URDF).
Eigen::Isometry3d PalmPoseFromEncoders(const robot::RobotDescription& robot, const RobotInterface& interface);

/// How far an assumed in-hand tool pose X_PT is from the true one (for scoring only): the
/// rotation between them [deg] and the distance between the effector centres p_T_effector they
/// put in the palm frame [m].
struct InHandError {
  double rotation_deg = 0.0;
  double effector_m = 0.0;
};
InHandError InHandPoseError(const Eigen::Isometry3d& X_PT, const Eigen::Isometry3d& X_PT_truth,
                            const Eigen::Vector3d& p_T_effector);

/// The scene's fixed furniture (sim::FixtureBoxes: table top and legs, the rack's boxes) as
/// obstacles for the arm's planning: known from the scene file, like the table height.
std::vector<control::ObstacleBox> WorkspaceObstacles(const sim::SceneSpec& spec);

/// The rack's boxes of WorkspaceObstacles (named "rack_..."): what a tool carried off the rack must
/// keep clear of (PullOptions::fixtures; the table is the pull's support, checked on its own).
std::vector<control::ObstacleBox> RackObstacles(const sim::SceneSpec& spec);

/// The table top in the horizontal plane of R (PullOptions::support_xy, and shrunk for
/// PutDownOptions::support_xy): known from the
/// scene file, like the table height.
Eigen::AlignedBox2d TableTopArea(const sim::SceneSpec& spec);

/// Point the robot looks at to see the rack: the middle of the rack, a little up the board.
Eigen::Vector3d RackViewTarget(const sim::SceneSpec& spec);

/// q_model (model q) with the observation posture's joints set: torso leaning back a little, the
/// right arm down beside it (LookAt's starting posture).
Eigen::VectorXd ObservePosture(const robot::RobotDescription& robot, const Eigen::VectorXd& q_model);

/// Outcome of turning torso and head toward a point.
struct LookResult {
  control::GazeResult gaze;
  control::MotionResult motion;
};

/// Solves gaze for `p_R_target` and moves torso and neck there with a minimum-jerk trajectory
/// (thesis Fig. 5.4), the right arm into the observation posture at the same time unless
/// `arm_down` is false (the arm then keeps its targets: e.g. a hand already cleared of the table,
/// which the joint-space move down would sweep across it), executed with `motion` (e.g. at
/// control::kTransferSpeed when the hand is empty and away from everything). Never throws for an
/// unreachable gaze: the result says so.
LookResult LookAt(RobotInterface& interface, const robot::RobotDescription& robot, const Eigen::Vector3d& p_R_target,
                  bool arm_down = true, const control::MotionOptions& motion = {});

/// Swings the right arm sideways, up and out of the camera's view of the table (the shoulder
/// abducted to at least kArmAsideShoulderRollRad; every other joint keeps its target), when it is
/// not already that far out. The open hand the put-down lifts clear of the placed tool can leave
/// the forearm across the view of the table (`bench --protocol random --seed 1`: episodes 11 and
/// 17 then saw no ball, and their table_after.png showed the forearm), and lowering it beside the
/// torso would sweep it over the table. Nothing moves (reached, elapsed 0) when the arm is
/// already out. Throws std::invalid_argument when the robot has no r_shoulder_roll.
control::MotionResult MoveArmAside(RobotInterface& interface);
inline constexpr double kArmAsideShoulderRollRad = 1.4;

/// Points the head at `p_R_target` with the neck alone, from the current posture: torso and arms
/// keep their targets (e.g. to look at a tool held in the hand, which a torso move would carry
/// along). Never throws for an unreachable gaze: the result says so.
LookResult LookWithNeck(RobotInterface& interface, const robot::RobotDescription& robot,
                        const Eigen::Vector3d& p_R_target);

/// The effector of a library tool as the pull skill needs it, in T: the sidecar's effector
/// centre, working direction +x_T, its reach along +x_T from the mesh, and the points of the
/// effector region and of the whole tool: the mesh vertices and, on each face with an edge longer
/// than max_edge_m [m] (> 0), a grid of points that splits it into triangles with edges no longer
/// (a user's mesh of a few large faces is otherwise empty between its corners, where the pull's
/// clearance checks see no tool; the library's meshes have edges of at most 2 cm, and get none).
control::ToolEffector EffectorOf(const toollib::ToolModel& model, double max_edge_m = 0.02);

/// The hand's grasp frame G in the palm frame P: origin at the centre of the cylinder the hand
/// holds (desc.grasp.center), z_G along its axis (desc.grasp.axis), x_G the palm's x_P turned by
/// the shortest rotation that takes z_P onto the axis (toward the fingertips for the iCub hand).
/// A handle held in the hand has its frame H on G up to a roll about z_G.
Eigen::Isometry3d PalmGraspFrame(const robot::RobotDescription& desc);

/// How far the hand's grasp cylinder can slide from the centre of a handle of length
/// `handle_length` [m] either way and stay `margin` [m] inside its ends: (handle_length - grasp
/// length) / 2 - margin, at least 0 (GraspOptions::handle_slide, HandleSlide::Symmetric).
double FreeHandleSlide(const robot::RobotDescription& desc, double handle_length, double margin = 0.01);

/// Where along a handle's axis the hand may hold a tool: FreeHandleSlide(desc, handle.length,
/// margin) either way, and further on a side where the tool stays a bar like its handle past the
/// handle's end (toollib::HandleBarSpan of tool.mesh: a shovel's neck), the hand's grasp cylinder
/// then `margin` [m] inside the bar and off tool.effector's extent along the axis: a hand on the
/// effector hides the part that works (a stick held by its far end was pulled with that end in
/// the hand, and the ball rolled off the table). `handle` is in T (tool.handle, or a perceived
/// handle mapped into T); the slide is along z of HandleFrame(handle) (handle.axis).
control::HandleSlide GripSlide(const robot::RobotDescription& desc, const toollib::ToolModel& tool,
                               const toollib::Segment& handle, double margin = 0.01);

/// Where the robot holds a tool: the handle frame X_TH (in T, z_H along the handle) moved along
/// z_H toward the handle's end away from the effector (centre p_T_effector) by `fraction` of
/// FreeHandleSlide(desc, handle_length). 0.6 is the first choke GraspToolForAction tries (the
/// tool then reaches furthest); the hand-over and exploration hold tools there too, and the
/// episode predicts each tool's affordance there.
Eigen::Isometry3d ChokedHandleFrame(const robot::RobotDescription& desc, const Eigen::Isometry3d& X_TH,
                                    const Eigen::Vector3d& p_T_effector, double handle_length, double fraction = 0.6);

/// Handle frame H of a tool's handle segment, in T: origin at the handle centre, z_H along the
/// handle axis (the grasp skills' convention; the rotation about z_H is the shortest turn from z_T).
Eigen::Isometry3d HandleFrame(const toollib::Segment& handle);

/// What PutDownOnTable did.
struct TablePutDown {
  control::PutDownResult put;  // the last place tried (placed or not)
  int places_tried = 0;
  bool clear_of_ball = true;   // placed on a pass that kept the tool clear of the ball and on the table
  bool tool_axis_level = true; // placed with the tool's handle axis level (else the hand's grasp axis)
  bool hand_cleared = false;   // the palm ended within 3 cm of 15 cm above the table, or higher
  std::string clear_reason;    // why the clearing path stopped short ("" = it went all the way)
};

/// Puts the tool held as X_PT down on the scene's table, away from the ball, and clears the hand
/// of the table. Places: 8 fixed ones (10 cm in from the table's sides and half-way to the middle,
/// near and middle rows, the right hand's side first) at least 20 cm from ball_R[0], then a 5 x 5
/// grid 8 cm in from the edges at least 15 cm from it; each with control::PutDown, keeping every
/// point of the model's mesh 8 cm from every ball_R (base.keep_out_radius_m) and the tool's
/// centroid 5 cm inside the table, the model's handle axis laid level (control::PutDownOptions::
/// tool_axis_T). When no place passes, the places again with the hand's grasp axis level, and then
/// without the checks (a hand still holding the tool cannot grasp the ball). Then the open hand rises to 15 cm above
/// the table and crosses, as far as IK goes, to above where the observation posture puts it: the
/// joint-space move into that posture had swept the hand across the table top. ball_R: where the
/// ball is or should be, in R, at least one. Throws as control::PutDown does, and
/// std::invalid_argument for an empty or non-finite ball_R.
TablePutDown PutDownOnTable(RobotInterface& robot, const robot::RobotDescription& desc, const sim::SceneSpec& spec,
                            const Eigen::Isometry3d& X_PT, const toollib::ToolModel& model,
                            const std::vector<Eigen::Vector3d>& ball_R,
                            const control::PutDownOptions& base = control::PutDownOptions());

}  // namespace toolbench::app
