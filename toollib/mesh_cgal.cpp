// The only translation unit of toollib that includes CGAL (a CGAL TU takes 30-45 s to build).
#include <cstddef>
#include <vector>

#include <CGAL/Exact_predicates_exact_constructions_kernel.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Polygon_mesh_processing/corefinement.h>
#include <CGAL/Polygon_mesh_processing/self_intersections.h>
#include <CGAL/Surface_mesh.h>

#include "common/check.h"
#include "toollib/internal/mesh_boolean.h"
#include "toollib/mesh.h"

namespace toolbench::toollib {
namespace {

namespace PMP = CGAL::Polygon_mesh_processing;
using Epeck = CGAL::Exact_predicates_exact_constructions_kernel;
using Epick = CGAL::Exact_predicates_inexact_constructions_kernel;

template <typename Kernel>
CGAL::Surface_mesh<typename Kernel::Point_3> ToSurfaceMesh(const TriangleMesh& mesh,
                                                           const char* caller) {
  using SurfaceMesh = CGAL::Surface_mesh<typename Kernel::Point_3>;
  SurfaceMesh out;
  const auto num_vertices = static_cast<int>(mesh.vertices.cols());
  std::vector<typename SurfaceMesh::Vertex_index> handles;
  handles.reserve(static_cast<std::size_t>(num_vertices));
  for (int i = 0; i < num_vertices; ++i) {
    handles.push_back(out.add_vertex(
        typename Kernel::Point_3(mesh.vertices(0, i), mesh.vertices(1, i), mesh.vertices(2, i))));
  }
  for (int f = 0; f < mesh.faces.cols(); ++f) {
    for (int k = 0; k < 3; ++k) {
      if (mesh.faces(k, f) < 0 || mesh.faces(k, f) >= num_vertices) {
        ThrowInvalid(caller, ": face ", f, " has vertex index ", mesh.faces(k, f), " outside [0, ",
                     num_vertices, ")");
      }
    }
    const auto face = out.add_face(handles[static_cast<std::size_t>(mesh.faces(0, f))],
                                   handles[static_cast<std::size_t>(mesh.faces(1, f))],
                                   handles[static_cast<std::size_t>(mesh.faces(2, f))]);
    if (face == SurfaceMesh::null_face()) {
      ThrowInvalid(caller, ": face ", f, " makes the mesh non-manifold");
    }
  }
  return out;
}

TriangleMesh FromSurfaceMesh(const CGAL::Surface_mesh<Epeck::Point_3>& mesh) {
  using SurfaceMesh = CGAL::Surface_mesh<Epeck::Point_3>;
  TriangleMesh out;
  // Index map that skips removed elements: corefinement leaves garbage in place.
  std::vector<int> new_index(mesh.num_vertices() + mesh.number_of_removed_vertices(), -1);
  out.vertices.resize(3, static_cast<Eigen::Index>(mesh.number_of_vertices()));
  int next = 0;
  for (const SurfaceMesh::Vertex_index v : mesh.vertices()) {
    const Epeck::Point_3& p = mesh.point(v);
    out.vertices.col(next) << CGAL::to_double(p.x()), CGAL::to_double(p.y()),
        CGAL::to_double(p.z());
    new_index[static_cast<std::size_t>(v.idx())] = next++;
  }
  out.faces.resize(3, static_cast<Eigen::Index>(mesh.number_of_faces()));
  int face = 0;
  for (const SurfaceMesh::Face_index f : mesh.faces()) {
    int k = 0;
    for (const SurfaceMesh::Vertex_index v : CGAL::vertices_around_face(mesh.halfedge(f), mesh)) {
      TOOLBENCH_DEMAND(k < 3);
      out.faces(k++, face) = new_index[static_cast<std::size_t>(v.idx())];
    }
    TOOLBENCH_DEMAND(k == 3);
    ++face;
  }
  return out;
}

}  // namespace

namespace internal {

TriangleMesh UnionMeshes(const std::vector<TriangleMesh>& parts) {
  if (parts.empty()) {
    ThrowInvalid("UnionMeshes: no parts");
  }
  auto result = ToSurfaceMesh<Epeck>(parts.front(), "UnionMeshes");
  for (std::size_t i = 1; i < parts.size(); ++i) {
    auto part = ToSurfaceMesh<Epeck>(parts[i], "UnionMeshes");
    if (!PMP::corefine_and_compute_union(result, part, result)) {
      ThrowInvalid("UnionMeshes: CGAL union failed at part ", i);
    }
  }
  return FromSurfaceMesh(result);
}

TriangleMesh DifferenceMeshes(const TriangleMesh& a, const TriangleMesh& b) {
  auto result = ToSurfaceMesh<Epeck>(a, "DifferenceMeshes");
  auto cutter = ToSurfaceMesh<Epeck>(b, "DifferenceMeshes");
  if (!PMP::corefine_and_compute_difference(result, cutter, result)) {
    ThrowInvalid("DifferenceMeshes: CGAL difference failed");
  }
  return FromSurfaceMesh(result);
}

}  // namespace internal

bool HasSelfIntersections(const TriangleMesh& mesh) {
  const auto surface = ToSurfaceMesh<Epick>(mesh, "HasSelfIntersections");
  return PMP::does_self_intersect(surface);
}

}  // namespace toolbench::toollib
