#include "sim/scene_spec.h"

#include <algorithm>
#include <cmath>
#include <initializer_list>
#include <set>

#include <nlohmann/json.hpp>

#include "common/check.h"
#include "common/paths.h"

namespace toolbench::sim {
namespace {

using nlohmann::json;

/// Reads fields of one JSON object into a struct, rejecting unknown keys and wrong types.
class Reader {
 public:
  Reader(const json& object, std::string path, std::string_view source)
      : object_(object), path_(std::move(path)), source_(source) {
    if (!object_.is_object()) Fail(path_, "must be an object");
  }

  void Number(const char* key, double& out) {
    if (const json* v = Take(key)) {
      if (!v->is_number()) Fail(Path(key), "must be a number");
      out = v->get<double>();
      if (!std::isfinite(out)) Fail(Path(key), "must be finite");
    }
  }
  void Integer(const char* key, int& out) {
    if (const json* v = Take(key)) {
      if (!v->is_number_integer()) Fail(Path(key), "must be an integer");
      out = v->get<int>();
    }
  }
  void String(const char* key, std::string& out) {
    if (const json* v = Take(key)) {
      if (!v->is_string()) Fail(Path(key), "must be a string");
      out = v->get<std::string>();
    }
  }
  void Strings(const char* key, std::vector<std::string>& out) {
    if (const json* v = Take(key)) {
      if (!v->is_array()) Fail(Path(key), "must be an array of strings");
      out.clear();
      for (const json& item : *v) {
        if (!item.is_string()) Fail(Path(key), "must be an array of strings");
        out.push_back(item.get<std::string>());
      }
    }
  }
  template <int N>
  void Vector(const char* key, Eigen::Matrix<double, N, 1>& out) {
    if (const json* v = Take(key)) {
      if (!v->is_array() || v->size() != N) Fail(Path(key), Cat("must be an array of ", N, " numbers"));
      for (int i = 0; i < N; ++i) {
        if (!(*v)[i].is_number()) Fail(Path(key), Cat("must be an array of ", N, " numbers"));
        out[i] = (*v)[i].get<double>();
        if (!std::isfinite(out[i])) Fail(Path(key), "must be finite");
      }
    }
  }
  /// Returns a reader for a nested object, or nullptr-like empty optional when absent.
  const json* Object(const char* key) { return Take(key); }
  std::string Path(const char* key) const { return path_.empty() ? key : path_ + "." + key; }

  /// Call after reading every known key: any key left is unknown.
  void Finish() const {
    for (const auto& [key, value] : object_.items()) {
      if (!taken_.count(key)) Fail(Path(key.c_str()), "is not a known field");
    }
  }

  [[noreturn]] void Fail(const std::string& field, const std::string& what) const {
    ThrowInvalid("scene '", source_, "': field '", field, "' ", what);
  }

 private:
  const json* Take(const char* key) {
    taken_.insert(key);
    auto it = object_.find(key);
    return it == object_.end() ? nullptr : &*it;
  }

  const json& object_;
  std::string path_;
  std::string source_;
  std::set<std::string> taken_;
};

void Require(bool ok, std::string_view field, double value, std::string_view expected) {
  if (!ok) ThrowInvalid("SceneSpec: field '", field, "' is ", value, ", expected ", expected);
}

// A text field that must be one of `allowed` (MuJoCo's option keywords).
void RequireOneOf(std::string_view field, const std::string& value, std::initializer_list<std::string_view> allowed) {
  if (std::find(allowed.begin(), allowed.end(), value) != allowed.end()) return;
  std::string expected;
  for (const std::string_view a : allowed) expected += (expected.empty() ? "'" : ", '") + std::string(a) + "'";
  ThrowInvalid("SceneSpec: field '", field, "' is '", value, "', expected one of ", expected);
}

}  // namespace

void SceneSpec::Validate() const {
  Require(table.size.x() > 0 && table.size.y() > 0, "table.size", table.size.minCoeff(), "> 0");
  Require(table.thickness > 0, "table.thickness", table.thickness, "> 0");
  Require(ball.radius > 0 && ball.radius < 0.5, "ball.radius", ball.radius, "in (0, 0.5) m");
  Require(ball.mass > 0, "ball.mass", ball.mass, "> 0");
  Require(ball.x_range[0] <= ball.x_range[1], "ball.x_range", ball.x_range[0], "min <= max");
  Require(ball.y_range[0] <= ball.y_range[1], "ball.y_range", ball.y_range[0], "min <= max");
  Require(rack.incline_deg >= 0 && rack.incline_deg <= 45, "rack.incline_deg", rack.incline_deg,
          "in [0, 45]");
  Require(rack.yaw_deg >= -90 && rack.yaw_deg <= 90, "rack.yaw_deg", rack.yaw_deg, "in [-90, 90]");
  Require(rack.width > 0, "rack.width", rack.width, "> 0");
  Require(rack.height > 0, "rack.height", rack.height, "> 0");
  Require(rack.ledge_depth > 0, "rack.ledge_depth", rack.ledge_depth, "> 0");
  Require(rack.lip_height >= 0, "rack.lip_height", rack.lip_height, ">= 0");
  Require(rack.standoff >= 0 && rack.standoff < rack.ledge_depth - 0.02, "rack.standoff",
          rack.standoff, "in [0, ledge_depth - 0.02)");
  Require(rack.rail_height > 0 && rack.rail_height < rack.height, "rack.rail_height",
          rack.rail_height, "in (0, height)");
  for (double slot : {rack.slot_pos1, rack.slot_pos2, rack.slot_pos3}) {
    Require(std::abs(slot) < rack.width / 2, "rack.slot_pos*", slot, "inside the rack width");
  }
  Require(tools.min_count >= 1, "tools.min_count", tools.min_count, ">= 1");
  Require(tools.max_count >= tools.min_count && tools.max_count <= 3, "tools.max_count",
          tools.max_count, "in [min_count, 3]");
  Require(physics.timestep > 0 && physics.timestep <= 0.01, "physics.timestep", physics.timestep,
          "in (0, 0.01] s");
  RequireOneOf("physics.cone", physics.cone, {"elliptic", "pyramidal"});
  RequireOneOf("physics.noslip_scope", physics.noslip_scope, {"always", "resting"});
  RequireOneOf("physics.solver", physics.solver, {"Newton", "CG", "PGS"});
  RequireOneOf("physics.jacobian", physics.jacobian, {"auto", "dense", "sparse"});
  Require(physics.impratio >= 1, "physics.impratio", physics.impratio, ">= 1");
  Require(physics.noslip_iterations >= 0, "physics.noslip_iterations", physics.noslip_iterations,
          ">= 0");
  Require(physics.noslip_tolerance > 0, "physics.noslip_tolerance", physics.noslip_tolerance, "> 0");
  for (int i = 0; i < 2; ++i) {
    Require(physics.robot_solimp[i] > 0 && physics.robot_solimp[i] < 1, "physics.robot_solimp",
            physics.robot_solimp[i], "d0 and dwidth in (0, 1)");
  }
  Require(physics.robot_solimp[2] > 0, "physics.robot_solimp", physics.robot_solimp[2], "width > 0 m");
  Require(physics.robot_solmix > 0, "physics.robot_solmix", physics.robot_solmix, "> 0");
  Require(physics.tolerance > 0, "physics.tolerance", physics.tolerance, "> 0");
  Require(physics.iterations >= 1, "physics.iterations", physics.iterations, ">= 1");
  Require(physics.max_contacts >= 1, "physics.max_contacts", physics.max_contacts, ">= 1");
  Require(physics.max_constraint_rows >= 1, "physics.max_constraint_rows", physics.max_constraint_rows, ">= 1");
  Require(physics.settle_time >= 0 && physics.settle_time <= 10, "physics.settle_time",
          physics.settle_time, "in [0, 10] s");
  Require(physics.sleep_window >= 0 && physics.sleep_window <= 10, "physics.sleep_window", physics.sleep_window,
          "in [0, 10] s (0 = never sleep)");
  Require(physics.sleep_tolerance > 0, "physics.sleep_tolerance", physics.sleep_tolerance, "> 0");
  Require(physics.wake_margin > 0, "physics.wake_margin", physics.wake_margin, "> 0");
  if (robot.empty()) ThrowInvalid("SceneSpec: field 'robot' is empty");
}

SceneSpec ParseSceneSpec(std::string_view json_text, std::string_view source) {
  json doc;
  try {
    doc = json::parse(json_text);
  } catch (const json::exception& e) {
    ThrowInvalid("scene '", source, "' is not valid JSON: ", e.what());
  }
  SceneSpec spec;
  Reader top(doc, "", source);
  top.String("name", spec.name);
  top.String("robot", spec.robot);
  top.Strings("tool_dirs", spec.tool_dirs);
  top.Vector<3>("robot_base", spec.robot_base);
  if (const json* t = top.Object("table")) {
    Reader r(*t, "table", source);
    r.Vector<2>("center", spec.table.center);
    r.Vector<2>("size", spec.table.size);
    r.Number("top_z", spec.table.top_z);
    r.Number("thickness", spec.table.thickness);
    r.Finish();
  }
  if (const json* b = top.Object("ball")) {
    Reader r(*b, "ball", source);
    r.Number("radius", spec.ball.radius);
    r.Number("mass", spec.ball.mass);
    r.Vector<2>("x_range", spec.ball.x_range);
    r.Vector<2>("y_range", spec.ball.y_range);
    r.Finish();
  }
  if (const json* k = top.Object("rack")) {
    Reader r(*k, "rack", source);
    r.Vector<3>("origin", spec.rack.origin);
    r.Number("yaw_deg", spec.rack.yaw_deg);
    r.Number("incline_deg", spec.rack.incline_deg);
    r.Number("width", spec.rack.width);
    r.Number("height", spec.rack.height);
    r.Number("ledge_depth", spec.rack.ledge_depth);
    r.Number("lip_height", spec.rack.lip_height);
    r.Number("standoff", spec.rack.standoff);
    r.Number("rail_height", spec.rack.rail_height);
    r.Number("slot_pos1", spec.rack.slot_pos1);
    r.Number("slot_pos2", spec.rack.slot_pos2);
    r.Number("slot_pos3", spec.rack.slot_pos3);
    r.Finish();
  }
  if (const json* t = top.Object("tools")) {
    Reader r(*t, "tools", source);
    r.Integer("min_count", spec.tools.min_count);
    r.Integer("max_count", spec.tools.max_count);
    r.Strings("choices", spec.tools.choices);
    r.Finish();
  }
  if (const json* p = top.Object("physics")) {
    Reader r(*p, "physics", source);
    r.Number("timestep", spec.physics.timestep);
    r.String("cone", spec.physics.cone);
    r.Number("impratio", spec.physics.impratio);
    r.Integer("noslip_iterations", spec.physics.noslip_iterations);
    r.Number("noslip_tolerance", spec.physics.noslip_tolerance);
    r.String("noslip_scope", spec.physics.noslip_scope);
    r.Vector<3>("robot_solimp", spec.physics.robot_solimp);
    r.Number("robot_solmix", spec.physics.robot_solmix);
    r.String("solver", spec.physics.solver);
    r.String("jacobian", spec.physics.jacobian);
    r.Number("tolerance", spec.physics.tolerance);
    r.Integer("iterations", spec.physics.iterations);
    r.Number("settle_time", spec.physics.settle_time);
    r.Integer("max_contacts", spec.physics.max_contacts);
    r.Integer("max_constraint_rows", spec.physics.max_constraint_rows);
    r.Number("sleep_window", spec.physics.sleep_window);
    r.Number("sleep_tolerance", spec.physics.sleep_tolerance);
    r.Number("wake_margin", spec.physics.wake_margin);
    r.Finish();
  }
  top.Finish();
  try {
    spec.Validate();
  } catch (const std::invalid_argument& e) {
    ThrowInvalid("scene '", source, "': ", e.what());
  }
  return spec;
}

SceneSpec LoadSceneSpec(const std::filesystem::path& path) {
  if (!std::filesystem::is_regular_file(path)) {
    ThrowInvalid("scene file '", path.string(), "' does not exist");
  }
  return ParseSceneSpec(ReadTextFile(path), path.string());
}

std::filesystem::path DefaultScenePath() { return ScenesDir() / "default.json"; }

}  // namespace toolbench::sim
