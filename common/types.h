#pragma once

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

namespace toolbench {

/// Pinhole intrinsics in pixel-index coordinates (pixel (u, v) centre = (u, v)).
/// A point (x, y, z) in the OpenCV camera frame (x right, y down, z forward) projects to
/// u = fx * x / z + cx, v = fy * y / z + cy.
struct CameraIntrinsics {
  int width = 640;    // image width [px], > 0
  int height = 480;   // image height [px], > 0
  double fx = 0.0;    // focal length along u [px]
  double fy = 0.0;    // focal length along v [px]
  double cx = 0.0;    // principal point u [px]
  double cy = 0.0;    // principal point v [px]
};

/// One RGB-D frame as the robot would receive it: images, intrinsics and the camera pose in the
/// robot root frame computed by forward kinematics from the joint encoders (never simulator truth).
struct RgbdFrame {
  double time = 0.0;            // simulation time of capture [s]
  cv::Mat rgb;                  // CV_8UC3, RGB order, row 0 = top of image
  cv::Mat depth;                // CV_32FC1, metres along the optical axis, 0 = no return
  CameraIntrinsics intrinsics;  // of both images (registered)
  Eigen::Isometry3d X_RC = Eigen::Isometry3d::Identity();  // camera (OpenCV frame) in robot root R
};

}  // namespace toolbench
