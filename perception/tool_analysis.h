#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <opencv2/core.hpp>

namespace toolbench::perception {

/// A superquadric (thesis eq. 2.5): the inside-outside function in its own frame S is
/// F(x, y, z) = ((|x/a1|^(2/e2) + |y/a2|^(2/e2))^(e2/e1) + |z/a3|^(2/e1)), F = 1 on the surface.
struct Superquadric {
  Eigen::Vector3d size = Eigen::Vector3d::Zero();  // semi-axes (a1, a2, a3) along x_S, y_S, z_S [m], > 0
  double e1 = 1.0;  // "north-south" exponent (shape along z_S), in [0.01, 2]
  double e2 = 1.0;  // "east-west" exponent (cross-section in x_S-y_S), in [0.01, 2]
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();  // X_FS: S in the frame F of the owner
                                                           // (T for a model's parts, R in a ToolAnalysis)
};

/// One part of a tool's surface (a shape-diameter-function segment) and its superquadric.
struct Part {
  Eigen::Matrix3Xf points;  // 3 x N surface points of the part, in the owner's frame F [m]
  Superquadric sq;          // fitted to `points`, pose in F
  double fit_error = 0.0;   // mean |F^e1 - 1| of the points under `sq` (0 = on the surface)
  /// Dissimilarity to the 32 mm x 80 mm cylinder the iCub hand holds (thesis Alg. 5): 0 for a
  /// perfect match, larger is worse, invariant to the order of the superquadric's axes.
  double cylinder_score = 0.0;
};

/// The handle chosen among the parts, as control needs it (all in the owner's frame F).
struct Handle {
  int part = -1;                                        // index into the parts, -1 = none found
  Eigen::Vector3d center = Eigen::Vector3d::Zero();     // p_FH, centre of the graspable region [m]
  Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();      // unit axis, pointing toward the effector
  double radius = 0.0;                                  // [m]
  double length = 0.0;                                  // graspable length along the axis [m]
  /// Handle frame H in F: origin at `center`, z_H = `axis`, x_H toward the effector's working
  /// side when known (library tools: the tool's +x), else any perpendicular.
  Eigen::Isometry3d X_FH = Eigen::Isometry3d::Identity();
};

/// Geometric features the affordance model reads (tool frame T, metres): where the effector is
/// relative to the handle, how far it reaches sideways, how big it is.
struct ToolFeatures {
  double total_length = 0.0;         // extent of the tool along z_T [m]
  double handle_length = 0.0;        // [m]
  double handle_radius = 0.0;        // [m]
  Eigen::Vector3d effector_center = Eigen::Vector3d::Zero();  // p_TE, effector centre in T [m]
  Eigen::Vector3d effector_size = Eigen::Vector3d::Zero();    // effector extents along x_T, y_T, z_T [m]
  double effector_protrusion = 0.0;  // how far the effector reaches past the handle axis along +x_T [m]
};

/// Outcome class of one tool's analysis.
enum class AnalysisStatus {
  kOk,          // recognised (or analysed as unknown) with a handle
  kNoCloud,     // the mask gave too few 3D points
  kNoFit,       // no model fitted / shape analysis failed
  kNoHandle,    // parts found, none resembles a handle
};

/// Everything perception reports about one tool seen in one frame, in the robot root frame R.
struct ToolAnalysis {
  AnalysisStatus status = AnalysisStatus::kNoCloud;
  std::string reason;        // empty when kOk
  int segment = -1;          // index of the 2D segment it came from
  cv::Rect roi;              // the segment's bounding box [px]
  std::string model;         // recognised library model; for an unknown tool (known = false) the
                             // closest library model, empty when no model could be fitted
  bool known = false;        // true: a library model was recognised with enough confidence
                             // (AnalyzerOptions::min_known_confidence), fit (max_known_fit_error)
                             // and extent (max_outside_fraction: not larger than the model)
  double confidence = 0.0;   // in [0, 1]: the recogniser's probability of `model`; 0 when the
                             // fit or the extent rules `model` out (an unknown tool)
  Eigen::Isometry3d X_RT = Eigen::Isometry3d::Identity();  // tool frame T in R: the fitted model's
                             // when known, else estimated from the observed handle
  double fit_error = 0.0;    // mean observed-to-model distance of `model`'s fit [m]
  std::vector<Part> parts;   // in R
  Handle handle;             // in R (X_FH is X_RH)
  ToolFeatures features;     // in T
};

}  // namespace toolbench::perception
