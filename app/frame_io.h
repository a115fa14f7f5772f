#pragma once

#include <filesystem>
#include <map>
#include <string>

#include <nlohmann/json_fwd.hpp>

#include "common/types.h"

namespace toolbench::app {

/// Writes a frame as a person or another tool would want it:
///   rgb.png    8-bit RGB
///   depth.png  16-bit depth in millimetres (0 = no return)
///   camera.json intrinsics, X_RC (4x4, row-major), capture time, plus `extra`
///   cloud.ply  the back-projected points in the robot root frame R, with colour
/// Creates `dir`. Throws std::runtime_error naming a file that cannot be written.
void WriteFrame(const std::filesystem::path& dir, const RgbdFrame& frame,
                const nlohmann::json& extra);

/// Back-projects the depth image (pinhole) and moves the points to the root frame with X_RC.
/// Returns 3xN points [m] in R and their RGB colours (3xN, 0-255); pixels with no return are
/// skipped. Throws std::invalid_argument on empty or mismatched images.
void BackProject(const RgbdFrame& frame, Eigen::Matrix3Xf& p_R, Eigen::Matrix<unsigned char, 3, Eigen::Dynamic>& colour);

/// Writes points (and optional colours, same column count or empty) as binary little-endian PLY.
void WritePointCloudPly(const std::filesystem::path& path, const Eigen::Matrix3Xf& points,
                        const Eigen::Matrix<unsigned char, 3, Eigen::Dynamic>& colour);

/// JSON form of a pose: {"matrix": 4x4 row-major, "position": [x,y,z], "quat_wxyz": [...]}.
nlohmann::json PoseJson(const Eigen::Isometry3d& X);

}  // namespace toolbench::app
