// The right hand grasps tools on the rack from their ground-truth handle pose, lifts them and
// holds them by contact forces alone (issue 4, item 5).
#include <algorithm>
#include <optional>
#include <string>
#include <string_view>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "app/bench_grasp.h"
#include "app/scene_setup.h"
#include "control/clearance.h"
#include "control/skills.h"

namespace toolbench::app {
namespace {

constexpr double kMinLiftM = 0.05;   // issue 4: tool >= 5 cm above its rest height
constexpr double kMaxSlipM = 0.005;  // issue 4: < 5 mm in the palm during the 2 s hold

// grasp-gt's success: the tool settled on the rack, was grasped, lifted >= kMinLiftM and held
// with < kMaxSlipM of slip, touching nothing but the hand.
void ExpectGraspedLiftedAndHeld(const GraspCaseResult& r) {
  ASSERT_TRUE(r.settled) << "the tool did not come to rest on the rack";
  ASSERT_EQ(r.grasp.status, control::GraspStatus::kGrasped) << r.grasp.reason;
  EXPECT_GE(r.lift_m, kMinLiftM);
  EXPECT_LT(r.slip_m, kMaxSlipM);
  EXPECT_THAT(r.foreign_contacts, ::testing::IsEmpty());
  EXPECT_TRUE(r.success) << r.reason;
}

// The library model named `name` in the scene's library, or nullptr.
const toollib::ToolModel* LibraryModel(const LoadedScene& scene, const std::string& name) {
  for (const auto& t : scene.library) {
    if (t.name == name) return &t;
  }
  return nullptr;
}

// grasp-gt's scene of `tool` alone in `cell`.
LoadedScene SceneOfOne(const std::string& tool, const std::string& cell) {
  SceneRequest request;
  request.tools = {tool};
  request.cells = {cell};
  return LoadScene(request);
}

// grasp-gt's case of `tool` alone in `cell`, grasped as the episode grasps it: after the look at
// the rack, whose torso turn leaves the hand hanging beside the hip.
GraspCaseResult GraspAfterTheRackLook(const std::string& tool, const std::string& cell) {
  SceneRequest request;
  request.tools = {tool};
  request.cells = {cell};
  const LoadedScene scene = LoadScene(request);
  GraspCaseOptions after_look;
  after_look.from_rack_look = true;
  return RunGraspCase(scene, tool, cell, request.seed, after_look);
}

// No robot body touches the rack at any of the grasp's `stages` ("staged", "at_grasp", ...).
void ExpectClearOfTheRackAt(const GraspCaseResult& r, std::initializer_list<std::string_view> stages) {
  for (const auto& h : r.handle_in_hand) {
    if (std::find(stages.begin(), stages.end(), h.stage) == stages.end()) continue;
    for (const std::string& c : h.contacts) EXPECT_EQ(c.find("-rack"), std::string::npos) << h.stage << ": " << c;
  }
}

// `scene`'s one tool settled on the rack and the robot after the look at the rack, as the episode
// grasps (the torso turn leaves the hand hanging beside the hip), with the tool's ground-truth
// pose in R.
struct AfterRackLook {
  AfterRackLook(const LoadedScene& scene, const std::string& name)
      : world(scene.composed.mjcf, name), body(scene.composed.tools.at(0).body), X_RW(scene.composed.X_WR.inverse()) {
    world.SettleFreeBodies(scene.spec.physics.settle_time);
    robot.emplace(world);
    LookAt(*robot, scene.robot, RackViewTarget(scene.spec));
    X_RT = X_RW * world.ground_truth().Pose(body);
  }
  // How far the tool has risen since then [m].
  double LiftM() const { return (X_RW * world.ground_truth().Pose(body)).translation().z() - X_RT.translation().z(); }
  sim::World world;
  std::string body;
  std::optional<sim::SimRobot> robot;
  Eigen::Isometry3d X_RW, X_RT;
};

class GraspTest : public ::testing::TestWithParam<const char*> {};

TEST_P(GraspTest, GraspsLiftsAndHoldsFromGroundTruthHandle) {
  SceneRequest request;
  request.tools = {GetParam()};
  request.cells = {"pos2"};
  const LoadedScene scene = LoadScene(request);
  const GraspCaseResult r = RunGraspCase(scene, GetParam(), "pos2", request.seed);
  ExpectGraspedLiftedAndHeld(r);
}

INSTANTIATE_TEST_SUITE_P(StickAndHoe, GraspTest, ::testing::Values("stick_2", "hoe_2"));

// A tool lying across the rack (cell rot3) catches the board's rail when lifted straight up; the
// lift goes up and back toward the robot (failed with "foreign_contact: rack" before).
TEST(GraspHandle, GraspsAndLiftsAToolLyingAcrossTheRack) {
  SceneRequest request;
  request.tools = {"lstick_2"};
  request.cells = {"rot3"};
  const LoadedScene scene = LoadScene(request);
  const GraspCaseResult r = RunGraspCase(scene, "lstick_2", "rot3", request.seed);
  ExpectGraspedLiftedAndHeld(r);
}

// hook_3 at the rack's end beside the robot (pos1): the joint-space swing from the arm's rest (hand
// hanging beside the hip) to the grasp's staging pose passes through the rack's ledge, where it
// juts out toward the robot (in random episodes such swings left the open hand stuck on the ledge,
// 6 of 50 in session 9). Given the workspace's fixture boxes, the grasp reroutes the swing over
// the ledge: nothing of the robot touches the rack when it arrives, and it grasps and lifts.
TEST(GraspHandle, RoutesTheTransferOverTheRacksLedge) {
  SceneRequest request;
  request.tools = {"hook_3"};
  request.cells = {"pos1"};
  const LoadedScene scene = LoadScene(request);
  const sim::PlacedTool& placed = scene.composed.tools.at(0);
  const toollib::ToolModel* model = LibraryModel(scene, placed.name);
  ASSERT_NE(model, nullptr);
  const std::vector<control::ObstacleBox> obstacles = WorkspaceObstacles(scene.spec);
  const control::ArmClearance clearance(scene.robot, obstacles, scene.robot.hand_open, 0.0);
  struct Run {
    control::GraspResult grasp;
    Eigen::VectorXd q_start, q_staged;
    std::vector<std::string> rack_contacts;  // robot bodies touching the rack at the staging pose
  };
  auto grasp = [&](bool with_obstacles) {
    Run run;
    sim::World world(scene.composed.mjcf, "reroute test");
    world.SettleFreeBodies(scene.spec.physics.settle_time);
    sim::SimRobot robot(world);
    const std::vector<std::string> names = robot.JointNames();
    run.q_start = ModelQ(scene.robot, names, robot.ReadEncoders());
    const Eigen::Isometry3d X_RW = scene.composed.X_WR.inverse();
    const Eigen::Isometry3d X_WT = world.ground_truth().Pose(placed.body);
    control::GraspOptions options;  // as grasp-gt grasps
    options.handle_slide = GripSlide(scene.robot, *model, model->handle);
    if (with_obstacles) options.obstacles = obstacles;
    options.on_stage = [&](const char* stage) {
      if (std::string_view(stage) != "staged") return;
      run.q_staged = ModelQ(scene.robot, names, robot.ReadEncoders());
      for (const std::string& body : world.ContactingBodies("rack")) {
        if (body.rfind("tool/", 0) != 0) run.rack_contacts.push_back(body);
      }
    };
    run.grasp = control::GraspHandle(robot, scene.robot, X_RW * X_WT * HandleFrame(model->handle), options);
    return run;
  };
  const Run direct = grasp(false);
  ASSERT_EQ(direct.q_staged.size(), direct.q_start.size()) << direct.grasp.reason;
  const auto hit = clearance.CheckLine(direct.q_start, direct.q_staged, 0.05);
  ASSERT_TRUE(hit.has_value()) << "the direct swing no longer meets the rack: pick another case";
  EXPECT_EQ(hit->obstacle.rfind("rack_", 0), 0u) << hit->obstacle;
  EXPECT_FALSE(direct.grasp.transfer_raised);

  const Run routed = grasp(true);
  EXPECT_TRUE(routed.grasp.transfer_raised);
  EXPECT_EQ(routed.grasp.paths_blocked, 0);
  EXPECT_THAT(routed.rack_contacts, ::testing::IsEmpty());
  EXPECT_EQ(routed.grasp.status, control::GraspStatus::kGrasped) << routed.grasp.reason;
}

// stick_2 at the rack's end beside the robot (pos1), grasped as the episode grasps it: after the
// look at the rack, whose torso turn leaves the hand hanging beside the hip below the top of the
// rack's ledge. Every palm-raising route to the clear grasp poses swept the fingers through the
// ledge's near end, and the grasp took a pose with the hand against the rack: the hand closed on
// nothing and the stick fell (so did 5 of the 96 pos1, rot1 and pos2 cells grasped from there,
// and 7 of the 13 failed tool grasps of random-50 seeds 1 and 2 followed such blocks). The arm
// bends up first, then swings out: the transfer clears the rack, the chosen pose keeps the hand
// clear of it, and the stick is grasped and lifted.
TEST(GraspHandle, BendsTheArmUpFirstWhenTheHandHangsBelowTheLedge) {
  const GraspCaseResult r = GraspAfterTheRackLook("stick_2", "pos1");
  EXPECT_TRUE(r.grasp.transfer_raised) << "the direct swing no longer meets the rack: pick another case";
  EXPECT_FALSE(r.grasp.hand_touches_fixture) << r.grasp.last_touching << "; " << r.grasp.paths_blocked
                                             << " paths blocked, the last: " << r.grasp.last_blocked;
  ExpectClearOfTheRackAt(r, {"staged", "at_grasp"});
  ExpectGraspedLiftedAndHeld(r);
}

// stick_1 lying across the rack (rot3), grasped as the episode grasps it, after the look at the
// rack. Every raised and joint-by-joint transfer to the palm poses at the handle's centre swept the
// hand through the rack's ledge, so the grasp slid 4 cm along the handle, off the stick's balance,
// and the stick slipped out in the lift (grasp-gt --from-rack-look, rot3: 13 of 32 grasped; others
// took poses that pressed the open hand 20-25 mm into the board, and the palm stopped 9-11 cm short
// of the handle). The transfer goes through the home posture instead, keeps clear of the rack, and
// the stick is grasped at its handle's centre, lifted and held.
TEST(GraspHandle, ReachesAToolLyingAcrossTheRackThroughTheHomePosture) {
  const GraspCaseResult r = GraspAfterTheRackLook("stick_1", "rot3");
  EXPECT_EQ(r.grasp.transfer_route, "home") << r.grasp.paths_blocked << " paths blocked, the last: "
                                             << r.grasp.last_blocked;
  EXPECT_NEAR(r.grasp.slide_m, 0.0, 1e-9);
  EXPECT_LT(r.grasp.hand_touch_depth_m, 0.02);
  ExpectClearOfTheRackAt(r, {"staged"});
  ExpectGraspedLiftedAndHeld(r);
}

// hook_2 upright at the rack's end beside the robot (pos1), grasped after the look at the rack.
// Its palm poses that keep the hand clear of the board are reached from home only over the palm
// raised there; from the hand beside the hip every route, the home posture alone included, swept
// the fingers through the ledge, and the grasp took a pose 17 mm into the board, from which the
// hook dropped out in the lift (so did hook_3 and spatula_3 at pos1: grasp-gt --from-rack-look
// pos1 29 of 32). The transfer goes home, then on over the raised palm: the hand stays clear of
// the rack, and the hook is grasped, lifted and held.
TEST(GraspHandle, GoesOnFromTheHomePostureAsFromHome) {
  const GraspCaseResult r = GraspAfterTheRackLook("hook_2", "pos1");
  EXPECT_EQ(r.grasp.transfer_route, "home")
      << r.grasp.paths_blocked << " paths blocked, the last: " << r.grasp.last_blocked;
  EXPECT_LT(r.grasp.hand_touch_depth_m, 0.005) << r.grasp.last_touching;
  ExpectClearOfTheRackAt(r, {"staged"});
  ExpectGraspedLiftedAndHeld(r);
}

// stick_2 at the rack's end beside the robot (pos1): the reachable palm pose of lowest rest cost
// puts the open hand's fingertips against the rack's board, which stops the palm 7 mm short of the
// handle and tilted, and the closing fingers flick the stick off the rack (9 of the 10 failures at
// pos1 in grasp-gt were such grasps). The grasp puts such poses last and takes one whose hand stays
// clear: it arrives touching nothing but the stick, and lifts and holds it.
TEST(GraspHandle, PrefersAGraspPoseWhoseHandStaysClearOfTheRack) {
  SceneRequest request;
  request.tools = {"stick_2"};
  request.cells = {"pos1"};
  const LoadedScene scene = LoadScene(request);
  auto arrival = [](const GraspCaseResult& r) {
    for (const auto& h : r.handle_in_hand) {
      if (h.stage == "at_grasp") return h;
    }
    return GraspCaseResult::HandleInHand{};
  };
  auto touches_rack = [](const GraspCaseResult::HandleInHand& h) {
    return std::any_of(h.contacts.begin(), h.contacts.end(),
                       [](const std::string& c) { return c.find("-rack") != std::string::npos; });
  };
  GraspCaseOptions rest_cost_only;
  rest_cost_only.grasp.prefer_clear_hand = false;
  const GraspCaseResult old_way = RunGraspCase(scene, "stick_2", "pos1", request.seed, rest_cost_only);
  ASSERT_EQ(arrival(old_way).stage, "at_grasp") << old_way.reason;
  ASSERT_TRUE(touches_rack(arrival(old_way))) << "the cheapest pose no longer touches the rack: pick another case";
  EXPECT_EQ(old_way.grasp.candidates_touching, 0);

  const GraspCaseResult r = RunGraspCase(scene, "stick_2", "pos1", request.seed);
  EXPECT_GT(r.grasp.candidates_touching, 0);
  EXPECT_FALSE(r.grasp.hand_touches_fixture);
  ASSERT_EQ(arrival(r).stage, "at_grasp") << r.reason;
  EXPECT_FALSE(touches_rack(arrival(r)));
  EXPECT_LT(arrival(r).palm_off_plan_m, 0.003);
  ExpectGraspedLiftedAndHeld(r);
}

// Grasp paths on which the hand would touch a neighbouring tool (GraspOptions::neighbours) come
// after every other path, and are never taken when neighbour contact is not allowed: the grasp
// then fails before anything moves, naming the neighbour. Here one box covers the whole
// workspace, so every path touches it.
TEST(GraspHandle, PlansGraspsTouchingANeighbourLastOrNotAtAll) {
  SceneRequest request;
  request.tools = {"stick_2"};
  request.cells = {"pos2"};
  const LoadedScene scene = LoadScene(request);
  GraspCaseOptions everywhere;
  everywhere.grasp.neighbours = {{"neighbour", Eigen::Isometry3d::Identity(), Eigen::Vector3d(2.0, 2.0, 2.0)}};
  GraspCaseOptions strict = everywhere;
  strict.grasp.neighbour_contact_allowed = false;

  const GraspCaseResult refused = RunGraspCase(scene, "stick_2", "pos2", request.seed, strict);
  EXPECT_EQ(refused.grasp.status, control::GraspStatus::kIkFailed);
  EXPECT_THAT(refused.grasp.reason, ::testing::HasSubstr("would touch a neighbouring tool"));
  EXPECT_THAT(refused.grasp.last_neighbour_touch, ::testing::HasSubstr(" m of neighbour"));
  EXPECT_GT(refused.grasp.candidates_touching_neighbour, 0);
  EXPECT_FALSE(refused.grasp.hand_touches_neighbour);
  EXPECT_THAT(refused.handle_in_hand, ::testing::IsEmpty()) << "the robot moved";

  const GraspCaseResult alone = RunGraspCase(scene, "stick_2", "pos2", request.seed);
  const GraspCaseResult touching = RunGraspCase(scene, "stick_2", "pos2", request.seed, everywhere);
  EXPECT_EQ(alone.grasp.candidates_touching_neighbour, 0);
  EXPECT_FALSE(alone.grasp.hand_touches_neighbour);
  EXPECT_TRUE(touching.grasp.hand_touches_neighbour);
  EXPECT_EQ(touching.grasp.candidates_touching_neighbour, refused.grasp.candidates_touching_neighbour);
  // The same pose as without the neighbour: among the touching paths the order is unchanged.
  EXPECT_TRUE(touching.grasp.X_RP_grasp.isApprox(alone.grasp.X_RP_grasp, 1e-9));
  ExpectGraspedLiftedAndHeld(touching);
}

// A caller may refuse the planned grasp before anything moves (GraspOptions::accept_plan: the
// episode refuses a grasp from which the action cannot be planned): GraspHandle then reports
// kRejected with the caller's reason and the arm has not moved; GraspToolForAction goes on to
// its next way of grasping the handle and grasps with the first one accepted.
TEST(GraspHandle, AsksTheCallerBeforeMovingAndGoesOnWhenRefused) {
  SceneRequest request;
  request.tools = {"stick_2"};
  request.cells = {"pos2"};
  const LoadedScene scene = LoadScene(request);
  const sim::PlacedTool& placed = scene.composed.tools.at(0);
  const toollib::ToolModel* model = LibraryModel(scene, placed.name);
  ASSERT_NE(model, nullptr);
  sim::World world(scene.composed.mjcf, "accept test");
  world.SettleFreeBodies(scene.spec.physics.settle_time);
  sim::SimRobot robot(world);
  const Eigen::Isometry3d X_RW = scene.composed.X_WR.inverse();
  const Eigen::Isometry3d X_RT = X_RW * world.ground_truth().Pose(placed.body);
  const Eigen::Isometry3d X_RH = X_RT * HandleFrame(model->handle);
  const Eigen::VectorXd before = robot.PositionTargets();
  std::vector<Eigen::Isometry3d> asked;
  control::GraspOptions options;  // as grasp-gt grasps
  options.handle_slide = GripSlide(scene.robot, *model, model->handle);
  options.obstacles = WorkspaceObstacles(scene.spec);
  options.accept_plan = [&](const Eigen::Isometry3d& X_RP, const Eigen::VectorXd& q_lifted) -> std::string {
    EXPECT_EQ(q_lifted.size(), scene.robot.HomeQ().size());
    asked.push_back(X_RP);
    return asked.size() < 3 ? "too short for the job" : "";
  };
  const control::GraspResult refused = control::GraspHandle(robot, scene.robot, X_RH, options);
  EXPECT_EQ(refused.status, control::GraspStatus::kRejected);
  EXPECT_TRUE(control::PlanningFailed(refused.status));
  EXPECT_THAT(refused.reason, ::testing::HasSubstr("too short for the job"));
  ASSERT_EQ(asked.size(), 1u);
  EXPECT_TRUE(asked[0].isApprox(refused.X_RP_grasp, 1e-12));
  EXPECT_EQ(robot.PositionTargets(), before);

  asked.clear();
  const Eigen::Vector3d p_R_effector = X_RT * model->effector.center;
  const control::GraspResult g = control::GraspToolForAction(robot, scene.robot, X_RH, p_R_effector,
                                                             GripSlide(scene.robot, *model, model->handle), options);
  EXPECT_EQ(g.status, control::GraspStatus::kGrasped) << g.reason;
  ASSERT_EQ(asked.size(), 3u);
  EXPECT_TRUE(asked[2].isApprox(g.X_RP_grasp, 1e-12));
  EXPECT_FALSE(asked[0].isApprox(asked[2], 1e-6));  // another way of holding it
  const double lift = (X_RW * world.ground_truth().Pose(placed.body)).translation().z() - X_RT.translation().z();
  EXPECT_GE(lift, kMinLiftM);
}

// A tool lying across the rack (rot3) rests on the ledge against the board: choked toward the
// handle's end first, the hand closed on nothing or let it roll out of the fingertips (1 of the 32
// rot3 episodes of table53 --episodes grasped its tool; the regression suite's
// episodes_table53_lying runs four of them). GraspToolForAction takes a lying handle where the
// whole-handle planner (grasp-gt's) puts it first: the same grasp as GraspHandle sliding either
// way from the same posture, held at the first try.
TEST(GraspToolForAction, GraspsALyingHandleWhereTheWholeHandlePlannerPutsIt) {
  const LoadedScene scene = SceneOfOne("hoe_1", "rot3");
  const sim::PlacedTool& placed = scene.composed.tools.at(0);
  const toollib::ToolModel* model = LibraryModel(scene, placed.name);
  ASSERT_NE(model, nullptr);
  const control::HandleSlide slide = GripSlide(scene.robot, *model, model->handle);
  control::GraspOptions options;
  options.obstacles = WorkspaceObstacles(scene.spec);
  auto grasp = [&](bool for_action) {
    AfterRackLook c(scene, "lying handle test");
    const Eigen::Isometry3d X_RH = c.X_RT * HandleFrame(model->handle);
    EXPECT_LT(std::abs(X_RH.linear().col(2).z()), 0.1) << "the handle no longer lies: pick another case";
    control::GraspOptions o = options;
    o.handle_slide = slide;
    const control::GraspResult g =
        for_action
            ? control::GraspToolForAction(*c.robot, scene.robot, X_RH, c.X_RT * model->effector.center, slide, options)
            : control::GraspHandle(*c.robot, scene.robot, X_RH, o);
    return std::make_pair(g, c.LiftM());
  };
  const auto [whole, whole_lift] = grasp(false);
  const auto [g, lift] = grasp(true);
  ASSERT_EQ(g.status, control::GraspStatus::kGrasped) << g.reason;
  EXPECT_EQ(g.regrasps, 0) << g.regrasp_reason;
  EXPECT_TRUE(g.X_RP_grasp.isApprox(whole.X_RP_grasp, 1e-9)) << "not the whole-handle planner's grasp";
  EXPECT_GE(lift, kMinLiftM);
}

// rake_2 standing turned toward the robot (rot1): its handle's lower end, where GraspToolForAction
// first chokes it, is reachable only with the hand against the rack's ledge, and closing there
// pushed the handle up and out of the fingers (random seeds 7 and 8: rake_2 twice and shovel_2
// fell off the rack). With clear_hand_first (the default) every way to grasp is first planned
// with the hand clear of the fixtures, so the grasp moves up the handle; the ways that have only
// poses touching a fixture come after all of them.
TEST(GraspToolForAction, PlansEveryWayWithTheHandClearOfTheRackFirst) {
  const LoadedScene scene = SceneOfOne("rake_2", "rot1");
  const sim::PlacedTool& placed = scene.composed.tools.at(0);
  const toollib::ToolModel* model = LibraryModel(scene, placed.name);
  ASSERT_NE(model, nullptr);
  const control::HandleSlide slide = GripSlide(scene.robot, *model, model->handle);
  auto grasp = [&](bool clear_hand_first) {
    AfterRackLook c(scene, "clear hand test");
    control::GraspOptions options;
    options.obstacles = WorkspaceObstacles(scene.spec);
    options.clear_hand_first = clear_hand_first;
    const control::GraspResult g = control::GraspToolForAction(
        *c.robot, scene.robot, c.X_RT * HandleFrame(model->handle), c.X_RT * model->effector.center, slide, options);
    return std::make_pair(g, c.LiftM());
  };
  const auto [touching, touching_lift] = grasp(false);
  ASSERT_TRUE(touching.hand_touches_fixture) << "the first way no longer touches the ledge: pick another case";
  const auto [g, lift] = grasp(true);
  ASSERT_EQ(g.status, control::GraspStatus::kGrasped) << g.reason;
  EXPECT_FALSE(g.hand_touches_fixture) << g.hand_touch_depth_m;
  EXPECT_FALSE(g.X_RP_grasp.isApprox(touching.X_RP_grasp, 1e-6));
  EXPECT_EQ(g.regrasps, 0) << g.regrasp_reason;
  EXPECT_GE(lift, kMinLiftM);
}

// GraspHandle with fixture_contact_allowed false never plans a pose whose hand would touch a
// fixture: with only those reachable (the handle's lower end of rake_2 at rot1, no slide) it
// fails before anything moves, saying so; allowed, it takes one.
TEST(GraspHandle, RefusesPosesTouchingAFixtureWhenAsked) {
  const LoadedScene scene = SceneOfOne("rake_2", "rot1");
  const sim::PlacedTool& placed = scene.composed.tools.at(0);
  const toollib::ToolModel* model = LibraryModel(scene, placed.name);
  ASSERT_NE(model, nullptr);
  AfterRackLook c(scene, "fixture contact test");
  sim::SimRobot& robot = *c.robot;
  // The handle's end nearest the ledge, less a grasp's half length.
  Eigen::Isometry3d X_RH = c.X_RT * HandleFrame(model->handle);
  const control::HandleSlide slide = GripSlide(scene.robot, *model, model->handle);
  const double down = X_RH.linear().col(2).z() > 0 ? slide.min_m : slide.max_m;
  X_RH.translation() += down * X_RH.linear().col(2);
  control::GraspOptions options;
  options.obstacles = WorkspaceObstacles(scene.spec);
  options.fixture_contact_allowed = false;
  const Eigen::VectorXd before = robot.PositionTargets();
  const control::GraspResult refused = control::GraspHandle(robot, scene.robot, X_RH, options);
  ASSERT_EQ(refused.status, control::GraspStatus::kIkFailed) << refused.reason;
  EXPECT_TRUE(refused.fixture_contact_refused);
  EXPECT_GT(refused.candidates_touching, 0);
  EXPECT_THAT(refused.reason, ::testing::HasSubstr("clear of the fixtures"));
  EXPECT_EQ(robot.PositionTargets(), before);

  options.fixture_contact_allowed = true;
  options.accept_plan = [](const Eigen::Isometry3d&, const Eigen::VectorXd&) { return std::string("only planning"); };
  const control::GraspResult allowed = control::GraspHandle(robot, scene.robot, X_RH, options);
  EXPECT_EQ(allowed.status, control::GraspStatus::kRejected) << allowed.reason;
  EXPECT_TRUE(allowed.hand_touches_fixture);
  EXPECT_FALSE(allowed.fixture_contact_refused);
}

TEST(GraspHandle, RejectsBadInputAndReportsUnreachableHandles) {
  SceneRequest request;
  request.tools = {"stick_2"};
  const LoadedScene scene = LoadScene(request);
  sim::World world(scene.composed.mjcf, "grasp test");
  sim::SimRobot robot(world);
  Eigen::Isometry3d X_RH = Eigen::Isometry3d::Identity();
  X_RH.linear() *= 2.0;  // not a rotation
  EXPECT_THAT([&] { control::GraspHandle(robot, scene.robot, X_RH); },
              ::testing::ThrowsMessage<std::invalid_argument>(::testing::HasSubstr("X_RH")));
  control::GraspOptions bad;
  bad.close_time = 0.1;
  EXPECT_THAT([&] { control::GraspHandle(robot, scene.robot, Eigen::Isometry3d::Identity(), bad); },
              ::testing::ThrowsMessage<std::invalid_argument>(::testing::HasSubstr("close_time")));
  EXPECT_THAT(
      [&] {
        control::GraspToolForAction(robot, scene.robot, Eigen::Isometry3d::Identity(), Eigen::Vector3d::Zero(),
                                    control::HandleSlide{0.1, 0.2});
      },
      ::testing::ThrowsMessage<std::invalid_argument>(::testing::HasSubstr("slide = [0.1, 0.2]")));
  control::GraspOptions bad_slide;
  bad_slide.handle_slide.max_m = std::nan("");
  EXPECT_THAT([&] { control::GraspHandle(robot, scene.robot, Eigen::Isometry3d::Identity(), bad_slide); },
              ::testing::ThrowsMessage<std::invalid_argument>(::testing::HasSubstr("handle_slide.max_m")));
  // 2 m in front of the robot: out of reach, and nothing moves.
  X_RH = Eigen::Isometry3d::Identity();
  X_RH.translation() = Eigen::Vector3d(-2.0, 0.2, 0.0);
  const Eigen::VectorXd before = robot.PositionTargets();
  const control::GraspResult r = control::GraspHandle(robot, scene.robot, X_RH);
  EXPECT_EQ(r.status, control::GraspStatus::kUnreachable);
  EXPECT_FALSE(r.reason.empty());
  EXPECT_EQ(robot.PositionTargets(), before);
}

}  // namespace
}  // namespace toolbench::app
