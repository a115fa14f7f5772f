#include "toollib/generator.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <numeric>
#include <optional>
#include <queue>
#include <string>
#include <tuple>
#include <unordered_map>
#include <utility>
#include <vector>

#include <spdlog/spdlog.h>

#include "common/check.h"
#include "toollib/internal/log.h"
#include "toollib/internal/mesh_boolean.h"
#include "toollib/mesh.h"
#include "toollib/tool_model.h"

namespace toolbench::toollib {
namespace {

using Eigen::Isometry3d;
using Eigen::Matrix3d;
using Eigen::Vector3d;

// Tessellation: 32 segments around handles (a 35 mm handle then deviates < 0.1 mm from a
// true cylinder), rings every 10 mm along tubes, no edge longer than 20 mm, so that triangles
// stay compact enough for area-weighted sampling and SDF segmentation, at 2k-5k faces a tool.
constexpr int kRoundSegments = 32;
constexpr int kThinSegments = 20;       // thin hook shafts (radius <= 8 mm)
constexpr double kRingSpacing = 0.010;  // [m]
constexpr double kMaxEdge = 0.020;      // longest edge after refinement [m]

constexpr double kWoodDensity = 700.0;      // beech [kg/m^3]
constexpr double kPlasticDensity = 1100.0;  // ABS / nylon [kg/m^3]

double Deg(double degrees) { return degrees * std::numbers::pi / 180.0; }

Matrix3d RotY(double angle) {
  return Eigen::AngleAxisd(angle, Vector3d::UnitY()).toRotationMatrix();
}

Isometry3d Pose(const Vector3d& p_TP, const Matrix3d& R_TP = Matrix3d::Identity()) {
  Isometry3d X = Isometry3d::Identity();
  X.linear() = R_TP;
  X.translation() = p_TP;
  return X;
}

// Snaps a coordinate to a multiple of 2^-24 m (60 nm), exactly representable as float for
// |x| < 1 m. Near-coincidences between building blocks (a cylinder vertex 1e-18 m off a box's
// grid line) then become exact coincidences, which the exact union resolves cleanly instead
// of leaving slivers that collapse when rounded to float.
double Snap(double x) {
  constexpr double kGrid = 16777216.0;  // 2^24
  return std::round(x * kGrid) / kGrid;
}

// Indexed mesh under construction; orientation is fixed once at the end from the volume sign.
class MeshBuilder {
 public:
  int AddVertex(const Vector3d& p) {
    points_.push_back(p.unaryExpr([](double x) { return Snap(x); }));
    return static_cast<int>(points_.size()) - 1;
  }
  void AddTriangle(int a, int b, int c) { triangles_.push_back({a, b, c}); }
  // Quad a-b-c-d in cyclic order, split along a-c.
  void AddQuad(int a, int b, int c, int d) {
    AddTriangle(a, b, c);
    AddTriangle(a, c, d);
  }
  TriangleMesh Build() const {
    TriangleMesh mesh;
    mesh.vertices.resize(3, static_cast<Eigen::Index>(points_.size()));
    for (std::size_t i = 0; i < points_.size(); ++i) {
      mesh.vertices.col(static_cast<Eigen::Index>(i)) = points_[i];
    }
    mesh.faces.resize(3, static_cast<Eigen::Index>(triangles_.size()));
    for (std::size_t f = 0; f < triangles_.size(); ++f) {
      mesh.faces.col(static_cast<Eigen::Index>(f)) << triangles_[f][0], triangles_[f][1],
          triangles_[f][2];
    }
    if (Volume(mesh) < 0.0) {
      mesh.faces.row(1).swap(mesh.faces.row(2));
    }
    return mesh;
  }

 private:
  std::vector<Vector3d> points_;
  std::vector<std::array<int, 3>> triangles_;
};

// Closed box with half extents `half`, posed by X_TP: 8 vertices, 12 triangles. Boxes are not
// subdivided before the union (grid lines of neighbouring boxes would nearly coincide and
// leave slivers); FinishMesh refines long edges afterwards.
TriangleMesh BoxMesh(const Isometry3d& X_TP, const Vector3d& half) {
  MeshBuilder builder;
  for (int i = 0; i < 8; ++i) {
    const Vector3d corner((i & 1) ? half.x() : -half.x(), (i & 2) ? half.y() : -half.y(),
                          (i & 4) ? half.z() : -half.z());
    builder.AddVertex(X_TP * corner);
  }
  // Faces as quads of corner bits, CCW seen from outside.
  builder.AddQuad(0, 2, 3, 1);  // -z
  builder.AddQuad(4, 5, 7, 6);  // +z
  builder.AddQuad(0, 1, 5, 4);  // -y
  builder.AddQuad(2, 6, 7, 3);  // +y
  builder.AddQuad(0, 4, 6, 2);  // -x
  builder.AddQuad(1, 3, 7, 5);  // +x
  return builder.Build();
}

// Closed tube of radius r along a polyline lying in a plane with unit normal `plane_normal`,
// mitred at the bends (each joint ring lies in the bisecting plane, so the tube is exactly
// the union of the segments' cylinders clipped at the bisectors), flat end caps, rings at
// most `ring_spacing` apart. `phase` (a fraction of one segment's angle) turns the polygonal
// cross-section about the axis.
TriangleMesh TubeMesh(const std::vector<Vector3d>& path, const Vector3d& plane_normal, double r,
                      int segments, double phase, double ring_spacing) {
  TOOLBENCH_DEMAND(path.size() >= 2);
  const std::size_t num_points = path.size();
  std::vector<Vector3d> dirs;
  for (std::size_t i = 0; i + 1 < num_points; ++i) {
    dirs.push_back((path[i + 1] - path[i]).normalized());
  }
  // Ring = (centre, direction it is projected along, plane normal of the ring).
  struct Ring {
    Vector3d center;
    Vector3d dir;
    Vector3d normal;
  };
  std::vector<Ring> rings;
  for (std::size_t i = 0; i + 1 < num_points; ++i) {
    const Vector3d& d = dirs[i];
    const Vector3d start_normal = i == 0 ? d : Vector3d((dirs[i - 1] + d).normalized());
    const Vector3d end_normal = i + 2 == num_points ? d : Vector3d((d + dirs[i + 1]).normalized());
    rings.push_back({path[i], d, start_normal});
    // Intermediate perpendicular rings, kept clear of the tilted joint rings.
    const double length = (path[i + 1] - path[i]).norm();
    const auto tilt_reach = [&](const Vector3d& normal) {
      const double c = std::clamp(normal.dot(d), 1e-6, 1.0);
      return r * std::sqrt(1.0 - c * c) / c + 0.002;
    };
    const double lo = i == 0 ? 0.0 : tilt_reach(start_normal);
    const double hi = length - (i + 2 == num_points ? 0.0 : tilt_reach(end_normal));
    const int divisions = static_cast<int>(std::ceil(length / ring_spacing));
    for (int j = 1; j < divisions; ++j) {
      const double s = length * j / divisions;
      if (s > lo && s < hi) {
        rings.push_back({path[i] + s * d, d, d});
      }
    }
  }
  rings.push_back({path.back(), dirs.back(), dirs.back()});

  MeshBuilder builder;
  std::vector<std::vector<int>> ids;
  for (const Ring& ring : rings) {
    const Vector3d b = ring.dir.cross(plane_normal).normalized();
    std::vector<int> row;
    for (int k = 0; k < segments; ++k) {
      const double theta = 2.0 * std::numbers::pi * (k + phase) / segments;
      const Vector3d offset = r * (std::cos(theta) * plane_normal + std::sin(theta) * b);
      // Slide along the segment direction onto the (possibly tilted) ring plane.
      const double t = -offset.dot(ring.normal) / ring.dir.dot(ring.normal);
      row.push_back(builder.AddVertex(ring.center + offset + t * ring.dir));
    }
    ids.push_back(std::move(row));
  }
  for (std::size_t i = 0; i + 1 < ids.size(); ++i) {
    for (int k = 0; k < segments; ++k) {
      const auto k0 = static_cast<std::size_t>(k);
      const auto k1 = static_cast<std::size_t>((k + 1) % segments);
      builder.AddQuad(ids[i][k0], ids[i][k1], ids[i + 1][k1], ids[i + 1][k0]);
    }
  }
  const int first_center = builder.AddVertex(rings.front().center);
  const int last_center = builder.AddVertex(rings.back().center);
  for (int k = 0; k < segments; ++k) {
    const auto k0 = static_cast<std::size_t>(k);
    const auto k1 = static_cast<std::size_t>((k + 1) % segments);
    builder.AddTriangle(first_center, ids.front()[k1], ids.front()[k0]);
    builder.AddTriangle(last_center, ids.back()[k0], ids.back()[k1]);
  }
  return builder.Build();
}

// A plane normal perpendicular to `axis`, preferring +y (the tools' bending planes are x-z).
Vector3d NormalTo(const Vector3d& axis) {
  const Vector3d candidate = std::abs(axis.y()) < 0.9 ? Vector3d::UnitY() : Vector3d::UnitX();
  return (candidate - candidate.dot(axis) * axis).normalized();
}

TriangleMesh CylinderMesh(const Vector3d& p0, const Vector3d& p1, double r, int segments,
                          double phase, double ring_spacing) {
  return TubeMesh({p0, p1}, NormalTo((p1 - p0).normalized()), r, segments, phase, ring_spacing);
}

CollisionPart BoxPart(const Isometry3d& X_TP, const Vector3d& half) {
  CollisionPart part;
  part.type = CollisionPart::Type::kBox;
  part.size = half;
  part.X_TP = X_TP;
  return part;
}

CollisionPart CylinderPart(const Vector3d& p0, const Vector3d& p1, double r) {
  CollisionPart part;
  part.type = CollisionPart::Type::kCylinder;
  part.size = Vector3d(r, 0.5 * (p1 - p0).norm(), 0.0);
  const Matrix3d R =
      Eigen::Quaterniond::FromTwoVectors(Vector3d::UnitZ(), p1 - p0).toRotationMatrix();
  part.X_TP = Pose(0.5 * (p0 + p1), R);
  return part;
}

CollisionPart SpherePart(const Vector3d& center, double r) {
  CollisionPart part;
  part.type = CollisionPart::Type::kSphere;
  part.size = Vector3d(r, 0.0, 0.0);
  part.X_TP = Pose(center);
  return part;
}

double PartVolume(const CollisionPart& part) {
  switch (part.type) {
    case CollisionPart::Type::kBox:
      return 8.0 * part.size.prod();
    case CollisionPart::Type::kCylinder:
      return std::numbers::pi * part.size.x() * part.size.x() * 2.0 * part.size.y();
    case CollisionPart::Type::kCapsule:
      return std::numbers::pi * part.size.x() * part.size.x() *
             (2.0 * part.size.y() + 4.0 / 3.0 * part.size.x());
    case CollisionPart::Type::kSphere:
      return 4.0 / 3.0 * std::numbers::pi * std::pow(part.size.x(), 3);
    case CollisionPart::Type::kMesh:
      break;
  }
  TOOLBENCH_DEMAND(false);
  return 0.0;
}

Segment MakeSegment(const Vector3d& center, const Vector3d& axis, double length, double radius) {
  Segment s;
  s.center = center;
  s.axis = axis.normalized();
  s.length = length;
  s.radius = radius;
  return s;
}

// Tessellation choices. Regular polygons and evenly spaced rings of different blocks can
// nearly coincide (a vertex 1e-9 m off another block's edge) and leave slivers that collapse
// when rounded to float; a tool that comes out broken is rebuilt with the next attempt's
// shifted phases and ring spacing (deterministically).
struct Tessellation {
  double phase = 0.0;                  // polygon rotation, fraction of one segment
  double ring_spacing = kRingSpacing;  // [m]
};

Tessellation TessellationForAttempt(int attempt) {
  Tessellation t;
  t.phase = 0.173 * attempt;
  t.ring_spacing = kRingSpacing * (1.0 - 0.031 * attempt);
  return t;
}

// A tool while it is being assembled from convex blocks.
struct Draft {
  Tessellation tess;
  std::string name;
  std::string family;
  double density = kWoodDensity;
  std::vector<TriangleMesh> solids;  // unioned into the visual mesh
  std::vector<CollisionPart> parts;  // masses filled in by Finish
  Segment handle;
  Segment effector;
  std::vector<std::string> symmetries;
  std::map<std::string, double> params;
};

Draft NewDraft(const std::string& family, int index, double density, int attempt) {
  Draft draft;
  draft.tess = TessellationForAttempt(attempt);
  draft.name = family + "_" + std::to_string(index);
  draft.family = family;
  draft.density = density;
  return draft;
}

// Handle: cylinder from the butt (origin) to z = length, with its collision part.
void AddHandle(Draft& draft, double length, double diameter) {
  const double r = 0.5 * diameter;
  draft.solids.push_back(CylinderMesh(Vector3d::Zero(), Vector3d(0, 0, length), r, kRoundSegments,
                                      draft.tess.phase, draft.tess.ring_spacing));
  draft.parts.push_back(CylinderPart(Vector3d::Zero(), Vector3d(0, 0, length), r));
  draft.params["handle_length"] = length;
  draft.params["handle_diameter"] = diameter;
}

// Handle segment over the clear part of the handle, [0, clear_length] along z.
Segment HandleSegment(double clear_length, double diameter) {
  return MakeSegment(Vector3d(0, 0, 0.5 * clear_length), Vector3d::UnitZ(), clear_length,
                     0.5 * diameter);
}

void AddBox(Draft& draft, const Isometry3d& X_TP, const Vector3d& half) {
  draft.solids.push_back(BoxMesh(X_TP, half));
  draft.parts.push_back(BoxPart(X_TP, half));
}

// Box from its corner ranges in a frame X_TB.
void AddBoxRange(Draft& draft, const Isometry3d& X_TB, const Vector3d& lo, const Vector3d& hi) {
  AddBox(draft, X_TB * Pose(0.5 * (lo + hi)), 0.5 * (hi - lo));
}

// Mesh moved by X_TB, vertices snapped again (see Snap).
TriangleMesh Transformed(const TriangleMesh& mesh_B, const Isometry3d& X_TB) {
  TriangleMesh mesh_T;
  mesh_T.faces = mesh_B.faces;
  mesh_T.vertices =
      ((X_TB.linear() * mesh_B.vertices).colwise() + X_TB.translation()).unaryExpr([](double x) {
        return Snap(x);
      });
  return mesh_T;
}

Vector3d RoundToFloat(const Vector3d& p) {
  return Vector3d(static_cast<float>(p.x()), static_cast<float>(p.y()), static_cast<float>(p.z()));
}

std::uint64_t DirectedEdge(int a, int b) {
  return (static_cast<std::uint64_t>(static_cast<std::uint32_t>(a)) << 32) |
         static_cast<std::uint32_t>(b);
}

// Longest-first edge bisection until no edge is longer than max_length: each split edge is cut
// at its midpoint in both faces that share it, so the surface and its closedness are kept.
// New vertices are rounded to float like the others.
void RefineLongEdges(std::vector<Vector3d>& points, std::vector<std::array<int, 3>>& faces,
                     double max_length) {
  std::unordered_map<std::uint64_t, int> face_of;  // directed edge -> face holding it
  using Item = std::tuple<double, int, int>;       // (length, a, b), a < b
  std::priority_queue<Item> queue;
  const auto length = [&](int a, int b) {
    return (points[static_cast<std::size_t>(a)] - points[static_cast<std::size_t>(b)]).norm();
  };
  const auto link = [&](int f) {
    const auto& t = faces[static_cast<std::size_t>(f)];
    for (int k = 0; k < 3; ++k) {
      const int a = t[static_cast<std::size_t>(k)];
      const int b = t[static_cast<std::size_t>((k + 1) % 3)];
      face_of[DirectedEdge(a, b)] = f;
      if (a < b && length(a, b) > max_length) {
        queue.emplace(length(a, b), a, b);
      }
    }
  };
  const auto unlink = [&](int f) {
    const auto& t = faces[static_cast<std::size_t>(f)];
    for (int k = 0; k < 3; ++k) {
      face_of.erase(
          DirectedEdge(t[static_cast<std::size_t>(k)], t[static_cast<std::size_t>((k + 1) % 3)]));
    }
  };
  // Replaces face f = (a, b, c) (in some rotation) by (a, m, c) and appends (m, b, c).
  const auto split = [&](int f, int a, int b, int m) {
    auto t = faces[static_cast<std::size_t>(f)];
    while (t[0] != a) {
      std::rotate(t.begin(), t.begin() + 1, t.end());
    }
    TOOLBENCH_DEMAND(t[1] == b);
    const int c = t[2];
    unlink(f);
    faces[static_cast<std::size_t>(f)] = {a, m, c};
    faces.push_back({m, b, c});
    link(f);
    link(static_cast<int>(faces.size()) - 1);
  };
  for (int f = 0; f < static_cast<int>(faces.size()); ++f) {
    link(f);
  }
  while (!queue.empty()) {
    const auto [len, a, b] = queue.top();
    queue.pop();
    const auto f1 = face_of.find(DirectedEdge(a, b));
    const auto f2 = face_of.find(DirectedEdge(b, a));
    if (f1 == face_of.end() || f2 == face_of.end()) {
      continue;  // already split
    }
    const int face1 = f1->second;
    const int face2 = f2->second;
    points.push_back(RoundToFloat(
        0.5 * (points[static_cast<std::size_t>(a)] + points[static_cast<std::size_t>(b)])));
    const int m = static_cast<int>(points.size()) - 1;
    split(face1, a, b, m);
    split(face2, b, a, m);
  }
}

// Rounds to float (what a binary STL stores), refines long edges, renumbers vertices in order
// of first use (so an STL round trip returns the same mesh), and checks the result: the
// library promises valid, single-shell, self-intersection-free meshes.
std::optional<TriangleMesh> FinishMesh(const TriangleMesh& raw, const std::string& name) {
  std::vector<Vector3d> points;
  for (Eigen::Index i = 0; i < raw.vertices.cols(); ++i) {
    points.push_back(RoundToFloat(raw.vertices.col(i)));
  }
  // CGAL's output order depends on memory addresses (it differs between an ASan and a
  // release build), so sort vertices by position and faces by vertices first: the result then
  // depends on the geometry alone.
  std::vector<int> order(points.size());
  std::iota(order.begin(), order.end(), 0);
  const auto position = [&](int i) {
    const Vector3d& p = points[static_cast<std::size_t>(i)];
    return std::array<double, 3>{p.x(), p.y(), p.z()};
  };
  std::stable_sort(order.begin(), order.end(),
                   [&](int a, int b) { return position(a) < position(b); });
  std::vector<int> rank(points.size());
  std::vector<Vector3d> sorted_points;
  for (std::size_t i = 0; i < order.size(); ++i) {
    rank[static_cast<std::size_t>(order[i])] = static_cast<int>(i);
    sorted_points.push_back(points[static_cast<std::size_t>(order[i])]);
  }
  points = std::move(sorted_points);
  std::vector<std::array<int, 3>> faces;
  for (Eigen::Index f = 0; f < raw.faces.cols(); ++f) {
    std::array<int, 3> t{rank[static_cast<std::size_t>(raw.faces(0, f))],
                         rank[static_cast<std::size_t>(raw.faces(1, f))],
                         rank[static_cast<std::size_t>(raw.faces(2, f))]};
    std::rotate(t.begin(), std::min_element(t.begin(), t.end()), t.end());  // keeps orientation
    faces.push_back(t);
  }
  std::sort(faces.begin(), faces.end());
  RefineLongEdges(points, faces, kMaxEdge);

  std::vector<int> new_index(points.size(), -1);
  TriangleMesh mesh;
  mesh.faces.resize(3, static_cast<Eigen::Index>(faces.size()));
  std::vector<Vector3d> used;
  for (std::size_t f = 0; f < faces.size(); ++f) {
    for (std::size_t k = 0; k < 3; ++k) {
      int& index = new_index[static_cast<std::size_t>(faces[f][k])];
      if (index < 0) {
        index = static_cast<int>(used.size());
        used.push_back(points[static_cast<std::size_t>(faces[f][k])]);
      }
      mesh.faces(static_cast<Eigen::Index>(k), static_cast<Eigen::Index>(f)) = index;
    }
  }
  mesh.vertices.resize(3, static_cast<Eigen::Index>(used.size()));
  for (std::size_t i = 0; i < used.size(); ++i) {
    mesh.vertices.col(static_cast<Eigen::Index>(i)) = used[i];
  }

  // Distinct vertices must stay distinct after rounding, or STL welding would change topology.
  std::vector<std::array<double, 3>> sorted;
  for (const Vector3d& p : used) {
    sorted.push_back({p.x(), p.y(), p.z()});
  }
  std::sort(sorted.begin(), sorted.end());
  const bool distinct = std::adjacent_find(sorted.begin(), sorted.end()) == sorted.end();
  const MeshReport report = ValidateMesh(mesh);
  // Only a valid mesh meets HasSelfIntersections' precondition (an oriented 2-manifold).
  const bool self_intersects = distinct && report.valid && HasSelfIntersections(mesh);
  if (!distinct || !report.valid || report.num_components != 1 || self_intersects) {
    internal::Logger()->debug(
        "toollib generator: {} mesh rejected: distinct vertices {}, components {}, "
        "self-intersecting {}, {}",
        name, distinct, report.num_components, self_intersects,
        report.problems.empty() ? std::string() : report.problems.front());
    return std::nullopt;
  }
  return mesh;
}

// Turns a draft into a tool: the union mesh, mass, part masses, total length. Empty when the
// mesh came out broken (see Tessellation).
std::optional<ToolModel> Finish(Draft draft) {
  std::optional<TriangleMesh> mesh = FinishMesh(
      draft.solids.size() == 1 ? draft.solids.front() : internal::UnionMeshes(draft.solids),
      draft.name);
  if (!mesh) {
    return std::nullopt;
  }
  ToolModel tool;
  tool.name = draft.name;
  tool.family = draft.family;
  tool.mesh = std::move(*mesh);
  tool.mesh_file = draft.name + ".stl";
  tool.mass = draft.density * Volume(tool.mesh);
  double part_volume = 0.0;
  for (const CollisionPart& part : draft.parts) {
    part_volume += PartVolume(part);
  }
  for (CollisionPart& part : draft.parts) {
    part.mass = tool.mass * PartVolume(part) / part_volume;
  }
  tool.collision = std::move(draft.parts);
  tool.handle = draft.handle;
  tool.effector = draft.effector;
  tool.symmetries = std::move(draft.symmetries);
  draft.params["density"] = draft.density;
  tool.params = std::move(draft.params);
  const Eigen::AlignedBox3d box = Bounds(tool.mesh);
  tool.total_length = box.max().z() - box.min().z();
  return tool;
}

// ------------------------------------------------------------------------- families
// Parameter tables: lengths [m], angles [deg]. Four variants per family.

struct HoeParams {
  double handle_length, handle_diameter, blade_width, blade_reach, blade_thickness;
};
constexpr HoeParams kHoes[] = {
    {0.26, 0.028, 0.080, 0.060, 0.005},
    {0.32, 0.030, 0.110, 0.050, 0.006},
    {0.25, 0.024, 0.065, 0.075, 0.005},
    {0.38, 0.033, 0.130, 0.085, 0.006},
};

// Flat blade across the top of the handle, normal along the handle, reaching toward +x.
std::optional<ToolModel> MakeHoe(const HoeParams& p, int index, int attempt) {
  Draft d = NewDraft("hoe", index, kWoodDensity, attempt);
  AddHandle(d, p.handle_length, p.handle_diameter);
  const double back = 0.5 * p.handle_diameter + 0.004;  // blade covers the handle's end cap
  const double top = p.handle_length + 0.0015;
  AddBoxRange(d, Isometry3d::Identity(),
              Vector3d(-back, -0.5 * p.blade_width, top - p.blade_thickness),
              Vector3d(p.blade_reach, 0.5 * p.blade_width, top));
  d.handle = HandleSegment(top - p.blade_thickness, p.handle_diameter);
  d.effector = MakeSegment(Vector3d(0.5 * (p.blade_reach - back), 0, top - 0.5 * p.blade_thickness),
                           Vector3d::UnitX(), p.blade_reach + back, 0.5 * p.blade_width);
  d.symmetries = {"mirror_y"};
  d.params["blade_width"] = p.blade_width;
  d.params["blade_reach"] = p.blade_reach;
  d.params["blade_thickness"] = p.blade_thickness;
  return Finish(std::move(d));
}

struct HookParams {
  double handle_length, handle_diameter, shaft_radius, shaft_length, depth, tip_length, tip_angle;
};
constexpr HookParams kHooks[] = {
    {0.16, 0.026, 0.006, 0.20, 0.050, 0.030, 0.0},
    {0.18, 0.028, 0.007, 0.24, 0.070, 0.040, 20.0},
    {0.15, 0.024, 0.006, 0.16, 0.040, 0.025, 0.0},
    {0.20, 0.030, 0.008, 0.28, 0.080, 0.035, 30.0},
};

// Thin shaft out of the handle, bent to +x at the top (the hook's depth), with a tip bent
// back down (tilted back toward the shaft by tip_angle).
std::optional<ToolModel> MakeHook(const HookParams& p, int index, int attempt) {
  Draft d = NewDraft("hook", index, kPlasticDensity, attempt);
  AddHandle(d, p.handle_length, p.handle_diameter);
  const double r = p.shaft_radius;
  const double z_bend = p.handle_length + p.shaft_length;
  const double a = Deg(p.tip_angle);
  const std::vector<Vector3d> path = {
      Vector3d(0, 0, p.handle_length - 0.02), Vector3d(0, 0, z_bend), Vector3d(p.depth, 0, z_bend),
      Vector3d(p.depth - p.tip_length * std::sin(a), 0, z_bend - p.tip_length * std::cos(a))};
  d.solids.push_back(TubeMesh(path, Vector3d::UnitY(), r, kThinSegments, d.tess.phase + 0.29,
                              d.tess.ring_spacing));
  d.parts.push_back(CylinderPart(Vector3d(0, 0, p.handle_length), path[1], r));
  d.parts.push_back(SpherePart(path[1], r));
  d.parts.push_back(CylinderPart(path[1], path[2], r));
  d.parts.push_back(SpherePart(path[2], r));
  d.parts.push_back(CylinderPart(path[2], path[3], r));
  d.handle = HandleSegment(p.handle_length, p.handle_diameter);
  d.effector = MakeSegment(Vector3d(0.5 * p.depth, 0, z_bend), Vector3d::UnitX(), p.depth, r);
  d.symmetries = {"mirror_y"};
  d.params["shaft_diameter"] = 2.0 * r;
  d.params["shaft_length"] = p.shaft_length;
  d.params["hook_depth"] = p.depth;
  d.params["tip_length"] = p.tip_length;
  d.params["tip_angle"] = a;
  return Finish(std::move(d));
}

struct RakeParams {
  double handle_length, handle_diameter, head_width, head_height;
  int teeth;
  double tooth_length, tooth_width;
};
constexpr RakeParams kRakes[] = {
    {0.30, 0.026, 0.120, 0.014, 5, 0.035, 0.007},
    {0.34, 0.030, 0.150, 0.016, 7, 0.045, 0.007},
    {0.26, 0.024, 0.090, 0.012, 3, 0.030, 0.008},
    {0.40, 0.032, 0.140, 0.015, 5, 0.050, 0.008},
};

// Cross bar (head) across the top of the handle along y, square teeth toward +x.
std::optional<ToolModel> MakeRake(const RakeParams& p, int index, int attempt) {
  Draft d = NewDraft("rake", index, kWoodDensity, attempt);
  AddHandle(d, p.handle_length, p.handle_diameter);
  const double hx = 0.5 * p.handle_diameter + 0.004;
  const double top = p.handle_length + 0.002;
  const double zc = top - 0.5 * p.head_height;
  AddBoxRange(d, Isometry3d::Identity(), Vector3d(-hx, -0.5 * p.head_width, top - p.head_height),
              Vector3d(hx, 0.5 * p.head_width, top));
  const double y_max = 0.5 * p.head_width - 0.5 * p.tooth_width - 0.003;
  for (int k = 0; k < p.teeth; ++k) {
    const double y = -y_max + 2.0 * y_max * k / (p.teeth - 1);
    AddBoxRange(d, Isometry3d::Identity(),
                Vector3d(0.0, y - 0.5 * p.tooth_width, zc - 0.5 * p.tooth_width),
                Vector3d(hx + p.tooth_length, y + 0.5 * p.tooth_width, zc + 0.5 * p.tooth_width));
  }
  d.handle = HandleSegment(top - p.head_height, p.handle_diameter);
  d.effector = MakeSegment(Vector3d(0.5 * p.tooth_length, 0, zc), Vector3d::UnitX(),
                           2.0 * hx + p.tooth_length, 0.5 * p.head_width);
  d.symmetries = {"mirror_y"};
  d.params["head_width"] = p.head_width;
  d.params["head_height"] = p.head_height;
  d.params["teeth"] = p.teeth;
  d.params["tooth_length"] = p.tooth_length;
  d.params["tooth_width"] = p.tooth_width;
  return Finish(std::move(d));
}

struct StickParams {
  double length, diameter;
};
constexpr StickParams kSticks[] = {{0.35, 0.022}, {0.42, 0.026}, {0.50, 0.030}, {0.58, 0.034}};
constexpr double kStickEffectorLength = 0.08;  // the distal end that touches the object [m]

std::optional<ToolModel> MakeStick(const StickParams& p, int index, int attempt) {
  Draft d = NewDraft("stick", index, kWoodDensity, attempt);
  AddHandle(d, p.length, p.diameter);
  d.handle = HandleSegment(p.length - kStickEffectorLength, p.diameter);
  d.effector = MakeSegment(Vector3d(0, 0, p.length - 0.5 * kStickEffectorLength), Vector3d::UnitZ(),
                           kStickEffectorLength, 0.5 * p.diameter);
  d.symmetries = {"rot_z_any", "rot_x_180"};
  return Finish(std::move(d));
}

struct LStickParams {
  double shaft_length, diameter, foot_length, foot_angle;
};
constexpr LStickParams kLSticks[] = {
    {0.30, 0.024, 0.080, 90.0},
    {0.36, 0.028, 0.110, 90.0},
    {0.26, 0.022, 0.065, 75.0},
    {0.40, 0.030, 0.120, 105.0},
};

// One round bar bent at the top: the foot leaves the shaft at foot_angle from +z toward +x.
std::optional<ToolModel> MakeLStick(const LStickParams& p, int index, int attempt) {
  Draft d = NewDraft("lstick", index, kWoodDensity, attempt);
  const double r = 0.5 * p.diameter;
  const double phi = Deg(p.foot_angle);
  const Vector3d corner(0, 0, p.shaft_length);
  const Vector3d foot_dir(std::sin(phi), 0, std::cos(phi));
  const Vector3d tip = corner + p.foot_length * foot_dir;
  d.solids.push_back(TubeMesh({Vector3d::Zero(), corner, tip}, Vector3d::UnitY(), r, kRoundSegments,
                              d.tess.phase, d.tess.ring_spacing));
  d.parts.push_back(CylinderPart(Vector3d::Zero(), corner, r));
  d.parts.push_back(SpherePart(corner, r));
  d.parts.push_back(CylinderPart(corner, tip, r));
  d.handle = HandleSegment(p.shaft_length - r, p.diameter);
  d.effector = MakeSegment(corner + 0.5 * p.foot_length * foot_dir, foot_dir, p.foot_length, r);
  d.symmetries = {"mirror_y"};
  d.params["handle_length"] = p.shaft_length;
  d.params["handle_diameter"] = p.diameter;
  d.params["foot_length"] = p.foot_length;
  d.params["foot_angle"] = phi;
  return Finish(std::move(d));
}

struct ShovelParams {
  double handle_length, handle_diameter, blade_width, blade_length, wall_height, tilt;
};
constexpr ShovelParams kShovels[] = {
    {0.24, 0.028, 0.080, 0.100, 0.015, 0.0},
    {0.30, 0.030, 0.100, 0.120, 0.018, 10.0},
    {0.20, 0.026, 0.070, 0.090, 0.012, 15.0},
    {0.32, 0.032, 0.110, 0.140, 0.020, 20.0},
};
constexpr double kShovelNeck = 0.02;    // neck between handle and blade [m]
constexpr double kShovelPlate = 0.004;  // blade plate thickness [m]

// Scoop: a plate continuing the handle, with side walls and a back wall rising toward +x,
// joined to the handle by a neck; the blade tilts toward +x by `tilt`.
std::optional<ToolModel> MakeShovel(const ShovelParams& p, int index, int attempt) {
  Draft d = NewDraft("shovel", index, kWoodDensity, attempt);
  AddHandle(d, p.handle_length, p.handle_diameter);
  const double z0 = p.handle_length + kShovelNeck;  // blade's near edge
  const double t = 0.5 * kShovelPlate;
  const double w = 0.5 * p.blade_width;
  AddBoxRange(d, Isometry3d::Identity(), Vector3d(-0.006, -0.010, p.handle_length - 0.015),
              Vector3d(0.006, 0.010, z0 + 0.003));
  // Blade frame B: pivot at the neck's top, tilted about y. The tray is one box minus a
  // cavity box that overshoots the open sides, so no two faces are coplanar (coplanar
  // overlaps leave slivers once rounded to float); it is built in B and then turned.
  const Isometry3d X_TB = Pose(Vector3d(0, 0, Snap(z0 + 0.003)), RotY(Deg(p.tilt)));
  const double b0 = -0.003;  // near edge of the blade in B
  const double b1 = b0 + p.blade_length;
  const double x1 = t + p.wall_height;
  constexpr double kWall = 0.004;      // side wall thickness [m]
  constexpr double kBackWall = 0.006;  // back wall thickness [m]
  const auto box_B = [](const Vector3d& lo, const Vector3d& hi) {
    return BoxMesh(Pose(0.5 * (lo + hi)), 0.5 * (hi - lo));
  };
  const TriangleMesh tray_B = internal::DifferenceMeshes(
      box_B(Vector3d(-t, -w, b0), Vector3d(x1, w, b1)),
      box_B(Vector3d(t, -w + kWall, b0 + kBackWall), Vector3d(x1 + 0.01, w - kWall, b1 + 0.01)));
  d.solids.push_back(Transformed(tray_B, X_TB));
  const auto part = [&](const Vector3d& lo, const Vector3d& hi) {
    d.parts.push_back(BoxPart(X_TB * Pose(0.5 * (lo + hi)), 0.5 * (hi - lo)));
  };
  part(Vector3d(-t, -w, b0), Vector3d(t, w, b1));               // plate
  part(Vector3d(-t, -w, b0), Vector3d(x1, w, b0 + kBackWall));  // back wall
  part(Vector3d(t, -w, b0), Vector3d(x1, -w + kWall, b1));      // side walls
  part(Vector3d(t, w - kWall, b0), Vector3d(x1, w, b1));
  d.handle = HandleSegment(p.handle_length, p.handle_diameter);
  d.effector = MakeSegment(X_TB * Vector3d(0, 0, 0.5 * (b0 + b1)),
                           X_TB.linear() * Vector3d::UnitZ(), p.blade_length, w);
  d.symmetries = {"mirror_y"};
  d.params["blade_width"] = p.blade_width;
  d.params["blade_length"] = p.blade_length;
  d.params["wall_height"] = p.wall_height;
  d.params["blade_tilt"] = Deg(p.tilt);
  return Finish(std::move(d));
}

struct HammerParams {
  double handle_length, handle_diameter, head_radius, head_length;
};
constexpr HammerParams kHammers[] = {
    {0.25, 0.026, 0.018, 0.090},
    {0.30, 0.030, 0.021, 0.110},
    {0.24, 0.024, 0.016, 0.080},
    {0.33, 0.032, 0.022, 0.120},
};

// Round head across the top of the handle along x: a wider striking face at +x, a narrower
// peen at -x.
std::optional<ToolModel> MakeHammer(const HammerParams& p, int index, int attempt) {
  Draft d = NewDraft("hammer", index, kWoodDensity, attempt);
  AddHandle(d, p.handle_length, p.handle_diameter);
  const double z = p.handle_length;
  const double half = 0.5 * p.head_length;
  const double R = p.head_radius;
  const auto add_round = [&](double x0, double x1, double radius, double phase) {
    const Vector3d p0(x0, 0, z);
    const Vector3d p1(x1, 0, z);
    d.solids.push_back(
        CylinderMesh(p0, p1, radius, kRoundSegments, d.tess.phase + phase, d.tess.ring_spacing));
    d.parts.push_back(CylinderPart(p0, p1, radius));
  };
  // Different phases keep the coaxial polygons' vertices apart; not half a step, where the
  // face's spokes would pass through the midpoints of the body's chords.
  add_round(-half + 0.012, half - 0.010, R, 0.0);    // body
  add_round(half - 0.014, half, R + 0.002, 0.37);    // striking face
  add_round(-half, -half + 0.016, R - 0.004, 0.61);  // peen
  d.handle = HandleSegment(z - R, p.handle_diameter);
  d.effector = MakeSegment(Vector3d(0.5 * half, 0, z), Vector3d::UnitX(), half, R + 0.002);
  d.symmetries = {"mirror_y"};
  d.params["head_radius"] = R;
  d.params["head_length"] = p.head_length;
  return Finish(std::move(d));
}

struct SpatulaParams {
  double handle_length, handle_diameter, blade_width, blade_length, tilt, shank_length;
};
constexpr SpatulaParams kSpatulas[] = {
    {0.16, 0.022, 0.060, 0.090, 0.0, 0.040},
    {0.18, 0.024, 0.070, 0.100, 15.0, 0.050},
    {0.16, 0.022, 0.055, 0.080, 25.0, 0.045},
    {0.20, 0.026, 0.080, 0.110, 10.0, 0.060},
};
constexpr double kSpatulaBlade = 0.003;  // blade thickness [m]

// Flat thin blade on a flat shank; the blade is bent toward +x by `tilt` at the shank's end.
std::optional<ToolModel> MakeSpatula(const SpatulaParams& p, int index, int attempt) {
  Draft d = NewDraft("spatula", index, kPlasticDensity, attempt);
  AddHandle(d, p.handle_length, p.handle_diameter);
  const double pivot_z = p.handle_length + p.shank_length;
  AddBoxRange(d, Isometry3d::Identity(), Vector3d(-0.0025, -0.006, p.handle_length - 0.02),
              Vector3d(0.0025, 0.006, pivot_z + 0.006));
  const Isometry3d X_TB = Pose(Vector3d(0, 0, pivot_z), RotY(Deg(p.tilt)));
  const double b0 = -0.010;
  const double b1 = b0 + p.blade_length;
  const double w = 0.5 * p.blade_width;
  AddBoxRange(d, X_TB, Vector3d(-0.5 * kSpatulaBlade, -w, b0),
              Vector3d(0.5 * kSpatulaBlade, w, b1));
  d.handle = HandleSegment(p.handle_length, p.handle_diameter);
  d.effector = MakeSegment(X_TB * Vector3d(0, 0, 0.5 * (b0 + b1)),
                           X_TB.linear() * Vector3d::UnitZ(), p.blade_length, w);
  d.symmetries = {"mirror_y"};
  d.params["blade_width"] = p.blade_width;
  d.params["blade_length"] = p.blade_length;
  d.params["blade_tilt"] = Deg(p.tilt);
  d.params["shank_length"] = p.shank_length;
  // Untilted, the spatula is boxes and a cylinder centred on the handle axis: turned half about
  // it, it is the same shape, so its working side cannot be told from the shape.
  if (p.tilt == 0.0) d.symmetries.push_back("rot_z_180");
  return Finish(std::move(d));
}

constexpr int kMaxAttempts = 6;

template <typename Params, typename Maker>
void AddFamily(const Params& table, Maker make, std::vector<ToolModel>& tools) {
  int index = 1;
  for (const auto& p : table) {
    std::optional<ToolModel> tool;
    for (int attempt = 0; attempt < kMaxAttempts && !tool; ++attempt) {
      tool = make(p, index, attempt);
    }
    TOOLBENCH_DEMAND(tool.has_value());  // a parameter table entry no tessellation can build
    tools.push_back(std::move(*tool));
    ++index;
  }
}

}  // namespace

std::vector<ToolModel> GenerateToolLibrary() {
  std::vector<ToolModel> tools;
  AddFamily(kHoes, MakeHoe, tools);
  AddFamily(kHooks, MakeHook, tools);
  AddFamily(kRakes, MakeRake, tools);
  AddFamily(kSticks, MakeStick, tools);
  AddFamily(kLSticks, MakeLStick, tools);
  AddFamily(kShovels, MakeShovel, tools);
  AddFamily(kHammers, MakeHammer, tools);
  AddFamily(kSpatulas, MakeSpatula, tools);
  return tools;
}

void WriteToolLibrary(const std::filesystem::path& dir) {
  for (const ToolModel& tool : GenerateToolLibrary()) {
    SaveToolModel(tool, dir);
  }
}

}  // namespace toolbench::toollib
