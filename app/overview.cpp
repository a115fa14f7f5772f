#include "app/overview.h"

#include <stdexcept>
#include <vector>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "sim/renderer.h"

namespace toolbench::app {

void WriteOverviewPng(sim::World& world, const std::filesystem::path& png) {
  sim::GlContext gl;
  std::vector<cv::Mat> views;
  for (const char* camera : {"overview", "side", "rack_close"}) {
    sim::RendererOptions options;
    options.camera = camera;
    options.noise.enabled = false;
    sim::Renderer renderer(gl, world, options);
    const RgbdFrame frame = renderer.Render(world, 0);
    cv::Mat bgr;
    cv::cvtColor(frame.rgb, bgr, cv::COLOR_RGB2BGR);
    views.push_back(bgr);
  }
  cv::Mat both;
  cv::hconcat(views, both);
  if (png.has_parent_path()) std::filesystem::create_directories(png.parent_path());
  if (!cv::imwrite(png.string(), both)) throw std::runtime_error("cannot write " + png.string());
}

}  // namespace toolbench::app
