#pragma once
// A RobotInterface for tests without physics: every joint follows its position target with a
// first-order lag (time constant 20 ms, integrated at 1 ms); a blocked joint does not move (a
// finger closed on a handle).
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "common/robot_interface.h"

namespace toolbench::test {

class FirstOrderRobot : public RobotInterface {
 public:
  explicit FirstOrderRobot(std::vector<std::string> names)
      : blocked(names.size(), false),
        names_(std::move(names)),
        q_(Eigen::VectorXd::Zero(static_cast<Eigen::Index>(names_.size()))),
        target_(q_),
        v_(q_) {}
  std::vector<bool> blocked;  // per joint, in JointNames() order
  std::vector<std::string> JointNames() const override { return names_; }
  Eigen::VectorXd ReadEncoders() const override { return q_; }
  Eigen::VectorXd ReadVelocities() const override { return v_; }
  void SetPositionTargets(const Eigen::VectorXd& q) override { target_ = q; }
  Eigen::VectorXd PositionTargets() const override { return target_; }
  void Wait(double seconds) override {
    for (double t = 0; t < seconds - 1e-12; t += 0.001) {
      v_ = (target_ - q_) / 0.02;
      for (Eigen::Index i = 0; i < v_.size(); ++i) {
        if (blocked[static_cast<size_t>(i)]) v_[i] = 0;
      }
      q_ += v_ * 0.001;
      time_ += 0.001;
    }
  }
  double Time() const override { return time_; }

 private:
  std::vector<std::string> names_;
  Eigen::VectorXd q_, target_, v_;
  double time_ = 0;
};

}  // namespace toolbench::test
