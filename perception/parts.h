#pragma once

#include <cstdint>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "perception/model_fit.h"
#include "perception/superquadric.h"
#include "perception/tool_analysis.h"
#include "toollib/tool_model.h"

namespace toolbench::perception {

/// Configuration of the shape analysis: surface reconstruction, SDF segmentation, one
/// superquadric per part, and the handle choice (thesis sections 4.4.2-4.4.4, Algorithm 5).
struct ShapeOptions {
  int samples = 4000;               // surface samples of a library mesh (thesis: 4000); an
                                    // observed cloud is subsampled (evenly) to at most this, >= 50
  std::uint64_t seed = 1;           // seed of the mesh sampling and the superquadric subsamples
  int sdf_clusters = 3;             // CGAL segmentation_from_sdf_values number_of_clusters, in [2, 10]
  double sdf_smoothing = 0.4;       // CGAL smoothing_lambda, in [0, 1]
  double min_part_fraction = 0.03;  // a segment with less of the surface area is merged into
                                    // the neighbour it shares the longest border with, in [0, 0.5)
  SuperquadricOptions superquadric;  // per-part fits
  double hand_radius = 0.016;       // radius of the cylinder the iCub hand holds [m] (thesis: 32 mm
                                    // diameter), > 0
  double hand_length = 0.080;       // its length [m] (thesis: 80 mm), > 0
  double preferred_length = 0.16;   // a part shorter than this is penalised as a handle [m]: the
                                    // hand's 80 mm plus room on both sides, >= hand_length
  double radius_log_tolerance = 0.25;  // |ln(r / hand_radius)| below this costs nothing (handles
                                       // of 11-20 mm radius are all fine), >= 0
  double max_handle_score = 1.5;    // a part whose GraspScore exceeds this is no handle, > 0
  double lone_part_effector_length = 0.08;  // a tool that is one part (a stick) keeps this much of
                                            // its effector end out of the grasp region [m], >= 0
  int normal_neighbours = 12;       // observed clouds: neighbours of the PCA normal, >= 3
  void Validate() const;            // throws std::invalid_argument naming the field and its value
};

/// Outcome class of a shape analysis (expected failures are results, not exceptions).
enum class ShapeStatus {
  kOk,                     // parts and a handle
  kTooFewPoints,           // fewer than kMinShapePoints points
  kSegmentationFailed,     // surface reconstruction or SDF segmentation gave no usable part
  kNoHandle,               // parts found, none scores below max_handle_score
};

/// Smallest cloud the shape analysis attempts.
inline constexpr int kMinShapePoints = 50;

/// Parts of a surface in the owner's frame F.
struct PartsResult {
  ShapeStatus status = ShapeStatus::kTooFewPoints;
  std::string reason;        // empty when kOk
  std::vector<Part> parts;   // largest surface area first; points and superquadrics in F
  int mesh_faces = 0;        // faces of the mesh that was segmented
  bool mesh_fallback = false;  // true: AFSR failed and the caller's mesh was segmented instead
};

/// Splits a sampled surface into parts: CGAL advancing-front reconstruction of the points,
/// shape-diameter-function segmentation of that mesh, small segments merged into neighbours,
/// then one superquadric (and its cylinder_score) per part. Points the reconstruction left out
/// join the part of their nearest labelled point. `samples.normals` (outward) orient the
/// reconstruction. Returns kTooFewPoints / kSegmentationFailed with a reason; throws
/// std::invalid_argument for mismatched sizes, non-finite points or bad options.
PartsResult SegmentParts(const SurfaceSamples& samples, const ShapeOptions& options);

/// Dissimilarity of `sq` to the hand's cylinder (Part::cylinder_score): with the semi-axes
/// sorted s1 <= s2 <= s3 (so the order of the axes does not matter),
///   sqrt(dz(ln(s1 / r_h))^2 + dz(ln(s2 / r_h))^2 + max(0, ln(L_p / (2 s3)))^2),
/// dz(v) = max(0, |v| - radius_log_tolerance), r_h = hand_radius, L_p = preferred_length.
double CylinderScore(const Superquadric& sq, const ShapeOptions& options);

/// Picks the handle among `parts` (thesis Algorithm 5): each part is tried as the handle, and the
/// lowest cylinder_score + GraspScore wins (parts whose GraspScore exceeds max_handle_score are
/// not candidates). Its axis is the superquadric's longest axis, or the main direction (PCA) of
/// the part's middle half when they differ by more than 5 deg, pointing toward the tool's
/// points outside the graspable cylinder (below); with (almost) none, toward `z_hint` when
/// given. `x_hint` (when given) fixes x_H's side, else the side of those points. The axis line
/// passes through the centroid of the part's middle half; radius: median distance of the middle
/// half from that line. Graspable region: the tool is sliced along the axis (5 mm) and, from the
/// part's median, the region grows while each slice of *all* parts' points fits the handle's
/// cylinder (all within 1.3 r + 2 mm of the axis, and at least 0.7 r wide), so it stops at the
/// effector even where SDF segments cut the handle short; a lone part also loses
/// lone_part_effector_length at its +axis end. Returns part = -1 when no part qualifies, i.e. none
/// with a GraspScore <= options.max_handle_score. Frames: everything in the parts' frame F.
Handle ChooseHandle(const std::vector<Part>& parts, const ShapeOptions& options,
                    const std::optional<Eigen::Vector3d>& z_hint = std::nullopt,
                    const std::optional<Eigen::Vector3d>& x_hint = std::nullopt);

/// How well the handle region measured around a part's axis (radius, graspable length) suits the
/// hand: sqrt(dz(ln(radius / r_h))^2 + max(0, ln(L_p / length))^2), dz and the names as in
/// CylinderScore; infinity for part = -1 or a zero radius or length.
double GraspScore(const Handle& handle, const ShapeOptions& options);

/// A tool's parts, handle and features.
struct ModelShape {
  std::string model;            // library model name; empty for an observed tool
  ShapeStatus status = ShapeStatus::kTooFewPoints;
  std::string reason;           // empty when kOk
  std::vector<Part> parts;      // in F
  Handle handle;                // in F
  ToolFeatures features;        // in the tool frame T
  Eigen::Isometry3d X_FT = Eigen::Isometry3d::Identity();  // T in F: identity for a model
                                // analysed in T; estimated from the handle for observed tools
  int mesh_faces = 0;           // see PartsResult
  bool mesh_fallback = false;   // see PartsResult
};

/// Features in T (see ToolFeatures) from parts and handle given in F, with T placed by X_FT.
/// The effector is every point past the handle's graspable region toward the effector, or
/// beside that region but outside the handle's cylinder. Zero features when handle.part < 0.
ToolFeatures ComputeFeatures(const std::vector<Part>& parts, const Handle& handle, const Eigen::Isometry3d& X_FT);

/// Analyses a library model in its tool frame T (F = T): options.samples area-weighted samples
/// of the mesh (seeded), SegmentParts, ChooseHandle with the T conventions as hints (+z toward
/// the effector, +x its working side); parts lying (90 % of their points) inside the handle's
/// cylinder and graspable region (end caps the SDF split off) are then merged into the handle
/// part, its superquadric refitted and the handle chosen again; then ComputeFeatures. When AFSR gives no usable surface the
/// library mesh itself is segmented (mesh_fallback = true). Throws std::invalid_argument for
/// bad options or a mesh that cannot be sampled.
ModelShape AnalyzeModelShape(const toollib::ToolModel& model, const ShapeOptions& options);

/// Which part each of AnalyzeModelShape's surface samples of a library mesh belongs to: the one
/// step of the analysis that a process cannot repeat. CGAL's advancing-front reconstruction orders
/// equally good border edges by their address in memory, so its surface, and the SDF parts on it,
/// can differ by a few faces with the process's allocation history; everything after the labels
/// (superquadrics, handle, features) is a function of them. A recorded segmentation
/// (ShapeCache's `segmentations`, assets/models/library_segmentation.json) gives every process on
/// every machine the same analysis of a library model.
struct ShapeSegmentation {
  ShapeStatus status = ShapeStatus::kTooFewPoints;  // kOk, else why there are no labels
  std::string reason;          // empty when kOk
  std::vector<int> labels;     // per sample, in SampleSurface's order, each in [0, num_labels)
  int num_labels = 0;
  int mesh_faces = 0;          // see PartsResult
  bool mesh_fallback = false;  // see PartsResult
};

/// The first half of AnalyzeModelShape: sampling and SegmentParts' labels (with its fallback to
/// the library mesh's own SDF segmentation when the reconstruction gives no usable part).
/// Throws like AnalyzeModelShape.
ShapeSegmentation SegmentModelShape(const toollib::ToolModel& model, const ShapeOptions& options);

/// The second half: the parts, superquadrics, handle and features of `model` from a segmentation
/// of its samples (SegmentModelShape under the same options, perhaps in another process). A failed
/// segmentation gives its status and reason. Throws std::invalid_argument naming the model when
/// the labels do not fit the samples (count, range), and like AnalyzeModelShape.
ModelShape AnalyzeModelShape(const toollib::ToolModel& model, const ShapeOptions& options,
                             const ShapeSegmentation& segmentation);

/// Recorded segmentations of library models, by ShapeCacheKey (model name, mesh and options
/// hashes: a changed mesh or option never picks up a stale one).
using ShapeSegmentations = std::map<std::string, ShapeSegmentation>;

/// Reads / writes a segmentations file (JSON: format, then per key num_labels, mesh_faces,
/// mesh_fallback and the labels as one base-36 digit each). Read throws std::runtime_error
/// naming the file and what is wrong with it (missing, not JSON, a field missing or out of
/// range); write throws std::runtime_error naming the file when it cannot be written, and
/// std::invalid_argument for a segmentation that is not kOk or has more than 36 labels.
ShapeSegmentations ReadShapeSegmentations(const std::filesystem::path& path);
void WriteShapeSegmentations(const std::filesystem::path& path, const ShapeSegmentations& segmentations);

/// Moves a shape from its frame F into R given X_RF (e.g. a model's shape in T with the fitted
/// X_RT): part points, superquadric poses, the handle and X_FT. Features stay in T.
ModelShape TransformShape(const ModelShape& shape, const Eigen::Isometry3d& X_RF);

/// Shape analysis of an observed, partial cloud of an unknown tool, all in R: subsampled to
/// options.samples points, normals from the PCA of the normal_neighbours nearest points turned
/// toward the camera centre p_R_camera, then SegmentParts, ChooseHandle (no hints) and the
/// merging of AnalyzeModelShape, and an
/// estimated tool frame X_FT (origin at the butt end of the cloud along the handle axis, z_T =
/// handle axis, x_T toward the effector side). Caveat: one-sided fits under-estimate radii;
/// widen radius_log_tolerance (e.g. 0.6) for observed clouds. Returns statuses like
/// SegmentParts; throws std::invalid_argument for non-finite points or bad options.
ModelShape AnalyzeObservedShape(const Eigen::Matrix3Xf& p_R, const Eigen::Vector3d& p_R_camera,
                                const ShapeOptions& options);

/// Key of a cached analysis: model name, a hash of the mesh data and a hash of the options, as
/// "<name>-<mesh hash>-<options hash>" (16 hex digits each).
std::string ShapeCacheKey(const toollib::ToolModel& model, const ShapeOptions& options);

/// Per-process (and optionally on-disk) cache of AnalyzeModelShape results. Parts do not depend
/// on the tool's pose, so one analysis per model and options serves every episode. On disk,
/// one JSON file per key in `dir`; the key includes the mesh and options hashes, so a changed
/// mesh or option never reads a stale file. Not thread-safe.
class ShapeCache {
 public:
  /// `dir` empty: memory only. Otherwise the folder is created when first written. A model with a
  /// recorded segmentation in `segmentations` (same key) is analysed from it, never segmented
  /// anew; its file in `dir` has "-seg" appended to the key, so analyses segmented anew (by an
  /// earlier version, or for models without a record) are not taken for it.
  explicit ShapeCache(std::filesystem::path dir = {}, ShapeSegmentations segmentations = {});

  /// The analysis of `model` under `options`: from memory, else from disk, else computed (and
  /// stored in both). The reference stays valid as long as the cache lives. Throws like
  /// AnalyzeModelShape; a cache file that cannot be parsed is recomputed and overwritten.
  const ModelShape& Get(const toollib::ToolModel& model, const ShapeOptions& options);

  int memory_hits() const { return memory_hits_; }  // Get calls answered from memory
  int disk_hits() const { return disk_hits_; }      // Get calls answered from a file
  int misses() const { return misses_; }            // Get calls that ran the analysis
  int recorded() const { return recorded_; }        // of the misses, those from a recorded segmentation

 private:
  std::filesystem::path dir_;
  ShapeSegmentations segmentations_;
  std::map<std::string, ModelShape> memory_;
  int memory_hits_ = 0;
  int disk_hits_ = 0;
  int misses_ = 0;
  int recorded_ = 0;
};

/// Writes an ASCII PLY of coloured points (x y z as float, red green blue as uchar) for
/// display: each part's points in its own colour and, with `superquadric_points` > 0, that
/// many surface points of each part's superquadric (SuperquadricSurface with n =
/// sqrt(points / 2)) in a lighter shade; the handle part is always blue. Coordinates in F.
/// Throws std::runtime_error naming the file when it cannot be written.
void WritePartsPly(const std::filesystem::path& path, const std::vector<Part>& parts, int handle_part,
                   int superquadric_points = 0);

/// Writes an ASCII PLY triangle mesh (vertex x y z as float with red green blue as uchar, faces
/// as vertex-index lists) of every part's superquadric surface (SuperquadricMesh with `n`
/// latitudes, 2n (2n - 4) faces per part), each part in the colour WritePartsPly gives its
/// points (the handle part blue), so that a mesh viewer shows the fitted shapes. Parts whose
/// superquadric has a non-positive semi-axis are left out. Coordinates in F. Throws
/// std::invalid_argument for n < 3, std::runtime_error naming the file when it cannot be written.
void WriteSuperquadricsPly(const std::filesystem::path& path, const std::vector<Part>& parts, int handle_part,
                           int n = 24);

}  // namespace toolbench::perception
