#pragma once

#include <filesystem>

#include "sim/world.h"

namespace toolbench::app {

/// Renders the world's current state from the fixed "overview", "side" and "rack_close" cameras
/// (no sensor noise), side by side, and writes it as a PNG (creating folders): for looking at benchmark cases. Creates its own GL
/// context (~0.1-0.2 s), so it is meant for debugging runs, not for loops.
/// Throws std::runtime_error when the image cannot be rendered or written.
void WriteOverviewPng(sim::World& world, const std::filesystem::path& png);

}  // namespace toolbench::app
