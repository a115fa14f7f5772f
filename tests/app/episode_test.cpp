#include "app/episode.h"

#include <gtest/gtest.h>

namespace toolbench::app {
namespace {

// Where a ball lies relative to the table top, from where it was seen: resting on it (sensor
// noise either way), or on the floor, half a metre down.
TEST(BallBelowTableTest, ARestingBallIsAtZeroAndOneOnTheFloorFarBelow) {
  sim::TableSpec table;
  table.top_z = -0.10;
  const double radius = 0.035;
  EXPECT_NEAR(BallBelowTable(table, radius, Eigen::Vector3d(-0.5, 0.0, -0.065)), 0.0, 1e-12);
  EXPECT_LT(BallBelowTable(table, radius, Eigen::Vector3d(-0.5, 0.0, -0.060)), kBallOffTableM);
  EXPECT_LT(BallBelowTable(table, radius, Eigen::Vector3d(-0.5, 0.0, -0.075)), kBallOffTableM);
  // Random-50 seed 1, episode 40: seen at z = -0.594 m in R after a pull swept it off the table.
  EXPECT_NEAR(BallBelowTable(table, radius, Eigen::Vector3d(-0.338, 0.592, -0.594)), 0.529, 1e-9);
  EXPECT_GT(BallBelowTable(table, radius, Eigen::Vector3d(-0.338, 0.592, -0.594)), kBallOffTableM);
  // Lifted in the hand: above the table, negative.
  EXPECT_LT(BallBelowTable(table, radius, Eigen::Vector3d(-0.3, 0.1, 0.05)), 0.0);
}

}  // namespace
}  // namespace toolbench::app
