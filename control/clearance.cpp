#include "control/clearance.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

#include "common/check.h"
#include "robot/robot_model.h"

namespace toolbench::control {

ArmClearance::ArmClearance(const robot::RobotDescription& desc, std::vector<ObstacleBox> obstacles,
                           const std::map<std::string, double>& hand, double margin_m, std::string_view first_link)
    : model_(&desc.model), obstacles_(std::move(obstacles)), margin_m_(margin_m) {
  if (!(margin_m >= 0) || !std::isfinite(margin_m)) ThrowInvalid("ArmClearance: margin_m = ", margin_m, " (expected >= 0)");
  for (const ObstacleBox& box : obstacles_) {
    if (!(box.half.minCoeff() > 0) || !box.half.allFinite() || !box.X_RB.matrix().allFinite()) {
      ThrowInvalid("ArmClearance: obstacle '", box.name, "' has half extents (", box.half.transpose(),
                   ") or a pose that is not finite and positive");
    }
  }
  const robot::RobotModel& model = *model_;
  for (const auto& [joint, value] : hand) {
    const int q_index = model.joints[model.JointIndex(joint)].q_index;
    if (q_index < 0) ThrowInvalid("ArmClearance: hand joint '", joint, "' is fixed");
    hand_.emplace_back(q_index, value);
  }
  // The link and its subtree (links are stored parent before child).
  std::vector<int> links = {model.LinkIndex(first_link)};
  for (size_t i = 0; i < links.size(); ++i) {
    for (const int j : model.links[links[i]].child_joints) links.push_back(model.joints[j].child_link);
  }
  for (const int link : links) {
    for (const robot::Geometry& g : model.links[link].collisions) {
      using Type = robot::Geometry::Type;
      if (g.type == Type::kSphere) {
        spheres_.push_back({link, g.X_LG.translation(), g.size.x()});
      } else if (g.type == Type::kCylinder) {
        // A row of spheres along the axis, at most one radius apart: the widest gap between two
        // of them lies within 1.12 radii of their centres.
        const double r = g.size.x();
        const double length = g.size.y();
        const int n = std::max(1, static_cast<int>(std::ceil(length / r))) + 1;
        for (int i = 0; i < n; ++i) {
          const double s = -length / 2 + length * i / (n - 1);
          spheres_.push_back({link, g.X_LG * Eigen::Vector3d(0, 0, s), 1.12 * r});
        }
      } else if (g.type == Type::kBox) {
        // Cells about as long as the box's thinnest side, each covered by the sphere around it.
        const Eigen::Vector3d e = g.size;
        const double side = std::max(e.minCoeff(), 1e-3);
        Eigen::Vector3i n;
        for (int k = 0; k < 3; ++k) n[k] = std::max(1, static_cast<int>(std::ceil(e[k] / side - 1e-9)));
        const Eigen::Vector3d cell = e.cwiseQuotient(n.cast<double>());
        for (int a = 0; a < n[0]; ++a) {
          for (int b = 0; b < n[1]; ++b) {
            for (int c = 0; c < n[2]; ++c) {
              const Eigen::Vector3d p = -e / 2 + cell.cwiseProduct(Eigen::Vector3d(a + 0.5, b + 0.5, c + 0.5));
              spheres_.push_back({link, g.X_LG * p, cell.norm() / 2});
            }
          }
        }
      }
    }
  }
}

double BoxDistance(const ObstacleBox& box, const Eigen::Vector3d& p_R) {
  const Eigen::Vector3d p_B = box.X_RB.linear().transpose() * (p_R - box.X_RB.translation());
  const Eigen::Vector3d d = p_B.cwiseAbs() - box.half;
  const double outside = d.cwiseMax(0.0).norm();
  return outside > 0 ? outside : d.maxCoeff();
}

double ArmClearance::Distance(const Sphere& sphere, const Eigen::Vector3d& p_R, const ObstacleBox& box) {
  return BoxDistance(box, p_R) - sphere.radius;
}

std::vector<Eigen::Isometry3d> ArmClearance::LinkPoses(const Eigen::VectorXd& q_model) const {
  Eigen::VectorXd q = q_model;
  for (const auto& [index, value] : hand_) {
    if (index < q.size()) q[index] = value;
  }
  return robot::LinkPoses(*model_, q);
}

std::optional<ClearanceHit> ArmClearance::CheckAgainst(const Eigen::VectorXd& q_model,
                                                       const std::vector<bool>& skip) const {
  if (obstacles_.empty()) return std::nullopt;
  const std::vector<Eigen::Isometry3d> X_RL = LinkPoses(q_model);
  for (const Sphere& sphere : spheres_) {
    const Eigen::Vector3d p_R = X_RL[sphere.link] * sphere.p_L;
    for (size_t i = 0; i < obstacles_.size(); ++i) {
      if (skip[i]) continue;
      const double distance = Distance(sphere, p_R, obstacles_[i]);
      if (distance < margin_m_) return ClearanceHit{model_->links[sphere.link].name, obstacles_[i].name, p_R, distance};
    }
  }
  return std::nullopt;
}

std::optional<ClearanceHit> ArmClearance::Check(const Eigen::VectorXd& q_model) const {
  return CheckAgainst(q_model, std::vector<bool>(obstacles_.size(), false));
}

std::optional<ClearanceHit> ArmClearance::Closest(const Eigen::VectorXd& q_model) const {
  if (obstacles_.empty() || spheres_.empty()) return std::nullopt;
  const std::vector<Eigen::Isometry3d> X_RL = LinkPoses(q_model);
  ClearanceHit closest;
  closest.distance_m = std::numeric_limits<double>::infinity();
  for (const Sphere& sphere : spheres_) {
    const Eigen::Vector3d p_R = X_RL[sphere.link] * sphere.p_L;
    for (const ObstacleBox& box : obstacles_) {
      const double distance = Distance(sphere, p_R, box);
      if (distance < closest.distance_m) closest = {model_->links[sphere.link].name, box.name, p_R, distance};
    }
  }
  return closest;
}

std::optional<ClearanceHit> ArmClearance::CheckLine(const Eigen::VectorXd& from, const Eigen::VectorXd& to,
                                                    double max_step_rad) const {
  if (!(max_step_rad > 0)) ThrowInvalid("ArmClearance::CheckLine: max_step_rad = ", max_step_rad, " (expected > 0)");
  if (from.size() != to.size()) {
    ThrowInvalid("ArmClearance::CheckLine: postures of ", from.size(), " and ", to.size(), " joints");
  }
  if (obstacles_.empty()) return std::nullopt;
  // Obstacles the start already touches: the arm is there now, it cannot avoid them.
  std::vector<bool> skip(obstacles_.size(), false);
  const std::vector<Eigen::Isometry3d> X_RL = LinkPoses(from);
  for (const Sphere& sphere : spheres_) {
    const Eigen::Vector3d p_R = X_RL[sphere.link] * sphere.p_L;
    for (size_t i = 0; i < obstacles_.size(); ++i) {
      skip[i] = skip[i] || Distance(sphere, p_R, obstacles_[i]) < margin_m_;
    }
  }
  const double span = (to - from).cwiseAbs().maxCoeff();
  const int n = std::max(1, static_cast<int>(std::ceil(span / max_step_rad)));
  for (int i = 1; i <= n; ++i) {
    const Eigen::VectorXd q = from + (to - from) * (static_cast<double>(i) / n);
    if (auto hit = CheckAgainst(q, skip)) return hit;
  }
  return std::nullopt;
}

}  // namespace toolbench::control
