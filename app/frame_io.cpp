#include "app/frame_io.h"

#include <fstream>
#include <stdexcept>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "common/check.h"
#include "common/paths.h"

namespace toolbench::app {

nlohmann::json PoseJson(const Eigen::Isometry3d& X) {
  nlohmann::json matrix = nlohmann::json::array();
  for (int r = 0; r < 4; ++r) {
    nlohmann::json row = nlohmann::json::array();
    for (int c = 0; c < 4; ++c) row.push_back(X.matrix()(r, c));
    matrix.push_back(row);
  }
  const Eigen::Quaterniond q(X.linear());
  return {{"matrix", matrix},
          {"position", {X.translation().x(), X.translation().y(), X.translation().z()}},
          {"quat_wxyz", {q.w(), q.x(), q.y(), q.z()}}};
}

void BackProject(const RgbdFrame& frame, Eigen::Matrix3Xf& p_R,
                 Eigen::Matrix<unsigned char, 3, Eigen::Dynamic>& colour) {
  if (frame.depth.empty() || frame.depth.type() != CV_32FC1) {
    ThrowInvalid("BackProject: depth must be a non-empty CV_32FC1 image");
  }
  if (!frame.rgb.empty() && frame.rgb.size() != frame.depth.size()) {
    ThrowInvalid("BackProject: rgb and depth sizes differ");
  }
  const CameraIntrinsics& K = frame.intrinsics;
  const int count = cv::countNonZero(frame.depth > 0);
  p_R.resize(3, count);
  colour.resize(3, frame.rgb.empty() ? 0 : count);
  const Eigen::Matrix3f R = frame.X_RC.linear().cast<float>();
  const Eigen::Vector3f t = frame.X_RC.translation().cast<float>();
  int n = 0;
  for (int v = 0; v < frame.depth.rows; ++v) {
    const float* z_row = frame.depth.ptr<float>(v);
    for (int u = 0; u < frame.depth.cols; ++u) {
      const float z = z_row[u];
      if (!(z > 0.0f) || !std::isfinite(z)) continue;
      const Eigen::Vector3f p_C(static_cast<float>((u - K.cx) / K.fx) * z,
                                static_cast<float>((v - K.cy) / K.fy) * z, z);
      p_R.col(n) = R * p_C + t;
      if (colour.cols() > 0) {
        const cv::Vec3b& c = frame.rgb.at<cv::Vec3b>(v, u);
        colour.col(n) << c[0], c[1], c[2];
      }
      ++n;
    }
  }
  p_R.conservativeResize(3, n);
  if (colour.cols() > 0) colour.conservativeResize(3, n);
}

void WritePointCloudPly(const std::filesystem::path& path, const Eigen::Matrix3Xf& points,
                        const Eigen::Matrix<unsigned char, 3, Eigen::Dynamic>& colour) {
  const bool with_colour = colour.cols() == points.cols() && colour.cols() > 0;
  if (path.has_parent_path()) std::filesystem::create_directories(path.parent_path());
  std::ofstream out(path, std::ios::binary);
  out << "ply\nformat binary_little_endian 1.0\nelement vertex " << points.cols()
      << "\nproperty float x\nproperty float y\nproperty float z\n";
  if (with_colour) out << "property uchar red\nproperty uchar green\nproperty uchar blue\n";
  out << "end_header\n";
  for (Eigen::Index i = 0; i < points.cols(); ++i) {
    out.write(reinterpret_cast<const char*>(points.col(i).data()), 3 * sizeof(float));
    if (with_colour) out.write(reinterpret_cast<const char*>(colour.col(i).data()), 3);
  }
  if (!out) throw std::runtime_error(Cat("cannot write '", path.string(), "'"));
}

void WriteFrame(const std::filesystem::path& dir, const RgbdFrame& frame,
                const nlohmann::json& extra) {
  std::filesystem::create_directories(dir);
  cv::Mat bgr;
  cv::cvtColor(frame.rgb, bgr, cv::COLOR_RGB2BGR);
  if (!cv::imwrite((dir / "rgb.png").string(), bgr)) {
    throw std::runtime_error(Cat("cannot write '", (dir / "rgb.png").string(), "'"));
  }
  cv::Mat depth_mm(frame.depth.size(), CV_16UC1);
  for (int r = 0; r < frame.depth.rows; ++r) {
    for (int c = 0; c < frame.depth.cols; ++c) {
      const double z = frame.depth.at<float>(r, c);
      depth_mm.at<unsigned short>(r, c) =
          (z > 0 && std::isfinite(z)) ? static_cast<unsigned short>(std::min(65535.0, std::round(z * 1000.0))) : 0;
    }
  }
  if (!cv::imwrite((dir / "depth.png").string(), depth_mm)) {
    throw std::runtime_error(Cat("cannot write '", (dir / "depth.png").string(), "'"));
  }
  // For people: depth as a colour map (near = warm), black where there is no return.
  {
    cv::Mat valid = frame.depth > 0;
    double z_min = 0, z_max = 1;
    cv::minMaxLoc(frame.depth, &z_min, &z_max, nullptr, nullptr, valid);
    cv::Mat scaled;
    frame.depth.convertTo(scaled, CV_8U, -255.0 / std::max(1e-6, z_max - z_min), 255.0 * z_max / std::max(1e-6, z_max - z_min));
    cv::Mat vis;
    cv::applyColorMap(scaled, vis, cv::COLORMAP_TURBO);
    vis.setTo(cv::Scalar(0, 0, 0), ~valid);
    cv::imwrite((dir / "depth_vis.png").string(), vis);
  }
  const CameraIntrinsics& K = frame.intrinsics;
  nlohmann::json camera = extra;
  camera["time"] = frame.time;
  camera["intrinsics"] = {{"width", K.width}, {"height", K.height}, {"fx", K.fx},
                          {"fy", K.fy},       {"cx", K.cx},         {"cy", K.cy},
                          {"convention", "pixel-index; OpenCV camera frame x right, y down, z forward"}};
  camera["X_RC"] = PoseJson(frame.X_RC);
  camera["X_RC"]["source"] = extra.value("camera", std::string("helmet")) == "helmet"
                                 ? "forward kinematics of the joint encoders"
                                 : "calibrated extrinsics of a camera fixed in the world";
  camera["depth_png"] = "uint16 millimetres along the optical axis, 0 = no return";
  WriteTextFile(dir / "camera.json", camera.dump(2) + "\n");
  Eigen::Matrix3Xf points;
  Eigen::Matrix<unsigned char, 3, Eigen::Dynamic> colour;
  BackProject(frame, points, colour);
  WritePointCloudPly(dir / "cloud.ply", points, colour);
}

}  // namespace toolbench::app
