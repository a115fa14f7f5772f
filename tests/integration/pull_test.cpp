// Pull, ball grasp and hand-over skills: bad input gives clear errors, an out-of-reach pull moves
// nothing, and the hand-over fallback holds a tool put into the open hand (issue 4).
#include <cmath>
#include <limits>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "app/bench_pull.h"
#include "app/scene_setup.h"
#include "common/rng.h"
#include "control/ik.h"
#include "control/kinematics.h"
#include "control/motion.h"
#include "control/skills.h"
#include "sim/world.h"

namespace toolbench::app {
namespace {

using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

// The scene with stick_2 on the rack, settled, and the robot in it.
struct SettledScene {
  explicit SettledScene(const char* label)
      : scene(LoadScene(StickRequest())), world(scene.composed.mjcf, label), robot(Settled(world, scene)) {}
  static SceneRequest StickRequest() {
    SceneRequest request;
    request.tools = {"stick_2"};
    return request;
  }
  static sim::World& Settled(sim::World& world, const LoadedScene& scene) {
    world.SettleFreeBodies(scene.spec.physics.settle_time);
    return world;
  }
  // The ball's centre in R (ground truth).
  Eigen::Vector3d BallR() {
    return scene.composed.X_WR.inverse() * world.ground_truth().Pose(scene.composed.ball_body).translation();
  }
  // Puts the ball on the table at (x, y) in R, lets it settle 0.3 s and returns where it rests.
  Eigen::Vector3d PutBallAt(double x, double y) {
    Eigen::Isometry3d X_RB = Eigen::Isometry3d::Identity();
    X_RB.translation() = Eigen::Vector3d(x, y, BallR().z());
    world.TeleportFreeBody(scene.composed.ball_body, scene.composed.X_WR * X_RB);
    robot.Wait(0.3);
    return BallR();
  }
  LoadedScene scene;
  sim::World world;
  sim::SimRobot robot;
};

TEST(PullTest, RejectsBadInput) {
  SceneRequest request;
  request.tools = {"stick_2"};
  const LoadedScene scene = LoadScene(request);
  sim::World world(scene.composed.mjcf, "pull bad input");
  sim::SimRobot robot(world);
  control::ToolEffector effector;
  effector.center_T = Eigen::Vector3d(0, 0, 0.3);
  const Eigen::Isometry3d X_PT = Eigen::Isometry3d::Identity();
  const Eigen::Vector3d nan_target(std::nan(""), 0.0, 0.0);
  EXPECT_THAT([&] { control::PullObject(robot, scene.robot, X_PT, effector, nan_target, 0.035); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("p_RO")));
  const control::ToolEffector no_effector;  // centre NaN: a tool without effector information
  EXPECT_THAT(
      [&] { control::PullObject(robot, scene.robot, X_PT, no_effector, Eigen::Vector3d(-0.5, 0, 0), 0.035); },
      ThrowsMessage<std::invalid_argument>(HasSubstr("no effector information")));
  EXPECT_THAT([&] { control::PullObject(robot, scene.robot, X_PT, effector, Eigen::Vector3d(-0.5, 0, 0), 0.0); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("object_radius")));
  control::PullOptions bad;
  bad.drag_waypoints = 1;
  EXPECT_THAT(
      [&] { control::PullObject(robot, scene.robot, X_PT, effector, Eigen::Vector3d(-0.5, 0, 0), 0.035, bad); },
      ThrowsMessage<std::invalid_argument>(HasSubstr("drag_waypoints")));
  EXPECT_THAT([&] { control::GraspBall(robot, scene.robot, nan_target, 0.035); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("p_RB")));
  EXPECT_THAT([&] { control::HandOver(robot, scene.robot, Eigen::Vector3d(-0.2, 0.5, 0), {}); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("place")));
  EXPECT_THAT([&] { world.TeleportFreeBody("rack", Eigen::Isometry3d::Identity()); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("no free joint")));
  // Out of reach: 2 m away, and nothing moves.
  const Eigen::VectorXd before = robot.PositionTargets();
  const control::PullResult far =
      control::PullObject(robot, scene.robot, X_PT, effector, Eigen::Vector3d(-2.0, 0.0, 0.0), 0.035);
  EXPECT_EQ(far.status, control::PullStatus::kUnreachable);
  EXPECT_EQ(robot.PositionTargets(), before);
}

constexpr double kMinPullM = 0.05;  // issue 4: the ball comes > 5 cm toward the robot

// A tool grasped from its ground-truth handle on the rack reaches behind the ball, which starts
// out of the arm's reach, and drags it toward the robot into reach (pull-gt's case for this tool
// and seed). The tool pivots in the grip as it leaves the rack (rake_4 by less than 10 deg,
// hook_1 by about 45 deg: pull-gt's lift_pivot_deg), so the robot looks at it in the hand and
// plans with the pose it sees (without the look, hook_1 missed the ball).
class PullFromRackTest : public ::testing::TestWithParam<const char*> {};

TEST_P(PullFromRackTest, ToolFromItsGroundTruthHandlePullsTheBallIntoReach) {
  const char* tool = GetParam();
  SceneRequest request;
  request.tools = {tool};
  const LoadedScene scene = LoadScene(request);
  PullCaseOptions options;
  options.put_down_and_grasp_ball = false;
  const PullCaseResult r = RunPullCase(scene, tool, DeriveSeed(request.seed, std::string("pull/") + tool), options);
  EXPECT_FALSE(r.ball_in_reach_before) << "the ball must start out of reach";
  ASSERT_TRUE(r.grasped) << r.reason;
  EXPECT_TRUE(r.inspected) << r.inspect_reason;
  EXPECT_LT(r.used_pose_error_deg, 2.0) << "the in-hand pose seen by the camera vs the truth";
  EXPECT_LT(r.used_effector_error_m, 0.01);
  EXPECT_NE(r.pull.status, control::PullStatus::kUnreachable) << r.pull.reason;
  EXPECT_GT(r.displacement_m, kMinPullM);
  EXPECT_TRUE(r.ball_in_reach) << r.reason;
  EXPECT_EQ(r.pull.status, control::PullStatus::kPulled) << r.pull.reason;
  EXPECT_LT(r.ball_moved_before_drag_m, 0.02) << "the transfer must not touch the ball";
  // The servos sag under the tool; the offsets measured above the start put the palm on the plan.
  EXPECT_GT(r.pull.sag_offset_rad, 0.0);
  EXPECT_LT(r.pull.start_palm_error_m, 0.004);
}

INSTANTIATE_TEST_SUITE_P(RakeAndHook, PullFromRackTest, ::testing::Values("rake_4", "hook_1"));

// The ball in reach, the open hand low on the table beside it (where a put-down leaves it): the
// hand rises and crosses above the ball before coming down on it, and lifts it. A direct
// joint-space move from such a posture swept the hand through the ball and knocked it off the
// table in 5 of 50 random episodes (session 6).
TEST(BallGraspTest, HandLowBesideTheBallCrossesAboveItAndLiftsIt) {
  SettledScene settled("ball grasp");
  const LoadedScene& scene = settled.scene;
  sim::SimRobot& robot = settled.robot;
  auto ball_R = [&] { return settled.BallR(); };
  const double radius = scene.spec.ball.radius;
  const Eigen::Vector3d p_RB = settled.PutBallAt(-0.45, 0.03);
  ASSERT_TRUE(control::BallInReach(scene.robot, scene.robot.HomeQ(), p_RB, radius));

  // The open hand palm-down 4 cm above the table, 15 cm to the right of the ball and 3 cm nearer.
  const control::KinematicChain chain = control::MakeRightArmChain(scene.robot.model, scene.robot.palm_frame);
  control::CartesianSolver solver(chain, scene.robot.HomeQ());
  const Eigen::Vector3d p_low(p_RB.x() + 0.03, p_RB.y() - 0.15, p_RB.z() - radius + 0.04);
  control::IkResult low;
  for (int k = 0; k < 12 && low.status != control::IkStatus::kConverged; ++k) {
    Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
    X.linear() = (Eigen::AngleAxisd(k * M_PI / 6, Eigen::Vector3d::UnitZ()) *
                  Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()))
                     .toRotationMatrix();
    X.translation() = p_low;
    low = solver.Solve(X, scene.robot.HomeQ());
  }
  ASSERT_EQ(low.status, control::IkStatus::kConverged);
  std::map<std::string, double> goal;
  for (int i = 0; i < chain.num_joints(); ++i) goal[chain.joint_names()[i]] = low.q[chain.q_indices()[i]];
  for (const auto& [joint, value] : scene.robot.hand_open) goal[joint] = value;
  control::MoveJoints(robot, goal, {3.0, 0.01, 0.02, 0.05, 1.0});
  ASSERT_LT((ball_R() - p_RB).norm(), 0.01) << "setting up moved the ball";

  control::BallGraspOptions options;
  options.obstacles = WorkspaceObstacles(scene.spec);  // as in an episode
  Eigen::Vector3d at_pre_grasp = Eigen::Vector3d::Constant(std::nan(""));
  options.on_stage = [&](const char* stage) {
    if (std::string(stage) == "pre_grasp") at_pre_grasp = ball_R();
  };
  const double z0 = ball_R().z();
  const control::GraspResult g = control::GraspBall(robot, scene.robot, p_RB, radius, options);
  ASSERT_EQ(g.status, control::GraspStatus::kGrasped) << g.reason;
  EXPECT_LT((at_pre_grasp - p_RB).norm(), 0.01) << "the way to the pre-grasp touched the ball";
  EXPECT_GT(ball_R().z() - z0, 0.03) << "the ball is lifted";
}

// A fixture between the hand and the ball (a wall, known to the planner only) that every
// crossing would pass through: the grasp fails in planning, naming it, and nothing moves.
TEST(BallGraspTest, ACrossingThroughAFixtureIsNotTaken) {
  SettledScene settled("ball grasp wall");
  const LoadedScene& scene = settled.scene;
  sim::SimRobot& robot = settled.robot;
  const double radius = scene.spec.ball.radius;
  const Eigen::Vector3d p_RB = settled.PutBallAt(-0.45, 0.03);
  const Eigen::VectorXd before = robot.ReadEncoders();
  // From the home posture (hand beside the hip, right of the ball) every way to the ball crosses
  // a wall 10 cm to the ball's right, from the floor to 1 m above the table, 1 m long.
  control::ObstacleBox wall;
  wall.name = "wall";
  wall.X_RB = Eigen::Isometry3d::Identity();
  wall.X_RB.translation() = Eigen::Vector3d(p_RB.x(), p_RB.y() + 0.10, p_RB.z());
  wall.half = Eigen::Vector3d(0.5, 0.005, 1.0);
  control::BallGraspOptions options;
  options.obstacles = {wall};
  const control::GraspResult g = control::GraspBall(robot, scene.robot, p_RB, radius, options);
  EXPECT_EQ(g.status, control::GraspStatus::kIkFailed) << g.reason;
  EXPECT_GT(g.paths_blocked, 0);
  EXPECT_THAT(g.reason, HasSubstr("wall"));
  EXPECT_LT((robot.ReadEncoders() - before).cwiseAbs().maxCoeff(), 0.02) << "nothing moves";
  options.obstacle_margin_m = -0.01;
  EXPECT_THAT([&] { control::GraspBall(robot, scene.robot, p_RB, radius, options); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("obstacle_margin_m")));
}

// The edge of the arm's reach along a line out from the robot: a ball 1 cm inside it is in reach
// but not 3 cm within it (the episode pulls such a ball again: at the edge no crossing keeps the
// hand above it); 6 cm inside, it is.
TEST(BallGraspTest, ABallAtTheEdgeOfReachIsInReachButNotWithinAMargin) {
  SceneRequest request;
  const LoadedScene scene = LoadScene(request);
  const robot::RobotDescription& desc = scene.robot;
  const double radius = scene.spec.ball.radius;
  const double z = scene.spec.table.top_z + radius;
  const Eigen::Vector3d out = Eigen::Vector3d(-1.0, -0.1, 0.0).normalized();  // forward, a little left
  auto at = [&](double r) { return Eigen::Vector3d(r * out.x(), r * out.y(), z); };
  double inside = 0.40, outside = 0.70;  // distance from the robot's axis [m]
  ASSERT_TRUE(control::BallInReach(desc, desc.HomeQ(), at(inside), radius));
  ASSERT_FALSE(control::BallInReach(desc, desc.HomeQ(), at(outside), radius));
  while (outside - inside > 0.002) {
    const double mid = 0.5 * (inside + outside);
    (control::BallInReach(desc, desc.HomeQ(), at(mid), radius) ? inside : outside) = mid;
  }
  EXPECT_TRUE(control::BallInReach(desc, desc.HomeQ(), at(inside - 0.01), radius));
  EXPECT_FALSE(control::BallWithinReach(desc, desc.HomeQ(), at(inside - 0.01), radius, 0.03));
  EXPECT_TRUE(control::BallWithinReach(desc, desc.HomeQ(), at(inside - 0.06), radius, 0.03));
  EXPECT_EQ(control::BallWithinReach(desc, desc.HomeQ(), at(inside - 0.01), radius, 0.0),
            control::BallInReach(desc, desc.HomeQ(), at(inside - 0.01), radius));
  EXPECT_THAT([&] { control::BallWithinReach(desc, desc.HomeQ(), at(0.5), radius, -0.01); },
              ::testing::ThrowsMessage<std::invalid_argument>(::testing::HasSubstr("margin_m")));
}

// BallInReach runs Ipopt's rescue only for palm poses the pre-solve nearly reached
// (reach_rescue_max_error_m): over the table it answers as the rescue of every pose does.
TEST(BallGraspTest, ReachWithRescueOfNearMissesOnlyAgreesWithRescueOfEveryPose) {
  SceneRequest request;
  const LoadedScene scene = LoadScene(request);
  const robot::RobotDescription& desc = scene.robot;
  const sim::TableSpec& table = scene.spec.table;
  const double radius = scene.spec.ball.radius;
  control::BallGraspOptions every;
  every.reach_rescue_max_error_m = std::numeric_limits<double>::infinity();
  int in_reach = 0, out_of_reach = 0;
  for (int i = 0; i < 6; ++i) {
    for (int j = 0; j < 5; ++j) {
      const Eigen::Vector3d p_RB(table.center.x() + table.size.x() * (i / 5.0 - 0.5),
                                 table.center.y() + table.size.y() * (j / 4.0 - 0.5), table.top_z + radius);
      const bool reach = control::BallInReach(desc, desc.HomeQ(), p_RB, radius);
      EXPECT_EQ(reach, control::BallInReach(desc, desc.HomeQ(), p_RB, radius, every)) << "ball at " << p_RB.transpose();
      ++(reach ? in_reach : out_of_reach);
    }
  }
  EXPECT_GT(in_reach, 3);
  EXPECT_GT(out_of_reach, 3);
  control::BallGraspOptions bad;
  bad.reach_rescue_max_error_m = -1;
  EXPECT_THAT([&] { control::BallInReach(desc, desc.HomeQ(), Eigen::Vector3d(-0.4, 0, 0), radius, bad); },
              ::testing::ThrowsMessage<std::invalid_argument>(::testing::HasSubstr("reach_rescue_max_error_m")));
}

TEST(HandOverTest, ToolPlacedInTheOpenHandIsHeldAndFlaggedAssisted) {
  SettledScene settled("hand-over");
  const LoadedScene& scene = settled.scene;
  sim::World& world = settled.world;
  sim::SimRobot& robot = settled.robot;
  const std::string body = scene.composed.tools.front().body;
  const toollib::ToolModel* model = nullptr;
  for (const auto& t : scene.library) {
    if (t.name == "stick_2") model = &t;
  }
  ASSERT_NE(model, nullptr);
  const Eigen::Isometry3d X_RW = scene.composed.X_WR.inverse();
  const Eigen::Vector3d p_R_tool = X_RW * world.ground_truth().Pose(body).translation();
  int placed = 0;
  // The human: the handle centre onto the hand's grasp cylinder, handle along its axis (the one
  // permitted teleport, counted here as the bench records it).
  Eigen::Isometry3d X_RP_first = Eigen::Isometry3d::Identity();
  bool same_pose = true;
  const auto place = [&](const Eigen::Isometry3d& X_RP) {
    if (placed++ == 0) X_RP_first = X_RP;
    same_pose = same_pose && X_RP.isApprox(X_RP_first);
    Eigen::Isometry3d X_PH = Eigen::Isometry3d::Identity();
    X_PH.linear() = Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitZ(), scene.robot.grasp.axis.normalized())
                        .toRotationMatrix();
    X_PH.translation() = scene.robot.grasp.center;
    Eigen::Isometry3d X_TH = Eigen::Isometry3d::Identity();
    X_TH.translation() = model->handle.center;
    world.TeleportFreeBody(body, scene.composed.X_WR * X_RP * X_PH * X_TH.inverse());
  };
  const control::HandOverResult r = control::HandOver(robot, scene.robot, p_R_tool, place);
  // The person holds the tool where they put it while the fingers close, then lets go.
  EXPECT_GT(placed, 10);
  EXPECT_TRUE(same_pose) << "the person holds the tool still: one palm pose";
  EXPECT_TRUE(r.assisted);
  ASSERT_TRUE(r.holding) << r.reason;
  robot.Wait(1.0);
  // Still in the hand: the handle centre stays near the grasp cylinder's centre, and the handle
  // along its axis (left loose on the palm while the fingers closed, tools turned 30-57 deg).
  const Eigen::Isometry3d X_PT = world.ground_truth().Pose(scene.robot.palm_frame).inverse() * world.ground_truth().Pose(body);
  const Eigen::Vector3d p_P_handle = X_PT * model->handle.center;
  EXPECT_LT((p_P_handle - scene.robot.grasp.center).norm(), 0.05) << p_P_handle.transpose();
  const double turned_deg =
      std::acos(std::min(1.0, std::abs(X_PT.linear().col(2).dot(scene.robot.grasp.axis.normalized())))) * 180 / M_PI;
  EXPECT_LT(turned_deg, 10.0) << "the handle turned in the grip";
}

// The open hand can wait elsewhere than toward the tool (clear of the rack); a half-given
// receiving point is named.
TEST(HandOverTest, HandWaitsWhereAskedAndRejectsAPartialPoint) {
  SettledScene settled("hand-over elsewhere");
  const LoadedScene& scene = settled.scene;
  sim::SimRobot& robot = settled.robot;
  control::HandOverOptions options;
  options.receive_at_R = Eigen::Vector3d(-0.25, 0.17, 0.20);
  Eigen::Isometry3d X_RP_seen = Eigen::Isometry3d::Identity();
  const control::HandOverResult r = control::HandOver(
      robot, scene.robot, Eigen::Vector3d(-0.2, 0.5, 0.0), [&](const Eigen::Isometry3d& X_RP) { X_RP_seen = X_RP; },
      options);
  EXPECT_LT((X_RP_seen.translation() - options.receive_at_R).norm(), 0.03) << X_RP_seen.translation().transpose();
  EXPECT_FALSE(r.holding) << "nothing was put in the hand";
  options.receive_at_R.y() = std::nan("");
  EXPECT_THAT([&] { control::HandOver(robot, scene.robot, Eigen::Vector3d(-0.2, 0.5, 0.0), [](auto&) {}, options); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("receive_at_R")));
}

TEST(PalmPathTest, RaisesThePalmAndStopsAtAPointOutOfReach) {
  SettledScene settled("palm path");
  const LoadedScene& scene = settled.scene;
  sim::SimRobot& robot = settled.robot;
  EXPECT_THAT([&] { control::MovePalmThrough(robot, scene.robot, {Eigen::Vector3d(std::nan(""), 0, 0)}); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("points_R[0]")));
  const Eigen::Vector3d p0 = PalmPoseFromEncoders(scene.robot, robot).translation();
  const Eigen::Vector3d up = p0 + Eigen::Vector3d(0.0, 0.0, 0.1);
  const Eigen::Vector3d far = up + Eigen::Vector3d(-2.0, 0.0, 0.0);  // 2 m in front: out of reach
  const control::PalmPathResult r = control::MovePalmThrough(robot, scene.robot, {p0, up, far});
  EXPECT_FALSE(r.complete);
  EXPECT_EQ(r.points_reached, 2) << r.reason;
  EXPECT_THAT(r.reason, HasSubstr("stopped after waypoint"));
  robot.Wait(0.5);
  const Eigen::Vector3d p1 = PalmPoseFromEncoders(scene.robot, robot).translation();
  // The path stops short of the unreachable point: the palm is up, somewhere between.
  EXPECT_GT(p1.z() - p0.z(), 0.08);
  EXPECT_LT((p1 - far).norm(), (up - far).norm() + 0.01);
}

// A 40 cm rod's points in T, along z_T through its origin: held with X_PT = PalmGraspFrame, it
// runs through the palm's grasp centre along the grasp axis.
Eigen::Matrix3Xd RodPoints() {
  Eigen::Matrix3Xd points(3, 41);
  for (int i = 0; i <= 40; ++i) points.col(i) = Eigen::Vector3d(0, 0, -0.2 + 0.01 * i);
  return points;
}

TEST(PutDownTest, RejectsEveryYawThatLaysTheToolOverTheBallOrOffTheTable) {
  SettledScene settled("put-down checks");
  const LoadedScene& scene = settled.scene;
  sim::SimRobot& robot = settled.robot;
  const Eigen::VectorXd q0 = robot.ReadEncoders();
  const Eigen::Isometry3d X_PT = PalmGraspFrame(scene.robot);
  control::PutDownOptions options;
  options.tool_points_T = RodPoints();
  const Eigen::Vector3d place(-0.3, 0.05, scene.spec.table.top_z);
  options.keep_out_R = {place + Eigen::Vector3d(0.0, 0.0, 0.05)};  // under the grasp centre itself
  control::PutDownResult r = control::PutDown(robot, scene.robot, X_PT, place, 0.01, options);
  EXPECT_FALSE(r.placed);
  EXPECT_EQ(r.poses_sampled, 48);  // 12 yaws x 4 rolls about the handle
  EXPECT_EQ(r.yaws_kept_out, 48);
  EXPECT_THAT(r.reason, HasSubstr("48 too near a keep-out centre"));
  options.keep_out_R.clear();
  options.support_xy = Eigen::AlignedBox2d(Eigen::Vector2d(1.0, 1.0), Eigen::Vector2d(1.1, 1.1));  // elsewhere
  r = control::PutDown(robot, scene.robot, X_PT, place, 0.01, options);
  EXPECT_FALSE(r.placed);
  EXPECT_EQ(r.yaws_off_surface, 48);
  EXPECT_LT((robot.ReadEncoders() - q0).cwiseAbs().maxCoeff(), 1e-6) << "a rejected put-down moved the robot";
  options.tool_points_T.col(0).x() = std::nan("");
  EXPECT_THAT([&] { control::PutDown(robot, scene.robot, X_PT, place, 0.01, options); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("tool_points_T")));
}

TEST(PutDownTest, RejectsAWayThereThatSweepsTheToolThroughTheBall) {
  SettledScene settled("put-down path check");
  const LoadedScene& scene = settled.scene;
  sim::SimRobot& robot = settled.robot;
  const Eigen::VectorXd q0 = robot.ReadEncoders();
  const Eigen::Isometry3d X_PT = PalmGraspFrame(scene.robot);
  control::PutDownOptions options;
  options.tool_points_T = RodPoints();
  const Eigen::Vector3d place(-0.4, -0.15, scene.spec.table.top_z);
  // The keep-out centre where the held rod is now, far from the place: the tool lies clear of it
  // at the place for some yaws, but every way there starts through it.
  const Eigen::Vector3d rod_now = (PalmPoseFromEncoders(scene.robot, robot) * X_PT).translation();
  ASSERT_GT((rod_now.head<2>() - place.head<2>()).norm(), 0.3) << rod_now.transpose();
  options.keep_out_R = {rod_now};
  const control::PutDownResult r = control::PutDown(robot, scene.robot, X_PT, place, 0.01, options);
  EXPECT_FALSE(r.placed);
  EXPECT_GT(r.paths_kept_out, 0);
  EXPECT_LT(r.yaws_kept_out, r.poses_sampled);
  EXPECT_THAT(r.reason, HasSubstr("with a way there that passes one"));
  EXPECT_LT((robot.ReadEncoders() - q0).cwiseAbs().maxCoeff(), 1e-6) << "a rejected put-down moved the robot";
  // Without the keep-out centre the same put-down places the rod.
  options.keep_out_R.clear();
  EXPECT_TRUE(control::PutDown(robot, scene.robot, X_PT, place, 0.01, options).placed);
}

// A handle held across the hand's grasp axis (tools turn in the grip): with the tool's axis given,
// that axis, not the grasp axis, is laid level, and the tool's lowest point ends release_height_m
// above the table; a non-finite axis is named.
TEST(PutDownTest, LaysTheToolsOwnAxisLevelWhenItIsHeldAskew) {
  SettledScene settled("put-down level axis");
  const LoadedScene& scene = settled.scene;
  sim::SimRobot& robot = settled.robot;
  const Eigen::Isometry3d X_PT = PalmGraspFrame(scene.robot) * Eigen::AngleAxisd(20.0 * M_PI / 180, Eigen::Vector3d::UnitX());
  const Eigen::Vector3d axis_P = X_PT.linear().col(2);
  ASSERT_NEAR(std::acos(axis_P.dot(scene.robot.grasp.axis.normalized())) * 180 / M_PI, 20.0, 0.5);
  control::PutDownOptions options;
  options.tool_points_T = RodPoints();
  options.tool_axis_T = Eigen::Vector3d::UnitZ();
  const Eigen::Vector3d place(-0.3, 0.05, scene.spec.table.top_z);
  const control::PutDownResult r = control::PutDown(robot, scene.robot, X_PT, place, 0.01, options);
  ASSERT_TRUE(r.placed) << r.reason;
  const Eigen::Isometry3d X_RT = r.X_RP * X_PT;
  EXPECT_LT(std::abs(X_RT.linear().col(2).z()), std::sin(0.5 * M_PI / 180)) << "the rod is not level";
  const Eigen::Matrix3Xd points = X_RT * options.tool_points_T;
  EXPECT_NEAR(points.row(2).minCoeff(), place.z() + options.release_height_m, 1e-3);
  options.tool_axis_T.y() = std::nan("");
  EXPECT_THAT([&] { control::PutDown(robot, scene.robot, X_PT, place, 0.01, options); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("tool_axis_T")));
}

// When the open hand's straight rise cannot be planned (here: no joint may move at all between
// waypoints), the hand goes back up the way it came down, to 10 cm above where it opened, rather
// than staying beside the tool it let go of.
TEST(PutDownTest, RetracesTheDescentWhenTheRiseCannotBePlanned) {
  auto put_down = [](const control::PutDownOptions& options) {
    SettledScene settled("put-down rise");
    const LoadedScene& scene = settled.scene;
    const Eigen::Vector3d place(-0.3, 0.05, scene.spec.table.top_z);
    const control::PutDownResult r =
        control::PutDown(settled.robot, scene.robot, PalmGraspFrame(scene.robot), place, 0.01, options);
    const double rise = PalmPoseFromEncoders(scene.robot, settled.robot).translation().z() - r.X_RP.translation().z();
    return std::make_pair(r, rise);
  };
  control::PutDownOptions options;
  options.tool_points_T = RodPoints();
  const auto [straight, straight_rise] = put_down(options);
  ASSERT_TRUE(straight.placed) << straight.reason;
  EXPECT_FALSE(straight.rise_retraced) << straight.rise_reason;
  EXPECT_NEAR(straight_rise, options.retreat_up_m, 0.02);
  options.clear.max_joint_step_rad = 1e-9;
  const auto [retraced, retraced_rise] = put_down(options);
  ASSERT_TRUE(retraced.placed) << retraced.reason;
  EXPECT_TRUE(retraced.rise_retraced);
  EXPECT_THAT(retraced.rise_reason, HasSubstr("stopped after waypoint 0"));
  EXPECT_NEAR(retraced_rise, 0.10, 0.02);
}

}  // namespace
}  // namespace toolbench::app
