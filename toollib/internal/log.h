#pragma once

#include <memory>

namespace spdlog {
class logger;
}  // namespace spdlog

namespace toolbench::toollib::internal {

/// The module's logger: the one the app registered as "toollib", else spdlog's default.
/// Only for toollib's .cpp files (which include <spdlog/spdlog.h> to use it).
std::shared_ptr<spdlog::logger> Logger();

}  // namespace toolbench::toollib::internal
