#include "toollib/internal/log.h"

#include <spdlog/spdlog.h>

namespace toolbench::toollib::internal {

std::shared_ptr<spdlog::logger> Logger() {
  // Looked up on each call instead of cached: no global state, and the app may register its
  // "toollib" logger after the first use.
  auto logger = spdlog::get("toollib");
  return logger ? logger : spdlog::default_logger();
}

}  // namespace toolbench::toollib::internal
