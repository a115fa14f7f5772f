#include "perception/internal/nearest_neighbours.h"

#include <cstddef>

#include <flann/algorithms/dist.h>
#include <flann/algorithms/kdtree_single_index.h>
#include <flann/util/matrix.h>

#include "common/check.h"

namespace toolbench::perception::internal {

struct NearestNeighbours::Tree {
  explicit Tree(const Eigen::Matrix3Xf& p)
      : points(p),
        // Eigen's 3 x N column-major storage is FLANN's N x 3 row-major dataset, no copy. The
        // leaf size is PCL's (KdTreeFLANN::setInputCloud): the same tree, the same answers.
        index(flann::Matrix<float>(const_cast<float*>(points.data()), static_cast<std::size_t>(points.cols()), 3),
              flann::KDTreeSingleIndexParams(15)) {
    index.buildIndex();
  }
  Eigen::Matrix3Xf points;  // the index refers to these
  flann::KDTreeSingleIndex<flann::L2_Simple<float>> index;
};

NearestNeighbours::NearestNeighbours() = default;

NearestNeighbours::NearestNeighbours(const Eigen::Matrix3Xf& points) {
  if (points.cols() == 0) ThrowInvalid("NearestNeighbours: argument points is empty (expected >= 1 point)");
  if (!points.allFinite()) ThrowInvalid("NearestNeighbours: argument points has a non-finite coordinate");
  tree_ = std::make_shared<const Tree>(points);
}

Eigen::Index NearestNeighbours::size() const { return tree_ ? tree_->points.cols() : 0; }

void NearestNeighbours::Find(const Eigen::Matrix3Xf& queries, std::vector<int>& index,
                             std::vector<float>& sq_distance) const {
  if (!tree_) ThrowInvalid("NearestNeighbours::Find: the point set is empty");
  if (!queries.allFinite()) ThrowInvalid("NearestNeighbours::Find: argument queries has a non-finite coordinate");
  const auto count = static_cast<std::size_t>(queries.cols());
  index.resize(count);
  sq_distance.resize(count);
  if (count == 0) return;
  std::vector<std::size_t> found(count);
  flann::Matrix<std::size_t> found_matrix(found.data(), count, 1);
  flann::Matrix<float> distance_matrix(sq_distance.data(), count, 1);
  // PCL's search parameters: unlimited checks, no approximation (eps 0), one core.
  const flann::SearchParams exact(-1, 0.0f);
  tree_->index.knnSearch(flann::Matrix<float>(const_cast<float*>(queries.data()), count, 3), found_matrix,
                         distance_matrix, 1, exact);
  for (std::size_t i = 0; i < count; ++i) index[i] = static_cast<int>(found[i]);
}

}  // namespace toolbench::perception::internal
