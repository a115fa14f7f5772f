#pragma once

#include <map>
#include <memory>
#include <string>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "control/kinematics.h"

namespace toolbench::control {

/// Options of the Cartesian (inverse kinematics) solver. The defaults are the ones measured by
/// `toolbench bench --protocol ik`.
struct IkOptions {
  double position_tolerance_m = 5e-4;     // radius of the position constraint |p_target - p| [m], > 0
  double orientation_tolerance_rad = 0.01;  // bound on the axis-angle error norm [rad], > 0
  /// Joint -> weight of the rest-posture cost 0.5 * w * (q - q_rest)^2 [1/rad^2], >= 0; joints of
  /// the chain not named get default_rest_weight. The torso is weighted to move less.
  std::map<std::string, double> rest_weights{{"torso_pitch", 1.0}, {"torso_roll", 1.0}, {"torso_yaw", 1.0}};
  double default_rest_weight = 0.05;       // [1/rad^2], >= 0
  /// Pre-solve before Ipopt: damped least squares (Levenberg-Marquardt) on the pose error from
  /// the warm start (then from deterministic restarts if it stalls), then Gauss-Newton SQP steps
  /// toward the rest posture on the pose manifold. false = plain Ipopt from the warm start (the
  /// thesis / iKin configuration, the bench's baseline).
  bool presolve = true;
  int presolve_iterations = 60;            // LM iterations per start, > 0
  int presolve_restarts = 30;              // extra deterministic starts when the warm start stalls, >= 0
  /// A start is given up when its cost (squared pose error, orientation weighted by
  /// orientation_length_m) fell by less than presolve_stall_drop (in [0, 1)) of its value over the
  /// last presolve_stall_window iterations (>= 0; 0 = never) while the pose is still more than
  /// presolve_stall_error_m (>= 0) off: LM creeping toward the nearest pose of an out-of-reach
  /// target used all its iterations. Screening the pull's ~2600 sampled tool poses for a ball out
  /// of reach took 555k LM iterations, none of which led anywhere (BM_PlanPull far:1), every start
  /// stalled 15 cm or more off. Starts that stall nearer often get there in the end (slowly, along
  /// a joint limit), and giving those up too changed the postures chosen: 5 of 100 random
  /// episodes lost their grasp.
  int presolve_stall_window = 10;
  double presolve_stall_drop = 0.2;
  double presolve_stall_error_m = 0.05;
  int rest_iterations = 20;                // SQP steps toward the rest posture after the pre-solve, >= 0
  double orientation_length_m = 0.2;       // metres per radian when mixing errors in the pre-solve, > 0
  /// Also run Ipopt when the pre-solve reached the pose (to trade the tolerances for a posture
  /// nearer rest). Off by default: Ipopt costs ~0.6 ms per iteration here and needs ~20 from
  /// there (bench "ik": ~15 ms median vs 0.25 ms). Ipopt always runs when the pre-solve fails.
  bool polish = false;
  /// Run Ipopt when the pre-solve failed (from the warm start and every restart). false: report
  /// the failure at once; for screening many candidate poses, most of them out of reach, where
  /// Ipopt's rescue costs ~0.6 ms per iteration and rarely succeeds. Needs presolve.
  bool ipopt_after_failed_presolve = true;
  /// Ipopt max_iter when polishing a pose the pre-solve already reached, > 0.
  int polish_max_iterations = 50;
  double polish_mu_init = 1e-6;            // Ipopt mu_init (monotone strategy) after a pre-solve, > 0
  int max_iterations = 200;                // Ipopt max_iter otherwise, > 0; an iteration cap, never a time limit
  double ipopt_tol = 1e-4;                 // Ipopt `tol` (scaled NLP error), > 0
  void Validate() const;                   // throws std::invalid_argument naming the field and its value
};

/// How a solve ended (an expected failure is a result, not an exception).
enum class IkStatus {
  kConverged,      // within position_tolerance_m and orientation_tolerance_rad (small slack)
  kUnreachable,    // the pre-solve stalled from every start and Ipopt did not reach the target either,
                   // or Ipopt reported (local) infeasibility: out of reach as far as a local solver can tell
  kMaxIterations,  // Ipopt hit max_iterations without a pose within tolerance
  kSolverError,    // Ipopt failed for a numerical or internal reason; q is the best posture found
};

/// Human-readable name of a status ("converged", "unreachable", ...).
const char* ToString(IkStatus status);

/// Result of one solve.
struct IkResult {
  IkStatus status = IkStatus::kSolverError;
  Eigen::VectorXd q;                   // full model q: the warm start with the chain joints replaced [rad]
  double position_error_m = 0.0;       // |p_target - p(q)| of the returned q [m]
  double orientation_error_rad = 0.0;  // angle of R_target * R(q)^T [rad]
  int iterations = 0;                  // pre-solve LM iterations + Ipopt iterations
  int ipopt_iterations = 0;            // Ipopt iterations alone (0 when Ipopt did not run)
  double rest_cost = 0.0;              // 0.5 sum_i w_i (q_i - q_rest_i)^2 of the returned q [1]
  double solve_ms = 0.0;               // wall time of the solve [ms], informational only
};

/// Cartesian solver for a KinematicChain, posed as the iCub's own (iKin, measured.md A.3):
/// unknowns = the chain joints; minimise the weighted distance to a rest posture subject to
/// |p_target - p(q)|^2 <= position_tolerance^2 and |log(R_target R(q)^T)|^2 <= orientation_tolerance^2,
/// with the joint limits as bounds; exact gradients from the analytic Jacobian and a
/// Gauss-Newton Hessian of the constraints. By default a cheap pre-solve (IkOptions::presolve)
/// reaches the pose and moves toward the rest posture first; Ipopt runs when that fails (or
/// always, with IkOptions::polish or without the pre-solve).
/// Owns an Ipopt application (pimpl); not thread-safe (MUMPS is not): one solver per thread.
class CartesianSolver {
 public:
  /// Keeps a copy of `chain`. `q_rest` is a full model q (chain.num_model_q() entries) whose
  /// chain joints are the rest posture. Throws std::invalid_argument on bad options, a wrong-size
  /// or non-finite q_rest, or a rest weight naming a joint not in the chain.
  CartesianSolver(const KinematicChain& chain, const Eigen::VectorXd& q_rest, const IkOptions& options = {});
  ~CartesianSolver();
  CartesianSolver(CartesianSolver&&) noexcept;
  CartesianSolver& operator=(CartesianSolver&&) noexcept;
  CartesianSolver(const CartesianSolver&) = delete;
  CartesianSolver& operator=(const CartesianSolver&) = delete;

  /// Solves for the chain tip pose X_BT_target (chain base frame B, normally the robot root R),
  /// warm-started from `q_current` (full model q; joints outside the chain are copied to the
  /// result unchanged, chain joints outside their limits are clamped first). Never throws for a
  /// solver failure (see IkStatus). Throws std::invalid_argument for a non-finite target or a
  /// rotation part that is not a rotation, or a wrong-size / non-finite q_current.
  IkResult Solve(const Eigen::Isometry3d& X_BT_target, const Eigen::VectorXd& q_current);

  const KinematicChain& chain() const;
  const IkOptions& options() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace toolbench::control
