#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

namespace toolbench::perception::internal {

/// Triangles of CGAL's advancing-front surface reconstruction of `points` (3 x N [m]), as index
/// triples into the columns of `points`, oriented so that their normals agree (on balance)
/// with `normals` (3 x N outward unit normals of the points; ignored when empty). Degenerate
/// (zero-area) triangles are dropped. Empty when the reconstruction produced nothing.
std::vector<Eigen::Vector3i> AdvancingFrontFacets(const Eigen::Matrix3Xf& points, const Eigen::Matrix3Xf& normals);

/// Parameters of SegmentBySdf (see ShapeOptions for their meaning).
struct SdfParams {
  int clusters = 3;
  double smoothing = 0.4;
  double min_part_fraction = 0.03;  // segments with less area are merged into a neighbour
};

/// Shape-diameter-function segmentation of a triangle mesh.
struct MeshSegmentation {
  std::string error;                // non-empty when the mesh could not be segmented
  std::vector<int> face_labels;     // per input face: part index in [0, num_parts), -1 = dropped
  std::vector<int> vertex_labels;   // per vertex: label of the largest-area incident face, -1 = none
  int num_parts = 0;
  int num_faces = 0;                // faces that made it into the CGAL mesh
};

/// CGAL sdf_values + segmentation_from_sdf_values on the mesh (vertices 3 x V [m], faces as
/// index triples, CCW seen from outside), then segments smaller than min_part_fraction of the
/// area are merged into the neighbour they share the longest border with (islands without
/// neighbours are dropped). Part indices are ordered by decreasing area. Never throws for
/// geometric trouble: `error` says what went wrong.
MeshSegmentation SegmentBySdf(const Eigen::Matrix3Xd& vertices, const std::vector<Eigen::Vector3i>& faces,
                              const SdfParams& params);

}  // namespace toolbench::perception::internal
