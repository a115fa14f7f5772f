#include "toollib/tool_model.h"

#include <algorithm>
#include <cmath>
#include <set>
#include <string>
#include <utility>

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include "common/check.h"
#include "common/paths.h"
#include "toollib/internal/log.h"

namespace toolbench::toollib {
namespace {

using nlohmann::json;

constexpr double kUnitTol = 1e-6;     // |axis| and |quat| must be 1 within this
constexpr double kMassRelTol = 1e-6;  // collision masses must sum to mass within this
constexpr double kLengthTol = 1e-3;   // total_length vs the mesh's z extent [m]
constexpr double kSegmentMargin =
    0.01;                           // segment centres may lie this far outside the mesh box [m]
constexpr double kButtTol = 0.005;  // |min z of the mesh| above this: frame looks off [m]

// Reads fields of one sidecar, naming the file and the JSON path in every error.
class FieldReader {
 public:
  explicit FieldReader(std::string file) : file_(std::move(file)) {}

  template <typename... Parts>
  [[noreturn]] void Fail(const std::string& field, Parts&&... parts) const {
    ThrowInvalid(file_, ": field '", field, "': ", std::forward<Parts>(parts)...);
  }

  const json& Get(const json& object, const std::string& key, const std::string& path) const {
    const auto it = object.find(key);
    if (it == object.end()) {
      Fail(path, "missing");
    }
    return *it;
  }

  std::string String(const json& object, const std::string& key, const std::string& path) const {
    const json& value = Get(object, key, path);
    if (!value.is_string()) {
      Fail(path, "expected a string, got ", value.type_name());
    }
    return value.get<std::string>();
  }

  double Number(const json& value, const std::string& path) const {
    if (!value.is_number()) {
      Fail(path, "expected a number, got ", value.type_name());
    }
    const double x = value.get<double>();
    if (!std::isfinite(x)) {
      Fail(path, "not finite");
    }
    return x;
  }

  double Number(const json& object, const std::string& key, const std::string& path) const {
    return Number(Get(object, key, path), path);
  }

  double Positive(const json& object, const std::string& key, const std::string& path) const {
    const double x = Number(object, key, path);
    if (!(x > 0.0)) {
      Fail(path, "must be > 0, got ", x);
    }
    return x;
  }

  Eigen::VectorXd Vector(const json& object, const std::string& key, const std::string& path,
                         int size) const {
    const json& value = Get(object, key, path);
    if (!value.is_array() || static_cast<int>(value.size()) != size) {
      Fail(path, "expected an array of ", size, " numbers");
    }
    Eigen::VectorXd v(size);
    for (int i = 0; i < size; ++i) {
      v[i] = Number(value[static_cast<std::size_t>(i)], Cat(path, "[", i, "]"));
    }
    return v;
  }

  Eigen::Vector3d Vector3(const json& object, const std::string& key,
                          const std::string& path) const {
    return Vector(object, key, path, 3);
  }

  Eigen::Vector3d UnitVector3(const json& object, const std::string& key,
                              const std::string& path) const {
    const Eigen::Vector3d v = Vector3(object, key, path);
    if (std::abs(v.norm() - 1.0) > kUnitTol) {
      Fail(path, "must be a unit vector, has norm ", v.norm());
    }
    return v.normalized();
  }

  Segment ReadSegment(const json& root, const std::string& key) const {
    const json& object = Get(root, key, key);
    if (!object.is_object()) {
      Fail(key, "expected an object {center, axis, length, radius}");
    }
    Segment s;
    s.center = Vector3(object, "center", key + ".center");
    s.axis = UnitVector3(object, "axis", key + ".axis");
    s.length = Positive(object, "length", key + ".length");
    s.radius = Positive(object, "radius", key + ".radius");
    return s;
  }

  const std::string& file() const { return file_; }

 private:
  std::string file_;
};

CollisionPart::Type ParseCollisionType(const FieldReader& reader, const std::string& name,
                                       const std::string& path) {
  for (const auto type :
       {CollisionPart::Type::kBox, CollisionPart::Type::kCylinder, CollisionPart::Type::kCapsule,
        CollisionPart::Type::kSphere, CollisionPart::Type::kMesh}) {
    if (CollisionTypeName(type) == name) {
      return type;
    }
  }
  reader.Fail(path, "unknown collision type '", name, "' (box, cylinder, capsule, sphere, mesh)");
}

CollisionPart ReadCollisionPart(const FieldReader& reader, const json& object,
                                const std::string& path, const std::filesystem::path& folder) {
  if (!object.is_object()) {
    reader.Fail(path, "expected an object {type, size, pos, quat, mass}");
  }
  CollisionPart part;
  part.type =
      ParseCollisionType(reader, reader.String(object, "type", path + ".type"), path + ".type");
  part.mass = reader.Positive(object, "mass", path + ".mass");
  const Eigen::Vector3d pos = reader.Vector3(object, "pos", path + ".pos");
  const Eigen::Vector4d wxyz = reader.Vector(object, "quat", path + ".quat", 4);
  if (std::abs(wxyz.norm() - 1.0) > kUnitTol) {
    reader.Fail(path + ".quat", "must be a unit quaternion (w, x, y, z), has norm ", wxyz.norm());
  }
  const Eigen::Quaterniond q = Eigen::Quaterniond(wxyz[0], wxyz[1], wxyz[2], wxyz[3]).normalized();
  part.X_TP = Eigen::Isometry3d::Identity();
  part.X_TP.linear() = q.toRotationMatrix();
  part.X_TP.translation() = pos;
  if (part.type == CollisionPart::Type::kMesh) {
    part.mesh_file = reader.String(object, "file", path + ".file");
    if (!std::filesystem::is_regular_file(folder / part.mesh_file)) {
      reader.Fail(path + ".file", "no such file '", (folder / part.mesh_file).string(), "'");
    }
    return part;
  }
  part.size = reader.Vector3(object, "size", path + ".size");
  const int needed = part.type == CollisionPart::Type::kBox      ? 3
                     : part.type == CollisionPart::Type::kSphere ? 1
                                                                 : 2;
  for (int i = 0; i < needed; ++i) {
    if (!(part.size[i] > 0.0)) {
      reader.Fail(path + ".size", "entry ", i, " must be > 0 for a ", CollisionTypeName(part.type));
    }
  }
  return part;
}

using ordered_json = nlohmann::ordered_json;

ordered_json ToJson(const Eigen::Vector3d& v) { return ordered_json::array({v.x(), v.y(), v.z()}); }

ordered_json SegmentToJson(const Segment& s) {
  ordered_json j;
  j["center"] = ToJson(s.center);
  j["axis"] = ToJson(s.axis);
  j["length"] = s.length;
  j["radius"] = s.radius;
  return j;
}

}  // namespace

std::string_view CollisionTypeName(CollisionPart::Type type) {
  switch (type) {
    case CollisionPart::Type::kBox:
      return "box";
    case CollisionPart::Type::kCylinder:
      return "cylinder";
    case CollisionPart::Type::kCapsule:
      return "capsule";
    case CollisionPart::Type::kSphere:
      return "sphere";
    case CollisionPart::Type::kMesh:
      return "mesh";
  }
  return "unknown";
}

ToolModel LoadToolModel(const std::filesystem::path& sidecar_json) {
  const std::string text = ReadTextFile(sidecar_json);
  const FieldReader reader(sidecar_json.string());
  json root;
  try {
    root = json::parse(text);
  } catch (const json::parse_error& e) {
    ThrowInvalid(sidecar_json.string(), ": not valid JSON: ", e.what());
  }
  if (!root.is_object()) {
    ThrowInvalid(sidecar_json.string(), ": expected a JSON object at the top level");
  }
  const std::filesystem::path folder = std::filesystem::absolute(sidecar_json).parent_path();

  ToolModel tool;
  tool.name = reader.String(root, "name", "name");
  if (tool.name.empty()) {
    reader.Fail("name", "must not be empty");
  }
  tool.family = reader.String(root, "family", "family");
  if (tool.family != "custom" &&
      std::find(kToolFamilies.begin(), kToolFamilies.end(), tool.family) == kToolFamilies.end()) {
    reader.Fail("family", "unknown family '", tool.family,
                "' (hoe, hook, rake, stick, lstick, shovel, hammer, spatula, or custom)");
  }
  tool.mass = reader.Positive(root, "mass", "mass");
  tool.handle = reader.ReadSegment(root, "handle");
  tool.effector = reader.ReadSegment(root, "effector");

  if (const auto it = root.find("symmetries"); it != root.end()) {
    if (!it->is_array()) {
      reader.Fail("symmetries", "expected an array of strings");
    }
    for (std::size_t i = 0; i < it->size(); ++i) {
      if (!(*it)[i].is_string()) {
        reader.Fail(Cat("symmetries[", i, "]"), "expected a string");
      }
      tool.symmetries.push_back((*it)[i].get<std::string>());
    }
  }
  if (const auto it = root.find("params"); it != root.end()) {
    if (!it->is_object()) {
      reader.Fail("params", "expected an object of numbers");
    }
    for (const auto& [key, value] : it->items()) {
      tool.params[key] = reader.Number(value, "params." + key);
    }
  }

  const std::string mesh_name = reader.String(root, "mesh", "mesh");
  tool.mesh_file = (folder / mesh_name).lexically_normal();
  try {
    tool.mesh = ReadMesh(tool.mesh_file);
    RequireValidMesh(tool.mesh, tool.mesh_file.string());
  } catch (const std::invalid_argument& e) {
    reader.Fail("mesh", e.what());
  }
  const Eigen::AlignedBox3d box = Bounds(tool.mesh);
  const double z_extent = box.max().z() - box.min().z();
  if (const auto it = root.find("total_length"); it != root.end()) {
    tool.total_length = reader.Positive(root, "total_length", "total_length");
    if (std::abs(tool.total_length - z_extent) > kLengthTol) {
      reader.Fail("total_length", tool.total_length, " m disagrees with the mesh's z extent ",
                  z_extent, " m");
    }
  } else {
    tool.total_length = z_extent;
  }
  if (std::abs(box.min().z()) > kButtTol) {
    internal::Logger()->warn(
        "{}: mesh starts at z = {} m, but the tool frame has its origin at the handle's "
        "butt end (z = 0)",
        sidecar_json.string(), box.min().z());
  }
  Eigen::AlignedBox3d inflated = box;
  inflated.min().array() -= kSegmentMargin;
  inflated.max().array() += kSegmentMargin;
  if (!inflated.contains(tool.handle.center)) {
    reader.Fail("handle.center", "lies outside the mesh's bounding box");
  }
  if (!inflated.contains(tool.effector.center)) {
    reader.Fail("effector.center", "lies outside the mesh's bounding box");
  }

  if (const auto it = root.find("collision"); it != root.end()) {
    if (!it->is_array() || it->empty()) {
      reader.Fail("collision", "expected a non-empty array of parts");
    }
    double mass_sum = 0.0;
    for (std::size_t i = 0; i < it->size(); ++i) {
      tool.collision.push_back(
          ReadCollisionPart(reader, (*it)[i], Cat("collision[", i, "]"), folder));
      mass_sum += tool.collision.back().mass;
    }
    if (std::abs(mass_sum - tool.mass) > kMassRelTol * tool.mass) {
      reader.Fail("collision", "part masses sum to ", mass_sum, " kg but mass is ", tool.mass,
                  " kg");
    }
  } else {
    CollisionPart whole;
    whole.type = CollisionPart::Type::kMesh;
    whole.mesh_file = mesh_name;
    whole.mass = tool.mass;
    tool.collision.push_back(whole);
    internal::Logger()->warn(
        "{}: no 'collision' parts; the whole mesh is used, and MuJoCo collides a mesh as "
        "its convex hull, so a concave tool (hoe, hook, rake, ...) collides as its hull",
        sidecar_json.string());
  }
  return tool;
}

AxisSpan HandleBarSpan(const TriangleMesh& mesh, const Segment& handle, double slice_m, double thinnest,
                       double thicker_m) {
  if (!(slice_m > 0) || !std::isfinite(slice_m)) ThrowInvalid("HandleBarSpan: slice_m = ", slice_m, " (expected > 0)");
  if (!(thinnest >= 0 && thinnest <= 1)) ThrowInvalid("HandleBarSpan: thinnest = ", thinnest, " (expected in [0, 1])");
  if (!(thicker_m >= 0) || !std::isfinite(thicker_m)) {
    ThrowInvalid("HandleBarSpan: thicker_m = ", thicker_m, " (expected finite, >= 0)");
  }
  if (!(handle.axis.norm() > 0) || !handle.axis.allFinite() || !handle.center.allFinite()) {
    ThrowInvalid("HandleBarSpan: handle axis ", handle.axis.transpose(), " at ", handle.center.transpose(),
                 " (expected a finite non-zero axis at a finite centre)");
  }
  const Eigen::Matrix3Xd& v = mesh.vertices;
  if (v.cols() == 0) return {};
  const Eigen::Vector3d c = handle.center;
  const Eigen::Vector3d a = handle.axis.normalized();
  const Eigen::VectorXd t = (v.colwise() - c).transpose() * a;  // offset along the axis of each vertex
  auto radial = [&](const Eigen::Vector3d& p) { return ((p - c) - (p - c).dot(a) * a).norm(); };
  const double t0 = std::min(t.minCoeff(), 0.0);
  const auto slices = static_cast<Eigen::Index>(std::floor((std::max(t.maxCoeff(), 0.0) - t0) / slice_m)) + 1;
  std::vector<double> reach(static_cast<size_t>(slices), -1.0);  // farthest surface point from the axis
  auto slice_of = [&](double offset) {
    return std::clamp<Eigen::Index>(static_cast<Eigen::Index>(std::floor((offset - t0) / slice_m)), 0, slices - 1);
  };
  auto note = [&](Eigen::Index k, double r) {
    reach[static_cast<size_t>(k)] = std::max(reach[static_cast<size_t>(k)], r);
  };
  for (Eigen::Index i = 0; i < v.cols(); ++i) note(slice_of(t(i)), radial(v.col(i)));
  const Eigen::Matrix3Xi& f = mesh.faces;
  for (Eigen::Index j = 0; j < f.cols(); ++j) {
    for (int e = 0; e < 3; ++e) {
      const int i1 = f(e, j), i2 = f((e + 1) % 3, j);
      const double lo = std::min(t(i1), t(i2)), hi = std::max(t(i1), t(i2));
      // Each face between two slices that the edge crosses: the crossing belongs to both.
      for (Eigen::Index k = slice_of(lo) + 1; k <= slice_of(hi); ++k) {
        const double plane = t0 + static_cast<double>(k) * slice_m;
        if (plane <= lo || plane >= hi) continue;
        const double s = (plane - t(i1)) / (t(i2) - t(i1));
        const double r = radial(v.col(i1) + s * (v.col(i2) - v.col(i1)));
        note(k - 1, r);
        note(k, r);
      }
    }
  }
  const double r_min = thinnest * handle.radius, r_max = handle.radius + thicker_m;
  auto bar = [&](Eigen::Index k) {
    const double r = reach[static_cast<size_t>(k)];
    return r >= r_min && r <= r_max;
  };
  const Eigen::Index centre = slice_of(0.0);
  if (!bar(centre)) return {};
  Eigen::Index first = centre, last = centre;
  while (first > 0 && bar(first - 1)) --first;
  while (last + 1 < slices && bar(last + 1)) ++last;
  return {std::max(t0 + static_cast<double>(first) * slice_m, t.minCoeff()),
          std::min(t0 + static_cast<double>(last + 1) * slice_m, t.maxCoeff())};
}

std::vector<ToolModel> LoadToolLibrary(const std::filesystem::path& dir) {
  if (!std::filesystem::is_directory(dir)) {
    ThrowInvalid("LoadToolLibrary: '", dir.string(), "' is not a folder");
  }
  std::vector<std::filesystem::path> files;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    if (entry.is_regular_file() && entry.path().extension() == ".json") {
      files.push_back(entry.path());
    }
  }
  std::sort(files.begin(), files.end());  // deterministic load order
  std::vector<ToolModel> tools;
  std::set<std::string> names;
  for (const auto& file : files) {
    tools.push_back(LoadToolModel(file));
    if (!names.insert(tools.back().name).second) {
      ThrowInvalid(file.string(), ": field 'name': tool name '", tools.back().name,
                   "' is used by another sidecar in ", dir.string());
    }
  }
  std::sort(tools.begin(), tools.end(),
            [](const ToolModel& a, const ToolModel& b) { return a.name < b.name; });
  return tools;
}

void SaveToolModel(const ToolModel& tool, const std::filesystem::path& dir) {
  if (tool.name.empty()) {
    ThrowInvalid("SaveToolModel: tool has an empty name");
  }
  const std::string mesh_name = tool.name + ".stl";
  nlohmann::ordered_json j;
  j["name"] = tool.name;
  j["family"] = tool.family;
  j["mesh"] = mesh_name;
  j["mass"] = tool.mass;
  j["total_length"] = tool.total_length;
  j["handle"] = SegmentToJson(tool.handle);
  j["effector"] = SegmentToJson(tool.effector);
  j["symmetries"] = tool.symmetries;
  j["params"] = nlohmann::ordered_json::object();
  for (const auto& [key, value] : tool.params) {
    j["params"][key] = value;
  }
  j["collision"] = nlohmann::ordered_json::array();
  for (const CollisionPart& part : tool.collision) {
    nlohmann::ordered_json p;
    p["type"] = std::string(CollisionTypeName(part.type));
    if (part.type == CollisionPart::Type::kMesh) {
      p["file"] = part.mesh_file;
    } else {
      p["size"] = ToJson(part.size);
    }
    p["pos"] = ToJson(part.X_TP.translation());
    Eigen::Quaterniond q(part.X_TP.linear());
    if (q.w() < 0.0) {
      q.coeffs() = -q.coeffs();  // one canonical sign
    }
    p["quat"] = ordered_json::array({q.w(), q.x(), q.y(), q.z()});
    p["mass"] = part.mass;
    j["collision"].push_back(p);
  }
  WriteStlBinary(dir / mesh_name, tool.mesh);
  WriteTextFile(dir / (tool.name + ".json"), j.dump(2) + "\n");
}

}  // namespace toolbench::toollib
