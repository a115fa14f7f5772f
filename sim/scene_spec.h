#pragma once

#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

namespace toolbench::sim {

/// Table: a box whose top face is at `top_z`, in the robot root frame R (x backward, y right,
/// z up; see shared/facts/icub.md section 1).
struct TableSpec {
  Eigen::Vector2d center{-0.42, -0.12};  // top centre (x, y) in R [m]
  Eigen::Vector2d size{0.50, 0.60};      // top extent along x and y [m], > 0
  double top_z = -0.10;                  // height of the top face in R [m]
  double thickness = 0.03;               // [m], > 0

  bool operator==(const TableSpec&) const = default;
};

/// The ball to be retrieved; its (x, y) is drawn uniformly from the ranges (R frame).
struct BallSpec {
  double radius = 0.035;                   // [m], > 0
  double mass = 0.06;                      // [kg], > 0
  Eigen::Vector2d x_range{-0.62, -0.60};   // [m], min <= max
  Eigen::Vector2d y_range{-0.10, 0.05};    // [m], min <= max

  bool operator==(const BallSpec&) const = default;
};

/// The tool rack: an inclined board with a ledge at its foot, to the robot's right, facing it
/// (thesis Fig. 5.3). Rack frame K: origin where the board meets the ledge, at the middle of the
/// rack; x_K along the rack, y_K the board normal pointing toward the robot, z_K up the board.
/// With yaw 0 the board is parallel to the robot's sagittal plane (x_K = robot forward = -x_R,
/// y_K = -y_R); `yaw_deg` turns the rack about the vertical so that it faces the robot from
/// the front-right. Tools stand on the ledge (z_K >= 0) in front of the board (y_K >= 0).
struct RackSpec {
  Eigen::Vector3d origin{-0.19, 0.53, -0.10};  // K origin in R [m]
  double yaw_deg = 15.0;       // rotation of the rack about z_R [deg], [-90, 90]
  double incline_deg = 25.0;   // board tilt away from the robot, from vertical [deg], [0, 45]
  double width = 0.56;         // along x_K [m], > 0
  double height = 0.55;        // along z_K [m], > 0
  double ledge_depth = 0.20;   // along y_K [m], > 0; deep enough for a rake head lying across
  double lip_height = 0.0;     // ledge lip along z_K [m], >= 0 (0: none; wide effectors overhang)
  double standoff = 0.05;      // tools rest this far in front of the board, on a rail and a
                               // stop on the ledge, so fingers fit behind a handle [m], >= 0
  double rail_height = 0.18;   // z_K of the rail's centre [m], > 0
  double slot_pos1 = -0.13;    // x_K of place pos1 [m] (the end away from the table)
  double slot_pos2 = 0.0;      // x_K of place pos2 [m] (central place, used by rot0..rot3)
  double slot_pos3 = 0.14;     // x_K of place pos3 [m] (the end near the table)

  bool operator==(const RackSpec&) const = default;
};

/// How many tools a random scene gets and from which models.
struct ToolsSpec {
  int min_count = 1;                 // >= 1
  int max_count = 3;                 // >= min_count, <= 3
  std::vector<std::string> choices;  // model names; empty = the whole library

  bool operator==(const ToolsSpec&) const = default;
};

/// Simulation settings of the scene.
struct PhysicsSpec {
  double timestep = 0.002;           // [s], (0, 0.01]
  std::string cone = "elliptic";     // "pyramidal" or "elliptic"
  double impratio = 10.0;            // >= 1
  /// MuJoCo's noslip pass (>= 0 iterations; 0 = off) removes the creep of soft contacts
  /// (mujoco#3328) but costs ~60 % of a step whenever anything touches; noslip_tolerance (> 0)
  /// stops it below that improvement (MuJoCo's default). noslip_scope "always" runs it at every
  /// step (plain MuJoCo; scenes/noslip_always.json); "resting" (the default) only in the steps
  /// after one in which some free body touched the rack and not the robot (an awake tool resting
  /// on the rack: without the pass, some upside-down tools never came to rest); held tools are
  /// kept from creeping by robot_solimp instead, less well (README, Speed).
  int noslip_iterations = 30;
  std::string noslip_scope = "resting";
  double noslip_tolerance = 1e-6;
  /// Impedance (MuJoCo's solimp: d0, dwidth, width [m]) of every contact the robot makes, with
  /// solmix robot_solmix (> 0) against the other geom's 1 (1000: the robot's wins). The closer d
  /// is to 1, the less a soft contact's constraint force is regularised and the less a held tool
  /// or ball creeps under its weight and the drag (creep speed ~ (1 - d) / d), and the stiffer the
  /// grip. With the default [0.95, 0.99, 0.001] and no noslip pass the robot pulls from
  /// ground-truth handles about as well as with MuJoCo's [0.9, 0.95, 0.001] (solmix 1) and the
  /// pass, but held tools slip more (grasp-gt's 2 s hold: median 1.7 against 0.06 mm);
  /// [0.99, 0.999, 0.001] let more tools pivot out of the hand in pull-gt (README, Speed).
  /// 0 < d0, dwidth < 1, width > 0.
  Eigen::Vector3d robot_solimp{0.95, 0.99, 0.001};
  double robot_solmix = 1000.0;
  /// MuJoCo's constraint solver ("Newton", "CG" or "PGS") and its Jacobian layout ("dense",
  /// "sparse", or "auto": dense below 60 degrees of freedom, which the scene always is).
  std::string solver = "Newton";
  std::string jacobian = "auto";
  /// The constraint solver stops when its cost improves by less than `tolerance` (> 0; MuJoCo's
  /// default 1e-8) or after `iterations` (>= 1; MuJoCo's default 100).
  double tolerance = 1e-8;
  int iterations = 100;
  double settle_time = 4.0;          // longest wait for tools and ball to come to rest [s]
  /// Room for contacts (MuJoCo's nconmax, >= 1) and constraint rows (njmax, >= 1) a step. More
  /// than either stops the episode with MuJoCo's overflow warning (sim_unstable), never drops
  /// contacts silently. MuJoCo 2.2.2 gives every mjData a dense njmax x njmax matrix (efc_AR) and
  /// clears it, so room costs time: 2000 rows (the value until session 44) took 50 ms of each
  /// world's 65 ms to build; 600 take 12 ms. The most seen in 100 random episodes: 24 contacts,
  /// 147 rows.
  int max_contacts = 150;
  int max_constraint_rows = 600;
  /// Sleeping of resting tools and ball (sim::SleepSettings): still for sleep_window [s] (>= 0,
  /// 0 = never sleep, plain MuJoCo) within sleep_tolerance [m] (> 0), woken when a robot geom or
  /// an awake body comes within wake_margin [m] (> 0).
  double sleep_window = 0.25;
  double sleep_tolerance = 2.5e-4;
  double wake_margin = 0.02;

  bool operator==(const PhysicsSpec&) const = default;
};

/// A complete scene description (scenes/*.json). Paths are relative to the assets folder.
struct SceneSpec {
  std::string name = "default";
  std::string robot = "robots/icub_upper_body.json";
  std::vector<std::string> tool_dirs{"tools"};
  Eigen::Vector3d robot_base{0.0, 0.0, 0.63};  // root R origin in the world W [m]; R is not rotated
  TableSpec table;
  BallSpec ball;
  RackSpec rack;
  ToolsSpec tools;
  PhysicsSpec physics;

  /// Throws std::invalid_argument naming the field and value when out of range.
  void Validate() const;

  bool operator==(const SceneSpec&) const = default;
};

/// Parses scene JSON text. Every field is optional (defaults above); unknown fields are errors
/// (they are typos). `source` names the input in messages. Throws std::invalid_argument.
SceneSpec ParseSceneSpec(std::string_view json_text, std::string_view source);

/// Reads and parses a scene file; throws std::invalid_argument naming the path on failure.
SceneSpec LoadSceneSpec(const std::filesystem::path& path);

/// scenes/default.json under the source root.
std::filesystem::path DefaultScenePath();

}  // namespace toolbench::sim
