#include "perception/superquadric.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <vector>

#include <Eigen/Eigenvalues>
#include <coin/IpIpoptApplication.hpp>
#include <coin/IpSolveStatistics.hpp>
#include <coin/IpTNLP.hpp>

#include "common/check.h"
#include "common/rng.h"
#include "perception/internal/superquadric_cost.h"

namespace toolbench::perception {
namespace internal {

Eigen::Matrix3d ExpSo3(const Eigen::Vector3d& r) {
  const double theta = r.norm();
  if (theta < 1e-12) return Eigen::Matrix3d::Identity();
  return Eigen::AngleAxisd(theta, r / theta).toRotationMatrix();
}

namespace {

Eigen::Matrix3d Hat(const Eigen::Vector3d& v) {
  Eigen::Matrix3d m;
  m << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return m;
}

// Right Jacobian of SO(3): d Exp(s) w / ds = -Exp(s) [w]x Jr(s).
Eigen::Matrix3d RightJacobian(const Eigen::Vector3d& s) {
  const double theta = s.norm();
  const Eigen::Matrix3d K = Hat(s);
  if (theta < 1e-6) return Eigen::Matrix3d::Identity() - 0.5 * K + K * K / 6.0;
  const double t2 = theta * theta;
  return Eigen::Matrix3d::Identity() - (1.0 - std::cos(theta)) / t2 * K + (theta - std::sin(theta)) / (t2 * theta) * K * K;
}

// |v| clamped away from zero (keeps logs and divisions finite) with the sign of v.
double SafeSigned(double v, double floor) { return v < 0.0 ? -std::max(-v, floor) : std::max(v, floor); }

}  // namespace

double SuperquadricCost(const SqParams& x, const Eigen::Matrix3Xd& points, const Eigen::Matrix3d& R0,
                        SqParams* gradient) {
  const double a1 = x[0], a2 = x[1], a3 = x[2], e1 = x[3], e2 = x[4];
  const Eigen::Vector3d r = x.segment<3>(5);
  const Eigen::Vector3d t = x.segment<3>(8);
  const Eigen::Matrix3d E = ExpSo3(-r);        // q = E * R0^T * (p - t)
  const Eigen::Matrix3d M = E * R0.transpose();
  const double k1 = 2.0 / e1, k2 = 2.0 / e2, p12 = e2 / e1;
  constexpr double kFloor = 1e-9;  // relative floor of |x/a| (the point on a symmetry plane)

  double sum_r2 = 0.0;
  Eigen::Vector3d g_size = Eigen::Vector3d::Zero();  // sum 2 res dG/da
  double g_e1 = 0.0, g_e2 = 0.0;
  Eigen::Vector3d g_rot = Eigen::Vector3d::Zero();    // sum 2 res (w x v), times Jr at the end
  Eigen::Vector3d g_q_world = Eigen::Vector3d::Zero();  // sum 2 res M^T dG/dq
  const Eigen::Index n = points.cols();
  for (Eigen::Index i = 0; i < n; ++i) {
    const Eigen::Vector3d d = points.col(i) - t;
    const Eigen::Vector3d q = M * d;
    const double qx = SafeSigned(q.x(), kFloor * a1), qy = SafeSigned(q.y(), kFloor * a2),
                 qz = SafeSigned(q.z(), kFloor * a3);
    const double ax = std::abs(qx) / a1, ay = std::abs(qy) / a2, az = std::abs(qz) / a3;
    const double lax = std::log(ax), lay = std::log(ay), laz = std::log(az);
    const double A = std::exp(k2 * lax), B = std::exp(k2 * lay), C = std::exp(k1 * laz);
    const double u = A + B;
    const double lu = std::log(u);
    const double W = std::exp(p12 * lu);
    const double F = W + C;
    const double G = std::exp(e1 * std::log(F));
    const double res = G - 1.0;
    sum_r2 += res * res;
    if (gradient == nullptr) continue;
    const double dG_dF = e1 * G / F;
    const double dF_du = p12 * W / u;
    const double dA_dx = k2 * A / qx, dB_dy = k2 * B / qy, dC_dz = k1 * C / qz;
    const double two_res = 2.0 * res;
    g_size.x() += two_res * dG_dF * dF_du * (-k2 * A / a1);
    g_size.y() += two_res * dG_dF * dF_du * (-k2 * B / a2);
    g_size.z() += two_res * dG_dF * (-k1 * C / a3);
    const double dF_de1 = W * lu * (-e2 / (e1 * e1)) + C * laz * (-2.0 / (e1 * e1));
    g_e1 += two_res * (G * std::log(F) + dG_dF * dF_de1);
    const double dA_de2 = A * lax * (-2.0 / (e2 * e2)), dB_de2 = B * lay * (-2.0 / (e2 * e2));
    const double dW_de2 = W * (lu / e1 + p12 * (dA_de2 + dB_de2) / u);
    g_e2 += two_res * dG_dF * dW_de2;
    const Eigen::Vector3d dG_dq(dG_dF * dF_du * dA_dx, dG_dF * dF_du * dB_dy, dG_dF * dC_dz);
    // dq/dr = E [v]x Jr(-r) with v = R0^T d; the row dG/dq^T E [v]x equals (w x v)^T, w = E^T dG/dq.
    const Eigen::Vector3d v = R0.transpose() * d;
    const Eigen::Vector3d w = E.transpose() * dG_dq;
    g_rot += two_res * w.cross(v);
    g_q_world += two_res * (M.transpose() * dG_dq);
  }
  const double volume = a1 * a2 * a3;
  const double inv_n = 1.0 / static_cast<double>(n);
  const double cost = volume * inv_n * sum_r2;
  if (gradient != nullptr) {
    SqParams& g = *gradient;
    g[0] = a2 * a3 * inv_n * sum_r2 + volume * inv_n * g_size.x();
    g[1] = a1 * a3 * inv_n * sum_r2 + volume * inv_n * g_size.y();
    g[2] = a1 * a2 * inv_n * sum_r2 + volume * inv_n * g_size.z();
    g[3] = volume * inv_n * g_e1;
    g[4] = volume * inv_n * g_e2;
    g.segment<3>(5) = volume * inv_n * (RightJacobian(-r).transpose() * g_rot);
    g.segment<3>(8) = -volume * inv_n * g_q_world;  // dq/dt = -M
  }
  return cost;
}

}  // namespace internal

namespace {

using internal::SqParams;

class SuperquadricNlp : public Ipopt::TNLP {
 public:
  SuperquadricNlp(const Eigen::Matrix3Xd& points, const Eigen::Matrix3d& R0, const SqParams& x0, const SqParams& lower,
                  const SqParams& upper)
      : points_(points), R0_(R0), x0_(x0), lower_(lower), upper_(upper), x_best_(x0) {}

  const SqParams& solution() const { return x_best_; }
  double cost() const { return cost_; }

  bool get_nlp_info(Ipopt::Index& n, Ipopt::Index& m, Ipopt::Index& nnz_jac_g, Ipopt::Index& nnz_h_lag,
                    IndexStyleEnum& index_style) override {
    n = 11;
    m = 0;
    nnz_jac_g = 0;
    nnz_h_lag = 0;
    index_style = C_STYLE;
    return true;
  }
  bool get_bounds_info(Ipopt::Index n, Ipopt::Number* x_l, Ipopt::Number* x_u, Ipopt::Index /*m*/,
                       Ipopt::Number* /*g_l*/, Ipopt::Number* /*g_u*/) override {
    for (int i = 0; i < n; ++i) {
      x_l[i] = lower_[i];
      x_u[i] = upper_[i];
    }
    return true;
  }
  bool get_starting_point(Ipopt::Index n, bool init_x, Ipopt::Number* x, bool /*init_z*/, Ipopt::Number* /*z_L*/,
                          Ipopt::Number* /*z_U*/, Ipopt::Index /*m*/, bool /*init_lambda*/,
                          Ipopt::Number* /*lambda*/) override {
    TOOLBENCH_DEMAND(init_x);
    for (int i = 0; i < n; ++i) x[i] = x0_[i];
    return true;
  }
  bool eval_f(Ipopt::Index /*n*/, const Ipopt::Number* x, bool /*new_x*/, Ipopt::Number& obj_value) override {
    obj_value = internal::SuperquadricCost(Eigen::Map<const SqParams>(x), points_, R0_, nullptr);
    return std::isfinite(obj_value);
  }
  bool eval_grad_f(Ipopt::Index /*n*/, const Ipopt::Number* x, bool /*new_x*/, Ipopt::Number* grad_f) override {
    SqParams g;
    internal::SuperquadricCost(Eigen::Map<const SqParams>(x), points_, R0_, &g);
    for (int i = 0; i < 11; ++i) grad_f[i] = g[i];
    return g.allFinite();
  }
  bool eval_g(Ipopt::Index, const Ipopt::Number*, bool, Ipopt::Index, Ipopt::Number*) override { return true; }
  bool eval_jac_g(Ipopt::Index, const Ipopt::Number*, bool, Ipopt::Index, Ipopt::Index, Ipopt::Index*, Ipopt::Index*,
                  Ipopt::Number*) override {
    return true;
  }
  void finalize_solution(Ipopt::SolverReturn /*status*/, Ipopt::Index /*n*/, const Ipopt::Number* x,
                         const Ipopt::Number* /*z_L*/, const Ipopt::Number* /*z_U*/, Ipopt::Index /*m*/,
                         const Ipopt::Number* /*g*/, const Ipopt::Number* /*lambda*/, Ipopt::Number obj_value,
                         const Ipopt::IpoptData* /*ip_data*/, Ipopt::IpoptCalculatedQuantities* /*ip_cq*/) override {
    const SqParams xs = Eigen::Map<const SqParams>(x);
    if (xs.allFinite() && std::isfinite(obj_value)) {
      x_best_ = xs;
      cost_ = obj_value;
    } else {
      cost_ = internal::SuperquadricCost(x0_, points_, R0_, nullptr);
    }
  }

 private:
  const Eigen::Matrix3Xd& points_;
  Eigen::Matrix3d R0_;
  SqParams x0_, lower_, upper_;
  SqParams x_best_;
  double cost_ = std::numeric_limits<double>::infinity();
};

double SignedPow(double v, double e) { return (v < 0.0 ? -1.0 : 1.0) * std::pow(std::abs(v), e); }

}  // namespace

void SuperquadricOptions::Validate() const {
  const char* where = "SuperquadricOptions::Validate";
  if (max_points < 10) ThrowInvalid(where, ": max_points = ", max_points, ", expected >= 10");
  if (!(min_exponent > 0.0 && min_exponent < max_exponent)) {
    ThrowInvalid(where, ": min_exponent = ", min_exponent, ", expected in (0, max_exponent = ", max_exponent, ")");
  }
  if (!(max_exponent <= 2.0)) ThrowInvalid(where, ": max_exponent = ", max_exponent, ", expected <= 2");
  if (!(min_size_factor > 0.0 && min_size_factor <= 1.0)) {
    ThrowInvalid(where, ": min_size_factor = ", min_size_factor, ", expected in (0, 1]");
  }
  if (!(max_size_factor >= 1.0 && std::isfinite(max_size_factor))) {
    ThrowInvalid(where, ": max_size_factor = ", max_size_factor, ", expected >= 1");
  }
  if (!(min_size > 0.0 && std::isfinite(min_size))) ThrowInvalid(where, ": min_size = ", min_size, ", expected > 0");
  if (!(max_rotation > 0.0 && max_rotation <= M_PI / 2)) {
    ThrowInvalid(where, ": max_rotation = ", max_rotation, ", expected in (0, pi/2]");
  }
  if (axis_assignments < 1 || axis_assignments > 3) {
    ThrowInvalid(where, ": axis_assignments = ", axis_assignments, ", expected in [1, 3]");
  }
  if (max_iterations <= 0) ThrowInvalid(where, ": max_iterations = ", max_iterations, ", expected > 0");
  if (screen_iterations <= 0) ThrowInvalid(where, ": screen_iterations = ", screen_iterations, ", expected > 0");
  if (!(tolerance > 0.0)) ThrowInvalid(where, ": tolerance = ", tolerance, ", expected > 0");
}

double InsideOutside(const Superquadric& sq, const Eigen::Vector3d& p_F) {
  const Eigen::Vector3d q = sq.pose.inverse() * p_F;
  const double A = std::pow(std::abs(q.x() / sq.size.x()), 2.0 / sq.e2);
  const double B = std::pow(std::abs(q.y() / sq.size.y()), 2.0 / sq.e2);
  const double C = std::pow(std::abs(q.z() / sq.size.z()), 2.0 / sq.e1);
  return std::pow(A + B, sq.e2 / sq.e1) + C;
}

SuperquadricFit FitSuperquadric(const Eigen::Matrix3Xf& points, const SuperquadricOptions& options) {
  options.Validate();
  if (!points.allFinite()) ThrowInvalid("FitSuperquadric: points contain a non-finite coordinate");
  SuperquadricFit fit;
  const Eigen::Index n_all = points.cols();
  if (n_all < kMinSuperquadricPoints) {
    fit.reason = Cat("FitSuperquadric: ", n_all, " points, need at least ", kMinSuperquadricPoints);
    return fit;
  }

  // Seeded subsample without replacement (partial Fisher-Yates).
  std::vector<int> index(static_cast<std::size_t>(n_all));
  std::iota(index.begin(), index.end(), 0);
  const int m = static_cast<int>(std::min<Eigen::Index>(n_all, options.max_points));
  if (m < n_all) {
    Rng rng(options.seed);
    for (int i = 0; i < m; ++i) {
      std::swap(index[static_cast<std::size_t>(i)],
                index[static_cast<std::size_t>(UniformInt(rng, i, static_cast<int>(n_all) - 1))]);
    }
  }
  Eigen::Matrix3Xd sub(3, m);
  for (int i = 0; i < m; ++i) sub.col(i) = points.col(index[static_cast<std::size_t>(i)]).cast<double>();
  fit.points_used = m;

  // PCA frame of the whole cloud; the problem is solved in coordinates centred on the centroid
  // and scaled by the largest half-extent, so Ipopt's tolerances mean the same for any size.
  const Eigen::Matrix3Xd all = points.cast<double>();
  const Eigen::Vector3d centroid = all.rowwise().mean();
  const Eigen::Matrix3Xd centred = all.colwise() - centroid;
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(centred * centred.transpose());
  Eigen::Matrix3d axes;  // columns: principal axes, largest first
  for (int k = 0; k < 3; ++k) axes.col(k) = eig.eigenvectors().col(2 - k);
  const Eigen::Matrix3Xd local = axes.transpose() * centred;
  const Eigen::Vector3d lo = local.rowwise().minCoeff(), hi = local.rowwise().maxCoeff();
  const Eigen::Vector3d half = 0.5 * (hi - lo);
  const Eigen::Vector3d mid_local = 0.5 * (hi + lo);
  const double scale = half.maxCoeff();
  if (!(scale > 1e-6)) {
    fit.reason = Cat("FitSuperquadric: the ", n_all, " points span only ", 2 * scale, " m");
    return fit;
  }
  const Eigen::Matrix3Xd sub_n = (sub.colwise() - centroid) / scale;
  const Eigen::Vector3d t0 = axes * mid_local / scale;

  Ipopt::SmartPtr<Ipopt::IpoptApplication> app = new Ipopt::IpoptApplication(/*create_console_out=*/false);
  Ipopt::OptionsList& o = *app->Options();
  o.SetIntegerValue("print_level", 0);
  o.SetStringValue("sb", "yes");
  o.SetStringValue("hessian_approximation", "limited-memory");
  o.SetStringValue("mu_strategy", "adaptive");
  o.SetStringValue("nlp_scaling_method", "gradient-based");
  o.SetNumericValue("tol", options.tolerance);
  const Ipopt::ApplicationReturnStatus init = app->Initialize("");
  TOOLBENCH_DEMAND(init == Ipopt::Solve_Succeeded);

  // Each assignment is screened with a short run; the best one then runs to convergence from
  // where it stopped (Ipopt's per-iteration overhead, not the cost, dominates the time).
  struct Candidate {
    Eigen::Matrix3d R0;
    SqParams x, lower, upper;
    double cost = std::numeric_limits<double>::infinity();
    bool converged = false;
  };
  auto run = [&](Candidate& c, const SqParams& x0, int max_iter) {
    o.SetIntegerValue("max_iter", max_iter);
    Ipopt::SmartPtr<SuperquadricNlp> nlp = new SuperquadricNlp(sub_n, c.R0, x0, c.lower, c.upper);
    const Ipopt::ApplicationReturnStatus status = app->OptimizeTNLP(Ipopt::SmartPtr<Ipopt::TNLP>(Ipopt::GetRawPtr(nlp)));
    if (Ipopt::IsValid(app->Statistics())) fit.iterations += app->Statistics()->IterationCount();
    c.converged = status == Ipopt::Solve_Succeeded || status == Ipopt::Solved_To_Acceptable_Level;
    c.cost = nlp->cost();
    c.x = nlp->solution();
  };
  const int screen = options.axis_assignments > 1 ? std::min(options.screen_iterations, options.max_iterations)
                                                  : options.max_iterations;
  const double size_floor = options.min_size / scale;
  std::vector<Candidate> candidates(static_cast<std::size_t>(options.axis_assignments));
  for (int k = 0; k < options.axis_assignments; ++k) {
    Candidate& c = candidates[static_cast<std::size_t>(k)];
    // z_S along principal axis k, x_S along the next one, y_S completes a right-handed frame.
    const int ix = (k + 1) % 3, iy = (k + 2) % 3;
    c.R0.col(0) = axes.col(ix);
    c.R0.col(2) = axes.col(k);
    c.R0.col(1) = c.R0.col(2).cross(c.R0.col(0));
    const Eigen::Vector3d h(half[ix] / scale, half[iy] / scale, half[k] / scale);
    SqParams x0;
    for (int j = 0; j < 3; ++j) {
      c.lower[j] = std::max(options.min_size_factor * h[j], size_floor);
      c.upper[j] = std::max(options.max_size_factor * h[j], 2.0 * size_floor);
      x0[j] = std::clamp(h[j], c.lower[j], c.upper[j]);
    }
    c.lower[3] = c.lower[4] = options.min_exponent;
    c.upper[3] = c.upper[4] = options.max_exponent;
    x0[3] = x0[4] = 1.0;
    for (int j = 5; j < 8; ++j) {
      c.lower[j] = -options.max_rotation;
      c.upper[j] = options.max_rotation;
      x0[j] = 0.0;
    }
    for (int j = 0; j < 3; ++j) {
      c.lower[8 + j] = t0[j] - 1.0;
      c.upper[8 + j] = t0[j] + 1.0;
      x0[8 + j] = t0[j];
    }
    run(c, x0, screen);
    if (!std::isfinite(c.cost)) continue;
    if (fit.best_assignment < 0 || c.cost < candidates[static_cast<std::size_t>(fit.best_assignment)].cost) {
      fit.best_assignment = k;
    }
  }
  bool best_converged = false;
  if (fit.best_assignment >= 0) {
    Candidate& c = candidates[static_cast<std::size_t>(fit.best_assignment)];
    if (!c.converged && screen < options.max_iterations) run(c, c.x, options.max_iterations);
    if (std::isfinite(c.cost)) {
      best_converged = c.converged;
      fit.sq.size = c.x.head<3>() * scale;
      fit.sq.e1 = c.x[3];
      fit.sq.e2 = c.x[4];
      fit.sq.pose = Eigen::Isometry3d::Identity();
      fit.sq.pose.linear() = c.R0 * internal::ExpSo3(c.x.segment<3>(5));
      fit.sq.pose.translation() = centroid + scale * c.x.segment<3>(8);
      fit.cost = c.cost * scale * scale * scale;
    } else {
      fit.best_assignment = -1;
    }
  }
  if (fit.best_assignment < 0) {
    fit.status = SuperquadricStatus::kNotConverged;
    fit.reason = "FitSuperquadric: Ipopt returned no finite solution for any axis assignment";
    return fit;
  }
  double err = 0.0;
  for (Eigen::Index i = 0; i < n_all; ++i) {
    err += std::abs(std::pow(InsideOutside(fit.sq, all.col(i)), fit.sq.e1) - 1.0);
  }
  fit.fit_error = err / static_cast<double>(n_all);
  if (best_converged) {
    fit.status = SuperquadricStatus::kOk;
  } else {
    fit.status = SuperquadricStatus::kNotConverged;
    fit.reason = Cat("FitSuperquadric: Ipopt did not converge in ", options.max_iterations,
                     " iterations (best of ", options.axis_assignments, " axis assignments)");
  }
  return fit;
}

Eigen::Matrix3Xf SuperquadricSurface(const Superquadric& sq, int n) {
  if (n < 2) ThrowInvalid("SuperquadricSurface: n = ", n, ", expected >= 2");
  if (!(sq.size.minCoeff() > 0.0)) {
    ThrowInvalid("SuperquadricSurface: sq.size = (", sq.size.transpose(), "), expected positive semi-axes");
  }
  Eigen::Matrix3Xf out(3, 2 * n * n);
  int c = 0;
  for (int i = 0; i < n; ++i) {
    const double eta = -M_PI / 2 + M_PI * i / (n - 1);
    for (int j = 0; j < 2 * n; ++j) {
      const double omega = -M_PI + M_PI * j / n;
      const double ce = SignedPow(std::cos(eta), sq.e1);
      const Eigen::Vector3d q(sq.size.x() * ce * SignedPow(std::cos(omega), sq.e2),
                              sq.size.y() * ce * SignedPow(std::sin(omega), sq.e2),
                              sq.size.z() * SignedPow(std::sin(eta), sq.e1));
      out.col(c++) = (sq.pose * q).cast<float>();
    }
  }
  return out;
}

SurfaceMesh SuperquadricMesh(const Superquadric& sq, int n) {
  SurfaceMesh mesh;
  mesh.vertices = SuperquadricSurface(sq, n);
  const int m = 2 * n;  // vertices per latitude row
  mesh.faces.resize(3, 2 * m * (n - 2));
  int f = 0;
  for (int i = 0; i + 1 < n; ++i) {
    for (int j = 0; j < m; ++j) {
      const int a = i * m + j, b = i * m + (j + 1) % m;  // row i, j and its eastern neighbour
      const int c = a + m, d = b + m;                    // the same on row i + 1 (north)
      // East then north is counter-clockwise seen from outside. Row 0 is the south pole (a and
      // b coincide), row n - 1 the north pole (c and d coincide).
      if (i > 0) mesh.faces.col(f++) << a, b, d;
      if (i + 2 < n) mesh.faces.col(f++) << a, d, c;
    }
  }
  TOOLBENCH_DEMAND(f == mesh.faces.cols());
  return mesh;
}

}  // namespace toolbench::perception
