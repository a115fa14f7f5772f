// Tool actions (pull, drag-left, drag-right, push): names, directions, and the planned start and
// drag of each action with a stick-like tool (PlanPull, no simulator).
#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "control/clearance.h"
#include "control/kinematics.h"
#include "control/skills.h"
#include "robot/robot_description.h"

namespace toolbench::control {
namespace {

using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

constexpr ToolAction kActions[] = {ToolAction::kPull, ToolAction::kDragLeft, ToolAction::kDragRight,
                                   ToolAction::kPush};

TEST(ToolActionTest, NamesRoundTrip) {
  EXPECT_STREQ(ToString(ToolAction::kPull), "pull");
  EXPECT_STREQ(ToString(ToolAction::kDragLeft), "drag-left");
  EXPECT_STREQ(ToString(ToolAction::kDragRight), "drag-right");
  EXPECT_STREQ(ToString(ToolAction::kPush), "push");
  for (const ToolAction a : kActions) EXPECT_EQ(ParseToolAction(ToString(a)), a);
  EXPECT_EQ(ParseToolAction("Pull"), std::nullopt);
  EXPECT_EQ(ParseToolAction(""), std::nullopt);
  EXPECT_EQ(ParseToolAction("drag"), std::nullopt);
}

// Failures in planning (nothing moved) are told from failures in the motion, for grasps and actions alike.
TEST(ToolActionTest, PlanningFailuresAreTheOnesBeforeAnythingMoved) {
  using control::GraspStatus;
  using control::PullStatus;
  for (GraspStatus s : {GraspStatus::kUnreachable, GraspStatus::kIkFailed, GraspStatus::kRejected}) {
    EXPECT_TRUE(control::PlanningFailed(s));
  }
  for (GraspStatus s : {GraspStatus::kGrasped, GraspStatus::kMotionTimeout, GraspStatus::kEmptyHand,
                        GraspStatus::kDropped}) {
    EXPECT_FALSE(control::PlanningFailed(s)) << control::ToString(s);
  }
  for (PullStatus s : {PullStatus::kUnreachable, PullStatus::kIkFailed}) EXPECT_TRUE(control::PlanningFailed(s));
  for (PullStatus s : {PullStatus::kPulled, PullStatus::kMotionTimeout, PullStatus::kLostTool}) {
    EXPECT_FALSE(control::PlanningFailed(s)) << control::ToString(s);
  }
}

TEST(ToolActionTest, DirectionsInTheRootFrame) {
  // Object straight in front of the robot (x_R points backward, y_R to the robot's right).
  const Eigen::Vector3d front(-0.5, 0.0, -0.07);
  EXPECT_TRUE(ActionDirection(ToolAction::kPull, front).isApprox(Eigen::Vector3d::UnitX()));
  EXPECT_TRUE(ActionDirection(ToolAction::kPush, front).isApprox(-Eigen::Vector3d::UnitX()));
  EXPECT_TRUE(ActionDirection(ToolAction::kDragRight, front).isApprox(Eigen::Vector3d::UnitY()));
  EXPECT_TRUE(ActionDirection(ToolAction::kDragLeft, front).isApprox(-Eigen::Vector3d::UnitY()));
  // Off to the right: unit, horizontal, pull toward the axis, drags perpendicular to it.
  const Eigen::Vector3d right(-0.4, 0.3, 0.1);
  const Eigen::Vector3d pull = ActionDirection(ToolAction::kPull, right);
  EXPECT_TRUE(pull.isApprox(Eigen::Vector3d(0.8, -0.6, 0.0)));
  for (const ToolAction a : kActions) {
    const Eigen::Vector3d d = ActionDirection(a, right);
    EXPECT_NEAR(d.norm(), 1.0, 1e-12) << ToString(a);
    EXPECT_EQ(d.z(), 0.0) << ToString(a);
  }
  EXPECT_NEAR(ActionDirection(ToolAction::kDragLeft, right).dot(pull), 0.0, 1e-12);
  EXPECT_GT(ActionDirection(ToolAction::kDragRight, right).y(), 0.0);
  EXPECT_THAT([] { ActionDirection(ToolAction::kPull, Eigen::Vector3d(0.0, 0.0, -0.1)); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("vertical axis")));
  EXPECT_THAT([] { ActionDirection(ToolAction::kPush, Eigen::Vector3d(std::nan(""), 0.0, 0.0)); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("p_RO")));
}

class ToolActionPlanTest : public ::testing::TestWithParam<ToolAction> {
 protected:
  static void SetUpTestSuite() {
    robot_ = new robot::RobotDescription(robot::LoadRobotDescription(robot::DefaultRobotSidecar()));
  }
  static void TearDownTestSuite() { delete robot_; }
  static robot::RobotDescription* robot_;
};
robot::RobotDescription* ToolActionPlanTest::robot_ = nullptr;

// A 30 cm stick held at the hand's grasp cylinder, its axis z_T along the cylinder's axis; the
// effector (the far end) meets the object with its +x_T side.
Eigen::Isometry3d StickInTheHand(const robot::RobotDescription& desc) {
  Eigen::Isometry3d X_PT = Eigen::Isometry3d::Identity();
  X_PT.linear() =
      Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitZ(), desc.grasp.axis.normalized()).toRotationMatrix();
  X_PT.translation() = desc.grasp.center;
  return X_PT;
}

ToolEffector StickEffector() {
  ToolEffector effector;
  effector.center_T = Eigen::Vector3d(0.0, 0.0, 0.30);
  effector.direction_T = Eigen::Vector3d::UnitX();
  effector.half_thickness_m = 0.01;
  return effector;
}

// Few orientation samples keep the plan under a second; a straight 10 cm drag.
PullOptions FewOrientations() {
  PullOptions options;
  options.min_elevation_rad = 20.0 * M_PI / 180.0;
  options.max_elevation_rad = 40.0 * M_PI / 180.0;
  options.elevation_step_rad = 10.0 * M_PI / 180.0;
  options.max_yaw_rad = 40.0 * M_PI / 180.0;
  options.max_roll_rad = 60.0 * M_PI / 180.0;
  options.max_pull_turn_rad = 0.0;
  options.pull_length_m = 0.10;
  return options;
}

// The stick (StickInTheHand); no effector points, so the start lies on the drag line.
TEST_P(ToolActionPlanTest, StartsOnTheFarSideAndDragsAlongTheActionDirection) {
  const ToolAction action = GetParam();
  const robot::RobotDescription& desc = *robot_;
  const Eigen::Isometry3d X_PT = StickInTheHand(desc);
  const ToolEffector effector = StickEffector();
  PullOptions options = FewOrientations();
  options.action = action;
  const Eigen::Vector3d p_RO(-0.45, 0.12, -0.065);
  constexpr double kRadius = 0.035;
  const PullPlan plan = PlanPull(desc, desc.HomeQ(), X_PT, effector, p_RO, kRadius, options);
  ASSERT_TRUE(plan.complete()) << ToString(action) << ": " << plan.result.reason;
  EXPECT_EQ(plan.result.action, action);
  const Eigen::Vector3d dir = ActionDirection(action, p_RO);
  EXPECT_TRUE(plan.result.pull_dir_R.isApprox(dir, 1e-9)) << plan.result.pull_dir_R.transpose();

  // The planned start: the effector on the object's far side from the drag direction, on the line.
  const Eigen::Vector3d p_RE = plan.result.X_RT_start * effector.center_T;
  const Eigen::Vector3d d = p_RE - p_RO;
  EXPECT_LT(d.dot(dir), -kRadius) << "effector at " << p_RE.transpose();
  EXPECT_LT(std::abs(d.dot(Eigen::Vector3d::UnitZ().cross(dir))), 0.005) << "effector at " << p_RE.transpose();
  // Where the arm really ends at the start (IK within start_tolerance_m), and the drag.
  const KinematicChain chain = MakeRightArmChain(desc.model, desc.palm_frame);
  ASSERT_FALSE(plan.descend.empty());
  ASSERT_GE(plan.drag.size(), 2u);
  const Eigen::Vector3d p_start = (chain.TipPose(plan.descend.back()) * X_PT) * effector.center_T;
  EXPECT_LT((p_start - p_RE).norm(), options.start_tolerance_m + 1e-3);
  EXPECT_LT((p_start - p_RO).dot(dir), -kRadius);
  const Eigen::Vector3d p_end = (chain.TipPose(plan.drag.back()) * X_PT) * effector.center_T;
  const Eigen::Vector3d moved = p_end - p_start;
  EXPECT_GT(moved.dot(dir), options.min_pull_fraction * options.pull_length_m - 0.01) << moved.transpose();
  EXPECT_GT(moved.normalized().dot(dir), 0.98) << moved.transpose();
  EXPECT_NEAR(plan.result.planned_drag_m, options.pull_length_m * plan.drag.size() / options.drag_waypoints, 1e-9);

  // The transfer from the current posture ends above the start, with no joint jumping more than
  // max_joint_step_rad between postures (IK staying on one branch).
  ASSERT_FALSE(plan.transfer.empty());
  EXPECT_TRUE(plan.transfer.back().isApprox(plan.q_above, 1e-12));
  Eigen::VectorXd previous = desc.HomeQ();
  for (size_t i = 0; i < plan.transfer.size(); ++i) {
    EXPECT_LE((plan.transfer[i] - previous).cwiseAbs().maxCoeff(), options.max_joint_step_rad + 1e-9)
        << "transfer posture " << i << " of " << plan.transfer.size();
    previous = plan.transfer[i];
  }
}

// The pull's drag stops short of the edge of the object's support (the table top); with too
// little room left the direction is not tried.
TEST_F(ToolActionPlanTest, TheDragKeepsTheObjectOnItsSupport) {
  const robot::RobotDescription& desc = *robot_;
  const Eigen::Isometry3d X_PT = StickInTheHand(desc);
  const ToolEffector effector = StickEffector();
  PullOptions options = FewOrientations();
  const Eigen::Vector3d p_RO(-0.45, 0.12, -0.065);
  constexpr double kRadius = 0.035;
  const Eigen::Vector3d dir = ActionDirection(ToolAction::kPull, p_RO);
  // The table's near edge `beyond` past the ball's inset (radius + margin) along x: the ball may
  // travel beyond / dir.x() along the pull direction, which a drag of 1 / support_travel_fraction
  // times that makes: 6 cm of drag.
  const double inset = kRadius + options.support_edge_margin_m;
  const double beyond = 0.06 * options.support_travel_fraction;
  options.support_xy =
      Eigen::AlignedBox2d(Eigen::Vector2d(-1.0, -1.0), Eigen::Vector2d(p_RO.x() + inset + beyond, 1.0));
  const double room = beyond / dir.x() / options.support_travel_fraction;
  const PullPlan plan = PlanPull(desc, desc.HomeQ(), X_PT, effector, p_RO, kRadius, options);
  ASSERT_TRUE(plan.complete()) << plan.result.reason;
  EXPECT_LE(plan.result.planned_drag_m, room + 1e-9);
  EXPECT_GE(plan.result.planned_drag_m, options.min_pull_fraction * options.pull_length_m);
  const KinematicChain chain = MakeRightArmChain(desc.model, desc.palm_frame);
  const Eigen::Vector3d p_start = (chain.TipPose(plan.drag.front()) * X_PT) * effector.center_T;
  const Eigen::Vector3d p_end = (chain.TipPose(plan.drag.back()) * X_PT) * effector.center_T;
  EXPECT_LT((p_end - p_start).dot(dir), room + 0.01);
  const Eigen::Vector2d n = (plan.result.X_RT_start.linear() * effector.direction_T).head<2>().normalized();
  EXPECT_NEAR(plan.result.working_cos, n.dot(dir.head<2>()), 1e-9);

  // The ball 5 mm from falling over the edge (nearer it than the margin, it may come 2 cm closer
  // but not over it): 5 mm of travel, a drag under min_pull_fraction (3 cm); nothing is
  // planned, and the reason says why.
  options.support_xy.max().x() = p_RO.x() + kRadius + 0.005;
  const PullPlan none = PlanPull(desc, desc.HomeQ(), X_PT, effector, p_RO, kRadius, options);
  EXPECT_FALSE(none.complete());
  EXPECT_EQ(none.result.status, PullStatus::kUnreachable);
  EXPECT_THAT(none.result.reason, HasSubstr("off its support"));

  options.support_xy.max().y() = std::nan("");
  EXPECT_THAT([&] { options.Validate(); }, ThrowsMessage<std::invalid_argument>(HasSubstr("support_xy")));
  options.support_xy.max().y() = 1.0;
  options.support_travel_fraction = 0.0;
  EXPECT_THAT([&] { options.Validate(); }, ThrowsMessage<std::invalid_argument>(HasSubstr("support_travel_fraction")));
  options.support_travel_fraction = 0.5;
  options.support_edge_margin_m = -0.01;
  EXPECT_THAT([&] { options.Validate(); }, ThrowsMessage<std::invalid_argument>(HasSubstr("support_edge_margin_m")));
}

// The transfer turns the tool high above the table, where a fixture (the rack) may stand in the
// way of a long tool's far end: given the fixture's box, no tool point comes within
// fixture_clearance_m of it on the turn and the descent, and the plan goes around it.
TEST_F(ToolActionPlanTest, TheTransferKeepsTheToolClearOfTheFixtures) {
  const robot::RobotDescription& desc = *robot_;
  const Eigen::Isometry3d X_PT = StickInTheHand(desc);
  ToolEffector effector = StickEffector();
  // The stick's points every centimetre along its axis; the effector's, its last 3 cm.
  effector.tool_points_T.resize(3, 31);
  for (int i = 0; i <= 30; ++i) effector.tool_points_T.col(i) = Eigen::Vector3d(0.0, 0.0, 0.01 * i);
  effector.points_T = effector.tool_points_T.rightCols(4);
  PullOptions options = FewOrientations();
  const Eigen::Vector3d p_RO(-0.45, 0.12, -0.065);
  constexpr double kRadius = 0.035;
  const KinematicChain chain = MakeRightArmChain(desc.model, desc.palm_frame);
  // From above another object, to the right, the hand holding the stick out over the table.
  const PullPlan before = PlanPull(desc, desc.HomeQ(), X_PT, StickEffector(), Eigen::Vector3d(-0.40, 0.30, -0.065),
                                   kRadius, options);
  ASSERT_TRUE(before.complete()) << before.result.reason;
  const Eigen::VectorXd q_start = before.q_above;
  const PullPlan free = PlanPull(desc, q_start, X_PT, effector, p_RO, kRadius, options);
  ASSERT_TRUE(free.complete()) << free.result.reason;
  ASSERT_GE(free.transfer.size(), 6u);
  // A 6 cm box where the stick's far end passes two thirds of the way through that transfer.
  const Eigen::VectorXd& q_in_the_way = free.transfer[free.transfer.size() * 2 / 3];
  ObstacleBox box;
  box.name = "rack_board";
  box.X_RB.translation() = (chain.TipPose(q_in_the_way) * X_PT) * Eigen::Vector3d(0.0, 0.0, 0.30);
  box.half = Eigen::Vector3d::Constant(0.03);
  options.fixtures = {box};
  const PullPlan blocked = PlanPull(desc, q_start, X_PT, effector, p_RO, kRadius, options);
  EXPECT_FALSE(blocked.complete());
  EXPECT_THAT(blocked.result.reason, HasSubstr("of rack_board"));
  // With every orientation the planner samples by default, another one goes around the box.
  options.min_elevation_rad = PullOptions{}.min_elevation_rad;
  options.max_elevation_rad = PullOptions{}.max_elevation_rad;
  options.elevation_step_rad = PullOptions{}.elevation_step_rad;
  options.max_yaw_rad = PullOptions{}.max_yaw_rad;
  options.max_roll_rad = PullOptions{}.max_roll_rad;
  const PullPlan around = PlanPull(desc, q_start, X_PT, effector, p_RO, kRadius, options);
  ASSERT_TRUE(around.complete()) << around.result.reason;
  // Off the rack first (straight back and up, unchecked), then the turn and the descent.
  double nearest = std::numeric_limits<double>::infinity();
  for (const Eigen::VectorXd& q : around.transfer) {
    const Eigen::Matrix3Xd tool = (chain.TipPose(q) * X_PT) * effector.tool_points_T;
    for (Eigen::Index i = 0; i < tool.cols(); ++i) nearest = std::min(nearest, BoxDistance(box, tool.col(i)));
  }
  EXPECT_GE(nearest, options.fixture_clearance_m - 1e-9);

  options.fixture_clearance_m = -0.01;
  EXPECT_THAT([&] { options.Validate(); }, ThrowsMessage<std::invalid_argument>(HasSubstr("fixture_clearance_m")));
  options.fixture_clearance_m = 0.02;
  options.fixtures[0].half.x() = 0.0;
  EXPECT_THAT([&] { options.Validate(); }, ThrowsMessage<std::invalid_argument>(HasSubstr("rack_board")));
}

// A count option: 0 is accepted, a negative count refused with a message naming the field.
template <class Options>
void ExpectZeroAcceptedNegativeRefused(Options options, int Options::*count, const char* field) {
  options.*count = 0;
  EXPECT_NO_THROW(options.Validate()) << field;
  options.*count = -1;
  EXPECT_THAT([&] { options.Validate(); }, ThrowsMessage<std::invalid_argument>(HasSubstr(field)));
}

TEST(SkillOptionsTest, IpoptRescuesMayBeTurnedOff) {
  // 0 = no Ipopt after a failed pre-solve (the defaults of the grasp's fallback pass and of the
  // ball grasp); a negative count is refused, naming the field.
  EXPECT_EQ(GraspOptions{}.fallback_ipopt_iterations, 0);
  ExpectZeroAcceptedNegativeRefused(GraspOptions{}, &GraspOptions::fallback_ipopt_iterations,
                                    "fallback_ipopt_iterations");
  ExpectZeroAcceptedNegativeRefused(GraspOptions{}, &GraspOptions::path_ipopt_iterations, "path_ipopt_iterations");
  EXPECT_EQ(BallGraspOptions{}.grasp_ipopt_iterations, 0);
  EXPECT_NO_THROW(BallGraspOptions{}.Validate());
  ExpectZeroAcceptedNegativeRefused(BallGraspOptions{}, &BallGraspOptions::grasp_ipopt_iterations,
                                    "grasp_ipopt_iterations");
  EXPECT_EQ(PullOptions{}.path_restarts, 1);
  ExpectZeroAcceptedNegativeRefused(PullOptions{}, &PullOptions::path_restarts, "path_restarts");
}

TEST(HandleTowardEffectorTest, TurnsTheHandleAxisTowardTheEffector) {
  Eigen::Isometry3d X_RH = Eigen::Isometry3d::Identity();
  X_RH.linear() = Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  X_RH.translation() = Eigen::Vector3d(-0.3, 0.4, 0.1);
  const Eigen::Vector3d axis = X_RH.linear().col(2);
  // Already toward it: unchanged.
  EXPECT_TRUE(HandleTowardEffector(X_RH, X_RH.translation() + 0.2 * axis).isApprox(X_RH));
  // Behind it: z_H (and y_H) reversed, x_H and the origin kept, still a rotation.
  const Eigen::Isometry3d X = HandleTowardEffector(X_RH, X_RH.translation() - 0.2 * axis);
  EXPECT_TRUE(X.linear().col(2).isApprox(-axis));
  EXPECT_TRUE(X.linear().col(0).isApprox(X_RH.linear().col(0)));
  EXPECT_TRUE(X.translation().isApprox(X_RH.translation()));
  EXPECT_NEAR(X.linear().determinant(), 1.0, 1e-12);
  EXPECT_THAT([&] { HandleTowardEffector(X_RH, Eigen::Vector3d::Constant(std::nan(""))); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("not finite")));
}

INSTANTIATE_TEST_SUITE_P(Actions, ToolActionPlanTest, ::testing::ValuesIn(kActions),
                         [](const ::testing::TestParamInfo<ToolAction>& info) {
                           std::string name = ToString(info.param);
                           name.erase(std::remove(name.begin(), name.end(), '-'), name.end());
                           return name;
                         });

}  // namespace
}  // namespace toolbench::control
