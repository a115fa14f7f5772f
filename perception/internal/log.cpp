#include "perception/internal/log.h"

#include <spdlog/spdlog.h>

namespace toolbench::perception::internal {

std::shared_ptr<spdlog::logger> Logger() {
  // Looked up on each call instead of cached: no global state, and the app may register its
  // "perception" logger after the first use.
  auto logger = spdlog::get("perception");
  return logger ? logger : spdlog::default_logger();
}

}  // namespace toolbench::perception::internal
