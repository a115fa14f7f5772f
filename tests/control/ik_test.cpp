#include "control/ik.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "common/rng.h"
#include "common/check.h"
#include "robot/robot_description.h"

namespace toolbench::control {
namespace {

using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

constexpr double kPosTol = 1e-3;                // success criterion of issue 4 [m]
constexpr double kRotTol = 2.0 * M_PI / 180.0;  // [rad]

class IkTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    robot_ = new robot::RobotDescription(robot::LoadRobotDescription(robot::DefaultRobotSidecar()));
    chain_ = new KinematicChain(MakeRightArmChain(robot_->model));
  }
  static void TearDownTestSuite() {
    delete chain_;
    delete robot_;
  }
  // A random in-limit posture of the arm chain, other joints at home.
  static Eigen::VectorXd RandomArmQ(Rng& rng) {
    Eigen::VectorXd q_chain(chain_->num_joints());
    for (int i = 0; i < q_chain.size(); ++i) q_chain[i] = UniformReal(rng, chain_->lower()[i], chain_->upper()[i]);
    return chain_->ModelQ(robot_->HomeQ(), q_chain);
  }
  static robot::RobotDescription* robot_;
  static KinematicChain* chain_;
};
robot::RobotDescription* IkTest::robot_ = nullptr;
KinematicChain* IkTest::chain_ = nullptr;

TEST_F(IkTest, SolvesReachableTargetsWithinTolerance) {
  CartesianSolver solver(*chain_, robot_->HomeQ());
  Rng rng(DeriveSeed(1, "ik_test_reachable"));
  for (int trial = 0; trial < 100; ++trial) {
    const Eigen::VectorXd q_goal = RandomArmQ(rng);
    const Eigen::Isometry3d X_RT = chain_->TipPose(q_goal);
    const IkResult result = solver.Solve(X_RT, robot_->HomeQ());
    ASSERT_EQ(result.status, IkStatus::kConverged)
        << "goal [deg] " << (chain_->ChainQ(q_goal) * 180 / M_PI).transpose() << "\ngot [deg] "
        << (chain_->ChainQ(result.q) * 180 / M_PI).transpose() << "\ntrial " << trial << ": " << ToString(result.status) << " pos " << result.position_error_m << " rot "
        << result.orientation_error_rad;
    // Check independently with the URDF forward kinematics, and the limits and untouched joints.
    const Eigen::Isometry3d X_RP = robot::LinkPose(robot_->model, result.q, robot_->palm_frame);
    EXPECT_LT((X_RP.translation() - X_RT.translation()).norm(), kPosTol);
    EXPECT_LT(OrientationError(X_RT.linear(), X_RP.linear()).norm(), kRotTol);
    EXPECT_NEAR((X_RP.translation() - X_RT.translation()).norm(), result.position_error_m, 1e-9);
    const Eigen::VectorXd q_chain = chain_->ChainQ(result.q);
    EXPECT_TRUE((q_chain.array() >= chain_->lower().array() - 1e-9).all());
    EXPECT_TRUE((q_chain.array() <= chain_->upper().array() + 1e-9).all());
    const Eigen::VectorXd untouched = chain_->ModelQ(result.q, chain_->ChainQ(robot_->HomeQ()));
    EXPECT_TRUE(untouched.isApprox(robot_->HomeQ(), 0.0) || untouched == robot_->HomeQ());
  }
}

TEST_F(IkTest, PlainIpoptBaselineAlsoSolvesANearTarget) {
  IkOptions options;
  options.presolve = false;
  CartesianSolver solver(*chain_, robot_->HomeQ(), options);
  Eigen::Isometry3d X_RT = chain_->TipPose(robot_->HomeQ());
  X_RT.translation() += Eigen::Vector3d(-0.03, 0.02, 0.02);
  const IkResult result = solver.Solve(X_RT, robot_->HomeQ());
  EXPECT_EQ(result.status, IkStatus::kConverged) << ToString(result.status);
  EXPECT_LT(result.position_error_m, kPosTol);
  EXPECT_GT(result.ipopt_iterations, 0);
}

TEST_F(IkTest, UnreachableTargetsAreReportedNotThrown) {
  CartesianSolver solver(*chain_, robot_->HomeQ());
  const Eigen::Isometry3d X_home = chain_->TipPose(robot_->HomeQ());
  // 1.5 m in front of the robot (root -x is forward), and behind its back (+x).
  for (const Eigen::Vector3d& p : {Eigen::Vector3d(-1.5, 0.1, 0.1), Eigen::Vector3d(0.35, 0.05, 0.05)}) {
    Eigen::Isometry3d X_RT = X_home;
    X_RT.translation() = p;
    const IkResult result = solver.Solve(X_RT, robot_->HomeQ());
    EXPECT_NE(result.status, IkStatus::kConverged) << p.transpose();
    EXPECT_GT(result.position_error_m, 0.01) << p.transpose();
    EXPECT_EQ(result.q.size(), robot_->model.num_q());
    EXPECT_TRUE(result.q.allFinite());
  }
}

// For screening many poses: no Ipopt after a failed pre-solve reports the failure at once, and a
// reachable target still converges by the pre-solve alone.
TEST_F(IkTest, WithoutIpoptRescueFailuresAreReportedAtOnce) {
  IkOptions options;
  options.ipopt_after_failed_presolve = false;
  CartesianSolver solver(*chain_, robot_->HomeQ(), options);
  Eigen::Isometry3d X_RT = chain_->TipPose(robot_->HomeQ());
  X_RT.translation() = Eigen::Vector3d(-1.5, 0.1, 0.1);
  const IkResult far = solver.Solve(X_RT, robot_->HomeQ());
  EXPECT_EQ(far.status, IkStatus::kUnreachable) << ToString(far.status);
  EXPECT_EQ(far.ipopt_iterations, 0);
  Rng rng(DeriveSeed(1, "ik_test_no_rescue"));
  int converged = 0;
  for (int trial = 0; trial < 20; ++trial) {
    const IkResult r = solver.Solve(chain_->TipPose(RandomArmQ(rng)), robot_->HomeQ());
    converged += r.status == IkStatus::kConverged ? 1 : 0;
    EXPECT_EQ(r.ipopt_iterations, 0);
  }
  EXPECT_GE(converged, 19);
}

// Goals whose postures hold joints at their limits: the pre-solve's steps freeze the joints they
// push against a limit and go on with the others (alone, without Ipopt's rescue).
TEST_F(IkTest, ThePresolveReachesPosturesWithJointsAtTheirLimits) {
  IkOptions options;
  options.ipopt_after_failed_presolve = false;
  CartesianSolver solver(*chain_, robot_->HomeQ(), options);
  Rng rng(DeriveSeed(1, "ik_test_limits"));
  int converged = 0;
  constexpr int kTrials = 40;
  for (int trial = 0; trial < kTrials; ++trial) {
    Eigen::VectorXd q_chain = chain_->ChainQ(RandomArmQ(rng));
    for (int k = 0; k < 3; ++k) {
      const int i = UniformInt(rng, 0, chain_->num_joints() - 1);
      q_chain[i] = UniformReal(rng, 0.0, 1.0) < 0.5 ? chain_->lower()[i] : chain_->upper()[i];
    }
    const Eigen::Isometry3d X_RT = chain_->TipPose(chain_->ModelQ(robot_->HomeQ(), q_chain));
    const IkResult r = solver.Solve(X_RT, robot_->HomeQ());
    converged += r.status == IkStatus::kConverged ? 1 : 0;
    const Eigen::VectorXd q = chain_->ChainQ(r.q);
    EXPECT_TRUE((q.array() >= chain_->lower().array()).all() && (q.array() <= chain_->upper().array()).all())
        << "trial " << trial << ": " << q.transpose();
  }
  EXPECT_GE(converged, kTrials - 4);
}

// A start that stalls far from an out-of-reach target is given up early: the same verdict in a
// fraction of the LM iterations. Targets in reach converge to the same postures as without the
// stall test (their starts never stall that far off).
TEST_F(IkTest, StartsStalledFarFromTheTargetAreGivenUp) {
  IkOptions patient;
  patient.ipopt_after_failed_presolve = false;
  patient.presolve_stall_window = 0;
  IkOptions quick = patient;
  quick.presolve_stall_window = 10;
  CartesianSolver slow(*chain_, robot_->HomeQ(), patient);
  CartesianSolver fast(*chain_, robot_->HomeQ(), quick);
  Eigen::Isometry3d X_RT = chain_->TipPose(robot_->HomeQ());
  X_RT.translation() = Eigen::Vector3d(-1.0, 0.1, 0.1);  // out of reach in front
  const IkResult far_slow = slow.Solve(X_RT, robot_->HomeQ());
  const IkResult far_fast = fast.Solve(X_RT, robot_->HomeQ());
  EXPECT_EQ(far_slow.status, IkStatus::kUnreachable) << ToString(far_slow.status);
  EXPECT_EQ(far_fast.status, IkStatus::kUnreachable) << ToString(far_fast.status);
  EXPECT_LT(far_fast.iterations * 2, far_slow.iterations) << far_fast.iterations << " vs " << far_slow.iterations;
  Rng rng(DeriveSeed(1, "ik_test_stall"));
  for (int trial = 0; trial < 20; ++trial) {
    const Eigen::Isometry3d X = chain_->TipPose(RandomArmQ(rng));
    const IkResult a = slow.Solve(X, robot_->HomeQ());
    const IkResult b = fast.Solve(X, robot_->HomeQ());
    EXPECT_EQ(a.status, b.status) << "trial " << trial;
    EXPECT_TRUE(a.q.isApprox(b.q, 1e-12)) << "trial " << trial;
  }
}

TEST_F(IkTest, BadInputIsNamed) {
  CartesianSolver solver(*chain_, robot_->HomeQ());
  Eigen::Isometry3d X_RT = chain_->TipPose(robot_->HomeQ());
  X_RT.translation().x() = NAN;
  EXPECT_THAT([&] { solver.Solve(X_RT, robot_->HomeQ()); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("X_BT_target")));
  EXPECT_THAT([&] { solver.Solve(chain_->TipPose(robot_->HomeQ()), Eigen::VectorXd::Zero(4)); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("q_current has 4 entries")));
  Eigen::Isometry3d skewed = Eigen::Isometry3d::Identity();
  skewed.linear() << 2, 0, 0, 0, 1, 0, 0, 0, 1;
  EXPECT_THAT([&] { solver.Solve(skewed, robot_->HomeQ()); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("not a rotation")));
  IkOptions options;
  options.position_tolerance_m = -1.0;
  EXPECT_THAT([&] { CartesianSolver(*chain_, robot_->HomeQ(), options); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("position_tolerance_m")));
  options = {};
  options.presolve_stall_drop = 1.0;
  EXPECT_THAT([&] { CartesianSolver(*chain_, robot_->HomeQ(), options); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("presolve_stall_drop")));
  options = {};
  options.presolve_stall_error_m = NAN;
  EXPECT_THAT([&] { CartesianSolver(*chain_, robot_->HomeQ(), options); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("presolve_stall_error_m")));
  options = {};
  options.rest_weights["neck_yaw"] = 1.0;
  EXPECT_THAT([&] { CartesianSolver(*chain_, robot_->HomeQ(), options); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("neck_yaw")));
}

TEST(IkChainTest, AChainLongerThanTheSolverTakesIsNamed) {
  std::string urdf = R"(<?xml version="1.0"?><robot name="snake"><link name="l0"/>)";
  constexpr int kJoints = 17;
  for (int i = 1; i <= kJoints; ++i) {
    urdf += Cat("<link name=\"l", i, "\"/><joint name=\"j", i, "\" type=\"revolute\"><parent link=\"l", i - 1,
                "\"/><child link=\"l", i, "\"/><origin xyz=\"0.05 0 0\"/><axis xyz=\"0 0 1\"/>",
                "<limit lower=\"-1\" upper=\"1\" effort=\"1\" velocity=\"1\"/></joint>");
  }
  urdf += "</robot>";
  const robot::RobotModel model = robot::ParseUrdf(urdf, "inline snake");
  const KinematicChain chain(model, "l0", Cat("l", kJoints));
  ASSERT_EQ(chain.num_joints(), kJoints);
  EXPECT_THAT([&] { CartesianSolver(chain, Eigen::VectorXd::Zero(model.num_q())); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("has 17 joints; at most 16")));
}

}  // namespace
}  // namespace toolbench::control
