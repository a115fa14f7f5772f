#include "sim/scene_composer.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <map>
#include <numbers>
#include <set>
#include <sstream>
#include <string>
#include <tuple>

#include <Eigen/Eigenvalues>

#include "common/check.h"
#include "common/geometry.h"
#include "common/rng.h"

namespace toolbench::sim {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;
constexpr double kPlacementGap = 0.002;  // clearance left between a placed tool and the rack [m]
constexpr double kRailHalfHeight = 0.01;  // the rail is 2 cm tall [m]
constexpr double kStopHeight = 0.02;      // the stop on the ledge is 2 cm tall [m]

/// Formats numbers compactly and exactly enough for MJCF (9 significant digits).
std::string Num(double v) {
  if (std::abs(v) < 1e-12) v = 0.0;
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "%.9g", v);
  return buffer;
}

template <typename Derived>
std::string Vec(const Eigen::MatrixBase<Derived>& v) {
  std::string out;
  for (Eigen::Index i = 0; i < v.size(); ++i) {
    if (i) out += ' ';
    out += Num(v[i]);
  }
  return out;
}

/// MuJoCo quaternion (w x y z) of a rotation matrix.
std::string Quat(const Eigen::Matrix3d& R) {
  Eigen::Quaterniond q(R);
  q.normalize();
  if (q.w() < 0) q.coeffs() *= -1.0;
  return Vec(Eigen::Vector4d(q.w(), q.x(), q.y(), q.z()));
}

std::string PoseAttributes(const Eigen::Isometry3d& X) {
  return " pos=\"" + Vec(X.translation()) + "\" quat=\"" + Quat(X.linear()) + "\"";
}

/// Escapes a string for an XML attribute.
std::string Xml(std::string_view s) {
  std::string out;
  for (char c : s) {
    switch (c) {
      case '&': out += "&amp;"; break;
      case '"': out += "&quot;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      default: out += c;
    }
  }
  return out;
}

/// Largest value of d . p over the tool's collision parts and visual mesh, in a frame where the
/// tool frame has rotation R (d in that frame).
double Support(const toollib::ToolModel& tool, const Eigen::Matrix3d& R, const Eigen::Vector3d& d) {
  double best = -std::numeric_limits<double>::infinity();
  const Eigen::Vector3d d_T = R.transpose() * d;  // direction in the tool frame
  for (const auto& part : tool.collision) {
    const Eigen::Vector3d c = part.X_TP.translation();
    const Eigen::Matrix3d& A = part.X_TP.linear();
    const double center = c.dot(d_T);
    const double along = std::abs(A.col(2).dot(d_T));
    double extent = 0.0;
    using Type = toollib::CollisionPart::Type;
    switch (part.type) {
      case Type::kBox:
        extent = part.size.x() * std::abs(A.col(0).dot(d_T)) +
                 part.size.y() * std::abs(A.col(1).dot(d_T)) + part.size.z() * along;
        break;
      case Type::kCylinder:
        extent = part.size.y() * along +
                 part.size.x() * std::sqrt(std::max(0.0, 1.0 - along * along));
        break;
      case Type::kCapsule: extent = part.size.y() * along + part.size.x(); break;
      case Type::kSphere: extent = part.size.x(); break;
      case Type::kMesh: extent = 0.0; break;  // covered by the visual mesh below
    }
    best = std::max(best, center + extent);
  }
  for (Eigen::Index i = 0; i < tool.mesh.vertices.cols(); ++i) {
    best = std::max(best, tool.mesh.vertices.col(i).dot(d_T));
  }
  return best;
}

/// A distinct, saturated colour per tool (segmentation needs tools to stand out of the rack).
/// No red: the ball is red, and a red tool lying against it would hide it from DetectBall's
/// colour test.
Eigen::Vector4d ToolColour(size_t index) {
  static const double kPalette[][3] = {{0.85, 0.20, 0.65}, {0.15, 0.45, 0.85}, {0.95, 0.70, 0.10},
                                       {0.20, 0.70, 0.30}, {0.60, 0.25, 0.75}, {0.95, 0.45, 0.10}};
  const auto& c = kPalette[index % 6];
  return {c[0], c[1], c[2], 1.0};
}

class MjcfWriter {
 public:
  MjcfWriter(const SceneSpec& spec, const robot::RobotDescription& robot)
      : spec_(spec), robot_(robot) {}

  std::ostringstream& out() { return out_; }

  void Line(int indent, const std::string& text) {
    out_ << std::string(static_cast<size_t>(indent) * 2, ' ') << text << '\n';
  }

  std::string RobotGeom(const robot::Geometry& g, bool visual, const std::string& link,
                        int index) {
    std::string type;
    std::string size;
    switch (g.type) {
      case robot::Geometry::Type::kBox:
        type = "box";
        size = Vec(g.size / 2.0);
        break;
      case robot::Geometry::Type::kCylinder:
        type = "cylinder";
        size = Num(g.size.x()) + " " + Num(g.size.y() / 2.0);
        break;
      case robot::Geometry::Type::kSphere:
        type = "sphere";
        size = Num(g.size.x());
        break;
      case robot::Geometry::Type::kMesh:
        ThrowInvalid("ComposeScene: robot '", robot_.urdf_path.string(), "' link '", link,
                     "' uses a mesh ('", g.mesh_file,
                     "'); the composer supports box, cylinder and sphere geometry only");
    }
    std::string name = link + (visual ? "/visual" : "/collision") + std::to_string(index);
    std::string attrs = "<geom name=\"" + Xml(name) + "\" class=\"" +
                        (visual ? "robot_visual" : "robot_collision") + "\" type=\"" + type +
                        "\" size=\"" + size + "\"" + PoseAttributes(g.X_LG);
    if (visual) attrs += " rgba=\"" + Vec(g.rgba) + "\"";
    return attrs + "/>";
  }

  void RobotBody(int link_index, int indent) {
    const robot::RobotModel& model = robot_.model;
    const robot::Link& link = model.links[link_index];
    for (size_t i = 0; i < link.visuals.size(); ++i) {
      Line(indent, RobotGeom(link.visuals[i], true, link.name, static_cast<int>(i)));
    }
    for (size_t i = 0; i < link.collisions.size(); ++i) {
      Line(indent, RobotGeom(link.collisions[i], false, link.name, static_cast<int>(i)));
    }
    if (link.name == robot_.camera_frame) {
      // The link frame is the OpenCV optical frame; a MuJoCo camera looks along -z with +y up,
      // i.e. the OpenCV frame turned by 180 deg about x.
      Line(indent, "<camera name=\"helmet\" pos=\"0 0 0\" quat=\"0 1 0 0\" fovy=\"" +
                       Num(robot_.camera.fovy_deg) + "\"/>");
    }
    Line(indent, "<site name=\"" + Xml(link.name) + "\" class=\"frame\"/>");
    for (int j : link.child_joints) {
      const robot::Joint& joint = model.joints[j];
      const robot::Link& child = model.links[joint.child_link];
      Line(indent, "<body name=\"" + Xml(child.name) + "\"" + PoseAttributes(joint.X_PJ) + ">");
      if (child.inertial.mass > 0.0) Line(indent + 1, Inertial(child.inertial));
      if (joint.movable()) {
        const auto& act = robot_.actuators.at(joint.name);
        std::string type = joint.type == robot::Joint::Type::kPrismatic ? "slide" : "hinge";
        std::string attrs = "<joint name=\"" + Xml(joint.name) + "\" type=\"" + type +
                            "\" axis=\"" + Vec(joint.axis) + "\" damping=\"" +
                            Num(joint.damping) + "\" armature=\"" + Num(act.armature) + "\"";
        if (joint.friction > 0) attrs += " frictionloss=\"" + Num(joint.friction) + "\"";
        if (joint.type != robot::Joint::Type::kContinuous) {
          attrs += " range=\"" + Num(joint.lower) + " " + Num(joint.upper) + "\"";
        }
        Line(indent + 1, attrs + "/>");
      }
      RobotBody(joint.child_link, indent + 1);
      Line(indent, "</body>");
    }
  }

  static std::string Inertial(const robot::Inertial& inertial) {
    // MuJoCo wants principal axes: rotate the inertia into the link frame, then diagonalise.
    const Eigen::Matrix3d I_L =
        inertial.X_LI.linear() * inertial.inertia * inertial.X_LI.linear().transpose();
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(I_L);
    Eigen::Matrix3d axes = eig.eigenvectors();
    if (axes.determinant() < 0) axes.col(2) *= -1.0;
    return "<inertial pos=\"" + Vec(inertial.X_LI.translation()) + "\" quat=\"" + Quat(axes) +
           "\" mass=\"" + Num(inertial.mass) + "\" diaginertia=\"" +
           Vec(eig.eigenvalues().cwiseMax(1e-9)) + "\"/>";
  }

 private:
  const SceneSpec& spec_;
  const robot::RobotDescription& robot_;
  std::ostringstream out_;
};

std::string PartGeom(const toollib::CollisionPart& part, const std::string& name,
                     const std::string& mesh_asset) {
  using Type = toollib::CollisionPart::Type;
  std::string type;
  std::string size;
  switch (part.type) {
    case Type::kBox: type = "box"; size = Vec(part.size); break;
    case Type::kCylinder:
      // MuJoCo 2.2.2 collides cylinders through the general convex solver, one contact point at a
      // time, so a round handle lying on the rack rocks forever. A capsule of the same length
      // (half-length shortened by the radius) gets analytic multi-point contacts and rests.
      if (part.size.y() > part.size.x()) {
        type = "capsule";
        size = Num(part.size.x()) + " " + Num(part.size.y() - part.size.x());
      } else {
        type = "cylinder";
        size = Num(part.size.x()) + " " + Num(part.size.y());
      }
      break;
    case Type::kCapsule: type = "capsule"; size = Num(part.size.x()) + " " + Num(part.size.y()); break;
    case Type::kSphere: type = "sphere"; size = Num(part.size.x()); break;
    case Type::kMesh: type = "mesh"; break;
  }
  std::string attrs = "<geom name=\"" + Xml(name) + "\" class=\"tool_collision\" type=\"" + type + "\"";
  if (part.type == Type::kMesh) {
    attrs += " mesh=\"" + Xml(mesh_asset) + "\"";
  } else {
    attrs += " size=\"" + size + "\"";
  }
  return attrs + PoseAttributes(part.X_TP) + " mass=\"" + Num(part.mass) + "\"/>";
}

}  // namespace

bool IsCellName(std::string_view cell) {
  return std::find(std::begin(kCellNames), std::end(kCellNames), cell) != std::end(kCellNames) ||
         std::find(std::begin(kExtendedCellNames), std::end(kExtendedCellNames), cell) !=
             std::end(kExtendedCellNames);
}

Eigen::Isometry3d LookAtFrame(const Eigen::Vector3d& p_eye, const Eigen::Vector3d& p_target) {
  const Eigen::Vector3d z = (p_target - p_eye).normalized();      // optical axis
  const Eigen::Vector3d x = z.cross(Eigen::Vector3d::UnitZ()).normalized();  // image right
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.linear().col(0) = x;
  X.linear().col(1) = z.cross(x);  // image down
  X.linear().col(2) = z;
  X.translation() = p_eye;
  return X;
}

Eigen::Isometry3d RackPose(const RackSpec& rack) {
  // K axes in R: x_K = -x_R (robot forward); z_K up the board, tilted away from the robot (+y_R);
  // y_K = z_K x x_K is the board normal toward the robot.
  const double t = rack.incline_deg * kDeg;
  Eigen::Matrix3d R;
  R.col(0) = Eigen::Vector3d(-1, 0, 0);
  R.col(2) = Eigen::Vector3d(0, std::sin(t), std::cos(t));
  R.col(1) = R.col(2).cross(R.col(0));
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.linear() = AxisAngle(Eigen::Vector3d::UnitZ(), rack.yaw_deg * kDeg) * R;
  X.translation() = rack.origin;
  return X;
}

Eigen::Isometry3d CellPose(const RackSpec& rack, std::string_view cell) {
  if (!IsCellName(cell)) {
    ThrowInvalid("CellPose: unknown cell '", cell,
                 "' (known: pos1 pos2 pos3 rot0 rot1 rot2 rot3, and pos<1-3>_rot<0-3>)");
  }
  // A cell is a place and a rotation: "posN" (rot0), "rotN" (pos2) or "posN_rotM".
  const std::string_view place = cell.substr(0, 3) == "pos" ? cell.substr(0, 4) : "pos2";
  const std::string_view rotation = cell.substr(0, 3) == "rot" ? cell : cell.size() > 5 ? cell.substr(5) : "rot0";
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  double slot = rack.slot_pos2;
  if (place == "pos1") slot = rack.slot_pos1;
  if (place == "pos3") slot = rack.slot_pos3;
  X.translation() = Eigen::Vector3d(slot, 0, 0);
  // rot0 / posN: tool axis z_T up the board (z_K), effector x_T along the rack (x_K).
  const Eigen::Vector3d z_K = Eigen::Vector3d::UnitZ();
  const Eigen::Vector3d y_K = Eigen::Vector3d::UnitY();  // rack normal, toward the robot
  if (rotation == "rot1") X.linear() = AxisAngle(z_K, std::numbers::pi / 2);   // effector -> robot
  if (rotation == "rot2") X.linear() = AxisAngle(y_K, std::numbers::pi);       // upside down
  if (rotation == "rot3") X.linear() = AxisAngle(y_K, -std::numbers::pi / 2);  // across, effector up
  return X;
}

ScenePlan PlanScene(const SceneSpec& spec, const std::vector<std::string>& library_names,
                    std::uint64_t seed, const std::vector<ToolPlacement>& requested) {
  const std::set<std::string> known(library_names.begin(), library_names.end());
  ScenePlan plan;
  plan.seed = seed;
  Rng ball_rng(DeriveSeed(seed, "ball"));
  plan.ball_xy = {UniformReal(ball_rng, spec.ball.x_range[0], spec.ball.x_range[1]),
                  UniformReal(ball_rng, spec.ball.y_range[0], spec.ball.y_range[1])};

  auto require_tool = [&](const std::string& name) {
    if (!known.count(name)) {
      std::string names;
      for (const auto& n : library_names) names += (names.empty() ? "" : ", ") + n;
      ThrowInvalid("PlanScene: unknown tool '", name, "' (library: ", names, ")");
    }
  };

  if (!requested.empty()) {
    std::set<std::string> places;
    for (const ToolPlacement& p : requested) {
      require_tool(p.tool);
      if (!IsCellName(p.cell)) {
        ThrowInvalid("PlanScene: unknown cell '", p.cell,
                     "' for tool '", p.tool, "' (known: pos1 pos2 pos3 rot0 rot1 rot2 rot3, pos<1-3>_rot<0-3>)");
      }
      const std::string place = p.cell.rfind("pos", 0) == 0 ? p.cell.substr(0, 4) : "pos2";
      if (!places.insert(place).second) {
        ThrowInvalid("PlanScene: two tools requested at place '", place,
                     "' (rot0..rot3 all use the central place pos2)");
      }
    }
    if (requested.size() > 3) ThrowInvalid("PlanScene: at most 3 tools fit the rack, got ", requested.size());
    plan.tools = requested;
    return plan;
  }

  std::vector<std::string> pool = spec.tools.choices.empty() ? library_names : spec.tools.choices;
  for (const auto& name : pool) require_tool(name);
  std::sort(pool.begin(), pool.end());
  if (pool.empty()) ThrowInvalid("PlanScene: the tool library is empty");
  Rng rng(DeriveSeed(seed, "tools"));
  const int count =
      std::min<int>(UniformInt(rng, spec.tools.min_count, spec.tools.max_count), pool.size());
  // Partial Fisher-Yates with our portable integer draw.
  for (int i = 0; i < count; ++i) {
    std::swap(pool[i], pool[UniformInt(rng, i, static_cast<int>(pool.size()) - 1)]);
  }
  std::vector<std::string> places = {"pos1", "pos2", "pos3"};
  for (int i = 0; i < 3; ++i) std::swap(places[i], places[UniformInt(rng, i, 2)]);
  for (int i = 0; i < count; ++i) {
    ToolPlacement p;
    p.tool = pool[i];
    // Upright (pos), effector toward the robot (rot1) or upside down (rot2); a single tool may
    // also lie across the rack (rot3).
    const int pose = UniformInt(rng, 0, count == 1 ? 3 : 2);
    if (pose == 0) {
      p.cell = places[i];
    } else {
      p.cell = "rot" + std::to_string(pose);
    }
    p.offset = UniformReal(rng, -0.01, 0.01);
    p.spin = pose == 0 || pose == 2 ? UniformReal(rng, 0.0, 25.0 * kDeg) : 0.0;
    if (pose == 1 || pose == 2) {
      // rotN cells sit at the central place; move the tool to its drawn place instead.
      const RackSpec& rack = spec.rack;
      const double slot = places[i] == "pos1" ? rack.slot_pos1
                          : places[i] == "pos3" ? rack.slot_pos3 : rack.slot_pos2;
      p.offset += slot - rack.slot_pos2;
    }
    plan.tools.push_back(p);
  }
  return plan;
}

namespace {

/// A fixture box in the frame of the body that carries it ("table" or "rack").
struct LocalBox {
  std::string name;
  std::string body;
  Eigen::Isometry3d X_bodyB = Eigen::Isometry3d::Identity();
  Eigen::Vector3d half = Eigen::Vector3d::Zero();
  bool rotated = false;  // X_bodyB has a rotation (written as quat)
};

/// The table body: at the centre of its top, axes of the world.
Eigen::Isometry3d TableBodyPose(const SceneSpec& spec, const Eigen::Isometry3d& X_WR) {
  const TableSpec& table = spec.table;
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.translation() = X_WR * Eigen::Vector3d(table.center.x(), table.center.y(), table.top_z - table.thickness / 2);
  return X;
}

/// Table (top, four legs to the floor) and rack (board y_K <= 0, ledge z_K <= 0, lip, rail and
/// stop, two posts to the floor) as boxes in their bodies.
std::vector<LocalBox> FixtureBoxesLocal(const SceneSpec& spec, const Eigen::Isometry3d& X_WR) {
  std::vector<LocalBox> boxes;
  auto add = [&](std::string name, const char* body, const Eigen::Vector3d& center, const Eigen::Vector3d& half,
                 const Eigen::Matrix3d* rotation = nullptr) {
    LocalBox b;
    b.name = std::move(name);
    b.body = body;
    b.X_bodyB.translation() = center;
    if (rotation) b.X_bodyB.linear() = *rotation;
    b.half = half;
    b.rotated = rotation != nullptr;
    boxes.push_back(std::move(b));
  };
  const TableSpec& table = spec.table;
  const double table_top_W = TableBodyPose(spec, X_WR).translation().z();
  add("table_top", "table", Eigen::Vector3d::Zero(),
      Eigen::Vector3d(table.size.x() / 2, table.size.y() / 2, table.thickness / 2));
  const double leg_length = std::max(0.05, table_top_W - table.thickness / 2);
  for (int i = 0; i < 4; ++i) {
    const double sx = (i & 1) ? 1 : -1;
    const double sy = (i & 2) ? 1 : -1;
    add("table_leg" + std::to_string(i), "table",
        Eigen::Vector3d(sx * (table.size.x() / 2 - 0.03), sy * (table.size.y() / 2 - 0.03),
                        -table.thickness / 2 - leg_length / 2),
        Eigen::Vector3d(0.02, 0.02, leg_length / 2));
  }
  const RackSpec& rack = spec.rack;
  const double board_t = 0.02;
  add("rack_board", "rack", Eigen::Vector3d(0, -board_t / 2, rack.height / 2 - 0.03),
      Eigen::Vector3d(rack.width / 2, board_t / 2, rack.height / 2));
  add("rack_ledge", "rack", Eigen::Vector3d(0, rack.ledge_depth / 2 - board_t / 2, -0.01),
      Eigen::Vector3d(rack.width / 2, rack.ledge_depth / 2 + board_t / 2, 0.01));
  if (rack.lip_height > 0) {
    add("rack_lip", "rack", Eigen::Vector3d(0, rack.ledge_depth + 0.005, rack.lip_height / 2 - 0.01),
        Eigen::Vector3d(rack.width / 2, 0.005, rack.lip_height / 2 + 0.01));
  }
  if (rack.standoff > 0) {
    add("rack_rail", "rack", Eigen::Vector3d(0, rack.standoff / 2, rack.rail_height),
        Eigen::Vector3d(rack.width / 2, rack.standoff / 2, kRailHalfHeight));
    add("rack_stop", "rack", Eigen::Vector3d(0, rack.standoff / 2, kStopHeight / 2),
        Eigen::Vector3d(rack.width / 2, rack.standoff / 2, kStopHeight / 2));
  }
  // Posts: vertical in the world, from the ledge down to the floor, behind the board.
  const Eigen::Isometry3d X_WK = X_WR * RackPose(rack);
  const double ledge_height_W = X_WK.translation().z();
  const Eigen::Matrix3d R_KW = X_WK.linear().transpose();
  for (int side = -1; side <= 1; side += 2) {
    const Eigen::Vector3d foot_K(side * (rack.width / 2 - 0.03), -board_t - 0.02, -0.02);
    const double length = ledge_height_W - 0.02;
    const Eigen::Vector3d center_K = foot_K + R_KW * Eigen::Vector3d(0, 0, -length / 2);
    add("rack_post" + std::to_string(side > 0), "rack", center_K, Eigen::Vector3d(0.02, 0.02, length / 2), &R_KW);
  }
  return boxes;
}

/// Colour and contact attributes of a fixture geom. The rack is covered with rubber (high
/// friction): tools rest on it by friction alone. The table top resists rolling (condim 6; a pair's
/// rolling friction is the larger of its geoms', so the tools' 0.002 m and the ball's 0.0005 m):
/// with condim 4 a round stick put down on it rolled on across it and swept the ball off its far
/// edge (episode 28 of `bench --protocol random --episodes 50 --seed 1`).
std::string FixtureStyle(const std::string& name) {
  const std::string rubber = " friction=\"1.5 0.02 0.001\" condim=\"6\"";
  if (name == "table_top") return " rgba=\"0.62 0.45 0.30 1\" condim=\"6\"";
  if (name.rfind("table_leg", 0) == 0) return " rgba=\"0.45 0.32 0.2 1\"";
  if (name == "rack_board") return " rgba=\"0.82 0.82 0.80 1\"" + rubber;
  if (name == "rack_ledge") return " rgba=\"0.70 0.70 0.68 1\"" + rubber;
  if (name == "rack_lip") return " rgba=\"0.70 0.70 0.68 1\"";
  if (name == "rack_rail" || name == "rack_stop") return " rgba=\"0.55 0.55 0.53 1\"" + rubber;
  return " rgba=\"0.3 0.3 0.3 1\"";  // posts
}

}  // namespace

std::vector<FixtureBox> FixtureBoxes(const SceneSpec& spec) {
  spec.Validate();
  Eigen::Isometry3d X_WR = Eigen::Isometry3d::Identity();
  X_WR.translation() = spec.robot_base;
  const Eigen::Isometry3d X_RW = X_WR.inverse();
  const Eigen::Isometry3d X_R_table = X_RW * TableBodyPose(spec, X_WR);
  const Eigen::Isometry3d X_RK = RackPose(spec.rack);
  std::vector<FixtureBox> out;
  for (const LocalBox& b : FixtureBoxesLocal(spec, X_WR)) {
    out.push_back({b.name, (b.body == "table" ? X_R_table : X_RK) * b.X_bodyB, b.half});
  }
  return out;
}

ComposedScene ComposeScene(const SceneSpec& spec, const robot::RobotDescription& robot,
                           const std::vector<toollib::ToolModel>& library, const ScenePlan& plan) {
  spec.Validate();
  ComposedScene scene;
  scene.plan = plan;
  scene.X_WR.translation() = spec.robot_base;
  scene.X_RK = RackPose(spec.rack);
  const Eigen::Isometry3d X_WK = scene.X_WR * scene.X_RK;

  std::map<std::string, const toollib::ToolModel*> by_name;
  for (const auto& tool : library) by_name[tool.name] = &tool;

  MjcfWriter w(spec, robot);
  w.Line(0, "<mujoco model=\"toolbench_" + Xml(spec.name) + "\">");
  w.Line(1, "<!-- Composed by toolbench from scene '" + Xml(spec.name) + "', seed " +
                std::to_string(plan.seed) + "; robot from " + Xml(robot.urdf_path.string()) +
                ". Frames: world W; robot root R at robot_base (x back, y right, z up). -->");
  w.Line(1, "<compiler angle=\"radian\" autolimits=\"true\" inertiafromgeom=\"auto\"/>");
  w.Line(1, "<option timestep=\"" + Num(spec.physics.timestep) + "\" cone=\"" +
                spec.physics.cone + "\" impratio=\"" + Num(spec.physics.impratio) +
                "\" noslip_iterations=\"" + std::to_string(spec.physics.noslip_iterations) +
                "\" noslip_tolerance=\"" + Num(spec.physics.noslip_tolerance) +
                "\" solver=\"" + spec.physics.solver + "\" jacobian=\"" + spec.physics.jacobian +
                "\" tolerance=\"" + Num(spec.physics.tolerance) +
                "\" iterations=\"" + std::to_string(spec.physics.iterations) +
                "\" integrator=\"Euler\"/>");
  w.Line(1, "<size njmax=\"" + std::to_string(spec.physics.max_constraint_rows) + "\" nconmax=\"" +
                std::to_string(spec.physics.max_contacts) + "\"/>");
  // Read by sim::World (SleepSettings, PhysicsSpec::noslip_scope); other MuJoCo programs ignore
  // them and run plain physics (the noslip pass at every step).
  const bool noslip_on_demand = spec.physics.noslip_scope == "resting" && spec.physics.noslip_iterations > 0;
  if (spec.physics.sleep_window > 0 || noslip_on_demand) {
    w.Line(1, "<custom>");
    if (spec.physics.sleep_window > 0) {
      w.Line(2, "<numeric name=\"toolbench_sleep\" data=\"" + Num(spec.physics.sleep_window) + " " +
                    Num(spec.physics.sleep_tolerance) + " " + Num(spec.physics.wake_margin) + "\"/>");
    }
    if (noslip_on_demand) w.Line(2, "<text name=\"toolbench_noslip_fixtures\" data=\"rack_\"/>");
    w.Line(1, "</custom>");
  }
  // Pinned extent: znear/zfar scale with it (measured.md C.2 #5), so the depth conversion must not
  // change with the tools on the rack.
  w.Line(1, "<statistic extent=\"1\" center=\"-0.3 0.2 0.6\"/>");
  w.Line(1, "<visual>");
  w.Line(2, "<global offwidth=\"" + std::to_string(robot.camera.width) + "\" offheight=\"" +
                std::to_string(robot.camera.height) + "\"/>");
  w.Line(2, "<quality offsamples=\"0\" shadowsize=\"2048\"/>");
  w.Line(2, "<map znear=\"0.01\" zfar=\"50\"/>");
  w.Line(2, "<headlight ambient=\"0.35 0.35 0.35\" diffuse=\"0.45 0.45 0.45\" specular=\"0.1 0.1 0.1\"/>");
  w.Line(1, "</visual>");

  w.Line(1, "<default>");
  w.Line(2, "<default class=\"robot_visual\"><geom contype=\"0\" conaffinity=\"0\" group=\"1\" density=\"0\"/></default>");
  // The robot's contact impedance: MuJoCo's default, or stiffer so that a held tool does not
  // creep without the noslip pass (PhysicsSpec::robot_solimp).
  w.Line(2, "<default class=\"robot_collision\"><geom contype=\"1\" conaffinity=\"0\" group=\"3\" density=\"0\" condim=\"4\" friction=\"1.2 0.01 0.001\" solimp=\"" +
                Vec(spec.physics.robot_solimp) + "\" solmix=\"" + Num(spec.physics.robot_solmix) + "\" rgba=\"0.4 0.6 0.9 0.5\"/></default>");
  w.Line(2, "<default class=\"world\"><geom contype=\"1\" conaffinity=\"1\" group=\"0\" friction=\"0.8 0.005 0.0001\"/></default>");
  w.Line(2, "<default class=\"tool_visual\"><geom contype=\"0\" conaffinity=\"0\" group=\"0\" density=\"0\"/></default>");
  // Tools: sliding and torsional friction (condim 4), no rolling friction of their own; the
  // rubber-covered rack adds it (condim 6 on its geoms, the larger condim of a pair wins). The
  // noslip pass costs about the square of the friction rows, and tools resting on the rack and
  // fingers on a handle make most of them. Episode seed 3 stepped, with 30 noslip iterations at
  // every step, at ~680 us with condim 6 everywhere, ~450 us like this, ~330 us with condim 4 on
  // the rack too, but then spatula_3 crept down the rack at 0.55 mm/s
  // (WorldTest.ToolsAndBallStayPutAtRest). pull-gt and grasp-gt kept their success (session-7 note).
  w.Line(2, "<default class=\"tool_collision\"><geom contype=\"1\" conaffinity=\"1\" group=\"3\" condim=\"4\" friction=\"1.0 0.01 0.002\" rgba=\"0.9 0.6 0.2 0.5\"/></default>");
  w.Line(2, "<default class=\"frame\"><site size=\"0.005\" group=\"5\" rgba=\"1 0 0 1\"/></default>");
  w.Line(1, "</default>");

  // Assets: one visual mesh per placed tool, plus convex mesh parts when a tool has them.
  std::vector<const toollib::ToolModel*> tools;
  for (const ToolPlacement& p : plan.tools) {
    auto it = by_name.find(p.tool);
    if (it == by_name.end()) ThrowInvalid("ComposeScene: tool '", p.tool, "' is not in the library");
    tools.push_back(it->second);
  }
  w.Line(1, "<asset>");
  w.Line(2, "<texture name=\"floor\" type=\"2d\" builtin=\"checker\" rgb1=\"0.55 0.55 0.52\" rgb2=\"0.45 0.45 0.43\" width=\"256\" height=\"256\"/>");
  w.Line(2, "<material name=\"floor\" texture=\"floor\" texrepeat=\"8 8\"/>");
  for (const auto* tool : tools) {
    w.Line(2, "<mesh name=\"mesh/" + Xml(tool->name) + "\" file=\"" +
                  Xml(std::filesystem::absolute(tool->mesh_file).string()) + "\"/>");
    for (size_t i = 0; i < tool->collision.size(); ++i) {
      const auto& part = tool->collision[i];
      if (part.type != toollib::CollisionPart::Type::kMesh) continue;
      const std::filesystem::path file = part.mesh_file.empty()
                                             ? tool->mesh_file
                                             : tool->mesh_file.parent_path() / part.mesh_file;
      w.Line(2, "<mesh name=\"part/" + Xml(tool->name) + "/" + std::to_string(i) + "\" file=\"" +
                    Xml(std::filesystem::absolute(file).string()) + "\"/>");
    }
  }
  w.Line(1, "</asset>");

  w.Line(1, "<worldbody>");
  w.Line(2, "<light name=\"sun\" directional=\"true\" castshadow=\"true\" pos=\"0 0 3\" dir=\"0.3 0.2 -1\" diffuse=\"0.5 0.5 0.5\"/>");
  w.Line(2, "<geom name=\"floor\" class=\"world\" type=\"plane\" size=\"3 3 0.1\" material=\"floor\"/>");

  // Fixed cameras for looking at what happens (never for perception). "overview": in front of
  // the robot, to its right, looking at robot, table and rack. "side": on the robot's left,
  // looking across the table at the ball and the working tool (pictures of the tool actions).
  // "rack_close": from the robot's left end of the rack's ledge, looking along it at the hand on
  // a handle (the handle's cross-section, the fingers, the ledge and the board).
  const Eigen::Vector3d& p_R_rack = spec.rack.origin;
  const std::vector<std::tuple<const char*, Eigen::Isometry3d, int>> cameras = {
      {"overview", LookAtFrame(Eigen::Vector3d(-1.15, -0.45, 0.60), Eigen::Vector3d(-0.20, 0.20, -0.05)), 50},
      {"side", LookAtFrame(Eigen::Vector3d(-0.40, -1.25, 0.05), Eigen::Vector3d(-0.40, 0.0, -0.10)), 50},
      {"rack_close",
       LookAtFrame(p_R_rack + Eigen::Vector3d(-0.28, -0.17, 0.08), p_R_rack + Eigen::Vector3d(0.02, -0.09, 0.06)), 40},
  };
  for (const auto& [name, X_RC, fovy_deg] : cameras) {
    scene.X_R_fixed_cameras[name] = X_RC;
    const Eigen::Isometry3d X_WC = scene.X_WR * X_RC;
    // MuJoCo cameras look along -z with +y up: the OpenCV frame turned 180 deg about x.
    w.Line(2, std::string("<camera name=\"") + name + "\" pos=\"" + Vec(X_WC.translation()) + "\" xyaxes=\"" +
                  Vec(X_WC.linear().col(0)) + " " + Vec(-X_WC.linear().col(1)) + "\" fovy=\"" +
                  std::to_string(fovy_deg) + "\"/>");
  }

  // Table and rack: the fixture boxes, in their bodies (one definition, shared with FixtureBoxes).
  const TableSpec& table = spec.table;
  const RackSpec& rack = spec.rack;
  const std::vector<LocalBox> fixtures = FixtureBoxesLocal(spec, scene.X_WR);
  for (const char* body : {"table", "rack"}) {
    const bool table = std::string_view(body) == "table";
    const Eigen::Isometry3d X_WBody = table ? TableBodyPose(spec, scene.X_WR) : X_WK;
    w.Line(2, "<body name=\"" + std::string(body) + "\"" +
                  (table ? " pos=\"" + Vec(X_WBody.translation()) + "\"" : PoseAttributes(X_WBody)) + ">");
    for (const LocalBox& box : fixtures) {
      if (box.body != body) continue;
      w.Line(3, "<geom name=\"" + box.name + "\" class=\"world\" type=\"box\" size=\"" + Vec(box.half) +
                    "\" pos=\"" + Vec(box.X_bodyB.translation()) + "\"" +
                    (box.rotated ? " quat=\"" + Quat(box.X_bodyB.linear()) + "\"" : std::string()) +
                    FixtureStyle(box.name) + "/>");
    }
    w.Line(2, "</body>");
  }

  // Robot: root link fixed in the world.
  w.Line(2, "<body name=\"" + Xml(robot.model.links[0].name) + "\"" + PoseAttributes(scene.X_WR) + ">");
  if (robot.model.links[0].inertial.mass > 0) {
    w.Line(3, MjcfWriter::Inertial(robot.model.links[0].inertial));
  }
  w.RobotBody(0, 3);
  w.Line(2, "</body>");

  // Tools, resting on the ledge against the board.
  std::vector<std::pair<double, double>> occupied;  // x_K intervals
  for (size_t i = 0; i < tools.size(); ++i) {
    const toollib::ToolModel& tool = *tools[i];
    const ToolPlacement& p = plan.tools[i];
    Eigen::Isometry3d X_KT = CellPose(rack, p.cell);
    X_KT.linear() = X_KT.linear() * AxisAngle(Eigen::Vector3d::UnitZ(), p.spin);
    const Eigen::Matrix3d& R = X_KT.linear();
    const double min_x = -Support(tool, R, -Eigen::Vector3d::UnitX());
    const double max_x = Support(tool, R, Eigen::Vector3d::UnitX());
    const double min_z = -Support(tool, R, -Eigen::Vector3d::UnitZ());
    // Distance from the board: where the tool passes the rail or the ledge stop it must clear
    // their front face (standoff), elsewhere the board itself (y_K = 0).
    const double z_shift = kPlacementGap - min_z;
    double y_shift = -std::numeric_limits<double>::infinity();
    for (Eigen::Index v = 0; v < tool.mesh.vertices.cols(); ++v) {
      const Eigen::Vector3d p = R * tool.mesh.vertices.col(v);
      const double z = p.z() + z_shift;
      const bool at_rail = std::abs(z - rack.rail_height) < kRailHalfHeight + 0.005;
      const bool at_stop = z < kStopHeight + 0.005;
      y_shift = std::max(y_shift, ((at_rail || at_stop) ? rack.standoff : 0.0) - p.y());
    }
    y_shift = std::max(y_shift, Support(tool, R, -Eigen::Vector3d::UnitY()));  // parts clear the board
    double x = X_KT.translation().x() + p.offset - (min_x + max_x) / 2;
    // A long tool lying across at an end place (pos1_rot3, pos3_rot3) would overhang the rack:
    // it goes as far toward that end as the rack allows.
    const double half = rack.width / 2 + 0.05;
    if (max_x - min_x <= 2 * half) x = std::clamp(x, -half - min_x, half - max_x);
    // Keep tools apart: push this one out of any interval already taken, away from the centre.
    for (const auto& [lo, hi] : occupied) {
      if (x + max_x > lo - 0.01 && x + min_x < hi + 0.01) {
        x = (x + (min_x + max_x) / 2 >= (lo + hi) / 2) ? hi + 0.01 - min_x : lo - 0.01 - max_x;
      }
    }
    if (x + min_x < -rack.width / 2 - 0.05 || x + max_x > rack.width / 2 + 0.05) {
      ThrowInvalid("ComposeScene: tool '", tool.name, "' in cell '", p.cell,
                   "' does not fit on the rack beside the other tools");
    }
    occupied.emplace_back(x + min_x, x + max_x);
    X_KT.translation() = Eigen::Vector3d(x, kPlacementGap + y_shift, z_shift);

    PlacedTool placed;
    placed.name = tool.name;
    placed.cell = p.cell;
    placed.body = "tool/" + tool.name;
    placed.X_RT = scene.X_RK * X_KT;
    const Eigen::Isometry3d X_WT = scene.X_WR * placed.X_RT;
    w.Line(2, "<body name=\"" + Xml(placed.body) + "\"" + PoseAttributes(X_WT) + ">");
    w.Line(3, "<freejoint name=\"" + Xml(placed.body) + "\"/>");
    w.Line(3, "<geom name=\"" + Xml(placed.body) + "/visual\" class=\"tool_visual\" type=\"mesh\" mesh=\"mesh/" +
                  Xml(tool.name) + "\" rgba=\"" + Vec(ToolColour(i)) + "\"/>");
    for (size_t k = 0; k < tool.collision.size(); ++k) {
      w.Line(3, PartGeom(tool.collision[k], placed.body + "/part" + std::to_string(k),
                         "part/" + tool.name + "/" + std::to_string(k)));
    }
    w.Line(2, "</body>");
    scene.tools.push_back(placed);
  }

  // Ball on the table.
  const Eigen::Vector3d p_R_ball(plan.ball_xy.x(), plan.ball_xy.y(),
                                 table.top_z + spec.ball.radius + 0.0005);
  w.Line(2, "<body name=\"ball\" pos=\"" + Vec(scene.X_WR * p_R_ball) + "\">");
  w.Line(3, "<freejoint name=\"ball\"/>");
  w.Line(3, "<geom name=\"ball\" type=\"sphere\" size=\"" + Num(spec.ball.radius) +
                "\" mass=\"" + Num(spec.ball.mass) +
                "\" rgba=\"0.9 0.1 0.1 1\" condim=\"6\" friction=\"0.8 0.005 0.0005\"/>");
  w.Line(2, "</body>");
  w.Line(1, "</worldbody>");

  // One position servo per movable robot joint; targets within the joint limits.
  w.Line(1, "<actuator>");
  for (int j : robot.model.movable_joints) {
    const robot::Joint& joint = robot.model.joints[j];
    std::string attrs = "<position name=\"" + Xml(joint.name) + "\" joint=\"" + Xml(joint.name) +
                        "\" kp=\"" + Num(robot.actuators.at(joint.name).kp) + "\"";
    if (joint.type != robot::Joint::Type::kContinuous) {
      attrs += " ctrlrange=\"" + Num(joint.lower) + " " + Num(joint.upper) + "\"";
    }
    if (joint.effort > 0) attrs += " forcerange=\"" + Num(-joint.effort) + " " + Num(joint.effort) + "\"";
    w.Line(2, attrs + "/>");
  }
  w.Line(1, "</actuator>");

  // Keyframe "home": robot at home, hand open, everything else where it was placed.
  {
    const Eigen::VectorXd q_home = robot.HomeQ();
    std::string qpos = Vec(q_home);
    for (const PlacedTool& placed : scene.tools) {
      const Eigen::Isometry3d X_WT = scene.X_WR * placed.X_RT;
      qpos += " " + Vec(X_WT.translation()) + " " + Quat(X_WT.linear());
    }
    qpos += " " + Vec(scene.X_WR * p_R_ball) + " 1 0 0 0";
    w.Line(1, "<keyframe>");
    w.Line(2, "<key name=\"home\" qpos=\"" + qpos + "\" ctrl=\"" + Vec(q_home) + "\"/>");
    w.Line(1, "</keyframe>");
  }
  w.Line(0, "</mujoco>");
  scene.mjcf = w.out().str();
  return scene;
}

}  // namespace toolbench::sim
