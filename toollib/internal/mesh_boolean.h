#pragma once

#include <vector>

#include "toollib/mesh.h"

namespace toolbench::toollib::internal {

/// Union of closed, outward-oriented, non-self-intersecting meshes (all in one frame, metres),
/// computed with CGAL's corefinement on exact constructions and rounded back to double.
/// The result is one closed mesh per connected solid. Throws std::invalid_argument when a
/// part is not a closed 2-manifold or the boolean operation fails. Deterministic.
TriangleMesh UnionMeshes(const std::vector<TriangleMesh>& parts);

/// The solid `a` minus the solid `b`, under the same conditions and guarantees as UnionMeshes.
TriangleMesh DifferenceMeshes(const TriangleMesh& a, const TriangleMesh& b);

}  // namespace toolbench::toollib::internal
