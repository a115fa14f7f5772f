#pragma once

#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace toolbench::toollib {

/// An indexed triangle mesh, the one mesh type of toollib.
/// Vertices are in metres, in whatever frame the owner names (a tool's model frame T for
/// library tools). Faces index columns of `vertices` and run counter-clockwise seen from
/// outside, so that the right-hand normal points out of the solid.
struct TriangleMesh {
  Eigen::Matrix3Xd vertices;  // 3 x V vertex positions [m]
  Eigen::Matrix3Xi faces;     // 3 x F vertex indices in [0, V), CCW seen from outside
};

/// What ValidateMesh found. A mesh is `valid` when every listed count of problems is zero,
/// the signed volume is positive and the bounding-box diagonal is in the plausible range.
struct MeshReport {
  bool valid = false;                 // true when `problems` is empty
  int num_vertices = 0;               // columns of vertices
  int num_faces = 0;                  // columns of faces
  int bad_indices = 0;                // face indices outside [0, V)
  int nonfinite_vertices = 0;         // vertices with a NaN or infinite coordinate
  int degenerate_faces = 0;           // faces with a repeated index or (near-)zero area
  int boundary_edges = 0;             // undirected edges used by exactly one face (holes)
  int nonmanifold_edges = 0;          // undirected edges used by more than two faces
  int misoriented_edges = 0;          // edges whose two faces traverse them in the same direction
  int nonmanifold_vertices = 0;       // vertices whose faces form more than one fan
  int num_components = 0;             // edge-connected shells (informative; not a failure)
  double volume = 0.0;                // signed enclosed volume [m^3]; > 0 for outward faces
  double surface_area = 0.0;          // [m^2]
  double bbox_diagonal = 0.0;         // axis-aligned bounding-box diagonal [m]
  std::vector<std::string> problems;  // one human-readable sentence per failed check
};

/// Plausible range of a tool's bounding-box diagonal [m]; outside it the file is most
/// likely in the wrong unit (millimetres, centimetres).
inline constexpr double kMinToolDiagonal = 0.05;
inline constexpr double kMaxToolDiagonal = 2.5;

/// Reads a triangle mesh, choosing the parser from the (case-insensitive) extension:
///  - `.stl`: binary or ASCII (binary when the size matches 84 + 50 n or the header is not
///    text). STL stores a triangle soup; vertices with bit-identical positions are welded so
///    that connectivity is recovered.
///  - `.obj`: `v x y z [w]` and `f` statements (`a`, `a/b`, `a//c`, `a/b/c` forms, negative
///    indices relative to the vertices read so far); polygons are fan-triangulated.
///    Texture, normal, group and material statements are ignored.
///  - `.ply`: `ascii` or `binary_little_endian`, element `vertex` with float/double x, y, z
///    and element `face` with a list property `vertex_indices` (or `vertex_index`) of any
///    integer count and index types; polygons are fan-triangulated; other elements and
///    properties are skipped.
/// Coordinates are taken as metres, unconverted. The reader is strict: an empty file,
/// truncated data, wrong counts, an index out of range, a NaN or infinite coordinate, an
/// unknown extension or a mesh without faces throws std::invalid_argument whose message
/// names the file and the problem. It does not check topology: see ValidateMesh.
TriangleMesh ReadMesh(const std::filesystem::path& path);

/// Writes a binary STL (coordinates rounded to float, per-face unit normals).
/// Throws std::invalid_argument when the mesh has bad indices, std::runtime_error naming the
/// file when it cannot be written.
void WriteStlBinary(const std::filesystem::path& path, const TriangleMesh& mesh);

/// Writes an ASCII PLY (vertex x y z as double with 17 significant digits, face lists of 3).
/// Throws like WriteStlBinary.
void WritePly(const std::filesystem::path& path, const TriangleMesh& mesh);

/// Checks that the mesh is a closed, consistently outward-oriented 2-manifold of plausible
/// size: no bad indices or non-finite vertices, no degenerate faces, every undirected edge
/// used by exactly two faces in opposite directions, every vertex a single fan, positive
/// volume, bounding-box diagonal in [kMinToolDiagonal, kMaxToolDiagonal] m. Never throws;
/// an empty mesh gives a report with a problem. Self-intersection is not checked here (see
/// HasSelfIntersections).
MeshReport ValidateMesh(const TriangleMesh& mesh);

/// Runs ValidateMesh and throws std::invalid_argument when the mesh is not valid, with a
/// message "<name>: invalid mesh: <problems>", where `name` is usually the file name.
/// The unit check says e.g. "looks like millimetres (diagonal 412 m); scale by 0.001".
void RequireValidMesh(const TriangleMesh& mesh, std::string_view name);

/// True when two non-adjacent faces of the mesh intersect, or two adjacent faces overlap
/// beyond their shared vertex or edge (exact predicates, CGAL). Precondition: the faces form
/// an oriented 2-manifold, as they do when ValidateMesh(mesh).valid; throws
/// std::invalid_argument naming the offending face otherwise. Cost: ~10 ms for 5k faces.
bool HasSelfIntersections(const TriangleMesh& mesh);

/// Signed volume enclosed by the mesh [m^3] (divergence theorem); positive when the faces are
/// outward (CCW seen from outside) and the mesh is closed. Throws std::invalid_argument when a
/// face index is outside [0, V).
double Volume(const TriangleMesh& mesh);

/// Centroid of the enclosed solid (uniform density) in the mesh frame [m].
/// Throws std::invalid_argument when the volume is zero (open or flat mesh) or a face index is
/// outside [0, V).
Eigen::Vector3d Centroid(const TriangleMesh& mesh);

/// Axis-aligned bounding box of the vertices in the mesh frame [m]; empty box for no vertices.
Eigen::AlignedBox3d Bounds(const TriangleMesh& mesh);

/// Total area of the faces [m^2]. Throws std::invalid_argument when a face index is outside
/// [0, V).
double SurfaceArea(const TriangleMesh& mesh);

}  // namespace toolbench::toollib
