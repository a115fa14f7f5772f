// The one translation unit of perception that includes CGAL (a 30-45 s compile): advancing-front
// surface reconstruction and shape-diameter-function segmentation.
#include <algorithm>
#include <array>
#include <cmath>
#include <exception>
#include <limits>
#include <map>
#include <numeric>
#include <utility>
#include <vector>

#include <CGAL/Advancing_front_surface_reconstruction.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Surface_mesh.h>
#include <CGAL/mesh_segmentation.h>
#include <spdlog/spdlog.h>

#include "common/check.h"
#include "perception/internal/deterministic_heap.h"
#include "perception/internal/log.h"
#include "perception/internal/parts_cgal.h"

namespace toolbench::perception::internal {
namespace {

using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using Point3 = Kernel::Point_3;
using Mesh = CGAL::Surface_mesh<Point3>;

double TriangleArea(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  return 0.5 * (b - a).cross(c - a).norm();
}

// Union-find root with path halving.
int Root(std::vector<int>& parent, int i) {
  while (parent[static_cast<std::size_t>(i)] != i) {
    parent[static_cast<std::size_t>(i)] = parent[static_cast<std::size_t>(parent[static_cast<std::size_t>(i)])];
    i = parent[static_cast<std::size_t>(i)];
  }
  return i;
}

}  // namespace

std::vector<Eigen::Vector3i> AdvancingFrontFacets(const Eigen::Matrix3Xf& points, const Eigen::Matrix3Xf& normals) {
  std::vector<Point3> pts;
  pts.reserve(static_cast<std::size_t>(points.cols()));
  for (Eigen::Index i = 0; i < points.cols(); ++i) pts.emplace_back(points(0, i), points(1, i), points(2, i));
  // The reconstruction takes equally good border edges in the order of their addresses (a
  // std::set of (criterion, pointer)), so where the process's heap puts them decided between
  // equally good surfaces: rake_4's parts came out 2212 + 1604 or 2179 + 1637 samples after
  // different allocations before it. In a DeterministicHeap its allocations are laid out in the
  // order they are made: the same points give the same surface in every process.
  std::vector<std::array<std::size_t, 3>> facets;
  {
    DeterministicHeap heap;
    DeterministicHeap::Scope scope(heap);
    try {
      std::vector<std::array<std::size_t, 3>> in_heap;
      CGAL::advancing_front_surface_reconstruction(pts.begin(), pts.end(), std::back_inserter(in_heap));
      scope.Close();
      facets.assign(in_heap.begin(), in_heap.end());  // out of the heap, which goes with this block
    } catch (const std::exception&) {
      return {};  // CGAL precondition failures (e.g. all points coplanar) mean "no surface"
    }
    if (heap.overflowed()) {
      Logger()->warn(
          "advancing-front reconstruction of {} points outgrew its deterministic heap ({} bytes): its surface may "
          "differ between processes",
          pts.size(), heap.used_bytes());
    }
  }
  std::vector<Eigen::Vector3i> out;
  out.reserve(facets.size());
  double agreement = 0.0;
  for (const auto& f : facets) {
    const Eigen::Vector3i t(static_cast<int>(f[0]), static_cast<int>(f[1]), static_cast<int>(f[2]));
    const Eigen::Vector3d a = points.col(t[0]).cast<double>(), b = points.col(t[1]).cast<double>(),
                          c = points.col(t[2]).cast<double>();
    const Eigen::Vector3d n = (b - a).cross(c - a);
    if (!(n.norm() > 1e-14)) continue;
    if (normals.cols() == points.cols()) {
      const Eigen::Vector3d nv = (normals.col(t[0]) + normals.col(t[1]) + normals.col(t[2])).cast<double>();
      agreement += n.dot(nv) > 0.0 ? 1.0 : -1.0;
    }
    out.push_back(t);
  }
  // AFSR orients each surface consistently but not necessarily outward; SDF shoots its rays
  // against the face normals, so inward faces would measure the outside.
  if (agreement < 0.0) {
    for (Eigen::Vector3i& t : out) std::swap(t[1], t[2]);
  }
  return out;
}

MeshSegmentation SegmentBySdf(const Eigen::Matrix3Xd& vertices, const std::vector<Eigen::Vector3i>& faces,
                              const SdfParams& params) {
  MeshSegmentation result;
  const int num_vertices = static_cast<int>(vertices.cols());
  result.face_labels.assign(faces.size(), -1);
  result.vertex_labels.assign(static_cast<std::size_t>(num_vertices), -1);

  Mesh mesh;
  std::vector<Mesh::Vertex_index> vmap(static_cast<std::size_t>(num_vertices));
  for (int i = 0; i < num_vertices; ++i) {
    vmap[static_cast<std::size_t>(i)] = mesh.add_vertex(Point3(vertices(0, i), vertices(1, i), vertices(2, i)));
  }
  std::vector<int> mesh_face_to_input;  // Surface_mesh face index -> input face index
  for (std::size_t f = 0; f < faces.size(); ++f) {
    const Eigen::Vector3i& t = faces[f];
    if ((t.array() < 0).any() || (t.array() >= num_vertices).any()) continue;
    if (!(TriangleArea(vertices.col(t[0]), vertices.col(t[1]), vertices.col(t[2])) > 1e-14)) continue;
    // add_face refuses faces that would make the mesh non-manifold; those are skipped.
    const Mesh::Face_index fi = mesh.add_face(vmap[static_cast<std::size_t>(t[0])], vmap[static_cast<std::size_t>(t[1])],
                                              vmap[static_cast<std::size_t>(t[2])]);
    if (fi == Mesh::null_face()) continue;
    TOOLBENCH_DEMAND(static_cast<std::size_t>(fi.idx()) == mesh_face_to_input.size());
    mesh_face_to_input.push_back(static_cast<int>(f));
  }
  result.num_faces = static_cast<int>(mesh.number_of_faces());
  if (result.num_faces < 4) {
    result.error = "the mesh has fewer than 4 usable faces";
    return result;
  }

  auto sdf = mesh.add_property_map<Mesh::Face_index, double>("f:sdf", 0.0).first;
  auto seg = mesh.add_property_map<Mesh::Face_index, std::size_t>("f:seg", 0).first;
  std::size_t num_segments = 0;
  // Deterministic: sdf_values samples its ray cone on a fixed pattern, and the k-means / EM
  // steps of the segmentation seed CGAL::Random with a fixed CGAL_DEFAULT_SEED.
  try {
    CGAL::sdf_values(mesh, sdf);
    // CGAL's k-means++ seeding draws each next centre with probability proportional to the
    // squared distance to the centres so far; with fewer distinct SDF values than clusters (a
    // flat patch: every ray misses, every value the same) that range is empty, and boost::random
    // recurses until the stack overflows. So: at most as many clusters as distinct values, and
    // a surface of one thickness (or with non-finite values) is one part.
    std::vector<double> values;
    values.reserve(mesh.number_of_faces());
    bool finite = true;
    for (Mesh::Face_index f : mesh.faces()) {
      finite = finite && std::isfinite(sdf[f]);
      values.push_back(sdf[f]);
    }
    std::sort(values.begin(), values.end());
    const std::size_t distinct =
        finite ? static_cast<std::size_t>(std::unique(values.begin(), values.end()) - values.begin()) : 0;
    if (distinct >= 2) {
      const std::size_t clusters = std::min(static_cast<std::size_t>(params.clusters), distinct);
      num_segments = CGAL::segmentation_from_sdf_values(mesh, sdf, seg, clusters, params.smoothing);
    } else {
      for (Mesh::Face_index f : mesh.faces()) seg[f] = 0;
      num_segments = 1;
    }
  } catch (const std::exception& e) {
    result.error = std::string("CGAL SDF segmentation failed: ") + e.what();
    return result;
  }
  if (num_segments == 0) {
    result.error = "CGAL SDF segmentation produced no segment";
    return result;
  }

  // Areas of the segments and the border lengths between them.
  const int k = static_cast<int>(num_segments);
  std::vector<double> area(static_cast<std::size_t>(k), 0.0);
  std::vector<double> face_area(mesh.number_of_faces(), 0.0);
  auto pos = [&](Mesh::Vertex_index v) {
    const Point3& p = mesh.point(v);
    return Eigen::Vector3d(p.x(), p.y(), p.z());
  };
  for (Mesh::Face_index f : mesh.faces()) {
    std::array<Eigen::Vector3d, 3> p;
    int j = 0;
    for (Mesh::Vertex_index v : mesh.vertices_around_face(mesh.halfedge(f))) p[static_cast<std::size_t>(j++)] = pos(v);
    face_area[f.idx()] = TriangleArea(p[0], p[1], p[2]);
    area[seg[f]] += face_area[f.idx()];
  }
  const double total_area = std::accumulate(area.begin(), area.end(), 0.0);
  std::map<std::pair<int, int>, double> border;
  for (Mesh::Edge_index e : mesh.edges()) {
    if (mesh.is_border(e)) continue;
    const int a = static_cast<int>(seg[mesh.face(mesh.halfedge(e, 0))]);
    const int b = static_cast<int>(seg[mesh.face(mesh.halfedge(e, 1))]);
    if (a == b) continue;
    const double len = (pos(mesh.source(mesh.halfedge(e, 0))) - pos(mesh.target(mesh.halfedge(e, 0)))).norm();
    border[{std::min(a, b), std::max(a, b)}] += len;
  }

  // Merge the smallest segment below the area threshold into its longest-border neighbour,
  // repeatedly; a small segment with no neighbour (a separate shell) is dropped.
  std::vector<int> parent(static_cast<std::size_t>(k));
  std::iota(parent.begin(), parent.end(), 0);
  std::vector<bool> dropped(static_cast<std::size_t>(k), false);
  const double min_area = params.min_part_fraction * total_area;
  while (true) {
    int smallest = -1;
    for (int s = 0; s < k; ++s) {
      if (Root(parent, s) != s || dropped[static_cast<std::size_t>(s)]) continue;
      if (area[static_cast<std::size_t>(s)] < min_area &&
          (smallest < 0 || area[static_cast<std::size_t>(s)] < area[static_cast<std::size_t>(smallest)])) {
        smallest = s;
      }
    }
    if (smallest < 0) break;
    std::map<int, double> neighbours;
    for (const auto& [ab, len] : border) {
      const int a = Root(parent, ab.first), b = Root(parent, ab.second);
      if (a == b) continue;
      if (a == smallest && !dropped[static_cast<std::size_t>(b)]) neighbours[b] += len;
      if (b == smallest && !dropped[static_cast<std::size_t>(a)]) neighbours[a] += len;
    }
    if (neighbours.empty()) {
      dropped[static_cast<std::size_t>(smallest)] = true;
      continue;
    }
    const int target = std::max_element(neighbours.begin(), neighbours.end(),
                                        [](const auto& x, const auto& y) { return x.second < y.second; })
                           ->first;
    parent[static_cast<std::size_t>(smallest)] = target;
    area[static_cast<std::size_t>(target)] += area[static_cast<std::size_t>(smallest)];
  }

  // Compact labels, largest area first.
  std::vector<int> roots;
  for (int s = 0; s < k; ++s) {
    if (Root(parent, s) == s && !dropped[static_cast<std::size_t>(s)]) roots.push_back(s);
  }
  std::stable_sort(roots.begin(), roots.end(),
                   [&](int a, int b) { return area[static_cast<std::size_t>(a)] > area[static_cast<std::size_t>(b)]; });
  std::vector<int> label_of_root(static_cast<std::size_t>(k), -1);
  for (std::size_t i = 0; i < roots.size(); ++i) label_of_root[static_cast<std::size_t>(roots[i])] = static_cast<int>(i);
  result.num_parts = static_cast<int>(roots.size());

  std::vector<double> best_area(static_cast<std::size_t>(num_vertices), 0.0);
  for (Mesh::Face_index f : mesh.faces()) {
    const int label = label_of_root[static_cast<std::size_t>(Root(parent, static_cast<int>(seg[f])))];
    result.face_labels[static_cast<std::size_t>(mesh_face_to_input[f.idx()])] = label;
    if (label < 0) continue;
    for (Mesh::Vertex_index v : mesh.vertices_around_face(mesh.halfedge(f))) {
      if (face_area[f.idx()] > best_area[v.idx()]) {
        best_area[v.idx()] = face_area[f.idx()];
        result.vertex_labels[v.idx()] = label;
      }
    }
  }
  return result;
}

}  // namespace toolbench::perception::internal
