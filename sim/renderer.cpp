#include "sim/renderer.h"

#include <cmath>
#include <stdexcept>
#include <vector>

#include <GL/osmesa.h>
#include <mujoco/mujoco.h>

#include "common/check.h"

namespace toolbench::sim {

struct GlContext::Impl {
  OSMesaContext context = nullptr;
  std::vector<unsigned char> buffer;  // the default framebuffer; MuJoCo renders to its own FBO
  static constexpr int kSize = 64;
};

GlContext::GlContext() : impl_(std::make_unique<Impl>()) {
  impl_->context = OSMesaCreateContextExt(OSMESA_RGBA, 24, 8, 8, nullptr);
  if (!impl_->context) throw std::runtime_error("GlContext: OSMesaCreateContextExt failed");
  impl_->buffer.resize(4 * Impl::kSize * Impl::kSize);
  MakeCurrent();
}

GlContext::~GlContext() {
  if (impl_->context) OSMesaDestroyContext(impl_->context);
}

void GlContext::MakeCurrent() {
  if (!OSMesaMakeCurrent(impl_->context, impl_->buffer.data(), GL_UNSIGNED_BYTE, Impl::kSize,
                         Impl::kSize)) {
    throw std::runtime_error("GlContext: OSMesaMakeCurrent failed");
  }
}

void RendererOptions::Validate() const {
  if (camera.empty()) ThrowInvalid("RendererOptions: camera name is empty");
  noise.Validate();
}

struct Renderer::Impl {
  GlContext* gl = nullptr;
  RendererOptions options;
  mjvScene scene;
  mjvCamera camera;
  mjvOption option;
  mjrContext context;
  mjrRect viewport{0, 0, 0, 0};
  CameraIntrinsics intrinsics;
  std::vector<unsigned char> rgb_buffer;
  std::vector<float> depth_buffer;
  double znear = 0.0;
  double zfar = 0.0;

  ~Impl() {
    mjr_freeContext(&context);
    mjv_freeScene(&scene);
  }
};

Renderer::Renderer(GlContext& gl, const World& world, const RendererOptions& options)
    : impl_(std::make_unique<Impl>()) {
  options.Validate();
  impl_->gl = &gl;
  impl_->options = options;
  gl.MakeCurrent();
  const mjModel* m = world.mj_model();
  const int cam_id = mj_name2id(m, mjOBJ_CAMERA, options.camera.c_str());
  if (cam_id < 0) ThrowInvalid("Renderer: unknown camera '", options.camera, "' in the model");

  mjv_defaultScene(&impl_->scene);
  mjv_defaultCamera(&impl_->camera);
  mjv_defaultOption(&impl_->option);
  mjr_defaultContext(&impl_->context);
  mjv_makeScene(m, &impl_->scene, 2000);
  mjr_makeContext(m, &impl_->context, mjFONTSCALE_100);
  // Must follow mjr_makeContext, which leaves the window buffer selected (measured.md C.1).
  mjr_setBuffer(mjFB_OFFSCREEN, &impl_->context);
  if (impl_->context.currentBuffer != mjFB_OFFSCREEN) {
    throw std::runtime_error("Renderer: off-screen framebuffer not available");
  }
  impl_->viewport = mjr_maxViewport(&impl_->context);
  impl_->camera.type = mjCAMERA_FIXED;
  impl_->camera.fixedcamid = cam_id;
  impl_->scene.flags[mjRND_SHADOW] = options.shadows ? 1 : 0;
  impl_->scene.flags[mjRND_REFLECTION] = options.shadows ? 1 : 0;

  const int W = impl_->viewport.width;
  const int H = impl_->viewport.height;
  impl_->rgb_buffer.resize(3 * static_cast<size_t>(W) * H);
  impl_->depth_buffer.resize(static_cast<size_t>(W) * H);
  // fovy is in degrees whatever <compiler angle> says; pixel-index principal point.
  const double fovy = m->cam_fovy[cam_id] * M_PI / 180.0;
  impl_->intrinsics.width = W;
  impl_->intrinsics.height = H;
  impl_->intrinsics.fy = (H / 2.0) / std::tan(fovy / 2.0);
  impl_->intrinsics.fx = impl_->intrinsics.fy;
  impl_->intrinsics.cx = (W - 1) / 2.0;
  impl_->intrinsics.cy = (H - 1) / 2.0;
  // znear/zfar scale with stat.extent (pinned by the composer, read here anyway).
  impl_->znear = m->vis.map.znear * m->stat.extent;
  impl_->zfar = m->vis.map.zfar * m->stat.extent;
}

Renderer::~Renderer() {
  impl_->gl->MakeCurrent();
}

const CameraIntrinsics& Renderer::intrinsics() const { return impl_->intrinsics; }

RgbdFrame Renderer::Render(World& world, std::uint64_t noise_seed) {
  impl_->gl->MakeCurrent();
  const mjModel* m = world.mj_model();
  mjData* d = world.mj_data();
  mjv_updateScene(m, d, &impl_->option, nullptr, &impl_->camera, mjCAT_ALL, &impl_->scene);
  mjr_render(impl_->viewport, &impl_->scene, &impl_->context);
  mjr_readPixels(impl_->rgb_buffer.data(), impl_->depth_buffer.data(), impl_->viewport,
                 &impl_->context);

  const int W = impl_->viewport.width;
  const int H = impl_->viewport.height;
  RgbdFrame frame;
  frame.time = d->time;
  frame.intrinsics = impl_->intrinsics;
  frame.rgb.create(H, W, CV_8UC3);
  frame.depth.create(H, W, CV_32FC1);
  const double n = impl_->znear;
  const double f = impl_->zfar;
  for (int r = 0; r < H; ++r) {
    const int src_row = H - 1 - r;  // OpenGL rows are bottom-up
    std::memcpy(frame.rgb.ptr<unsigned char>(r), &impl_->rgb_buffer[3 * static_cast<size_t>(src_row) * W],
                3 * static_cast<size_t>(W));
    float* out = frame.depth.ptr<float>(r);
    const float* in = &impl_->depth_buffer[static_cast<size_t>(src_row) * W];
    for (int c = 0; c < W; ++c) {
      const double z_buffer = in[c];
      // Planar depth from the non-linear z-buffer; the far plane means nothing was hit.
      out[c] = z_buffer >= 1.0 ? 0.0f
                               : static_cast<float>(n / (1.0 - z_buffer * (1.0 - n / f)));
    }
  }
  if (impl_->options.noise.enabled) {
    ApplySensorNoise(frame.rgb, frame.depth, frame.intrinsics, impl_->options.noise, noise_seed);
  }
  return frame;
}

}  // namespace toolbench::sim
