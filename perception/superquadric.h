#pragma once

#include <cstdint>
#include <string>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "perception/tool_analysis.h"

namespace toolbench::perception {

/// Configuration of FitSuperquadric. The cost is the one of superquadric-lib (thesis eq. 2.6,
/// measured.md A.2); the initial guess and the bounds are taken from the principal-axes (PCA)
/// box of the points.
struct SuperquadricOptions {
  int max_points = 300;          // the cloud is subsampled (seeded, without replacement) to at
                                 // most this many points for the optimisation, >= 10
  std::uint64_t seed = 1;        // seed of that subsampling
  double min_exponent = 0.1;     // lower bound of e1 and e2, in (0, max_exponent)
  double max_exponent = 1.9;     // upper bound of e1 and e2, in (min_exponent, 2]
  double min_size_factor = 0.6;  // semi-axis i >= factor * PCA half-extent i, in (0, 1]
  double max_size_factor = 1.5;  // semi-axis i <= factor * PCA half-extent i, >= 1
  double min_size = 0.0005;      // floor of every semi-axis bound [m] (flat parts), > 0
  double max_rotation = 1.0;     // bound on each component of the rotation vector relative to
                                 // the initial axis assignment [rad], in (0, pi/2]
  int axis_assignments = 3;      // initial assignments tried: z_S along the 1st, 2nd, 3rd
                                 // principal axis (largest first); best cost wins, in [1, 3]
  int screen_iterations = 300;   // Ipopt max_iter of the screening run of each assignment; the
                                 // lowest-cost one then continues up to max_iterations, > 0.
                                 // >= max_iterations: no screening (every assignment converges).
                                 // 40 saves ~20 % but picked a wrong assignment on hammer_3's
                                 // handle, so screening is off by default
  int max_iterations = 300;      // Ipopt max_iter of the final run, > 0
  double tolerance = 1e-5;       // Ipopt tol (on the size-normalised problem), > 0
  void Validate() const;         // throws std::invalid_argument naming the field and its value
};

/// Outcome class of a superquadric fit (expected failures are results, not exceptions).
enum class SuperquadricStatus {
  kOk,            // Ipopt converged (or reached its acceptable level) for the best assignment
  kTooFewPoints,  // fewer than kMinSuperquadricPoints points, or all points (nearly) coincide
  kNotConverged,  // no assignment converged; `sq` holds the best iterate anyway
};

/// Smallest cloud FitSuperquadric attempts.
inline constexpr int kMinSuperquadricPoints = 11;

/// A fitted superquadric and how the fit went.
struct SuperquadricFit {
  SuperquadricStatus status = SuperquadricStatus::kTooFewPoints;
  std::string reason;      // empty when kOk
  Superquadric sq;         // pose X_FS in the frame F of the input points
  double cost = 0.0;       // eq. 2.6 cost (a1 a2 a3 / N) sum (F^e1 - 1)^2 on the subsample [m^3]
  double fit_error = 0.0;  // mean |F^e1 - 1| over all input points (0 = on the surface)
  int iterations = 0;      // Ipopt iterations summed over all runs (screening and final)
  int best_assignment = -1;  // which initial axis assignment won (0 = z_S along main axis)
  int points_used = 0;     // size of the subsample
};

/// Fits one superquadric to `points` (3 x N, any frame F [m]) by minimising eq. 2.6 with Ipopt
/// (analytic gradient, L-BFGS Hessian). The 11 unknowns are the semi-axes, the exponents, a
/// rotation vector relative to each initial axis assignment of the PCA frame and the centre.
/// Each assignment runs for up to options.screen_iterations Ipopt iterations; the lowest cost
/// continues (up to max_iterations) when it has not converged.
/// Works on a seeded subsample (options.max_points). Returns kTooFewPoints (with a reason) for
/// fewer than kMinSuperquadricPoints points or a degenerate cloud, kNotConverged when Ipopt
/// fails for every assignment. Throws std::invalid_argument for a non-finite point or bad
/// options.
SuperquadricFit FitSuperquadric(const Eigen::Matrix3Xf& points, const SuperquadricOptions& options);

/// The inside-outside function F of `sq` (thesis eq. 2.5) at point `p_F` given in the owner's
/// frame F: < 1 inside, 1 on the surface, > 1 outside.
double InsideOutside(const Superquadric& sq, const Eigen::Vector3d& p_F);

/// Points on the surface of `sq`, in its owner's frame F [m], for display: an n x 2n grid of
/// the usual signed-power parameterisation (latitude in [-pi/2, pi/2], longitude in
/// [-pi, pi)). Throws std::invalid_argument when n < 2 or the semi-axes are not positive.
Eigen::Matrix3Xf SuperquadricSurface(const Superquadric& sq, int n);

/// A closed triangle mesh for display.
struct SurfaceMesh {
  Eigen::Matrix3Xf vertices;  // 3 x V, in the owner's frame F [m]
  Eigen::Matrix3Xi faces;     // 3 x F vertex indices, counter-clockwise seen from outside
};

/// The surface of `sq` as a triangle mesh in its owner's frame F [m], for display: the n x 2n
/// grid of SuperquadricSurface (same vertices, same order; each pole row's 2n vertices
/// coincide, so the surface is closed although the pole vertices are not shared), its quads
/// split into two triangles each, the triangles that collapse at the poles left out:
/// 2n (2n - 4) faces with outward normals. Throws std::invalid_argument like
/// SuperquadricSurface.
SurfaceMesh SuperquadricMesh(const Superquadric& sq, int n);

}  // namespace toolbench::perception
