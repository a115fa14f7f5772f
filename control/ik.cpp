#include "control/ik.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <utility>

#include <coin/IpIpoptApplication.hpp>
#include <coin/IpSolveStatistics.hpp>
#include <coin/IpTNLP.hpp>

#include "common/check.h"

namespace toolbench::control {
namespace {

// Constraint values may exceed their bound by this fraction (Ipopt constr_viol_tol on the
// normalised constraints below), so the reported errors may exceed the tolerances by ~0.5 %.
constexpr double kConstraintSlack = 0.01;
// The pre-solve stops well inside the constraint balls so Ipopt starts strictly feasible.
constexpr double kPresolveInside = 0.2;
// LM damping limits: beyond kMaxDamping the steps are too small to matter, the start is stuck.
constexpr double kInitialDamping = 1e-3;
constexpr double kMinDamping = 1e-9;
constexpr double kMaxDamping = 1e4;
// Largest joint change of one rest-refinement step [rad]: keeps the linearisation valid.
constexpr double kMaxRestStep = 0.2;
// Longest chain the solver takes: the pre-solve's steps live in fixed-capacity vectors (no heap
// in the hot loop).
constexpr int kMaxChainJoints = 16;
using SmallVector = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxChainJoints, 1>;

// First primes, for the Halton restart points (one base per chain joint, cycled beyond ten).
constexpr int kPrimes[] = {2, 3, 5, 7, 11, 13, 17, 19, 23, 29, 31, 37, 41, 43, 47};

double Halton(int index, int base) {
  double f = 1.0;
  double r = 0.0;
  while (index > 0) {
    f /= base;
    r += f * (index % base);
    index /= base;
  }
  return r;
}

using Matrix6 = Eigen::Matrix<double, 6, 6>;
using Vector6 = Eigen::Matrix<double, 6, 1>;

// The damped least-squares step dq = Jw^T (A + damping I)^-1 ew for A = Jw Jw^T, by a 6 x 6
// Cholesky factorisation written out with its sizes known at compile time; false when
// A + damping I is not numerically positive definite. BM_PlanPull (path Ipopt off), CPU of one
// plan, run by turns with the n x n primal (a hand-written 10 x 10 Cholesky of J^T J + damping):
// near ball 518-646 -> 402-408 ms, far 625-678 -> 502-532 ms (Eigen's LLT for this 6 x 6: far
// 552-601 ms, its generic loops cost more than the arithmetic).
bool DampedStep(const Matrix6& A, const ChainJacobian& Jw, const Vector6& ew, double damping, SmallVector& dq) {
  double L[6][6];
  double inv_diag[6];  // 1 / L(j, j)
  for (int j = 0; j < 6; ++j) {
    double d = A(j, j) + damping;
    for (int k = 0; k < j; ++k) d -= L[j][k] * L[j][k];
    if (!(d > 0.0)) return false;
    inv_diag[j] = 1.0 / std::sqrt(d);
    for (int i = j + 1; i < 6; ++i) {
      double v = A(i, j);
      for (int k = 0; k < j; ++k) v -= L[i][k] * L[j][k];
      L[i][j] = v * inv_diag[j];
    }
  }
  double y[6];
  for (int i = 0; i < 6; ++i) {  // L z = ew
    double v = ew[i];
    for (int k = 0; k < i; ++k) v -= L[i][k] * y[k];
    y[i] = v * inv_diag[i];
  }
  for (int i = 5; i >= 0; --i) {  // L^T y = z
    double v = y[i];
    for (int k = i + 1; k < 6; ++k) v -= L[k][i] * y[k];
    y[i] = v * inv_diag[i];
  }
  dq.noalias() = Jw.transpose() * Eigen::Map<const Vector6>(y);
  return true;
}

struct PoseErrors {
  Eigen::Vector3d e_p;  // p_target - p [m]
  Eigen::Vector3d e_r;  // log(R_target R^T) [rad]
};

PoseErrors ComputeErrors(const Eigen::Isometry3d& X_target, const Eigen::Isometry3d& X) {
  return {X_target.translation() - X.translation(), OrientationError(X_target.linear(), X.linear())};
}

}  // namespace

void IkOptions::Validate() const {
  auto require = [](bool ok, const char* field, auto value, const char* expected) {
    if (!ok) ThrowInvalid("IkOptions: ", field, " = ", value, " is not valid (expected ", expected, ")");
  };
  require(std::isfinite(position_tolerance_m) && position_tolerance_m > 0, "position_tolerance_m",
          position_tolerance_m, "> 0");
  require(std::isfinite(orientation_tolerance_rad) && orientation_tolerance_rad > 0, "orientation_tolerance_rad",
          orientation_tolerance_rad, "> 0");
  for (const auto& [joint, weight] : rest_weights) {
    if (!(std::isfinite(weight) && weight >= 0)) {
      ThrowInvalid("IkOptions: rest_weights['", joint, "'] = ", weight, " is not valid (expected >= 0)");
    }
  }
  require(std::isfinite(default_rest_weight) && default_rest_weight >= 0, "default_rest_weight", default_rest_weight,
          ">= 0");
  require(presolve_iterations > 0, "presolve_iterations", presolve_iterations, "> 0");
  require(presolve_stall_window >= 0, "presolve_stall_window", presolve_stall_window, ">= 0");
  require(presolve_stall_drop >= 0 && presolve_stall_drop < 1, "presolve_stall_drop", presolve_stall_drop,
          "in [0, 1)");
  require(std::isfinite(presolve_stall_error_m) && presolve_stall_error_m >= 0, "presolve_stall_error_m",
          presolve_stall_error_m, ">= 0");
  require(rest_iterations >= 0, "rest_iterations", rest_iterations, ">= 0");
  require(presolve_restarts >= 0, "presolve_restarts", presolve_restarts, ">= 0");
  require(std::isfinite(orientation_length_m) && orientation_length_m > 0, "orientation_length_m",
          orientation_length_m, "> 0");
  require(std::isfinite(polish_mu_init) && polish_mu_init > 0, "polish_mu_init", polish_mu_init, "> 0");
  require(max_iterations > 0, "max_iterations", max_iterations, "> 0");
  require(polish_max_iterations > 0, "polish_max_iterations", polish_max_iterations, "> 0");
  require(std::isfinite(ipopt_tol) && ipopt_tol > 0, "ipopt_tol", ipopt_tol, "> 0");
}

const char* ToString(IkStatus status) {
  switch (status) {
    case IkStatus::kConverged: return "converged";
    case IkStatus::kUnreachable: return "unreachable";
    case IkStatus::kMaxIterations: return "max_iterations";
    case IkStatus::kSolverError: return "solver_error";
  }
  return "unknown";
}

namespace {

// The NLP handed to Ipopt. Constraints are normalised by the squared tolerances, so both are
// "<= 1" and Ipopt's absolute constr_viol_tol means the same for metres and radians:
//   g0 = |p_target - p(q)|^2 / tol_p^2,   g1 = |log(R_target R(q)^T)|^2 / tol_r^2.
// Gradients: d|e_p|^2/dq = -2 e_p^T J_v; d|e_r|^2/dq = -2 e_r^T J_w exactly (the inverse
// right Jacobian of SO(3) leaves e_r unchanged: e_r^T [e_r] = 0). Hessian: Gauss-Newton,
// 2 J_v^T J_v and 2 J_w^T J_w, plus the constant rest-posture diagonal.
class IkNlp : public Ipopt::TNLP {
 public:
  IkNlp(const KinematicChain& chain, const Eigen::VectorXd& weights, const Eigen::VectorXd& q_rest)
      : chain_(chain), weights_(weights), q_rest_(q_rest), n_(chain.num_joints()), q_(n_), J_(6, n_),
        x_best_(n_) {}

  void Setup(const Eigen::Isometry3d& X_target, const Eigen::VectorXd& q_start, double tol_p, double tol_r) {
    X_target_ = X_target;
    q_start_ = q_start;
    inv_tol_p2_ = 1.0 / (tol_p * tol_p);
    inv_tol_r2_ = 1.0 / (tol_r * tol_r);
    x_best_ = q_start;
    have_solution_ = false;
    cached_ = false;
  }
  const Eigen::VectorXd& solution() const { return x_best_; }
  bool have_solution() const { return have_solution_; }

  bool get_nlp_info(Ipopt::Index& n, Ipopt::Index& m, Ipopt::Index& nnz_jac_g, Ipopt::Index& nnz_h_lag,
                    IndexStyleEnum& index_style) override {
    n = n_;
    m = 2;
    nnz_jac_g = 2 * n_;
    nnz_h_lag = n_ * (n_ + 1) / 2;
    index_style = C_STYLE;
    return true;
  }

  bool get_bounds_info(Ipopt::Index n, Ipopt::Number* x_l, Ipopt::Number* x_u, Ipopt::Index m, Ipopt::Number* g_l,
                       Ipopt::Number* g_u) override {
    TOOLBENCH_DEMAND(n == n_ && m == 2);
    for (int i = 0; i < n_; ++i) {
      x_l[i] = std::isfinite(chain_.lower()[i]) ? chain_.lower()[i] : -2e19;
      x_u[i] = std::isfinite(chain_.upper()[i]) ? chain_.upper()[i] : 2e19;
    }
    for (int k = 0; k < 2; ++k) {
      g_l[k] = -2e19;  // no lower bound (Ipopt's nlp_lower_bound_inf is -1e19)
      g_u[k] = 1.0;
    }
    return true;
  }

  bool get_starting_point(Ipopt::Index n, bool init_x, Ipopt::Number* x, bool init_z, Ipopt::Number*, Ipopt::Number*,
                          Ipopt::Index, bool init_lambda, Ipopt::Number*) override {
    if (!init_x || init_z || init_lambda) return false;
    for (int i = 0; i < n; ++i) x[i] = q_start_[i];
    return true;
  }

  bool eval_f(Ipopt::Index n, const Ipopt::Number* x, bool, Ipopt::Number& obj_value) override {
    double f = 0.0;
    for (int i = 0; i < n; ++i) f += 0.5 * weights_[i] * (x[i] - q_rest_[i]) * (x[i] - q_rest_[i]);
    obj_value = f;
    return true;
  }

  bool eval_grad_f(Ipopt::Index n, const Ipopt::Number* x, bool, Ipopt::Number* grad_f) override {
    for (int i = 0; i < n; ++i) grad_f[i] = weights_[i] * (x[i] - q_rest_[i]);
    return true;
  }

  bool eval_g(Ipopt::Index n, const Ipopt::Number* x, bool new_x, Ipopt::Index, Ipopt::Number* g) override {
    Update(n, x, new_x);
    g[0] = errors_.e_p.squaredNorm() * inv_tol_p2_;
    g[1] = errors_.e_r.squaredNorm() * inv_tol_r2_;
    return true;
  }

  bool eval_jac_g(Ipopt::Index n, const Ipopt::Number* x, bool new_x, Ipopt::Index, Ipopt::Index,
                  Ipopt::Index* i_row, Ipopt::Index* j_col, Ipopt::Number* values) override {
    if (values == nullptr) {
      for (int k = 0; k < 2; ++k) {
        for (int i = 0; i < n_; ++i) {
          i_row[k * n_ + i] = k;
          j_col[k * n_ + i] = i;
        }
      }
      return true;
    }
    Update(n, x, new_x);
    for (int i = 0; i < n_; ++i) {
      values[i] = -2.0 * errors_.e_p.dot(J_.col(i).head<3>()) * inv_tol_p2_;
      values[n_ + i] = -2.0 * errors_.e_r.dot(J_.col(i).tail<3>()) * inv_tol_r2_;
    }
    return true;
  }

  bool eval_h(Ipopt::Index n, const Ipopt::Number* x, bool new_x, Ipopt::Number obj_factor, Ipopt::Index,
              const Ipopt::Number* lambda, bool, Ipopt::Index, Ipopt::Index* i_row, Ipopt::Index* j_col,
              Ipopt::Number* values) override {
    if (values == nullptr) {
      int k = 0;
      for (int r = 0; r < n_; ++r) {
        for (int c = 0; c <= r; ++c, ++k) {
          i_row[k] = r;
          j_col[k] = c;
        }
      }
      return true;
    }
    Update(n, x, new_x);
    const double a = 2.0 * lambda[0] * inv_tol_p2_;
    const double b = 2.0 * lambda[1] * inv_tol_r2_;
    int k = 0;
    for (int r = 0; r < n_; ++r) {
      for (int c = 0; c <= r; ++c, ++k) {
        values[k] = a * J_.col(r).head<3>().dot(J_.col(c).head<3>()) + b * J_.col(r).tail<3>().dot(J_.col(c).tail<3>());
        if (r == c) values[k] += obj_factor * weights_[r];
      }
    }
    return true;
  }

  void finalize_solution(Ipopt::SolverReturn, Ipopt::Index n, const Ipopt::Number* x, const Ipopt::Number*,
                         const Ipopt::Number*, Ipopt::Index, const Ipopt::Number*, const Ipopt::Number*,
                         Ipopt::Number, const Ipopt::IpoptData*, Ipopt::IpoptCalculatedQuantities*) override {
    for (int i = 0; i < n; ++i) x_best_[i] = x[i];
    have_solution_ = x_best_.allFinite();
  }

 private:
  void Update(Ipopt::Index n, const Ipopt::Number* x, bool new_x) {
    if (cached_ && !new_x) return;
    for (int i = 0; i < n; ++i) q_[i] = x[i];
    Eigen::Isometry3d X;
    chain_.Evaluate(q_, &X, &J_);
    errors_ = ComputeErrors(X_target_, X);
    cached_ = true;
  }

  const KinematicChain& chain_;
  const Eigen::VectorXd& weights_;
  const Eigen::VectorXd& q_rest_;
  const int n_;
  Eigen::Isometry3d X_target_ = Eigen::Isometry3d::Identity();
  Eigen::VectorXd q_start_;
  double inv_tol_p2_ = 1.0;
  double inv_tol_r2_ = 1.0;
  Eigen::VectorXd q_;
  ChainJacobian J_;
  PoseErrors errors_;
  bool cached_ = false;
  Eigen::VectorXd x_best_;
  bool have_solution_ = false;
};

}  // namespace

struct CartesianSolver::Impl {
  KinematicChain chain;
  IkOptions options;
  Eigen::VectorXd q_rest;   // chain values
  Eigen::VectorXd weights;  // chain values
  Ipopt::SmartPtr<IkNlp> nlp;
  Ipopt::SmartPtr<Ipopt::IpoptApplication> app;
  // Pre-solve workspace (no allocation per iteration).
  ChainJacobian J;
  ChainJacobian Jw;         // J with its orientation rows weighted by orientation_length_m
  ChainJacobian Jw_active;  // Jw with the columns of joints frozen at a limit zeroed
  Matrix6 A;                // Jw Jw^T
  Matrix6 A_active;         // Jw_active Jw_active^T
  Vector6 ew;               // [e_p; L e_r]
  SmallVector dq;
  Eigen::VectorXd q_try;

  Impl(const KinematicChain& c, const IkOptions& o) : chain(c), options(o) {}

  bool WithinTolerance(const PoseErrors& e, double factor) const {
    return e.e_p.norm() <= factor * options.position_tolerance_m &&
           e.e_r.norm() <= factor * options.orientation_tolerance_rad;
  }

  double Cost(const PoseErrors& e) const {
    const double L = options.orientation_length_m;
    return e.e_p.squaredNorm() + L * L * e.e_r.squaredNorm();
  }

  // Levenberg-Marquardt on the 6-D pose error from q (clamped to the limits after every step).
  // Returns true when the pose is well inside the tolerances; q holds the best iterate.
  bool Presolve(const Eigen::Isometry3d& X_target, Eigen::VectorXd& q, int& iterations) {
    const int n = chain.num_joints();
    const double L = options.orientation_length_m;
    Eigen::Isometry3d X;
    chain.Evaluate(q, &X, &J);
    PoseErrors e = ComputeErrors(X_target, X);
    double cost = Cost(e);
    double damping = kInitialDamping;
    const int window = options.presolve_stall_window;
    double window_cost = cost;  // the cost `window` iterations ago
    for (int it = 0; it < options.presolve_iterations; ++it) {
      if (WithinTolerance(e, kPresolveInside)) return true;
      if (window > 0 && it > 0 && it % window == 0) {
        const double hopeless = options.presolve_stall_error_m * options.presolve_stall_error_m;
        if (cost > hopeless && cost > (1.0 - options.presolve_stall_drop) * window_cost) return false;  // stalled
        window_cost = cost;
      }
      ++iterations;
      // The LM step on the weighted residual ew = [e_p; L e_r] (Jw: J's rows weighted alike),
      // dq = (Jw^T Jw + damping I)^-1 Jw^T ew, solved in its dual form
      // dq = Jw^T (Jw Jw^T + damping I)^-1 ew (the same step, by the push-through identity): a
      // 6 x 6 factorisation instead of an n x n one, whose n - 6 null directions hold nothing
      // but the damping (down to kMinDamping).
      Jw = J;
      Jw.bottomRows<3>() *= L;
      ew << e.e_p, L * e.e_r;
      A.noalias() = Jw.lazyProduct(Jw.transpose());
      bool improved = false;
      while (damping <= kMaxDamping) {
        if (!DampedStep(A, Jw, ew, damping, dq)) {  // numerically indefinite: damp more
          damping *= 4.0;
          continue;
        }
        // Projected Newton: joints at a limit that the step pushes outward are frozen (their
        // columns of Jw zeroed) and the step re-solved without them; clamping alone stalls LM
        // against the limits.
        bool frozen = false;
        for (int i = 0; i < n; ++i) {
          if ((q[i] <= chain.lower()[i] && dq[i] < 0) || (q[i] >= chain.upper()[i] && dq[i] > 0)) {
            if (!frozen) Jw_active = Jw;
            Jw_active.col(i).setZero();
            frozen = true;
          }
        }
        if (frozen) {
          A_active.noalias() = Jw_active.lazyProduct(Jw_active.transpose());
          if (!DampedStep(A_active, Jw_active, ew, damping, dq)) {
            damping *= 4.0;
            continue;
          }
        }
        q_try = (q + dq).cwiseMax(chain.lower()).cwiseMin(chain.upper());
        Eigen::Isometry3d X_try;
        chain.Evaluate(q_try, &X_try, nullptr);
        const PoseErrors e_try = ComputeErrors(X_target, X_try);
        const double cost_try = Cost(e_try);
        if (cost_try < cost) {
          q = q_try;
          cost = cost_try;
          damping = std::max(damping / 3.0, kMinDamping);
          improved = true;
          break;
        }
        damping *= 4.0;
      }
      if (!improved) return false;
      chain.Evaluate(q, &X, &J);
      e = ComputeErrors(X_target, X);
    }
    return WithinTolerance(e, kPresolveInside);
  }

  // Moves a posture that reaches the target toward the rest posture along the pose manifold:
  // Gauss-Newton SQP steps of  min 0.5 (q - q_rest)^T W (q - q_rest)  s.t. pose error = 0,
  //   dq = -(q - q_rest) + W^-1 J^T (J W^-1 J^T)^-1 (e + J (q - q_rest)),
  // with joints at a limit that the step pushes outward frozen (W^-1 = 0), the step capped and
  // the pose re-reached by Presolve. Cheap (microseconds), so Ipopt starts near its optimum.
  void RestRefine(const Eigen::Isometry3d& X_target, Eigen::VectorXd& q, int& iterations) {
    const int n = chain.num_joints();
    const double L = options.orientation_length_m;
    Eigen::VectorXd w_inv(n);
    Eigen::Isometry3d X;
    for (int it = 0; it < options.rest_iterations; ++it) {
      ++iterations;
      chain.Evaluate(q, &X, &J);
      const PoseErrors e = ComputeErrors(X_target, X);
      Eigen::Matrix<double, 6, 1> e6;
      e6 << e.e_p, L * e.e_r;
      J.bottomRows<3>() *= L;
      const Eigen::VectorXd d = q - q_rest;
      for (int i = 0; i < n; ++i) w_inv[i] = 1.0 / std::max(weights[i], 1e-6);
      for (int pass = 0; pass < 2; ++pass) {
        const Eigen::Matrix<double, 6, 6> A =
            J * w_inv.asDiagonal() * J.transpose() + 1e-9 * Eigen::Matrix<double, 6, 6>::Identity();
        const Eigen::Matrix<double, 6, 1> nu = A.ldlt().solve(e6 + J * d);
        dq = -d + w_inv.asDiagonal() * (J.transpose() * nu);
        for (int i = 0; i < n; ++i) {
          dq[i] = w_inv[i] == 0.0 ? 0.0 : dq[i];
          if ((q[i] <= chain.lower()[i] && dq[i] < 0) || (q[i] >= chain.upper()[i] && dq[i] > 0)) w_inv[i] = 0.0;
        }
      }
      const double step = dq.cwiseAbs().maxCoeff();
      if (step < 1e-6) break;
      if (step > kMaxRestStep) dq *= kMaxRestStep / step;
      const Eigen::VectorXd q_before = q;
      q = (q + dq).cwiseMax(chain.lower()).cwiseMin(chain.upper());
      int lm_iterations = 0;
      if (!Presolve(X_target, q, lm_iterations)) {
        q = q_before;  // the pose was lost: keep the last posture that reached it
        break;
      }
      iterations += lm_iterations;
    }
  }
};

CartesianSolver::CartesianSolver(const KinematicChain& chain, const Eigen::VectorXd& q_rest, const IkOptions& options)
    : impl_(std::make_unique<Impl>(chain, options)) {
  options.Validate();
  if (q_rest.size() != chain.num_model_q() || !q_rest.allFinite()) {
    ThrowInvalid("CartesianSolver: q_rest has ", q_rest.size(), " entries", q_rest.allFinite() ? "" : " (non-finite)",
                 ", expected ", chain.num_model_q(), " finite values");
  }
  const int n = chain.num_joints();
  if (n > kMaxChainJoints) {
    ThrowInvalid("CartesianSolver: the chain ", chain.base_link(), " -> ", chain.tip_link(), " has ", n,
                 " joints; at most ", kMaxChainJoints, " are supported");
  }
  for (const auto& [joint, weight] : options.rest_weights) {
    (void)weight;
    if (std::find(chain.joint_names().begin(), chain.joint_names().end(), joint) == chain.joint_names().end()) {
      ThrowInvalid("CartesianSolver: rest_weights names joint '", joint, "', which is not in the chain ",
                   chain.base_link(), " -> ", chain.tip_link());
    }
  }
  Impl& m = *impl_;
  m.q_rest = chain.ChainQ(q_rest).cwiseMax(chain.lower()).cwiseMin(chain.upper());
  m.weights.resize(n);
  for (int i = 0; i < n; ++i) {
    const auto it = options.rest_weights.find(chain.joint_names()[i]);
    m.weights[i] = it != options.rest_weights.end() ? it->second : options.default_rest_weight;
  }
  m.J.resize(6, n);
  m.Jw.resize(6, n);
  m.Jw_active.resize(6, n);
  m.dq.resize(n);
  m.q_try.resize(n);
  m.nlp = new IkNlp(m.chain, m.weights, m.q_rest);
  // No console journal: Ipopt prints nothing (style.md section 8).
  m.app = new Ipopt::IpoptApplication(/*create_console_out=*/false);
  Ipopt::OptionsList& o = *m.app->Options();
  o.SetIntegerValue("print_level", 0);
  o.SetStringValue("sb", "yes");
  o.SetStringValue("hessian_approximation", "exact");
  o.SetStringValue("mu_strategy", "adaptive");
  o.SetIntegerValue("max_iter", options.max_iterations);
  o.SetNumericValue("tol", options.ipopt_tol);
  o.SetNumericValue("constr_viol_tol", kConstraintSlack);
  if (options.presolve) {
    // The start is (nearly) optimal for the pose: keep Ipopt from pushing it off the limits
    // and from re-centring it with a large initial barrier.
    o.SetNumericValue("bound_push", 1e-8);
    o.SetNumericValue("bound_frac", 1e-8);
    o.SetNumericValue("slack_bound_push", 1e-8);
    o.SetNumericValue("slack_bound_frac", 1e-8);
  }
  // Initialize("") rather than Initialize(): do not read an ipopt.opt from the cwd.
  const Ipopt::ApplicationReturnStatus init = m.app->Initialize("");
  TOOLBENCH_DEMAND(init == Ipopt::Solve_Succeeded);
}

CartesianSolver::~CartesianSolver() = default;
CartesianSolver::CartesianSolver(CartesianSolver&&) noexcept = default;
CartesianSolver& CartesianSolver::operator=(CartesianSolver&&) noexcept = default;

const KinematicChain& CartesianSolver::chain() const { return impl_->chain; }
const IkOptions& CartesianSolver::options() const { return impl_->options; }

IkResult CartesianSolver::Solve(const Eigen::Isometry3d& X_BT_target, const Eigen::VectorXd& q_current) {
  Impl& m = *impl_;
  const KinematicChain& chain = m.chain;
  if (!X_BT_target.matrix().allFinite()) {
    ThrowInvalid("CartesianSolver::Solve: X_BT_target is not finite:\n", X_BT_target.matrix());
  }
  const Eigen::Matrix3d R = X_BT_target.linear();
  if (!(R.transpose() * R).isApprox(Eigen::Matrix3d::Identity(), 1e-6) || R.determinant() < 0) {
    ThrowInvalid("CartesianSolver::Solve: X_BT_target's rotation is not a rotation matrix:\n", R);
  }
  if (q_current.size() != chain.num_model_q() || !q_current.allFinite()) {
    ThrowInvalid("CartesianSolver::Solve: q_current has ", q_current.size(), " entries",
                 q_current.allFinite() ? "" : " (non-finite)", ", expected ", chain.num_model_q(), " finite values");
  }
  const auto start = std::chrono::steady_clock::now();
  IkResult result;
  const Eigen::VectorXd q_warm = chain.ChainQ(q_current).cwiseMax(chain.lower()).cwiseMin(chain.upper());
  Eigen::VectorXd q = q_warm;
  bool found = false;
  bool stalled = false;
  if (m.options.presolve) {
    found = m.Presolve(X_BT_target, q, result.iterations);
    Eigen::VectorXd q_best = q;
    Eigen::Isometry3d X;
    chain.Evaluate(q, &X, nullptr);
    double best_cost = m.Cost(ComputeErrors(X_BT_target, X));
    // Deterministic restarts (no RNG, so a solve depends on its inputs only): the rest posture,
    // then Halton points spread over the limits box.
    for (int r = 0; !found && r < m.options.presolve_restarts; ++r) {
      if (r == 0) {
        q = m.q_rest;
      } else {
        for (int i = 0; i < q.size(); ++i) {
          const double lo = std::isfinite(chain.lower()[i]) ? chain.lower()[i] : -M_PI;
          const double hi = std::isfinite(chain.upper()[i]) ? chain.upper()[i] : M_PI;
          const double u = Halton(r, kPrimes[i % std::size(kPrimes)]);
          q[i] = lo + u * (hi - lo);
        }
      }
      found = m.Presolve(X_BT_target, q, result.iterations);
      chain.Evaluate(q, &X, nullptr);
      const double cost = m.Cost(ComputeErrors(X_BT_target, X));
      if (found || cost < best_cost) {
        best_cost = cost;
        q_best = q;
      }
    }
    q = q_best;
    stalled = !found;
    if (found) m.RestRefine(X_BT_target, q, result.iterations);
  }

  Eigen::VectorXd q_final = q;
  Ipopt::ApplicationReturnStatus ipopt_status = Ipopt::Solve_Succeeded;
  const bool run_ipopt =
      !m.options.presolve || (found ? m.options.polish : m.options.ipopt_after_failed_presolve);
  if (run_ipopt) {
    m.nlp->Setup(X_BT_target, q, m.options.position_tolerance_m, m.options.orientation_tolerance_rad);
    // From a reached pose Ipopt only has to slide along the constraints: a small monotone
    // barrier. From anywhere else its defaults (adaptive mu from 0.1) do better.
    Ipopt::OptionsList& o = *m.app->Options();
    o.SetIntegerValue("max_iter", found ? m.options.polish_max_iterations : m.options.max_iterations);
    o.SetStringValue("mu_strategy", found ? "monotone" : "adaptive");
    o.SetNumericValue("mu_init", found ? m.options.polish_mu_init : 0.1);
    try {
      ipopt_status = m.app->OptimizeTNLP(Ipopt::SmartPtr<Ipopt::TNLP>(Ipopt::GetRawPtr(m.nlp)));
    } catch (...) {
      // Ipopt reports its own failures by status; anything thrown is an internal failure, and
      // a solver failure is a result (style.md section 6), never an exception to the caller.
      ipopt_status = Ipopt::NonIpopt_Exception_Thrown;
    }
    const Ipopt::SmartPtr<Ipopt::SolveStatistics> stats = m.app->Statistics();
    if (Ipopt::IsValid(stats)) result.ipopt_iterations = stats->IterationCount();
    result.iterations += result.ipopt_iterations;
    if (m.nlp->have_solution()) {
      const Eigen::VectorXd& x = m.nlp->solution();
      Eigen::Isometry3d X_ipopt;
      Eigen::Isometry3d X_pre;
      chain.Evaluate(x, &X_ipopt, nullptr);
      chain.Evaluate(q, &X_pre, nullptr);
      const PoseErrors e_ipopt = ComputeErrors(X_BT_target, X_ipopt);
      // Keep Ipopt's answer unless it lost a pose the pre-solve had reached.
      if (m.WithinTolerance(e_ipopt, 1.0 + kConstraintSlack) || !found ||
          m.Cost(e_ipopt) <= m.Cost(ComputeErrors(X_BT_target, X_pre))) {
        q_final = x.cwiseMax(chain.lower()).cwiseMin(chain.upper());
      }
      // Ipopt often ends near a pose the pre-solve could not find from its starts: finish it.
      if (m.options.presolve && !found && !m.WithinTolerance(e_ipopt, 1.0 + kConstraintSlack)) {
        Eigen::VectorXd q_lm = q_final;
        if (m.Presolve(X_BT_target, q_lm, result.iterations)) q_final = q_lm;
      }
    }
  }

  Eigen::Isometry3d X_final;
  chain.Evaluate(q_final, &X_final, nullptr);
  const PoseErrors e = ComputeErrors(X_BT_target, X_final);
  result.q = chain.ModelQ(q_current, q_final);
  result.position_error_m = e.e_p.norm();
  result.orientation_error_rad = e.e_r.norm();
  result.rest_cost = 0.5 * (q_final - m.q_rest).dot(m.weights.asDiagonal() * (q_final - m.q_rest));
  if (m.WithinTolerance(e, 1.0 + kConstraintSlack)) {
    result.status = IkStatus::kConverged;
  } else if (!run_ipopt) {
    result.status = stalled ? IkStatus::kUnreachable : IkStatus::kMaxIterations;
  } else if (stalled && (ipopt_status == Ipopt::Maximum_Iterations_Exceeded || ipopt_status >= 0)) {
    // Neither the pre-solve from every start nor Ipopt got there: out of reach, as far as
    // a local solver can tell.
    result.status = IkStatus::kUnreachable;
  } else {
    switch (ipopt_status) {
      case Ipopt::Maximum_Iterations_Exceeded:
      case Ipopt::Maximum_CpuTime_Exceeded:
        result.status = IkStatus::kMaxIterations;
        break;
      case Ipopt::Solve_Succeeded:
      case Ipopt::Solved_To_Acceptable_Level:
      case Ipopt::Feasible_Point_Found:
      case Ipopt::Infeasible_Problem_Detected:
      case Ipopt::Restoration_Failed:
      case Ipopt::Search_Direction_Becomes_Too_Small:
        result.status = IkStatus::kUnreachable;
        break;
      default:
        result.status = IkStatus::kSolverError;
        break;
    }
  }
  result.solve_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  return result;
}

}  // namespace toolbench::control
