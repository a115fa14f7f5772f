#include "perception/parts.h"

#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <numeric>
#include <sstream>
#include <tuple>
#include <stdexcept>
#include <utility>

#include <Eigen/Eigenvalues>
#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include "common/check.h"
#include "common/rng.h"
#include "perception/internal/log.h"
#include "perception/internal/parts_cgal.h"

namespace toolbench::perception {
namespace {

Eigen::Vector3d AnyPerpendicular(const Eigen::Vector3d& z) {
  const Eigen::Vector3d other = std::abs(z.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
  return (other - other.dot(z) * z).normalized();
}

// Index of the longest semi-axis.
int LongestAxis(const Superquadric& sq) {
  int k = 0;
  sq.size.maxCoeff(&k);
  return k;
}

void CheckCloud(const char* where, const char* name, const Eigen::Matrix3Xf& points) {
  if (!points.allFinite()) ThrowInvalid(where, ": ", name, " contains a non-finite coordinate");
}

// Gives every point with label -1 the label of its nearest labelled point (brute force: the
// unlabelled points are few).
void FillLabels(const Eigen::Matrix3Xf& points, std::vector<int>& labels) {
  std::vector<int> labelled;
  for (std::size_t i = 0; i < labels.size(); ++i) {
    if (labels[i] >= 0) labelled.push_back(static_cast<int>(i));
  }
  if (labelled.empty()) return;
  for (std::size_t i = 0; i < labels.size(); ++i) {
    if (labels[i] >= 0) continue;
    float best = std::numeric_limits<float>::infinity();
    int best_j = labelled.front();
    for (int j : labelled) {
      const float d = (points.col(j) - points.col(static_cast<Eigen::Index>(i))).squaredNorm();
      if (d < best) best = d, best_j = j;
    }
    labels[i] = labels[static_cast<std::size_t>(best_j)];
  }
}

// Builds the parts from per-point labels: points, superquadric, cylinder score.
PartsResult MakeParts(const Eigen::Matrix3Xf& points, const std::vector<int>& labels, int num_labels,
                      const ShapeOptions& options) {
  PartsResult result;
  std::vector<std::vector<int>> members(static_cast<std::size_t>(num_labels));
  for (std::size_t i = 0; i < labels.size(); ++i) {
    if (labels[i] >= 0) members[static_cast<std::size_t>(labels[i])].push_back(static_cast<int>(i));
  }
  for (int label = 0; label < num_labels; ++label) {
    const std::vector<int>& m = members[static_cast<std::size_t>(label)];
    if (static_cast<int>(m.size()) < kMinSuperquadricPoints) continue;
    Part part;
    part.points.resize(3, static_cast<Eigen::Index>(m.size()));
    for (std::size_t i = 0; i < m.size(); ++i) part.points.col(static_cast<Eigen::Index>(i)) = points.col(m[i]);
    SuperquadricOptions sq_options = options.superquadric;
    sq_options.seed = DeriveSeed(options.seed, Cat("superquadric_", label));
    const SuperquadricFit fit = FitSuperquadric(part.points, sq_options);
    if (fit.status == SuperquadricStatus::kTooFewPoints) continue;
    if (fit.status != SuperquadricStatus::kOk) {
      internal::Logger()->warn("part {}: {} (keeping the best iterate)", label, fit.reason);
    }
    part.sq = fit.sq;
    part.fit_error = fit.fit_error;
    part.cylinder_score = CylinderScore(fit.sq, options);
    result.parts.push_back(std::move(part));
  }
  if (result.parts.empty()) {
    result.status = ShapeStatus::kSegmentationFailed;
    result.reason = "SegmentParts: no segment has enough points for a superquadric";
  } else {
    result.status = ShapeStatus::kOk;
  }
  return result;
}

// Hashing (FNV-1a, 64 bit) for the cache key.
std::uint64_t Fnv1a(const void* data, std::size_t size, std::uint64_t h = 1469598103934665603ULL) {
  const auto* bytes = static_cast<const unsigned char*>(data);
  for (std::size_t i = 0; i < size; ++i) {
    h ^= bytes[i];
    h *= 1099511628211ULL;
  }
  return h;
}

std::string Hex(std::uint64_t v) {
  char buf[17];
  std::snprintf(buf, sizeof(buf), "%016llx", static_cast<unsigned long long>(v));
  return buf;
}

std::string OptionsText(const ShapeOptions& o) {
  // Every field that changes the result, printed exactly (hex floats).
  std::ostringstream s;
  s << std::hexfloat << o.samples << ' ' << o.seed << ' ' << o.sdf_clusters << ' ' << o.sdf_smoothing << ' '
    << o.min_part_fraction << ' ' << o.hand_radius << ' ' << o.hand_length << ' ' << o.preferred_length << ' '
    << o.radius_log_tolerance << ' ' << o.max_handle_score << ' ' << o.lone_part_effector_length << ' '
    << o.normal_neighbours << " | " << o.superquadric.max_points << ' ' << o.superquadric.seed << ' '
    << o.superquadric.min_exponent << ' ' << o.superquadric.max_exponent << ' ' << o.superquadric.min_size_factor
    << ' ' << o.superquadric.max_size_factor << ' ' << o.superquadric.min_size << ' ' << o.superquadric.max_rotation
    << ' ' << o.superquadric.axis_assignments << ' ' << o.superquadric.screen_iterations << ' '
    << o.superquadric.max_iterations << ' '
    << o.superquadric.tolerance << " | format 1";
  return s.str();
}

// JSON (de)serialisation of ModelShape for the disk cache.
nlohmann::json PoseToJson(const Eigen::Isometry3d& X) {
  return std::vector<double>(X.matrix().data(), X.matrix().data() + 16);
}
Eigen::Isometry3d PoseFromJson(const nlohmann::json& j) {
  const auto v = j.get<std::vector<double>>();
  if (v.size() != 16) throw std::runtime_error("pose needs 16 numbers");
  Eigen::Isometry3d X;
  X.matrix() = Eigen::Map<const Eigen::Matrix4d>(v.data());
  return X;
}
nlohmann::json VecToJson(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }
Eigen::Vector3d VecFromJson(const nlohmann::json& j) {
  const auto v = j.get<std::vector<double>>();
  if (v.size() != 3) throw std::runtime_error("vector needs 3 numbers");
  return {v[0], v[1], v[2]};
}

nlohmann::json ShapeToJson(const ModelShape& s, const std::string& key) {
  nlohmann::json j;
  j["key"] = key;
  j["model"] = s.model;
  j["status"] = static_cast<int>(s.status);
  j["reason"] = s.reason;
  j["mesh_faces"] = s.mesh_faces;
  j["mesh_fallback"] = s.mesh_fallback;
  j["X_FT"] = PoseToJson(s.X_FT);
  for (const Part& p : s.parts) {
    nlohmann::json jp;
    jp["points"] = std::vector<float>(p.points.data(), p.points.data() + p.points.size());
    jp["size"] = VecToJson(p.sq.size);
    jp["e1"] = p.sq.e1;
    jp["e2"] = p.sq.e2;
    jp["pose"] = PoseToJson(p.sq.pose);
    jp["fit_error"] = p.fit_error;
    jp["cylinder_score"] = p.cylinder_score;
    j["parts"].push_back(jp);
  }
  const Handle& h = s.handle;
  j["handle"] = {{"part", h.part},     {"center", VecToJson(h.center)}, {"axis", VecToJson(h.axis)},
                 {"radius", h.radius}, {"length", h.length},            {"X_FH", PoseToJson(h.X_FH)}};
  const ToolFeatures& f = s.features;
  j["features"] = {{"total_length", f.total_length},
                   {"handle_length", f.handle_length},
                   {"handle_radius", f.handle_radius},
                   {"effector_center", VecToJson(f.effector_center)},
                   {"effector_size", VecToJson(f.effector_size)},
                   {"effector_protrusion", f.effector_protrusion}};
  return j;
}

ModelShape ShapeFromJson(const nlohmann::json& j) {
  ModelShape s;
  s.model = j.at("model").get<std::string>();
  s.status = static_cast<ShapeStatus>(j.at("status").get<int>());
  s.reason = j.at("reason").get<std::string>();
  s.mesh_faces = j.at("mesh_faces").get<int>();
  s.mesh_fallback = j.at("mesh_fallback").get<bool>();
  s.X_FT = PoseFromJson(j.at("X_FT"));
  if (j.contains("parts")) {
    for (const nlohmann::json& jp : j.at("parts")) {
      Part p;
      const auto pts = jp.at("points").get<std::vector<float>>();
      if (pts.size() % 3 != 0) throw std::runtime_error("points need 3 numbers each");
      p.points = Eigen::Map<const Eigen::Matrix3Xf>(pts.data(), 3, static_cast<Eigen::Index>(pts.size() / 3));
      p.sq.size = VecFromJson(jp.at("size"));
      p.sq.e1 = jp.at("e1").get<double>();
      p.sq.e2 = jp.at("e2").get<double>();
      p.sq.pose = PoseFromJson(jp.at("pose"));
      p.fit_error = jp.at("fit_error").get<double>();
      p.cylinder_score = jp.at("cylinder_score").get<double>();
      s.parts.push_back(std::move(p));
    }
  }
  const nlohmann::json& h = j.at("handle");
  s.handle.part = h.at("part").get<int>();
  s.handle.center = VecFromJson(h.at("center"));
  s.handle.axis = VecFromJson(h.at("axis"));
  s.handle.radius = h.at("radius").get<double>();
  s.handle.length = h.at("length").get<double>();
  s.handle.X_FH = PoseFromJson(h.at("X_FH"));
  const nlohmann::json& f = j.at("features");
  s.features.total_length = f.at("total_length").get<double>();
  s.features.handle_length = f.at("handle_length").get<double>();
  s.features.handle_radius = f.at("handle_radius").get<double>();
  s.features.effector_center = VecFromJson(f.at("effector_center"));
  s.features.effector_size = VecFromJson(f.at("effector_size"));
  s.features.effector_protrusion = f.at("effector_protrusion").get<double>();
  return s;
}

// How a point sits relative to the handle's axis line.
struct AxisCoords {
  double s;  // along the axis from the origin [m]
  double d;  // distance from the axis line [m]
};
AxisCoords ToAxis(const Eigen::Vector3f& p, const Eigen::Vector3d& origin, const Eigen::Vector3d& axis) {
  const Eigen::Vector3d v = p.cast<double>() - origin;
  const double s = v.dot(axis);
  return {s, (v - s * axis).norm()};
}

// A point belongs to the handle's cylinder when it is this close to the axis line.
double CylinderReach(double radius) { return 1.3 * radius + 0.002; }

// Graspable interval [lo, hi] along `axis` from `origin`: starting at the handle part's median
// position, the tool is cut into slices along the axis, and the interval grows while every
// slice (of all parts' points) looks like the handle's cross-section (all points within its
// cylinder, and as wide as it). This keeps the interval off the effector even where the SDF
// segments cut the handle short (an end cap split off, the shaft top assigned to a head).
std::pair<double, double> GraspInterval(const std::vector<Part>& parts, int handle_part, const Eigen::Vector3d& origin,
                                        const Eigen::Vector3d& axis, double radius) {
  constexpr double kSlice = 0.005;       // slice thickness [m]
  constexpr double kInsideShare = 0.98;  // share of a slice's points inside the cylinder
  constexpr double kMinWidth = 0.7;      // a slice's widest point, relative to the radius
  double s_min = std::numeric_limits<double>::infinity(), s_max = -s_min;
  for (const Part& p : parts) {
    for (Eigen::Index i = 0; i < p.points.cols(); ++i) {
      const double s = ToAxis(p.points.col(i), origin, axis).s;
      s_min = std::min(s_min, s);
      s_max = std::max(s_max, s);
    }
  }
  const int n = std::max(1, static_cast<int>(std::ceil((s_max - s_min) / kSlice)));
  std::vector<int> count(static_cast<std::size_t>(n), 0), inside(static_cast<std::size_t>(n), 0);
  std::vector<double> widest(static_cast<std::size_t>(n), 0.0), lo(static_cast<std::size_t>(n), s_max),
      hi(static_cast<std::size_t>(n), s_min);
  auto slice = [&](double s) { return static_cast<std::size_t>(std::clamp(static_cast<int>((s - s_min) / kSlice), 0, n - 1)); };
  const double reach = CylinderReach(radius);
  for (const Part& p : parts) {
    for (Eigen::Index i = 0; i < p.points.cols(); ++i) {
      const AxisCoords c = ToAxis(p.points.col(i), origin, axis);
      const std::size_t b = slice(c.s);
      ++count[b];
      inside[b] += c.d <= reach ? 1 : 0;
      widest[b] = std::max(widest[b], c.d);
      lo[b] = std::min(lo[b], c.s);
      hi[b] = std::max(hi[b], c.s);
    }
  }
  auto handle_like = [&](int b) {
    const std::size_t k = static_cast<std::size_t>(b);
    return count[k] > 0 && inside[k] >= kInsideShare * count[k] && widest[k] >= kMinWidth * radius;
  };
  const Part& hp = parts[static_cast<std::size_t>(handle_part)];
  std::vector<double> along(static_cast<std::size_t>(hp.points.cols()));
  for (Eigen::Index i = 0; i < hp.points.cols(); ++i) along[static_cast<std::size_t>(i)] = ToAxis(hp.points.col(i), origin, axis).s;
  std::nth_element(along.begin(), along.begin() + static_cast<std::ptrdiff_t>(along.size() / 2), along.end());
  const int start = static_cast<int>(slice(along[along.size() / 2]));
  // Empty slices (sparse samples) neither stop nor bound the interval.
  auto passable = [&](int b) { return count[static_cast<std::size_t>(b)] == 0 || handle_like(b); };
  int first = start, last = start;
  while (first > 0 && passable(first - 1)) --first;
  while (last < n - 1 && passable(last + 1)) ++last;
  double i_lo = std::numeric_limits<double>::infinity(), i_hi = -i_lo;
  for (int b = first; b <= last; ++b) {
    if (count[static_cast<std::size_t>(b)] == 0) continue;
    i_lo = std::min(i_lo, lo[static_cast<std::size_t>(b)]);
    i_hi = std::max(i_hi, hi[static_cast<std::size_t>(b)]);
  }
  if (!(i_lo <= i_hi)) return {along[along.size() / 2], along[along.size() / 2]};
  return {i_lo, i_hi};
}

// The handle on part `best` (see ChooseHandle), with its axis given or the superquadric's
// longest axis.
Handle HandleFromPart(const std::vector<Part>& parts, int best, const std::optional<Eigen::Vector3d>& axis_override,
                      const ShapeOptions& options, const std::optional<Eigen::Vector3d>& z_hint,
                      const std::optional<Eigen::Vector3d>& x_hint);

// Chooses the handle, then merges into the handle part every other part that lies inside the
// handle's cylinder and graspable interval (a handle end cap the SDF split off, a stick's two
// ends), refits the merged part's superquadric and recomputes the handle on it, keeping the
// axis found before (a refit that lands in a poor local minimum must not move the handle).
Handle FinishHandle(std::vector<Part>& parts, const ShapeOptions& options, const std::optional<Eigen::Vector3d>& z_hint,
                    const std::optional<Eigen::Vector3d>& x_hint) {
  Handle handle = ChooseHandle(parts, options, z_hint, x_hint);
  if (handle.part < 0) return handle;
  constexpr double kInsideShare = 0.9;  // share of a part's points inside the handle's cylinder
  const double reach = CylinderReach(handle.radius);
  const double half = 0.5 * handle.length + 0.002;
  std::vector<Part> kept;
  Part merged = parts[static_cast<std::size_t>(handle.part)];
  bool any = false;
  for (std::size_t i = 0; i < parts.size(); ++i) {
    if (static_cast<int>(i) == handle.part) continue;
    const Part& p = parts[i];
    Eigen::Index in = 0;
    for (Eigen::Index k = 0; k < p.points.cols(); ++k) {
      const AxisCoords c = ToAxis(p.points.col(k), handle.center, handle.axis);
      in += (c.d <= reach && std::abs(c.s) <= half) ? 1 : 0;
    }
    if (in >= kInsideShare * static_cast<double>(p.points.cols())) {
      Eigen::Matrix3Xf joined(3, merged.points.cols() + p.points.cols());
      joined << merged.points, p.points;
      merged.points = std::move(joined);
      any = true;
    } else {
      kept.push_back(p);
    }
  }
  if (!any) return handle;
  SuperquadricOptions sq_options = options.superquadric;
  sq_options.seed = DeriveSeed(options.seed, "superquadric_merged_handle");
  const SuperquadricFit fit = FitSuperquadric(merged.points, sq_options);
  merged.sq = fit.sq;
  merged.fit_error = fit.fit_error;
  merged.cylinder_score = CylinderScore(fit.sq, options);
  kept.insert(kept.begin(), std::move(merged));
  parts = std::move(kept);
  return HandleFromPart(parts, 0, handle.axis, options, z_hint, x_hint);
}

}  // namespace

void ShapeOptions::Validate() const {
  const char* where = "ShapeOptions::Validate";
  if (samples < kMinShapePoints) ThrowInvalid(where, ": samples = ", samples, ", expected >= ", kMinShapePoints);
  if (sdf_clusters < 2 || sdf_clusters > 10) ThrowInvalid(where, ": sdf_clusters = ", sdf_clusters, ", expected in [2, 10]");
  if (!(sdf_smoothing >= 0.0 && sdf_smoothing <= 1.0)) {
    ThrowInvalid(where, ": sdf_smoothing = ", sdf_smoothing, ", expected in [0, 1]");
  }
  if (!(min_part_fraction >= 0.0 && min_part_fraction < 0.5)) {
    ThrowInvalid(where, ": min_part_fraction = ", min_part_fraction, ", expected in [0, 0.5)");
  }
  superquadric.Validate();
  if (!(hand_radius > 0.0)) ThrowInvalid(where, ": hand_radius = ", hand_radius, ", expected > 0");
  if (!(hand_length > 0.0)) ThrowInvalid(where, ": hand_length = ", hand_length, ", expected > 0");
  if (!(preferred_length >= hand_length)) {
    ThrowInvalid(where, ": preferred_length = ", preferred_length, ", expected >= hand_length = ", hand_length);
  }
  if (!(radius_log_tolerance >= 0.0)) {
    ThrowInvalid(where, ": radius_log_tolerance = ", radius_log_tolerance, ", expected >= 0");
  }
  if (!(max_handle_score > 0.0)) ThrowInvalid(where, ": max_handle_score = ", max_handle_score, ", expected > 0");
  if (!(lone_part_effector_length >= 0.0)) {
    ThrowInvalid(where, ": lone_part_effector_length = ", lone_part_effector_length, ", expected >= 0");
  }
  if (normal_neighbours < 3) ThrowInvalid(where, ": normal_neighbours = ", normal_neighbours, ", expected >= 3");
}

double CylinderScore(const Superquadric& sq, const ShapeOptions& options) {
  Eigen::Vector3d s = sq.size;
  std::sort(s.data(), s.data() + 3);
  auto dead_zone = [&](double v) { return std::max(0.0, std::abs(v) - options.radius_log_tolerance); };
  const double r1 = dead_zone(std::log(s[0] / options.hand_radius));
  const double r2 = dead_zone(std::log(s[1] / options.hand_radius));
  const double len = std::max(0.0, std::log(options.preferred_length / (2.0 * s[2])));
  return std::sqrt(r1 * r1 + r2 * r2 + len * len);
}

namespace {

// SegmentParts up to the labels: advancing-front reconstruction, SDF segmentation, the points the
// reconstruction left out labelled like their nearest labelled point.
ShapeSegmentation SegmentLabels(const SurfaceSamples& samples, const ShapeOptions& options) {
  options.Validate();
  const Eigen::Matrix3Xf& points = samples.points;
  if (samples.normals.cols() != points.cols()) {
    ThrowInvalid("SegmentParts: samples.normals has ", samples.normals.cols(), " columns, expected ", points.cols(),
                 " (one per point)");
  }
  CheckCloud("SegmentParts", "samples.points", points);
  CheckCloud("SegmentParts", "samples.normals", samples.normals);
  ShapeSegmentation result;
  if (points.cols() < kMinShapePoints) {
    result.reason = Cat("SegmentParts: ", points.cols(), " points, need at least ", kMinShapePoints);
    return result;
  }
  const std::vector<Eigen::Vector3i> facets = internal::AdvancingFrontFacets(points, samples.normals);
  if (facets.empty()) {
    result.status = ShapeStatus::kSegmentationFailed;
    result.reason = "SegmentParts: advancing-front reconstruction produced no surface";
    return result;
  }
  const internal::MeshSegmentation seg = internal::SegmentBySdf(
      points.cast<double>(), facets, {options.sdf_clusters, options.sdf_smoothing, options.min_part_fraction});
  if (!seg.error.empty() || seg.num_parts == 0) {
    result.status = ShapeStatus::kSegmentationFailed;
    result.reason = Cat("SegmentParts: ", seg.error.empty() ? "no part left" : seg.error);
    return result;
  }
  result.labels = seg.vertex_labels;
  FillLabels(points, result.labels);
  result.num_labels = seg.num_parts;
  result.mesh_faces = seg.num_faces;
  result.status = ShapeStatus::kOk;
  return result;
}

// Whether MakeParts finds a part in these labels: some label with enough points for a superquadric.
bool AnyPartLargeEnough(const ShapeSegmentation& s) {
  std::vector<int> count(static_cast<std::size_t>(std::max(0, s.num_labels)), 0);
  for (int label : s.labels) {
    if (label >= 0 && label < s.num_labels) ++count[static_cast<std::size_t>(label)];
  }
  return std::any_of(count.begin(), count.end(), [](int c) { return c >= kMinSuperquadricPoints; });
}

}  // namespace

PartsResult SegmentParts(const SurfaceSamples& samples, const ShapeOptions& options) {
  const ShapeSegmentation seg = SegmentLabels(samples, options);
  if (seg.status != ShapeStatus::kOk) {
    PartsResult result;
    result.status = seg.status;
    result.reason = seg.reason;
    return result;
  }
  PartsResult result = MakeParts(samples.points, seg.labels, seg.num_labels, options);
  result.mesh_faces = seg.mesh_faces;
  return result;
}

double GraspScore(const Handle& h, const ShapeOptions& options) {
  if (h.part < 0 || !(h.radius > 0.0) || !(h.length > 0.0)) return std::numeric_limits<double>::infinity();
  const double r = std::max(0.0, std::abs(std::log(h.radius / options.hand_radius)) - options.radius_log_tolerance);
  const double len = std::max(0.0, std::log(options.preferred_length / h.length));
  return std::sqrt(r * r + len * len);
}

Handle ChooseHandle(const std::vector<Part>& parts, const ShapeOptions& options,
                    const std::optional<Eigen::Vector3d>& z_hint, const std::optional<Eigen::Vector3d>& x_hint) {
  // Each part is tried as the handle; the superquadric's cylinder_score (thesis Alg. 5) plus
  // the GraspScore of the region actually measured around its axis ranks them. The second term
  // catches a part whose superquadric is poor (a segment that also holds some teeth) and a
  // small part whose superquadric happens to look like a cylinder.
  Handle best;
  double best_score = std::numeric_limits<double>::infinity();
  for (int i = 0; i < static_cast<int>(parts.size()); ++i) {
    const Part& p = parts[static_cast<std::size_t>(i)];
    if (p.points.cols() < kMinSuperquadricPoints) continue;
    const Handle h = HandleFromPart(parts, i, std::nullopt, options, z_hint, x_hint);
    const double grasp = GraspScore(h, options);
    if (!(grasp <= options.max_handle_score)) continue;
    const double score = p.cylinder_score + grasp;
    if (score < best_score) {
      best_score = score;
      best = h;
    }
  }
  return best;
}

namespace {

Handle HandleFromPart(const std::vector<Part>& parts, int best, const std::optional<Eigen::Vector3d>& axis_override,
                      const ShapeOptions& options, const std::optional<Eigen::Vector3d>& z_hint,
                      const std::optional<Eigen::Vector3d>& x_hint) {
  Handle handle;
  const Part& hp = parts[static_cast<std::size_t>(best)];
  Eigen::Vector3d axis = axis_override ? *axis_override : Eigen::Vector3d(hp.sq.pose.linear().col(LongestAxis(hp.sq)));

  // Axis line through the centroid of the part's middle half (not the superquadric's centre,
  // which a part that also holds some effector, or a one-sided view, pulls off the axis).
  double part_lo = std::numeric_limits<double>::infinity(), part_hi = -part_lo;
  const Eigen::Vector3d sq_center = hp.sq.pose.translation();
  for (Eigen::Index i = 0; i < hp.points.cols(); ++i) {
    const double s = ToAxis(hp.points.col(i), sq_center, axis).s;
    part_lo = std::min(part_lo, s);
    part_hi = std::max(part_hi, s);
  }
  auto in_middle = [&](double s) { return std::abs(s - 0.5 * (part_lo + part_hi)) <= 0.25 * (part_hi - part_lo); };
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();
  int middle = 0;
  for (Eigen::Index i = 0; i < hp.points.cols(); ++i) {
    if (!in_middle(ToAxis(hp.points.col(i), sq_center, axis).s)) continue;
    origin += hp.points.col(i).cast<double>();
    ++middle;
  }
  if (middle == 0) return handle;
  origin /= middle;
  // The axis itself: the main direction of the middle half (a superquadric stretched over a
  // rod and some effector, or over a one-sided view, tilts), unless the caller fixed it.
  const Eigen::Vector3d axis_sq = axis;
  if (!axis_override && middle >= 3) {
    Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
    for (Eigen::Index i = 0; i < hp.points.cols(); ++i) {
      if (!in_middle(ToAxis(hp.points.col(i), sq_center, axis_sq).s)) continue;
      const Eigen::Vector3d d = hp.points.col(i).cast<double>() - origin;
      cov += d * d.transpose();
    }
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);
    const Eigen::Vector3d main = eig.eigenvectors().col(2);
    // Small disagreements are left to the superquadric: the middle half of a handle that runs
    // into a thinner shaft (hooks) has a slightly tilted main direction.
    constexpr double kMinTilt = 5.0 * M_PI / 180;
    if (std::abs(main.dot(axis_sq)) < std::cos(kMinTilt)) axis = main.dot(axis_sq) < 0.0 ? Eigen::Vector3d(-main) : main;
  }
  // Radius: median distance from that line over the middle half (no end caps).
  std::vector<double> radial;
  for (Eigen::Index i = 0; i < hp.points.cols(); ++i) {
    const AxisCoords c = ToAxis(hp.points.col(i), origin, axis);
    if (in_middle(ToAxis(hp.points.col(i), sq_center, axis_sq).s)) radial.push_back(c.d);
  }
  if (radial.empty()) return handle;
  std::sort(radial.begin(), radial.end());
  handle.radius = radial[radial.size() / 2];
  // The cylinder test uses the 90th percentile: on a one-sided view the line through the
  // centroid sits off the true axis, and the silhouette points are farther than the median.
  const double outer = radial[radial.size() * 9 / 10];
  auto [lo, hi] = GraspInterval(parts, best, origin, axis, outer);

  // The rest of the tool: every point outside the graspable cylinder.
  const double reach = CylinderReach(outer);
  Eigen::Vector3d rest = Eigen::Vector3d::Zero();
  Eigen::Index rest_count = 0;
  for (const Part& p : parts) {
    for (Eigen::Index i = 0; i < p.points.cols(); ++i) {
      const AxisCoords c = ToAxis(p.points.col(i), origin, axis);
      if (c.d <= reach && c.s >= lo - 1e-9 && c.s <= hi + 1e-9) continue;
      rest += p.points.col(i).cast<double>();
      ++rest_count;
    }
  }
  // Too few points outside (a stick's tip) tell no direction: the tool is one rod.
  constexpr double kMinRestShare = 0.01;
  Eigen::Index total = 0;
  for (const Part& p : parts) total += p.points.cols();
  const bool lone = rest_count < kMinRestShare * static_cast<double>(total);
  if (!lone) rest /= static_cast<double>(rest_count);
  constexpr double kMinOffset = 0.001;  // [m] below this the rest does not tell a direction
  bool flip = false;
  if (!lone && std::abs((rest - origin).dot(axis)) > kMinOffset) {
    flip = (rest - origin).dot(axis) < 0.0;
  } else if (z_hint) {
    flip = axis.dot(*z_hint) < 0.0;
  }
  if (flip) {
    axis = -axis;
    std::tie(lo, hi) = std::pair{-hi, -lo};
  }
  if (lone && hi - lo - options.lone_part_effector_length >= options.hand_length) {
    hi -= options.lone_part_effector_length;
  }
  handle.part = best;
  handle.axis = axis;
  handle.center = origin + axis * (0.5 * (lo + hi));
  handle.length = hi - lo;
  Eigen::Vector3d x = Eigen::Vector3d::Zero();
  if (x_hint) x = *x_hint - x_hint->dot(axis) * axis;
  if (x.norm() < 1e-6 && !lone) {
    x = (rest - handle.center) - (rest - handle.center).dot(axis) * axis;
    constexpr double kMinSide = 0.005;  // [m] a smaller sideways offset gives no working side
    if (x.norm() < kMinSide) x.setZero();
  }
  x = x.norm() > 1e-9 ? Eigen::Vector3d(x.normalized()) : AnyPerpendicular(axis);
  handle.X_FH = Eigen::Isometry3d::Identity();
  handle.X_FH.linear().col(0) = x;
  handle.X_FH.linear().col(1) = axis.cross(x);
  handle.X_FH.linear().col(2) = axis;
  handle.X_FH.translation() = handle.center;
  return handle;
}

}  // namespace

ToolFeatures ComputeFeatures(const std::vector<Part>& parts, const Handle& handle, const Eigen::Isometry3d& X_FT) {
  ToolFeatures f;
  if (handle.part < 0 || handle.part >= static_cast<int>(parts.size())) return f;
  const Eigen::Isometry3d X_TF = X_FT.inverse();
  const Eigen::Vector3d center_T = X_TF * handle.center;
  const double reach = CylinderReach(handle.radius);
  double z_lo = std::numeric_limits<double>::infinity(), z_hi = -z_lo;
  Eigen::Vector3d e_lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
  Eigen::Vector3d e_hi = -e_lo;
  bool any_effector = false;
  for (const Part& part : parts) {
    for (Eigen::Index k = 0; k < part.points.cols(); ++k) {
      const AxisCoords c = ToAxis(part.points.col(k), handle.center, handle.axis);
      const Eigen::Vector3d p = X_TF * part.points.col(k).cast<double>();
      z_lo = std::min(z_lo, p.z());
      z_hi = std::max(z_hi, p.z());
      // Effector: past the graspable region toward the effector, or sticking out of the
      // handle's cylinder beside it.
      const bool effector = c.s > 0.5 * handle.length + 1e-9 || (c.d > reach && c.s >= -0.5 * handle.length);
      if (!effector) continue;
      any_effector = true;
      e_lo = e_lo.cwiseMin(p);
      e_hi = e_hi.cwiseMax(p);
    }
  }
  f.total_length = z_hi - z_lo;
  f.handle_length = handle.length;
  f.handle_radius = handle.radius;
  if (any_effector) {
    f.effector_center = 0.5 * (e_lo + e_hi);
    f.effector_size = e_hi - e_lo;
    f.effector_protrusion = std::max(0.0, e_hi.x() - center_T.x());
  }
  return f;
}

namespace {

// The surface samples every analysis of a library model starts from (seeded: the same each time).
SurfaceSamples ModelSamples(const toollib::ToolModel& model, const ShapeOptions& options) {
  return SampleSurface(model.mesh, options.samples, DeriveSeed(options.seed, "shape_samples"));
}

// SegmentModelShape on samples already drawn.
ShapeSegmentation SegmentModelSamples(const toollib::ToolModel& model, const SurfaceSamples& samples,
                                      const ShapeOptions& options) {
  ShapeSegmentation seg = SegmentLabels(samples, options);
  if (seg.status == ShapeStatus::kOk && !AnyPartLargeEnough(seg)) {
    seg.status = ShapeStatus::kSegmentationFailed;
    seg.reason = "SegmentParts: no segment has enough points for a superquadric";
  }
  if (seg.status != ShapeStatus::kSegmentationFailed) return seg;
  // AFSR gave nothing usable: segment the library mesh itself and label each sample by the
  // face it was drawn from.
  const std::vector<Eigen::Vector3i> faces = [&] {
    std::vector<Eigen::Vector3i> out;
    for (Eigen::Index f = 0; f < model.mesh.faces.cols(); ++f) out.push_back(model.mesh.faces.col(f));
    return out;
  }();
  const internal::MeshSegmentation mesh_seg = internal::SegmentBySdf(
      model.mesh.vertices, faces, {options.sdf_clusters, options.sdf_smoothing, options.min_part_fraction});
  internal::Logger()->warn("{}: {}; segmenting the library mesh instead", model.name, seg.reason);
  if (!mesh_seg.error.empty() || mesh_seg.num_parts == 0) {
    seg.reason += Cat("; library mesh: ", mesh_seg.error);
    return seg;
  }
  seg.labels.resize(samples.faces.size());
  for (std::size_t i = 0; i < seg.labels.size(); ++i) {
    seg.labels[i] = mesh_seg.face_labels[static_cast<std::size_t>(samples.faces[i])];
  }
  FillLabels(samples.points, seg.labels);
  seg.num_labels = mesh_seg.num_parts;
  seg.mesh_faces = mesh_seg.num_faces;
  seg.mesh_fallback = true;
  seg.status = ShapeStatus::kOk;
  seg.reason.clear();
  return seg;
}

// AnalyzeModelShape(model, options, segmentation) on samples already drawn.
ModelShape AnalyzeModelSamples(const toollib::ToolModel& model, const SurfaceSamples& samples,
                               const ShapeOptions& options, const ShapeSegmentation& segmentation) {
  ModelShape shape;
  shape.model = model.name;
  if (segmentation.status != ShapeStatus::kOk) {
    shape.status = segmentation.status;
    shape.reason = segmentation.reason;
    shape.mesh_faces = segmentation.mesh_faces;
    shape.mesh_fallback = segmentation.mesh_fallback;
    return shape;
  }
  if (segmentation.labels.size() != static_cast<std::size_t>(samples.points.cols()) ||
      std::any_of(segmentation.labels.begin(), segmentation.labels.end(),
                  [&](int label) { return label < 0 || label >= segmentation.num_labels; })) {
    ThrowInvalid("AnalyzeModelShape: ", model.name, ": the segmentation has ", segmentation.labels.size(),
                 " labels in [0, ", segmentation.num_labels, "), expected one in that range for each of the ",
                 samples.points.cols(), " surface samples");
  }
  PartsResult parts = MakeParts(samples.points, segmentation.labels, segmentation.num_labels, options);
  shape.status = parts.status;
  shape.reason = parts.reason;
  shape.mesh_faces = segmentation.mesh_faces;
  shape.mesh_fallback = segmentation.mesh_fallback;
  shape.parts = std::move(parts.parts);
  if (shape.status != ShapeStatus::kOk) return shape;
  shape.handle = FinishHandle(shape.parts, options, Eigen::Vector3d::UnitZ(), Eigen::Vector3d::UnitX());
  if (shape.handle.part < 0) {
    shape.status = ShapeStatus::kNoHandle;
    shape.reason = Cat("AnalyzeModelShape: ", model.name, ": no part scores below max_handle_score = ",
                       options.max_handle_score);
    return shape;
  }
  shape.features = ComputeFeatures(shape.parts, shape.handle, shape.X_FT);
  return shape;
}

}  // namespace

ShapeSegmentation SegmentModelShape(const toollib::ToolModel& model, const ShapeOptions& options) {
  options.Validate();
  return SegmentModelSamples(model, ModelSamples(model, options), options);
}

ModelShape AnalyzeModelShape(const toollib::ToolModel& model, const ShapeOptions& options,
                             const ShapeSegmentation& segmentation) {
  options.Validate();
  return AnalyzeModelSamples(model, ModelSamples(model, options), options, segmentation);
}

ModelShape AnalyzeModelShape(const toollib::ToolModel& model, const ShapeOptions& options) {
  options.Validate();
  const SurfaceSamples samples = ModelSamples(model, options);
  return AnalyzeModelSamples(model, samples, options, SegmentModelSamples(model, samples, options));
}

ModelShape TransformShape(const ModelShape& shape, const Eigen::Isometry3d& X_RF) {
  ModelShape out = shape;
  const Eigen::Matrix3f R = X_RF.linear().cast<float>();
  const Eigen::Vector3f t = X_RF.translation().cast<float>();
  for (Part& p : out.parts) {
    p.points = (R * p.points).colwise() + t;
    p.sq.pose = X_RF * p.sq.pose;
  }
  out.handle.center = X_RF * shape.handle.center;
  out.handle.axis = X_RF.linear() * shape.handle.axis;
  out.handle.X_FH = X_RF * shape.handle.X_FH;
  out.X_FT = X_RF * shape.X_FT;
  return out;
}

ModelShape AnalyzeObservedShape(const Eigen::Matrix3Xf& p_R, const Eigen::Vector3d& p_R_camera,
                                const ShapeOptions& options) {
  options.Validate();
  CheckCloud("AnalyzeObservedShape", "p_R", p_R);
  if (!p_R_camera.allFinite()) ThrowInvalid("AnalyzeObservedShape: p_R_camera is not finite");
  ModelShape shape;
  if (p_R.cols() < kMinShapePoints) {
    shape.reason = Cat("AnalyzeObservedShape: ", p_R.cols(), " points, need at least ", kMinShapePoints);
    return shape;
  }
  // Even subsample by index, then PCA normals from the nearest neighbours (brute force: a few
  // thousand points), turned toward the camera.
  const Eigen::Index n = std::min<Eigen::Index>(p_R.cols(), options.samples);
  SurfaceSamples samples;
  samples.points.resize(3, n);
  for (Eigen::Index i = 0; i < n; ++i) samples.points.col(i) = p_R.col(i * p_R.cols() / n);
  samples.normals.resize(3, n);
  const int k = static_cast<int>(std::min<Eigen::Index>(options.normal_neighbours, n - 1));
  std::vector<std::pair<float, int>> dist(static_cast<std::size_t>(n));
  for (Eigen::Index i = 0; i < n; ++i) {
    for (Eigen::Index j = 0; j < n; ++j) {
      dist[static_cast<std::size_t>(j)] = {(samples.points.col(j) - samples.points.col(i)).squaredNorm(), static_cast<int>(j)};
    }
    std::partial_sort(dist.begin(), dist.begin() + k + 1, dist.end());
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (int m = 0; m <= k; ++m) mean += samples.points.col(dist[static_cast<std::size_t>(m)].second).cast<double>();
    mean /= (k + 1);
    Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
    for (int m = 0; m <= k; ++m) {
      const Eigen::Vector3d d = samples.points.col(dist[static_cast<std::size_t>(m)].second).cast<double>() - mean;
      cov += d * d.transpose();
    }
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);
    Eigen::Vector3d normal = eig.eigenvectors().col(0);
    if (normal.dot(p_R_camera - samples.points.col(i).cast<double>()) < 0.0) normal = -normal;
    samples.normals.col(i) = normal.cast<float>();
  }
  PartsResult parts = SegmentParts(samples, options);
  shape.status = parts.status;
  shape.reason = parts.reason;
  shape.mesh_faces = parts.mesh_faces;
  shape.parts = std::move(parts.parts);
  if (shape.status != ShapeStatus::kOk) return shape;
  shape.handle = FinishHandle(shape.parts, options, std::nullopt, std::nullopt);
  if (shape.handle.part < 0) {
    shape.status = ShapeStatus::kNoHandle;
    shape.reason = Cat("AnalyzeObservedShape: no part scores below max_handle_score = ", options.max_handle_score);
    return shape;
  }
  // Estimated tool frame: z along the handle axis, origin at the butt end of the cloud, x toward
  // the effector side (x_H).
  double butt = std::numeric_limits<double>::infinity();
  for (const Part& p : shape.parts) {
    for (Eigen::Index i = 0; i < p.points.cols(); ++i) {
      butt = std::min(butt, (p.points.col(i).cast<double>() - shape.handle.center).dot(shape.handle.axis));
    }
  }
  shape.X_FT = Eigen::Isometry3d::Identity();
  shape.X_FT.linear() = shape.handle.X_FH.linear();
  shape.X_FT.translation() = shape.handle.center + butt * shape.handle.axis;
  shape.features = ComputeFeatures(shape.parts, shape.handle, shape.X_FT);
  return shape;
}

std::string ShapeCacheKey(const toollib::ToolModel& model, const ShapeOptions& options) {
  std::uint64_t mesh_hash = Fnv1a(model.mesh.vertices.data(), sizeof(double) * static_cast<std::size_t>(model.mesh.vertices.size()));
  mesh_hash = Fnv1a(model.mesh.faces.data(), sizeof(int) * static_cast<std::size_t>(model.mesh.faces.size()), mesh_hash);
  const std::string text = OptionsText(options);
  return Cat(model.name, '-', Hex(mesh_hash), '-', Hex(Fnv1a(text.data(), text.size())));
}

ShapeSegmentations ReadShapeSegmentations(const std::filesystem::path& path) {
  auto fail = [&](const auto&... what) -> std::runtime_error {
    return std::runtime_error(Cat("shape segmentations '", path.string(), "': ", what...));
  };
  std::ifstream in(path);
  if (!in) throw fail("cannot be opened");
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(in);
  } catch (const nlohmann::json::exception& e) {
    throw fail("not valid JSON (", e.what(), ")");
  }
  ShapeSegmentations out;
  try {
    if (j.at("format").get<int>() != 1) throw fail("format ", j.at("format").dump(), ", expected 1");
    for (const auto& [key, e] : j.at("segmentations").items()) {
      ShapeSegmentation seg;
      seg.status = ShapeStatus::kOk;
      seg.num_labels = e.at("num_labels").get<int>();
      seg.mesh_faces = e.at("mesh_faces").get<int>();
      seg.mesh_fallback = e.at("mesh_fallback").get<bool>();
      if (seg.num_labels < 1 || seg.num_labels > 36) throw fail(key, ": num_labels ", seg.num_labels, ", expected 1..36");
      for (char c : e.at("labels").get<std::string>()) {
        const int label = c >= '0' && c <= '9' ? c - '0' : c >= 'a' && c <= 'z' ? c - 'a' + 10 : -1;
        if (label < 0 || label >= seg.num_labels) throw fail(key, ": label '", c, "' is not in [0, ", seg.num_labels, ")");
        seg.labels.push_back(label);
      }
      out.emplace(key, std::move(seg));
    }
  } catch (const nlohmann::json::exception& e) {
    throw fail("a field is missing or has the wrong type (", e.what(), ")");
  }
  return out;
}

void WriteShapeSegmentations(const std::filesystem::path& path, const ShapeSegmentations& segmentations) {
  nlohmann::json j;
  j["format"] = 1;
  j["segmentations"] = nlohmann::json::object();
  for (const auto& [key, seg] : segmentations) {
    if (seg.status != ShapeStatus::kOk || seg.num_labels < 1 || seg.num_labels > 36) {
      ThrowInvalid("WriteShapeSegmentations: ", key, ": status ", static_cast<int>(seg.status), ", ", seg.num_labels,
                   " labels (expected a kOk segmentation of 1..36 labels)");
    }
    std::string labels;
    labels.reserve(seg.labels.size());
    for (int label : seg.labels) {
      if (label < 0 || label >= seg.num_labels) ThrowInvalid("WriteShapeSegmentations: ", key, ": label ", label, " out of range");
      labels.push_back(static_cast<char>(label < 10 ? '0' + label : 'a' + label - 10));
    }
    j["segmentations"][key] = {{"num_labels", seg.num_labels},
                               {"mesh_faces", seg.mesh_faces},
                               {"mesh_fallback", seg.mesh_fallback},
                               {"labels", labels}};
  }
  std::ofstream out(path);
  out << j.dump(1) << '\n';
  if (!out) throw std::runtime_error(Cat("WriteShapeSegmentations: cannot write '", path.string(), "'"));
}

ShapeCache::ShapeCache(std::filesystem::path dir, ShapeSegmentations segmentations)
    : dir_(std::move(dir)), segmentations_(std::move(segmentations)) {}

const ModelShape& ShapeCache::Get(const toollib::ToolModel& model, const ShapeOptions& options) {
  options.Validate();
  const std::string model_key = ShapeCacheKey(model, options);
  const auto recorded = segmentations_.find(model_key);
  const std::string key = recorded != segmentations_.end() ? model_key + "-seg" : model_key;
  if (const auto it = memory_.find(key); it != memory_.end()) {
    ++memory_hits_;
    return it->second;
  }
  const std::filesystem::path file = dir_.empty() ? std::filesystem::path{} : dir_ / (key + ".json");
  if (!file.empty() && std::filesystem::exists(file)) {
    try {
      std::ifstream in(file);
      const nlohmann::json j = nlohmann::json::parse(in);
      if (j.at("key").get<std::string>() == key) {
        ++disk_hits_;
        return memory_.emplace(key, ShapeFromJson(j)).first->second;
      }
    } catch (const std::exception& e) {
      internal::Logger()->warn("shape cache: cannot read {} ({}); recomputing", file.string(), e.what());
    }
  }
  ++misses_;
  if (recorded != segmentations_.end()) ++recorded_;
  const ModelShape& shape =
      memory_
          .emplace(key, recorded != segmentations_.end() ? AnalyzeModelShape(model, options, recorded->second)
                                                          : AnalyzeModelShape(model, options))
          .first->second;
  if (!file.empty()) {
    std::error_code ec;
    std::filesystem::create_directories(dir_, ec);
    // Write to a temporary name and rename, so a concurrent reader never sees half a file.
    const std::filesystem::path tmp = file.string() + ".tmp" + std::to_string(::getpid());
    {
      std::ofstream out(tmp);
      out << ShapeToJson(shape, key).dump();
      if (!out) {
        internal::Logger()->warn("shape cache: cannot write {}", tmp.string());
        return shape;
      }
    }
    std::filesystem::rename(tmp, file, ec);
    if (ec) internal::Logger()->warn("shape cache: cannot rename {} ({})", tmp.string(), ec.message());
  }
  return shape;
}

namespace {

/// Display colour (RGB) of part i: the handle blue, the others from a palette without blue.
const unsigned char* PartColour(std::size_t i, int handle_part) {
  static constexpr unsigned char kPalette[][3] = {{230, 80, 40},  {60, 180, 75},  {240, 200, 40}, {170, 60, 200},
                                                  {240, 130, 200}, {70, 200, 200}, {150, 100, 40}, {128, 128, 0}};
  static constexpr unsigned char kHandle[3] = {40, 90, 230};
  return static_cast<int>(i) == handle_part ? kHandle : kPalette[i % 8];
}

}  // namespace

void WritePartsPly(const std::filesystem::path& path, const std::vector<Part>& parts, int handle_part,
                   int superquadric_points) {
  std::vector<std::pair<Eigen::Vector3f, std::array<unsigned char, 3>>> out;
  for (std::size_t i = 0; i < parts.size(); ++i) {
    const unsigned char* c = PartColour(i, handle_part);
    const std::array<unsigned char, 3> color{c[0], c[1], c[2]};
    for (Eigen::Index k = 0; k < parts[i].points.cols(); ++k) out.push_back({parts[i].points.col(k), color});
    if (superquadric_points > 0 && parts[i].sq.size.minCoeff() > 0.0) {
      const int n = std::max(2, static_cast<int>(std::sqrt(superquadric_points / 2.0)));
      const Eigen::Matrix3Xf s = SuperquadricSurface(parts[i].sq, n);
      const std::array<unsigned char, 3> light{static_cast<unsigned char>((c[0] + 255) / 2),
                                               static_cast<unsigned char>((c[1] + 255) / 2),
                                               static_cast<unsigned char>((c[2] + 255) / 2)};
      for (Eigen::Index k = 0; k < s.cols(); ++k) out.push_back({s.col(k), light});
    }
  }
  std::ofstream file(path);
  file << "ply\nformat ascii 1.0\nelement vertex " << out.size()
       << "\nproperty float x\nproperty float y\nproperty float z\n"
          "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n";
  for (const auto& [p, c] : out) {
    file << p.x() << ' ' << p.y() << ' ' << p.z() << ' ' << int{c[0]} << ' ' << int{c[1]} << ' ' << int{c[2]} << '\n';
  }
  if (!file) throw std::runtime_error(Cat("WritePartsPly: cannot write ", path.string()));
}

void WriteSuperquadricsPly(const std::filesystem::path& path, const std::vector<Part>& parts, int handle_part,
                           int n) {
  if (n < 3) ThrowInvalid("WriteSuperquadricsPly: n = ", n, " (expected >= 3)");
  std::vector<SurfaceMesh> meshes;
  std::vector<const unsigned char*> colours;
  Eigen::Index vertices = 0, faces = 0;
  for (std::size_t i = 0; i < parts.size(); ++i) {
    if (!(parts[i].sq.size.minCoeff() > 0.0)) continue;
    meshes.push_back(SuperquadricMesh(parts[i].sq, n));
    colours.push_back(PartColour(i, handle_part));
    vertices += meshes.back().vertices.cols();
    faces += meshes.back().faces.cols();
  }
  std::ofstream file(path);
  file << "ply\nformat ascii 1.0\nelement vertex " << vertices
       << "\nproperty float x\nproperty float y\nproperty float z\n"
          "property uchar red\nproperty uchar green\nproperty uchar blue\nelement face "
       << faces << "\nproperty list uchar int vertex_indices\nend_header\n";
  for (std::size_t m = 0; m < meshes.size(); ++m) {
    const unsigned char* c = colours[m];
    for (Eigen::Index k = 0; k < meshes[m].vertices.cols(); ++k) {
      const Eigen::Vector3f p = meshes[m].vertices.col(k);
      file << p.x() << ' ' << p.y() << ' ' << p.z() << ' ' << int{c[0]} << ' ' << int{c[1]} << ' ' << int{c[2]}
           << '\n';
    }
  }
  Eigen::Index offset = 0;
  for (const SurfaceMesh& mesh : meshes) {
    for (Eigen::Index f = 0; f < mesh.faces.cols(); ++f) {
      file << "3 " << offset + mesh.faces(0, f) << ' ' << offset + mesh.faces(1, f) << ' ' << offset + mesh.faces(2, f)
           << '\n';
    }
    offset += mesh.vertices.cols();
  }
  if (!file) throw std::runtime_error(Cat("WriteSuperquadricsPly: cannot write ", path.string()));
}

}  // namespace toolbench::perception
