#pragma once

#include <filesystem>
#include <vector>

#include "toollib/tool_model.h"

namespace toolbench::toollib {

/// Generates the tool library: 8 families (hoe, hook, rake, stick, lstick, shovel, hammer,
/// spatula), 4 variants each, named "<family>_<1..4>", in that order. Deterministic: the same
/// binary always returns bit-identical models.
///
/// Each tool is expressed in its model frame T (see tool_model.h): handle along +z from the
/// butt at the origin, effector toward +x. Every tool has
///  - `mesh`: ONE closed, consistently outward-oriented, non-self-intersecting triangle mesh
///    (1.5k-5k faces), the exact union of its building blocks, vertices rounded to float so
///    that a binary STL stores it losslessly; `mesh_file` is "<name>.stl" (relative);
///  - `collision`: the building blocks as convex MuJoCo primitives (box, cylinder, sphere),
///    each inside the visual shape, masses split by volume and summing to `mass`;
///  - `mass` = material density x mesh volume (wood 700 kg/m^3, plastic 1100 kg/m^3,
///    recorded in params["density"]), within 0.08-0.6 kg;
///  - `handle`: the graspable cylinder (diameter 20-35 mm), axis +z, centre mid-handle;
///  - `effector`: centre and main direction of the working part (see assets/tools/README.md);
///  - `total_length` in 0.25-0.60 m and the generator `params` in SI units.
/// Takes about half a second (CGAL exact unions on 2 cores).
std::vector<ToolModel> GenerateToolLibrary();

/// Generates the library and saves every tool with SaveToolModel into `dir` (created if
/// needed): "<name>.stl" + "<name>.json" per tool. Existing files of the same names are
/// overwritten; other files are left alone. Throws std::runtime_error when writing fails.
void WriteToolLibrary(const std::filesystem::path& dir);

}  // namespace toolbench::toollib
