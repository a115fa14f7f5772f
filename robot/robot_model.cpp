#include "robot/robot_model.h"

#include <cmath>
#include <functional>

#include <urdf_parser/urdf_parser.h>

#include "common/check.h"
#include "common/paths.h"

namespace toolbench::robot {
namespace {

Eigen::Isometry3d ToIsometry(const urdf::Pose& pose) {
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.translation() = Eigen::Vector3d(pose.position.x, pose.position.y, pose.position.z);
  X.linear() = Eigen::Quaterniond(pose.rotation.w, pose.rotation.x, pose.rotation.y,
                                  pose.rotation.z)
                   .normalized()
                   .toRotationMatrix();
  return X;
}

Geometry ToGeometry(const urdf::Geometry& g, const urdf::Pose& origin, std::string_view source,
                    const std::string& link) {
  Geometry out;
  out.X_LG = ToIsometry(origin);
  switch (g.type) {
    case urdf::Geometry::BOX: {
      const auto& box = static_cast<const urdf::Box&>(g);
      out.type = Geometry::Type::kBox;
      out.size = {box.dim.x, box.dim.y, box.dim.z};
      break;
    }
    case urdf::Geometry::CYLINDER: {
      const auto& cyl = static_cast<const urdf::Cylinder&>(g);
      out.type = Geometry::Type::kCylinder;
      out.size = {cyl.radius, cyl.length, 0.0};
      break;
    }
    case urdf::Geometry::SPHERE: {
      const auto& sphere = static_cast<const urdf::Sphere&>(g);
      out.type = Geometry::Type::kSphere;
      out.size = {sphere.radius, 0.0, 0.0};
      break;
    }
    case urdf::Geometry::MESH: {
      const auto& mesh = static_cast<const urdf::Mesh&>(g);
      out.type = Geometry::Type::kMesh;
      out.mesh_file = mesh.filename;
      out.size = {mesh.scale.x, mesh.scale.y, mesh.scale.z};
      break;
    }
    default:
      ThrowInvalid("ParseUrdf: ", source, ": link '", link, "' has an unknown geometry type");
  }
  for (int i = 0; i < 3; ++i) {
    if (!std::isfinite(out.size[i]) || out.size[i] < 0.0) {
      ThrowInvalid("ParseUrdf: ", source, ": link '", link, "' has a geometry with size ",
                   out.size.transpose(), " (expected finite, >= 0)");
    }
  }
  return out;
}

}  // namespace

int RobotModel::LinkIndex(std::string_view link_name) const {
  for (size_t i = 0; i < links.size(); ++i) {
    if (links[i].name == link_name) return static_cast<int>(i);
  }
  ThrowInvalid("RobotModel: unknown link '", link_name, "' in robot '", name, "'");
}

int RobotModel::JointIndex(std::string_view joint_name) const {
  for (size_t i = 0; i < joints.size(); ++i) {
    if (joints[i].name == joint_name) return static_cast<int>(i);
  }
  ThrowInvalid("RobotModel: unknown joint '", joint_name, "' in robot '", name, "'");
}

std::vector<std::string> RobotModel::JointNames() const {
  std::vector<std::string> names;
  names.reserve(movable_joints.size());
  for (int j : movable_joints) names.push_back(joints[j].name);
  return names;
}

RobotModel ParseUrdf(const std::string& urdf_xml, std::string_view source) {
  if (urdf_xml.empty()) ThrowInvalid("ParseUrdf: ", source, ": empty URDF text");
  const urdf::ModelInterfaceSharedPtr parsed = urdf::parseURDF(urdf_xml);
  if (!parsed || !parsed->getRoot()) {
    ThrowInvalid("ParseUrdf: ", source, ": urdfdom could not parse the URDF (malformed XML, ",
                 "missing <robot>, dangling joint or more than one root link)");
  }
  RobotModel model;
  model.name = parsed->getName();

  // Depth-first from the root so that parents precede children.
  std::function<void(const urdf::LinkConstSharedPtr&, int)> visit =
      [&](const urdf::LinkConstSharedPtr& ulink, int parent_joint) {
        const int link_index = static_cast<int>(model.links.size());
        Link link;
        link.name = ulink->name;
        link.parent_joint = parent_joint;
        if (ulink->inertial) {
          const auto& in = *ulink->inertial;
          link.inertial.mass = in.mass;
          link.inertial.X_LI = ToIsometry(in.origin);
          link.inertial.inertia << in.ixx, in.ixy, in.ixz, in.ixy, in.iyy, in.iyz, in.ixz, in.iyz,
              in.izz;
          if (!(in.mass >= 0.0) || !link.inertial.inertia.allFinite()) {
            ThrowInvalid("ParseUrdf: ", source, ": link '", link.name,
                         "' has a negative or non-finite mass or inertia");
          }
        }
        for (const auto& v : ulink->visual_array) {
          if (!v || !v->geometry) continue;
          Geometry g = ToGeometry(*v->geometry, v->origin, source, link.name);
          if (v->material) {
            const auto& c = v->material->color;
            g.rgba = {c.r, c.g, c.b, c.a};
          }
          link.visuals.push_back(g);
        }
        for (const auto& c : ulink->collision_array) {
          if (!c || !c->geometry) continue;
          link.collisions.push_back(ToGeometry(*c->geometry, c->origin, source, link.name));
        }
        model.links.push_back(std::move(link));
        if (parent_joint >= 0) model.joints[parent_joint].child_link = link_index;

        for (const auto& ujoint : ulink->child_joints) {
          Joint joint;
          joint.name = ujoint->name;
          joint.parent_link = link_index;
          joint.X_PJ = ToIsometry(ujoint->parent_to_joint_origin_transform);
          joint.axis = Eigen::Vector3d(ujoint->axis.x, ujoint->axis.y, ujoint->axis.z);
          switch (ujoint->type) {
            case urdf::Joint::REVOLUTE: joint.type = Joint::Type::kRevolute; break;
            case urdf::Joint::CONTINUOUS: joint.type = Joint::Type::kContinuous; break;
            case urdf::Joint::PRISMATIC: joint.type = Joint::Type::kPrismatic; break;
            case urdf::Joint::FIXED: joint.type = Joint::Type::kFixed; break;
            default:
              ThrowInvalid("ParseUrdf: ", source, ": joint '", joint.name,
                           "' has an unsupported type (floating and planar joints are not "
                           "supported)");
          }
          if (joint.movable()) {
            if (!(joint.axis.norm() > 1e-9)) {
              ThrowInvalid("ParseUrdf: ", source, ": joint '", joint.name, "' has a zero axis");
            }
            joint.axis.normalize();
          }
          if (ujoint->limits) {
            joint.lower = ujoint->limits->lower;
            joint.upper = ujoint->limits->upper;
            joint.effort = ujoint->limits->effort;
            joint.velocity = ujoint->limits->velocity;
          }
          if (joint.type == Joint::Type::kContinuous) {
            joint.lower = -M_PI * 1e3;
            joint.upper = M_PI * 1e3;
          }
          if (ujoint->dynamics) {
            joint.damping = ujoint->dynamics->damping;
            joint.friction = ujoint->dynamics->friction;
          }
          const int joint_index = static_cast<int>(model.joints.size());
          model.links[link_index].child_joints.push_back(joint_index);
          if (joint.movable()) {
            joint.q_index = static_cast<int>(model.movable_joints.size());
            model.movable_joints.push_back(joint_index);
          }
          model.joints.push_back(joint);
          const urdf::LinkConstSharedPtr child = parsed->getLink(ujoint->child_link_name);
          if (!child) {
            ThrowInvalid("ParseUrdf: ", source, ": joint '", joint.name, "' names unknown child '",
                         ujoint->child_link_name, "'");
          }
          visit(child, joint_index);
        }
      };
  visit(parsed->getRoot(), -1);
  return model;
}

RobotModel LoadUrdf(const std::filesystem::path& urdf_path) {
  return ParseUrdf(ReadTextFile(urdf_path), urdf_path.string());
}

std::vector<Eigen::Isometry3d> LinkPoses(const RobotModel& model, const Eigen::VectorXd& q) {
  if (q.size() != model.num_q()) {
    ThrowInvalid("LinkPoses: q has ", q.size(), " entries, robot '", model.name, "' has ",
                 model.num_q(), " movable joints");
  }
  if (!q.allFinite()) ThrowInvalid("LinkPoses: q has a non-finite entry: ", q.transpose());
  std::vector<Eigen::Isometry3d> X_RL(model.links.size(), Eigen::Isometry3d::Identity());
  for (size_t i = 0; i < model.links.size(); ++i) {
    const int parent_joint = model.links[i].parent_joint;
    if (parent_joint < 0) continue;
    const Joint& joint = model.joints[parent_joint];
    Eigen::Isometry3d X_PC = joint.X_PJ;
    if (joint.type == Joint::Type::kRevolute || joint.type == Joint::Type::kContinuous) {
      X_PC.rotate(Eigen::AngleAxisd(q[joint.q_index], joint.axis));
    } else if (joint.type == Joint::Type::kPrismatic) {
      X_PC.translate(joint.axis * q[joint.q_index]);
    }
    X_RL[i] = X_RL[joint.parent_link] * X_PC;
  }
  return X_RL;
}

Eigen::Isometry3d LinkPose(const RobotModel& model, const Eigen::VectorXd& q,
                           std::string_view link_name) {
  const int index = model.LinkIndex(link_name);
  return LinkPoses(model, q)[index];
}

}  // namespace toolbench::robot
