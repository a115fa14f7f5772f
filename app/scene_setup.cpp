#include "app/scene_setup.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <set>

#include <spdlog/spdlog.h>

#include "common/check.h"
#include "common/paths.h"

namespace toolbench::app {
namespace {

/// Posture while observing: torso leaning back a little (the camera gains distance from the rack),
/// right arm down beside the torso (in the home posture the hand reaches forward-right, right in
/// front of the rack).
const std::map<std::string, double> kObservePostureDeg = {
    {"torso_pitch", -20.0}, {"r_shoulder_pitch", -5.0}, {"r_shoulder_roll", 12.0}, {"r_shoulder_yaw", 0.0},
    {"r_elbow", 25.0},      {"r_wrist_prosup", 0.0},    {"r_wrist_pitch", 0.0},    {"r_wrist_yaw", 0.0}};

}  // namespace

std::vector<toollib::ToolModel> LoadLibraries(const sim::SceneSpec& spec,
                                              const std::vector<std::filesystem::path>& extra_dirs) {
  std::vector<std::filesystem::path> dirs;
  for (const auto& d : spec.tool_dirs) dirs.push_back(AssetsDir() / d);
  dirs.insert(dirs.end(), extra_dirs.begin(), extra_dirs.end());
  std::vector<toollib::ToolModel> library;
  std::set<std::string> names;
  for (const auto& dir : dirs) {
    if (!std::filesystem::is_directory(dir)) {
      ThrowInvalid("tool folder '", dir.string(), "' does not exist");
    }
    for (auto& tool : toollib::LoadToolLibrary(dir)) {
      if (!names.insert(tool.name).second) {
        ThrowInvalid("tool '", tool.name, "' in '", dir.string(),
                     "' has the same name as a tool loaded before; rename one of them");
      }
      library.push_back(std::move(tool));
    }
  }
  return library;
}

SceneAssets LoadSceneAssets(const std::filesystem::path& scene_file,
                            const std::vector<std::filesystem::path>& extra_tool_dirs) {
  SceneAssets assets;
  assets.scene_file = scene_file.empty() ? sim::DefaultScenePath() : scene_file;
  assets.extra_tool_dirs = extra_tool_dirs;
  assets.spec = sim::LoadSceneSpec(assets.scene_file);
  assets.robot = robot::LoadRobotDescription(AssetsDir() / assets.spec.robot);
  assets.library = LoadLibraries(assets.spec, extra_tool_dirs);
  return assets;
}

LoadedScene ComposeFromAssets(const SceneRequest& request, SceneAssets assets) {
  const std::filesystem::path scene_file = request.scene_file.empty() ? sim::DefaultScenePath() : request.scene_file;
  if (scene_file != assets.scene_file || request.extra_tool_dirs != assets.extra_tool_dirs) {
    ThrowInvalid("ComposeFromAssets: the scene asks for '", scene_file.string(), "' with ",
                 request.extra_tool_dirs.size(), " user tool folder(s), but the assets were loaded from '",
                 assets.scene_file.string(), "' with ", assets.extra_tool_dirs.size());
  }
  LoadedScene loaded;
  loaded.spec = std::move(assets.spec);
  loaded.robot = std::move(assets.robot);
  loaded.library = std::move(assets.library);

  std::vector<sim::ToolPlacement> placements;
  if (!request.cells.empty() && request.cells.size() != request.tools.size()) {
    ThrowInvalid("--cells has ", request.cells.size(), " entries but --tools has ", request.tools.size(),
                 "; give one cell per tool");
  }
  for (size_t i = 0; i < request.tools.size(); ++i) {
    sim::ToolPlacement p;
    p.tool = request.tools[i];
    if (!request.cells.empty()) {
      p.cell = request.cells[i];
    } else {
      p.cell = request.tools.size() == 1 ? "pos2" : "pos" + std::to_string(i + 1);
    }
    placements.push_back(p);
  }
  std::vector<std::string> names;
  for (const auto& tool : loaded.library) names.push_back(tool.name);
  const sim::ScenePlan plan = sim::PlanScene(loaded.spec, names, request.seed, placements);
  loaded.composed = sim::ComposeScene(loaded.spec, loaded.robot, loaded.library, plan);
  return loaded;
}

LoadedScene LoadScene(const SceneRequest& request) {
  return ComposeFromAssets(request, LoadSceneAssets(request.scene_file, request.extra_tool_dirs));
}

Eigen::VectorXd ModelQ(const robot::RobotDescription& robot, const std::vector<std::string>& names,
                       const Eigen::VectorXd& encoders) {
  if (static_cast<Eigen::Index>(names.size()) != encoders.size()) {
    ThrowInvalid("ModelQ: ", names.size(), " names for ", encoders.size(), " encoder values");
  }
  Eigen::VectorXd q = robot.HomeQ();
  for (size_t i = 0; i < names.size(); ++i) {
    const robot::Joint& joint = robot.model.joints[robot.model.JointIndex(names[i])];
    if (joint.q_index < 0) ThrowInvalid("ModelQ: joint '", names[i], "' is fixed in the URDF");
    q[joint.q_index] = encoders[static_cast<Eigen::Index>(i)];
  }
  return q;
}

Eigen::Isometry3d CameraPoseFromEncoders(const robot::RobotDescription& robot, const RobotInterface& interface) {
  const Eigen::VectorXd q = ModelQ(robot, interface.JointNames(), interface.ReadEncoders());
  return robot::LinkPose(robot.model, q, robot.camera_frame);
}

Eigen::Isometry3d PalmPoseFromEncoders(const robot::RobotDescription& robot, const RobotInterface& interface) {
  const Eigen::VectorXd q = ModelQ(robot, interface.JointNames(), interface.ReadEncoders());
  return robot::LinkPose(robot.model, q, robot.palm_frame);
}

InHandError InHandPoseError(const Eigen::Isometry3d& X_PT, const Eigen::Isometry3d& X_PT_truth,
                            const Eigen::Vector3d& p_T_effector) {
  return {Eigen::AngleAxisd(X_PT.linear() * X_PT_truth.linear().transpose()).angle() * 180 / M_PI,
          (X_PT * p_T_effector - X_PT_truth * p_T_effector).norm()};
}

std::vector<control::ObstacleBox> WorkspaceObstacles(const sim::SceneSpec& spec) {
  std::vector<control::ObstacleBox> out;
  for (const sim::FixtureBox& box : sim::FixtureBoxes(spec)) out.push_back({box.name, box.X_RB, box.half});
  return out;
}

std::vector<control::ObstacleBox> RackObstacles(const sim::SceneSpec& spec) {
  std::vector<control::ObstacleBox> out = WorkspaceObstacles(spec);
  out.erase(std::remove_if(out.begin(), out.end(),
                           [](const control::ObstacleBox& box) { return box.name.rfind("rack_", 0) != 0; }),
            out.end());
  return out;
}

Eigen::AlignedBox2d TableTopArea(const sim::SceneSpec& spec) {
  return {spec.table.center - spec.table.size / 2, spec.table.center + spec.table.size / 2};
}

Eigen::Vector3d RackViewTarget(const sim::SceneSpec& spec) {
  const Eigen::Isometry3d X_RK = sim::RackPose(spec.rack);
  return X_RK * Eigen::Vector3d(0.0, 0.0, 0.24);
}

namespace {

std::map<std::string, double> ObserveJoints() {
  std::map<std::string, double> observe;
  for (const auto& [joint, deg] : kObservePostureDeg) observe[joint] = deg * M_PI / 180.0;
  return observe;
}

}  // namespace

Eigen::VectorXd ObservePosture(const robot::RobotDescription& robot, const Eigen::VectorXd& q_model) {
  return robot.WithJoints(q_model, ObserveJoints());
}

LookResult LookAt(RobotInterface& interface, const robot::RobotDescription& robot, const Eigen::Vector3d& p_R_target,
                  bool arm_down, const control::MotionOptions& motion) {
  LookResult result;
  // Gaze starts from the observation posture (torso leaning back a little, for distance).
  std::map<std::string, double> observe = ObserveJoints();
  if (!arm_down) {
    for (auto it = observe.begin(); it != observe.end();) it = it->first.rfind("r_", 0) == 0 ? observe.erase(it) : std::next(it);
  }
  // The gaze is solved from the neck and torso yaw at zero, not from where they are: the same
  // target gives the same posture whatever the robot looked at before (the rack look after the
  // table look turned the torso 59 deg instead of 32, and grasps planned from there differed).
  std::map<std::string, double> seed = observe;
  for (const char* joint : {"torso_yaw", "neck_pitch", "neck_roll", "neck_yaw"}) seed[joint] = 0.0;
  const Eigen::VectorXd q = robot.WithJoints(ModelQ(robot, interface.JointNames(), interface.PositionTargets()), seed);
  result.gaze = control::LookAt(robot, q, p_R_target);
  if (!result.gaze.converged) {
    spdlog::warn(
        "gaze: target {} {} {} cannot be centred (residual {:.1f} deg); looking as close "
        "as the joint limits allow",
        p_R_target.x(), p_R_target.y(), p_R_target.z(), result.gaze.error_deg);
  }
  // The right arm moves down beside the torso at the same time, so that the hand does not hide
  // the rack (in the home posture it reaches forward-right, right in front of it).
  std::map<std::string, double> goal = observe;
  for (const auto& [joint, value] : result.gaze.joints) goal[joint] = value;
  result.motion = control::MoveJoints(interface, goal, motion);
  return result;
}

control::MotionResult MoveArmAside(RobotInterface& interface) {
  const std::vector<std::string> names = interface.JointNames();
  const auto it = std::find(names.begin(), names.end(), "r_shoulder_roll");
  if (it == names.end()) ThrowInvalid("MoveArmAside: the robot has no joint 'r_shoulder_roll'");
  const double roll = interface.PositionTargets()[it - names.begin()];
  if (roll >= kArmAsideShoulderRollRad) {
    control::MotionResult none;
    none.reached = true;
    return none;
  }
  control::MotionOptions motion;
  motion.max_speed = control::kTransferSpeed;  // up and away from everything
  return control::MoveJoints(interface, {{"r_shoulder_roll", kArmAsideShoulderRollRad}}, motion);
}

LookResult LookWithNeck(RobotInterface& interface, const robot::RobotDescription& robot,
                        const Eigen::Vector3d& p_R_target) {
  LookResult result;
  control::GazeOptions options;
  for (auto it = options.joint_weights.begin(); it != options.joint_weights.end();) {
    it = it->first.rfind("neck_", 0) == 0 ? std::next(it) : options.joint_weights.erase(it);
  }
  const Eigen::VectorXd q = ModelQ(robot, interface.JointNames(), interface.PositionTargets());
  result.gaze = control::LookAt(robot, q, p_R_target, options);
  // The neck alone: a short, light motion, at most 0.8 s, shorter for a small turn (a glance back
  // at the table after the put-down turned the neck by 0.07 rad in 0.8 s).
  control::MotionOptions motion;
  motion.duration = 0.8;
  motion.max_speed = control::kTransferSpeed;
  result.motion = control::MoveJoints(interface, result.gaze.joints, motion);
  return result;
}

Eigen::Isometry3d PalmGraspFrame(const robot::RobotDescription& desc) {
  Eigen::Isometry3d X_PG = Eigen::Isometry3d::Identity();
  X_PG.linear() =
      Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitZ(), desc.grasp.axis.normalized()).toRotationMatrix();
  X_PG.translation() = desc.grasp.center;
  return X_PG;
}

double FreeHandleSlide(const robot::RobotDescription& desc, double handle_length, double margin) {
  return std::max(0.0, (handle_length - desc.grasp.length) / 2 - margin);
}

control::HandleSlide GripSlide(const robot::RobotDescription& desc, const toollib::ToolModel& tool,
                               const toollib::Segment& handle, double margin) {
  const double free = FreeHandleSlide(desc, handle.length, margin);
  toollib::AxisSpan bar = toollib::HandleBarSpan(tool.mesh, handle);
  // The effector's extent along the handle axis: its length along it, its radius across.
  const Eigen::Vector3d a = handle.axis.normalized();
  const double along = (tool.effector.center - handle.center).dot(a);
  const double cos = std::abs(tool.effector.axis.normalized().dot(a));
  const double half = cos * tool.effector.length / 2 + std::sqrt(std::max(0.0, 1 - cos * cos)) * tool.effector.radius;
  if (along >= 0) bar.max_m = std::min(bar.max_m, along - half);
  if (along <= 0) bar.min_m = std::max(bar.min_m, along + half);
  const double inside = desc.grasp.length / 2 + margin;  // from the grasp centre to the bar's end
  return {std::min(-free, std::min(0.0, bar.min_m + inside)), std::max(free, std::max(0.0, bar.max_m - inside))};
}

Eigen::Isometry3d ChokedHandleFrame(const robot::RobotDescription& desc, const Eigen::Isometry3d& X_TH,
                                    const Eigen::Vector3d& p_T_effector, double handle_length, double fraction) {
  const Eigen::Vector3d z_H = X_TH.linear().col(2);
  const double toward_effector = (p_T_effector - X_TH.translation()).dot(z_H) >= 0 ? 1.0 : -1.0;
  Eigen::Isometry3d X = X_TH;
  X.translation() -= toward_effector * fraction * FreeHandleSlide(desc, handle_length) * z_H;
  return X;
}

control::ToolEffector EffectorOf(const toollib::ToolModel& model, double max_edge_m) {
  if (!(max_edge_m > 0)) ThrowInvalid("EffectorOf: max_edge_m = ", max_edge_m, " (expected > 0)");
  control::ToolEffector e;
  e.center_T = model.effector.center;
  e.direction_T = Eigen::Vector3d::UnitX();
  const double region = model.effector.length / 2 + model.effector.radius;
  double reach = 0.0;
  for (Eigen::Index v = 0; v < model.mesh.vertices.cols(); ++v) {
    const Eigen::Vector3d d = model.mesh.vertices.col(v).cast<double>() - e.center_T;
    if (d.norm() <= region) reach = std::max(reach, d.dot(e.direction_T));
  }
  e.half_thickness_m = reach;
  // The geometry the pull plans with: the vertices, then the grid points of faces with long edges
  // (barycentric (i, j, n - i - j) / n, n = longest edge / max_edge_m rounded up; 1 % slack keeps
  // a face whose longest edge is max_edge_m to a float's rounding whole), the whole tool's and
  // those of its effector region.
  const Eigen::Matrix3Xd& vertices = model.mesh.vertices;
  std::vector<Eigen::Vector3d> grid;
  for (Eigen::Index f = 0; f < model.mesh.faces.cols(); ++f) {
    const Eigen::Vector3d a = vertices.col(model.mesh.faces(0, f));
    const Eigen::Vector3d b = vertices.col(model.mesh.faces(1, f));
    const Eigen::Vector3d c = vertices.col(model.mesh.faces(2, f));
    const double longest = std::max({(b - a).norm(), (c - b).norm(), (a - c).norm()});
    const int n = static_cast<int>(std::ceil(longest / max_edge_m - 0.01));
    if (n < 2) continue;
    for (int i = 0; i <= n; ++i) {
      for (int j = 0; i + j <= n; ++j) {
        if (i == n || j == n || i + j == 0) continue;  // the corners are vertices already
        grid.push_back((i * a + j * b + (n - i - j) * c) / n);
      }
    }
  }
  e.tool_points_T.resize(3, vertices.cols() + static_cast<Eigen::Index>(grid.size()));
  e.tool_points_T.leftCols(vertices.cols()) = vertices;
  for (size_t i = 0; i < grid.size(); ++i) e.tool_points_T.col(vertices.cols() + static_cast<Eigen::Index>(i)) = grid[i];
  std::vector<Eigen::Index> near;
  for (Eigen::Index i = 0; i < e.tool_points_T.cols(); ++i) {
    if ((e.tool_points_T.col(i) - e.center_T).norm() <= region) near.push_back(i);
  }
  e.points_T.resize(3, static_cast<Eigen::Index>(near.size()));
  for (size_t i = 0; i < near.size(); ++i) e.points_T.col(static_cast<Eigen::Index>(i)) = e.tool_points_T.col(near[i]);
  return e;
}

Eigen::Isometry3d HandleFrame(const toollib::Segment& handle) {
  Eigen::Isometry3d X_TH = Eigen::Isometry3d::Identity();
  X_TH.linear() =
      Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitZ(), handle.axis.normalized()).toRotationMatrix();
  X_TH.translation() = handle.center;
  return X_TH;
}

}  // namespace toolbench::app

namespace toolbench::app {

TablePutDown PutDownOnTable(RobotInterface& robot, const robot::RobotDescription& desc, const sim::SceneSpec& spec,
                            const Eigen::Isometry3d& X_PT, const toollib::ToolModel& model,
                            const std::vector<Eigen::Vector3d>& ball_R, const control::PutDownOptions& base) {
  if (ball_R.empty()) ThrowInvalid("PutDownOnTable: no ball position given");
  for (const Eigen::Vector3d& p : ball_R) {
    if (!p.allFinite()) ThrowInvalid("PutDownOnTable: ball position (", p.transpose(), ") is not finite");
  }
  const Eigen::Vector2d ball_xy = ball_R.front().head<2>();
  // The fixed places: from 10 cm in from the table's sides to half-way to the middle, on the
  // right hand's side first (the other side was out of reach in 7 of 16 random episodes), at
  // least 20 cm from the ball; a place that does not plan has not moved the arm. (With the four
  // places at the sides only, none was reachable in 3 of 50 episodes, and the robot then went
  // for the ball with the tool still in its hand.)
  const double x_near = spec.table.center.x() + spec.table.size.x() / 2 - 0.12;
  const double y_side = spec.table.size.y() / 2 - 0.1;
  std::vector<Eigen::Vector3d> places;
  for (const double side : {1.0, -1.0}) {
    for (const double y_fraction : {1.0, 0.5}) {
      for (const double x : {x_near, spec.table.center.x()}) {
        const Eigen::Vector3d p(x, spec.table.center.y() + side * y_fraction * y_side, spec.table.top_z);
        if ((p.head<2>() - ball_xy).norm() >= 0.2) places.push_back(p);
      }
    }
  }
  // Then a 5 x 5 grid over the table, 8 cm in from its edges, at least 15 cm from the ball
  // (with the places above alone, none planned in 7 of 50 random episodes).
  const Eigen::Vector2d inner = spec.table.size / 2 - Eigen::Vector2d::Constant(0.08);
  for (int i = 0; i < 5; ++i) {
    for (int j = 0; j < 5; ++j) {
      const Eigen::Vector2d xy =
          spec.table.center + Eigen::Vector2d((i / 2.0 - 1.0) * inner.x(), (j / 2.0 - 1.0) * inner.y());
      if ((xy - ball_xy).norm() >= 0.15) places.emplace_back(xy.x(), xy.y(), spec.table.top_z);
    }
  }
  control::PutDownOptions options = base;
  options.tool_points_T = model.mesh.vertices.cast<double>();
  options.keep_out_R = ball_R;
  const Eigen::AlignedBox2d table = TableTopArea(spec);
  options.support_xy = Eigen::AlignedBox2d(table.min() + Eigen::Vector2d::Constant(0.05),
                                           table.max() - Eigen::Vector2d::Constant(0.05));
  TablePutDown out;
  out.put.reason = "no free place on the table 15 cm from the ball";
  // The tool's main axis laid level first, then (when no place plans so: a handle held steeply
  // across the grasp axis may need a palm orientation out of reach) the hand's grasp axis.
  struct Pass {
    bool clear_of_ball;
    bool level_tool_axis;
  };
  for (const Pass pass : {Pass{true, true}, Pass{true, false}, Pass{false, false}}) {
    if (out.put.placed) break;
    out.clear_of_ball = pass.clear_of_ball;
    if (!pass.clear_of_ball) options.tool_points_T.resize(3, 0);
    options.tool_axis_T = pass.level_tool_axis ? Eigen::Vector3d(model.handle.axis) : Eigen::Vector3d::Zero();
    out.tool_axis_level = pass.level_tool_axis;
    for (const Eigen::Vector3d& place : places) {
      ++out.places_tried;
      out.put = control::PutDown(robot, desc, X_PT, place, model.handle.radius, options);
      if (out.put.placed) break;
    }
  }
  // Clear the hand of the table: straight up to 15 cm above it, then (as far as IK goes) across
  // to above where the observation posture puts the hand, beside the table. A look may then
  // leave the arm up there: the joint-space move down into the observation posture swept the
  // hand onto the table top, where it stayed pressed (r_elbow 1.4 rad short, in every episode),
  // and knocked the ball aside.
  const double z_clear = spec.table.top_z + 0.15;
  const Eigen::Vector3d p_palm = PalmPoseFromEncoders(desc, robot).translation();
  const Eigen::VectorXd q = ModelQ(desc, robot.JointNames(), robot.ReadEncoders());
  const Eigen::Vector3d p_observe = robot::LinkPose(desc.model, ObservePosture(desc, q), desc.palm_frame).translation();
  const control::PalmPathResult clear = control::MovePalmThrough(
      robot, desc,
      {{p_palm.x(), p_palm.y(), std::max(p_palm.z(), z_clear)},
       {p_observe.x(), p_observe.y(), std::max(p_observe.z(), z_clear)}});
  out.clear_reason = clear.reason;
  out.hand_cleared = PalmPoseFromEncoders(desc, robot).translation().z() >= z_clear - 0.03;
  return out;
}

}  // namespace toolbench::app
