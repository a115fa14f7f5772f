#pragma once

#include <Eigen/Core>

namespace toolbench::perception::internal {

/// Unknowns of the superquadric fit: (a1, a2, a3, e1, e2, r_x, r_y, r_z, t_x, t_y, t_z), where
/// the superquadric frame S has rotation R0 * Exp(r) and origin t in the fitting frame.
using SqParams = Eigen::Matrix<double, 11, 1>;

/// Cost of thesis eq. 2.6, (a1 a2 a3 / N) sum_i (F(p_i)^e1 - 1)^2, for the points (3 x N, in the
/// fitting frame), and its exact gradient when `gradient` is not null. Declared here for the
/// finite-difference test; FitSuperquadric is the public entry point.
double SuperquadricCost(const SqParams& x, const Eigen::Matrix3Xd& points, const Eigen::Matrix3d& R0,
                        SqParams* gradient);

/// Rotation matrix of the rotation vector r (Rodrigues).
Eigen::Matrix3d ExpSo3(const Eigen::Vector3d& r);

}  // namespace toolbench::perception::internal
