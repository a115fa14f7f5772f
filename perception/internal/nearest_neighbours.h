#pragma once

#include <memory>
#include <vector>

#include <Eigen/Core>

namespace toolbench::perception::internal {

/// Exact Euclidean nearest neighbour in a fixed set of 3-D points, a whole batch of queries per
/// call. The tree is the one PCL's KdTreeFLANN builds (FLANN's single kd-tree, at most 15 points
/// a leaf, exact search), so every answer equals pcl::search::KdTree's, ties included. What
/// differs is the batch: FLANN opens an OpenMP parallel region on every knnSearch call, and
/// through PCL that is one call per query point: ~2.8 us each here, ten times the search itself
/// (2000 queries: 5.5 ms one by one, 0.4-0.5 ms as one batch). ICP asks thousands per iteration.
/// Copyable; copies share the immutable tree. Only for perception's .cpp files.
class NearestNeighbours {
 public:
  /// No points: size() == 0, Find throws.
  NearestNeighbours();
  /// Builds the tree over a copy of `points` (3 x N, [m]). Throws std::invalid_argument when
  /// `points` is empty or has a non-finite coordinate.
  explicit NearestNeighbours(const Eigen::Matrix3Xf& points);

  Eigen::Index size() const;

  /// For each column i of `queries` (3 x M): index[i] = the column of the nearest point,
  /// sq_distance[i] = its squared distance [m^2]. Both are resized to M. Throws
  /// std::invalid_argument when the set is empty or a query has a non-finite coordinate.
  void Find(const Eigen::Matrix3Xf& queries, std::vector<int>& index, std::vector<float>& sq_distance) const;

 private:
  struct Tree;
  std::shared_ptr<const Tree> tree_;
};

}  // namespace toolbench::perception::internal
