#include "robot/robot_description.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include <nlohmann/json.hpp>

#include "common/check.h"
#include "common/paths.h"

namespace toolbench::robot {
namespace {

using nlohmann::json;

const json& Field(const json& object, const char* key, const std::filesystem::path& file) {
  if (!object.is_object() || !object.contains(key)) {
    ThrowInvalid("LoadRobotDescription: '", file.string(), "': missing field '", key, "'");
  }
  return object.at(key);
}

std::string StringField(const json& object, const char* key, const std::filesystem::path& file) {
  const json& v = Field(object, key, file);
  if (!v.is_string()) {
    ThrowInvalid("LoadRobotDescription: '", file.string(), "': field '", key,
                 "' must be a string");
  }
  return v.get<std::string>();
}

std::map<std::string, double> JointMap(const json& object, const char* key,
                                       const std::filesystem::path& file, const RobotModel& model,
                                       double scale) {
  std::map<std::string, double> out;
  const json& v = Field(object, key, file);
  if (!v.is_object()) {
    ThrowInvalid("LoadRobotDescription: '", file.string(), "': field '", key,
                 "' must map joint names to numbers");
  }
  for (const auto& [name, value] : v.items()) {
    if (!value.is_number()) {
      ThrowInvalid("LoadRobotDescription: '", file.string(), "': ", key, ".", name,
                   " must be a number");
    }
    const int j = model.JointIndex(name);
    if (!model.joints[j].movable()) {
      ThrowInvalid("LoadRobotDescription: '", file.string(), "': ", key, " names fixed joint '",
                   name, "'");
    }
    out[name] = value.get<double>() * scale;
  }
  return out;
}

}  // namespace

Eigen::VectorXd RobotDescription::WithJoints(const Eigen::VectorXd& base,
                                             const std::map<std::string, double>& values) const {
  Eigen::VectorXd q = base;
  for (const auto& [name, value] : values) {
    const Joint& joint = model.joints[model.JointIndex(name)];
    if (joint.q_index < 0) ThrowInvalid("RobotDescription: joint '", name, "' is fixed");
    q[joint.q_index] = value;
  }
  return q;
}

Eigen::VectorXd RobotDescription::HomeQ() const {
  Eigen::VectorXd q = Eigen::VectorXd::Zero(model.num_q());
  for (int i = 0; i < model.num_q(); ++i) {
    const Joint& joint = model.joints[model.movable_joints[i]];
    q[i] = std::clamp(0.0, joint.lower, joint.upper);
  }
  return WithJoints(WithJoints(q, home), hand_open);
}

RobotDescription LoadRobotDescription(const std::filesystem::path& sidecar_json) {
  json doc;
  try {
    doc = json::parse(ReadTextFile(sidecar_json));
  } catch (const json::exception& e) {
    ThrowInvalid("LoadRobotDescription: '", sidecar_json.string(), "' is not valid JSON: ",
                 e.what());
  }
  RobotDescription d;
  d.sidecar_path = sidecar_json;
  d.urdf_path = std::filesystem::absolute(sidecar_json.parent_path() /
                                          StringField(doc, "urdf", sidecar_json));
  d.model = LoadUrdf(d.urdf_path);
  d.root_link = StringField(doc, "root_link", sidecar_json);
  d.palm_frame = StringField(doc, "palm_frame", sidecar_json);
  d.camera_frame = StringField(doc, "camera_frame", sidecar_json);
  try {
    for (const std::string& frame : {d.root_link, d.palm_frame, d.camera_frame}) {
      d.model.LinkIndex(frame);
    }
    if (d.model.LinkIndex(d.root_link) != 0) {
      ThrowInvalid("root_link '", d.root_link, "' is not the URDF's root");
    }
    const json& camera = Field(doc, "camera", sidecar_json);
    d.camera.fovy_deg = Field(camera, "fovy_deg", sidecar_json).get<double>();
    d.camera.width = Field(camera, "width", sidecar_json).get<int>();
    d.camera.height = Field(camera, "height", sidecar_json).get<int>();
    if (!(d.camera.fovy_deg > 1.0 && d.camera.fovy_deg < 179.0) || d.camera.width <= 0 ||
        d.camera.height <= 0) {
      ThrowInvalid("camera has fovy_deg ", d.camera.fovy_deg, ", size ", d.camera.width, "x",
                   d.camera.height, " (expected 1 < fovy < 179, positive size)");
    }
    const json& actuators = Field(doc, "actuators", sidecar_json);
    for (int j : d.model.movable_joints) {
      const std::string& name = d.model.joints[j].name;
      if (!actuators.contains(name)) ThrowInvalid("actuators: no entry for joint '", name, "'");
      ActuatorSpec spec;
      spec.kp = Field(actuators.at(name), "kp", sidecar_json).get<double>();
      spec.armature = actuators.at(name).value("armature", 0.0);
      if (!(spec.kp > 0.0) || !(spec.armature >= 0.0)) {
        ThrowInvalid("actuators.", name, ": kp ", spec.kp, ", armature ", spec.armature,
                     " (expected kp > 0, armature >= 0)");
      }
      d.actuators[name] = spec;
    }
    for (const auto& [group, joints] : Field(doc, "hand_groups", sidecar_json).items()) {
      for (const auto& joint : joints) {
        d.model.JointIndex(joint.get<std::string>());
        d.hand_groups[group].push_back(joint.get<std::string>());
      }
    }
    d.hand_open = JointMap(doc, "hand_open", sidecar_json, d.model, 1.0);
    d.hand_preshape = doc.contains("hand_preshape")
                          ? JointMap(doc, "hand_preshape", sidecar_json, d.model, 1.0)
                          : d.hand_open;
    if (doc.contains("grasp")) {
      const json& g = doc.at("grasp");
      const auto c = Field(g, "handle_axis_center", sidecar_json).get<std::vector<double>>();
      const auto a = Field(g, "handle_axis", sidecar_json).get<std::vector<double>>();
      if (c.size() != 3 || a.size() != 3) ThrowInvalid("grasp: centre and axis need 3 numbers");
      d.grasp.center = Eigen::Vector3d(c[0], c[1], c[2]);
      d.grasp.axis = Eigen::Vector3d(a[0], a[1], a[2]).normalized();
      d.grasp.radius = Field(g, "handle_radius", sidecar_json).get<double>();
      d.grasp.length = Field(g, "handle_length", sidecar_json).get<double>();
      if (StringField(g, "frame", sidecar_json) != d.palm_frame) {
        ThrowInvalid("grasp.frame must be the palm frame '", d.palm_frame, "'");
      }
    }
    d.hand_closed = JointMap(doc, "hand_closed", sidecar_json, d.model, 1.0);
    d.home = JointMap(doc, "home_deg", sidecar_json, d.model, std::numbers::pi / 180.0);
  } catch (const json::exception& e) {
    ThrowInvalid("LoadRobotDescription: '", sidecar_json.string(), "': ", e.what());
  } catch (const std::invalid_argument& e) {
    const std::string what = e.what();
    if (what.find(sidecar_json.string()) != std::string::npos) throw;
    ThrowInvalid("LoadRobotDescription: '", sidecar_json.string(), "': ", what);
  }
  return d;
}

std::filesystem::path DefaultRobotSidecar() {
  return AssetsDir() / "robots" / "icub_upper_body.json";
}

}  // namespace toolbench::robot
