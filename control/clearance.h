#pragma once

#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Geometry>

#include "robot/robot_description.h"

namespace toolbench::control {

/// A fixed box the arm must keep clear of (the table, the rack's board and ledge), in R.
struct ObstacleBox {
  std::string name;
  Eigen::Isometry3d X_RB = Eigen::Isometry3d::Identity();  // centre and axes in R
  Eigen::Vector3d half = Eigen::Vector3d::Zero();          // half extents [m], > 0
};

/// Distance of the point p_R (in R) from the box's surface [m]: negative inside it.
double BoxDistance(const ObstacleBox& box, const Eigen::Vector3d& p_R);

/// Where a posture comes too close to an obstacle.
struct ClearanceHit {
  std::string link;      // robot link, e.g. "r_little_distal_phalanx"
  std::string obstacle;  // ObstacleBox::name
  Eigen::Vector3d p_R = Eigen::Vector3d::Zero();  // the offending point of the link in R [m]
  double distance_m = 0;  // its distance to the box's surface less its radius (< margin) [m]
};

/// Checks the collision shapes of an arm's distal links (the link `first_link` and every link
/// below it in the tree: forearm, hand and fingers by default) against obstacle boxes, for
/// postures of the robot model with the hand's joints held at `hand` (e.g. the open hand during a
/// transfer). The shapes are the URDF's collision primitives, each covered by spheres (a box by a
/// grid of them, a cylinder by a row along its axis), so the test is conservative by at most the
/// spheres' overlap. Mesh shapes are not covered. Kinematics only: the robot does not move.
class ArmClearance {
 public:
  /// Throws std::invalid_argument naming the link, a joint of `hand` the model lacks, an obstacle
  /// with a non-positive or non-finite extent, or margin_m < 0.
  ArmClearance(const robot::RobotDescription& desc, std::vector<ObstacleBox> obstacles,
               const std::map<std::string, double>& hand, double margin_m,
               std::string_view first_link = "r_forearm");

  bool empty() const { return obstacles_.empty(); }
  int num_spheres() const { return static_cast<int>(spheres_.size()); }

  /// The first sphere (in link order) closer than the margin to an obstacle at posture q_model
  /// (full model q; the hand's joints are replaced), or nothing.
  std::optional<ClearanceHit> Check(const Eigen::VectorXd& q_model) const;

  /// The sphere that comes closest to an obstacle at posture q_model, however far (distance_m
  /// negative: inside it by that much), or nothing without obstacles. The margin plays no part.
  std::optional<ClearanceHit> Closest(const Eigen::VectorXd& q_model) const;

  /// Checks the straight joint-space line from `from` to `to` (inclusive of `to`, exclusive of
  /// `from`) at steps of at most max_step_rad (> 0) in any joint. Obstacles that the start
  /// posture already touches are left out (the arm cannot leave them without passing them).
  std::optional<ClearanceHit> CheckLine(const Eigen::VectorXd& from, const Eigen::VectorXd& to,
                                        double max_step_rad) const;

 private:
  struct Sphere {
    int link = -1;  // index into the model's links
    Eigen::Vector3d p_L = Eigen::Vector3d::Zero();
    double radius = 0;
  };
  // Distance of a sphere at p_R from a box's surface, less its radius (negative inside) [m].
  static double Distance(const Sphere& sphere, const Eigen::Vector3d& p_R, const ObstacleBox& box);
  // Link poses in R at q_model with the hand's joints replaced.
  std::vector<Eigen::Isometry3d> LinkPoses(const Eigen::VectorXd& q_model) const;
  std::optional<ClearanceHit> CheckAgainst(const Eigen::VectorXd& q_model, const std::vector<bool>& skip) const;

  const robot::RobotModel* model_;
  std::vector<ObstacleBox> obstacles_;
  std::vector<std::pair<int, double>> hand_;  // q index, value
  std::vector<Sphere> spheres_;
  double margin_m_;
};

}  // namespace toolbench::control
