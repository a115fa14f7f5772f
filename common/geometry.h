#pragma once

#include <Eigen/Geometry>

namespace toolbench {

/// Rotation from URDF-style fixed-axis roll, pitch, yaw [rad]: R = Rz(yaw) * Ry(pitch) * Rx(roll).
Eigen::Matrix3d RotationFromRpy(const Eigen::Vector3d& rpy);

/// Inverse of RotationFromRpy, pitch in [-pi/2, pi/2].
Eigen::Vector3d RpyFromRotation(const Eigen::Matrix3d& R);

/// Pose from translation [m] and roll-pitch-yaw [rad].
Eigen::Isometry3d PoseFromXyzRpy(const Eigen::Vector3d& xyz, const Eigen::Vector3d& rpy);

/// Angle of the relative rotation between two rotation matrices [rad], in [0, pi].
double RotationAngleBetween(const Eigen::Matrix3d& A, const Eigen::Matrix3d& B);

/// Rotation about a unit axis by angle [rad] (Eigen::AngleAxisd as a matrix).
Eigen::Matrix3d AxisAngle(const Eigen::Vector3d& axis, double angle);

}  // namespace toolbench
