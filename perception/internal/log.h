#pragma once

#include <memory>

namespace spdlog {
class logger;
}  // namespace spdlog

namespace toolbench::perception::internal {

/// The module's logger: the one the app registered as "perception", else spdlog's default.
/// Only for perception's .cpp files (which include <spdlog/spdlog.h> to use it).
std::shared_ptr<spdlog::logger> Logger();

}  // namespace toolbench::perception::internal
