#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "common/types.h"
#include "sim/world.h"

namespace toolbench::sim {

/// An off-screen OpenGL context (OSMesa, software; no display, no EGL). Creating one costs
/// 90-175 ms, so make one per process (or thread) and share it between Renderers. It is bound to
/// the creating thread.
class GlContext {
 public:
  /// Throws std::runtime_error when OSMesa cannot create a context.
  GlContext();
  ~GlContext();
  GlContext(const GlContext&) = delete;
  GlContext& operator=(const GlContext&) = delete;
  /// Makes this context current on the calling thread.
  void MakeCurrent();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Sensor model of the helmet RGB-D camera: what a RealSense D435-like active stereo sensor does
/// to ideal depth (RealSense maintainers' RMS model sigma_z = z^2 s / (f B), shared/facts/icub.md
/// section 10), plus dropouts where stereo fails and colour noise.
struct DepthNoiseOptions {
  bool enabled = true;                // false = ideal images (tests, ground-truth comparisons)
  double subpixel_rms = 0.08;         // disparity noise s [px], >= 0
  double baseline = 0.050;            // stereo baseline B [m], > 0
  double quantization = 0.001;        // depth step [m] (the D435 reports millimetres), >= 0
  double min_range = 0.17;            // nearer returns dropped [m] (D435 Min-Z at 848x480)
  double max_range = 4.0;             // farther returns dropped [m], > min_range
  double grazing_angle_deg = 80.0;    // surfaces seen more obliquely than this return nothing
  double edge_jump = 0.02;            // depth step that marks an occlusion edge [m], > 0
  double edge_dropout = 0.5;          // probability that the far side of an edge is lost, [0, 1]
  double rgb_sigma = 2.0;             // Gaussian colour noise [8-bit levels], >= 0
  /// Throws std::invalid_argument naming the field and value when out of range.
  void Validate() const;
};

/// Applies the sensor model in place. rgb CV_8UC3, depth CV_32FC1 [m, 0 = no return]. All draws
/// come from `seed`. Throws std::invalid_argument on mismatched or wrongly typed images.
void ApplySensorNoise(cv::Mat& rgb, cv::Mat& depth, const CameraIntrinsics& intrinsics,
                      const DepthNoiseOptions& options, std::uint64_t seed);

/// Options of the camera renderer.
struct RendererOptions {
  std::string camera = "helmet";  // MuJoCo camera name
  bool shadows = false;           // shadows and reflections cost ~10x on llvmpipe (measured.md C.2)
  DepthNoiseOptions noise;
  void Validate() const;
};

/// Renders RGB and metric depth from a camera of one World's model. The image size is the
/// model's <visual><global offwidth offheight>.
class Renderer {
 public:
  /// Uploads the model's meshes and textures to `gl` (made current). Throws std::invalid_argument
  /// for an unknown camera and std::runtime_error when the off-screen buffer is unavailable.
  Renderer(GlContext& gl, const World& world, const RendererOptions& options = {});
  ~Renderer();
  Renderer(const Renderer&) = delete;
  Renderer& operator=(const Renderer&) = delete;

  /// Renders the world's current state. Frame X_RC is left identity: the caller sets it from
  /// encoder forward kinematics (perception must not read simulator poses). `noise_seed` drives
  /// the sensor model (ignored when noise is off).
  RgbdFrame Render(World& world, std::uint64_t noise_seed);

  /// Intrinsics of the rendered images (pixel-index convention, square pixels).
  const CameraIntrinsics& intrinsics() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace toolbench::sim
