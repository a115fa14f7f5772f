#pragma once

#include <array>
#include <filesystem>
#include <map>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "toollib/mesh.h"

namespace toolbench::toollib {

// Tool model frame T (every pose and point of a ToolModel is in T, lengths in metres):
//  - origin on the tool's main axis at the butt (free) end of the handle;
//  - +z along the main axis, from the handle toward the effector;
//  - +x the direction the effector works toward: the hoe blade, hook, L-stick foot and rake
//    teeth protrude toward +x; the hammer's striking face faces +x; the shovel's and
//    spatula's blade face normal is +x (their scooping / lifting side);
//    for a stick, x is arbitrary (perpendicular to z);
//  - +y = z x x completes a right-handed frame.
// The mesh and every collision part are expressed in T, so the tool's pose X_WT places all
// of them at once.

/// The tool families of the library. "custom" is for user tools that fit none of them.
inline constexpr std::array<std::string_view, 8> kToolFamilies = {
    "hoe", "hook", "rake", "stick", "lstick", "shovel", "hammer", "spatula"};

/// A cylinder-like region of the tool: the handle (where the 32 mm x 80 mm grasp goes) or the
/// effector (the part that touches the object).
struct Segment {
  Eigen::Vector3d center = Eigen::Vector3d::Zero();  // p_TC, centre of the region in T [m]
  Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();   // unit main direction of the region in T
  double length = 0.0;                               // extent along `axis` [m], > 0
  double radius = 0.0;  // radial half-extent [m], > 0; half-width for flat effectors
};

/// One convex collision primitive, in MuJoCo geom conventions.
struct CollisionPart {
  enum class Type { kBox, kCylinder, kCapsule, kSphere, kMesh };
  Type type = Type::kBox;
  // MuJoCo geom size [m]: box half-extents (x, y, z); cylinder and capsule
  // (radius, half-length, 0) with the axis along the part's z; sphere (radius, 0, 0);
  // unused (zero) for kMesh.
  Eigen::Vector3d size = Eigen::Vector3d::Zero();
  Eigen::Isometry3d X_TP = Eigen::Isometry3d::Identity();  // pose of part P in tool frame T
  std::string mesh_file;  // kMesh only: a convex piece, path relative to the sidecar's folder
  double mass = 0.0;      // [kg], > 0; the parts' masses sum to the tool mass
};

/// Everything the twin knows about one library tool: identity, geometry, mass, semantic
/// segments and collision shape. Loaded from (and saved to) a JSON sidecar next to a mesh.
struct ToolModel {
  std::string name;    // unique, e.g. "hoe_1"; file stem of the sidecar and the mesh
  std::string family;  // one of kToolFamilies, or "custom"
  double mass = 0.0;   // total mass [kg], > 0
  Segment handle;      // graspable part, axis along +z for library tools
  Segment effector;    // working part
  std::vector<std::string> symmetries;   // shape symmetries in T, e.g. "rot_z_180", "mirror_y"
  std::map<std::string, double> params;  // generator parameters (SI units), informative
  std::filesystem::path mesh_file;       // visual mesh; absolute after LoadToolModel
  TriangleMesh mesh;                     // the visual mesh in T [m], valid (ValidateMesh)
  std::vector<CollisionPart> collision;  // convex parts approximating the shape
  double total_length = 0.0;             // extent of the mesh along z [m]
};

/// A stretch of a line, as offsets along it from a point on it [m]: min_m <= max_m.
struct AxisSpan {
  double min_m = 0.0;
  double max_m = 0.0;
};

/// The stretch of a handle's axis line over which a tool's mesh is a bar like its handle, as
/// offsets from handle.center along handle.axis [m] (both in the mesh's frame): the run of slices
/// `slice_m` thick (> 0), from the one holding the handle's centre both ways, in which the mesh's
/// surface reaches out from the axis at most between `thinnest` x handle.radius and
/// handle.radius + `thicker_m`. Where a hand can close on the tool as on its handle: a stick's
/// effector end, a shovel's neck (up to its blade), not a hook's thinner shaft or a hammer's head.
/// Exact for the mesh: in each slice the farthest surface point from the axis is a vertex or an
/// edge's crossing of a slice's face. {0, 0} when the slice at the centre is not such a bar.
/// Throws std::invalid_argument for a non-positive slice_m, thinnest outside [0, 1], negative
/// thicker_m or a zero axis.
AxisSpan HandleBarSpan(const TriangleMesh& mesh, const Segment& handle, double slice_m = 0.005, double thinnest = 0.7,
                       double thicker_m = 0.004);

/// Maps a CollisionPart::Type to its sidecar / MuJoCo name ("box", "cylinder", "capsule",
/// "sphere", "mesh").
std::string_view CollisionTypeName(CollisionPart::Type type);

/// Loads one tool from its JSON sidecar. Sidecar fields (SI units, frame T as above):
///   name (string), family (string), mesh (file name relative to the sidecar), mass (> 0),
///   handle and effector ({center: [3], axis: [3] unit, length > 0, radius > 0}),
///   symmetries (array of strings, optional), params (object of numbers, optional),
///   collision (optional array of {type: box|cylinder|capsule|sphere|mesh, size: [3],
///   pos: [3], quat: [w, x, y, z], mass > 0, file: string for type mesh}),
///   total_length (optional; when present it must match the mesh's z extent within 1 mm).
/// The mesh is read (ReadMesh) and validated (RequireValidMesh). Without `collision`, the
/// whole mesh becomes one kMesh part carrying the full mass; MuJoCo then collides it as its
/// convex hull, which a warning on the "toollib" logger points out for concave tools.
/// Throws std::invalid_argument naming the sidecar file and the field (or the mesh problem)
/// for a missing, ill-typed or out-of-range field, an unknown family (only kToolFamilies and
/// "custom" are allowed), collision masses not summing to `mass`, or an invalid mesh.
ToolModel LoadToolModel(const std::filesystem::path& sidecar_json);

/// Loads every `*.json` sidecar in `dir` (not recursive), sorted by tool name.
/// Throws std::invalid_argument when `dir` is not a folder, when two tools share a name, or
/// (from LoadToolModel) naming the first bad file.
std::vector<ToolModel> LoadToolLibrary(const std::filesystem::path& dir);

/// Writes `<dir>/<name>.stl` (binary STL of tool.mesh) and `<dir>/<name>.json` (the sidecar;
/// `mesh` is the STL's file name, kMesh collision parts keep their `mesh_file`), creating `dir`.
/// The inverse of LoadToolModel up to float rounding of the STL vertices.
/// Throws std::invalid_argument for an empty name, std::runtime_error when writing fails.
void SaveToolModel(const ToolModel& tool, const std::filesystem::path& dir);

}  // namespace toolbench::toollib
