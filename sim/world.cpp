#include "sim/world.h"

#include <cmath>
#include <cstdlib>
#include <cstring>
#include <algorithm>
#include <array>
#include <chrono>
#include <mutex>

#include <mujoco/mujoco.h>
#include <spdlog/spdlog.h>

#include "common/check.h"

namespace toolbench::sim {
namespace {

void OnMujocoError(const char* message) {
  // MuJoCo cannot continue after mju_error; never throw through its C frames (style.md 6).
  spdlog::critical("MuJoCo error: {}", message);
  std::abort();
}

void OnMujocoWarning(const char* message) { spdlog::warn("MuJoCo warning: {}", message); }

Eigen::Isometry3d PoseFrom(const mjtNum* pos, const mjtNum* quat) {
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.translation() = Eigen::Vector3d(pos[0], pos[1], pos[2]);
  X.linear() = Eigen::Quaterniond(quat[0], quat[1], quat[2], quat[3]).normalized().toRotationMatrix();
  return X;
}

}  // namespace

const Eigen::Isometry3d& GroundTruth::Pose(std::string_view body) const {
  auto it = X_WB.find(std::string(body));
  if (it == X_WB.end()) ThrowInvalid("GroundTruth::Pose: unknown body '", body, "'");
  return it->second;
}

void InstallMujocoHandlers() {
  static std::once_flag once;
  std::call_once(once, [] {
    mju_user_error = OnMujocoError;
    mju_user_warning = OnMujocoWarning;
  });
}

struct World::Impl {
  mjModel* m = nullptr;
  mjData* d = nullptr;
  std::vector<std::string> joints;  // actuated joint names, actuator order
  std::vector<int> qpos_adr;        // per actuator
  std::vector<int> dof_adr;         // per actuator
  SimStatus status;
  PhysicsStats stats;

  // ---- Sleeping (SleepSettings). ----
  struct FreeBody {
    int body = -1;
    int qpos_adr = 0;
    int dof_adr = 0;
    std::vector<int> geoms;  // collision geoms, with their own filter bits
    std::vector<int> contype, conaffinity;
    bool asleep = false;
    double window_start = 0.0;
    std::array<double, 7> window_pose{};  // qpos at the window's start
    std::array<double, 7> pinned{};       // qpos held while asleep
  };
  SleepSettings sleep;
  std::vector<FreeBody> free_bodies;
  std::vector<int> robot_geoms;  // collision geoms of bodies that move with joints (not free)
  std::vector<int> free_of_body;  // per body: index in free_bodies, or -1
  std::vector<char> awake, eligible, staying;  // per free body, scratch of the step's update
  int asleep_count = 0;
  // Per geom: a box in the geom's frame that encloses it (centre, half extents; for a mesh its
  // vertices', whose convex hull MuJoCo collides), or not valid (planes, height fields): the
  // bounding sphere alone then. A long tool's bounding sphere is as wide as the tool is long:
  // spheres alone kept its neighbours on the rack awake (and, with noslip_scope "resting", the
  // noslip pass on) while it was carried past them: random episodes seed 1, 4735 -> 913 steps
  // with the pass an episode (of ~20100).
  struct GeomBox {
    Eigen::Vector3d center = Eigen::Vector3d::Zero();
    Eigen::Vector3d half = Eigen::Vector3d::Zero();
    bool valid = true;
  };
  std::vector<GeomBox> boxes;

  // ---- The noslip pass on demand (PhysicsSpec::noslip_scope "resting"). ----
  bool noslip_on_demand = false;
  int noslip_iterations = 0;          // the scene's, used in the steps that need the pass
  std::vector<char> holding_fixture;  // per geom: a fixture that holds resting bodies (the rack)
  std::vector<char> on_fixture, held;  // per free body, scratch

  // The model's <text name="toolbench_noslip_fixtures" data="prefix"/> (written by the composer
  // for noslip_scope "resting") turns the pass on only for the steps that need it.
  void SetUpNoslip() {
    const int id = mj_name2id(m, mjOBJ_TEXT, "toolbench_noslip_fixtures");
    if (id < 0 || m->opt.noslip_iterations == 0) return;
    const std::string prefix = m->text_data + m->text_adr[id];
    noslip_on_demand = true;
    noslip_iterations = m->opt.noslip_iterations;
    holding_fixture.assign(m->ngeom, 0);
    for (int g = 0; g < m->ngeom; ++g) {
      const char* name = mj_id2name(m, mjOBJ_GEOM, g);
      holding_fixture[g] = name && !prefix.empty() && std::string_view(name).rfind(prefix, 0) == 0;
    }
    on_fixture.resize(free_bodies.size());
    held.resize(free_bodies.size());
  }

  // Whether the coming step needs the noslip pass: some free body touches a holding fixture and
  // not the robot (a tool resting on the rack, awake: without the pass it would creep down it),
  // judged from the contacts of the last step. A held tool, the ball on the table and bodies
  // asleep (out of the contact solve) do without it.
  bool NeedsNoslip() {
    std::fill(on_fixture.begin(), on_fixture.end(), 0);
    std::fill(held.begin(), held.end(), 0);
    for (int c = 0; c < d->ncon; ++c) {
      const int g1 = d->contact[c].geom1, g2 = d->contact[c].geom2;
      for (const auto& [mine, other] : {std::pair{g1, g2}, std::pair{g2, g1}}) {
        const int j = free_of_body[m->geom_bodyid[mine]];
        if (j < 0) continue;
        if (holding_fixture[other]) on_fixture[j] = 1;
        if (IsRobotGeom(other)) held[j] = 1;
      }
    }
    for (size_t j = 0; j < free_bodies.size(); ++j) {
      if (on_fixture[j] && !held[j]) return true;
    }
    return false;
  }

  // A geom of a body that moves with joints (the robot): neither a free body's nor welded to the
  // world, and not a plane.
  bool IsRobotGeom(int g) const {
    const int b = m->geom_bodyid[g];
    return free_of_body[b] < 0 && m->body_weldid[b] != 0 && m->geom_type[g] != mjGEOM_PLANE;
  }

  void SetUpSleeping() {
    const int id = mj_name2id(m, mjOBJ_NUMERIC, "toolbench_sleep");
    if (id >= 0 && m->numeric_size[id] == 3) {
      const mjtNum* v = m->numeric_data + m->numeric_adr[id];
      sleep = SleepSettings{v[0], v[1], v[2]};
    }
    free_of_body.assign(m->nbody, -1);
    for (int b = 1; b < m->nbody; ++b) {
      if (m->body_jntnum[b] != 1 || m->jnt_type[m->body_jntadr[b]] != mjJNT_FREE) continue;
      FreeBody fb;
      fb.body = b;
      fb.qpos_adr = m->jnt_qposadr[m->body_jntadr[b]];
      fb.dof_adr = m->jnt_dofadr[m->body_jntadr[b]];
      free_of_body[b] = static_cast<int>(free_bodies.size());
      free_bodies.push_back(fb);
    }
    awake.resize(free_bodies.size());
    eligible.resize(free_bodies.size());
    staying.resize(free_bodies.size());
    SetUpGeomBoxes();
    for (int g = 0; g < m->ngeom; ++g) {
      if (m->geom_contype[g] == 0 && m->geom_conaffinity[g] == 0) continue;
      const int b = m->geom_bodyid[g];
      if (free_of_body[b] >= 0) {
        FreeBody& fb = free_bodies[free_of_body[b]];
        fb.geoms.push_back(g);
        fb.contype.push_back(m->geom_contype[g]);
        fb.conaffinity.push_back(m->geom_conaffinity[g]);
      } else if (IsRobotGeom(g)) {
        robot_geoms.push_back(g);
      }
    }
  }

  std::array<double, 7> Qpos(const FreeBody& fb) const {
    std::array<double, 7> q;
    std::copy(d->qpos + fb.qpos_adr, d->qpos + fb.qpos_adr + 7, q.begin());
    return q;
  }

  // Movement between two free-joint poses [m], rotations at a 0.1 m lever.
  static double Moved(const std::array<double, 7>& a, const std::array<double, 7>& b) {
    const double dp = std::sqrt(std::pow(a[0] - b[0], 2) + std::pow(a[1] - b[1], 2) + std::pow(a[2] - b[2], 2));
    double dot = 0.0;
    for (int k = 3; k < 7; ++k) dot += a[k] * b[k];
    return std::max(dp, 0.1 * 2.0 * std::acos(std::min(1.0, std::abs(dot))));
  }

  void SetUpGeomBoxes() {
    boxes.assign(m->ngeom, GeomBox{});
    for (int g = 0; g < m->ngeom; ++g) {
      const mjtNum* size = m->geom_size + 3 * g;
      GeomBox& box = boxes[g];
      switch (m->geom_type[g]) {
        case mjGEOM_SPHERE: box.half.setConstant(size[0]); break;
        case mjGEOM_CAPSULE: box.half << size[0], size[0], size[0] + size[1]; break;
        case mjGEOM_CYLINDER: box.half << size[0], size[0], size[1]; break;
        case mjGEOM_ELLIPSOID:
        case mjGEOM_BOX: box.half << size[0], size[1], size[2]; break;
        case mjGEOM_MESH: {
          const int mesh = m->geom_dataid[g];
          const Eigen::Map<const Eigen::Matrix3Xf> v(m->mesh_vert + 3 * m->mesh_vertadr[mesh], 3,
                                                     m->mesh_vertnum[mesh]);
          const Eigen::Vector3d lo = v.rowwise().minCoeff().cast<double>();
          const Eigen::Vector3d hi = v.rowwise().maxCoeff().cast<double>();
          box.center = 0.5 * (lo + hi);
          box.half = 0.5 * (hi - lo);
          break;
        }
        default: box.valid = false; break;
      }
    }
  }

  // Whether geoms g and h come within the wake margin at their current poses: their bounding
  // spheres, then their boxes (separating axes, g's box grown by the margin).
  bool Near(int g, int h) const {
    const double reach = m->geom_rbound[g] + m->geom_rbound[h] + sleep.wake_margin_m;
    const mjtNum* a = d->geom_xpos + 3 * g;
    const mjtNum* b = d->geom_xpos + 3 * h;
    const double dx = a[0] - b[0], dy = a[1] - b[1], dz = a[2] - b[2];
    if (dx * dx + dy * dy + dz * dz >= reach * reach) return false;
    const GeomBox& box_g = boxes[g];
    const GeomBox& box_h = boxes[h];
    if (!box_g.valid || !box_h.valid) return true;
    using RowMajor3 = Eigen::Matrix<double, 3, 3, Eigen::RowMajor>;
    const Eigen::Matrix3d Ra = Eigen::Map<const RowMajor3>(d->geom_xmat + 9 * g);
    const Eigen::Matrix3d Rb = Eigen::Map<const RowMajor3>(d->geom_xmat + 9 * h);
    const Eigen::Vector3d ca = Eigen::Map<const Eigen::Vector3d>(a) + Ra * box_g.center;
    const Eigen::Vector3d cb = Eigen::Map<const Eigen::Vector3d>(b) + Rb * box_h.center;
    return BoxesOverlap(Ra, ca, box_g.half.array() + sleep.wake_margin_m, Rb, cb, box_h.half);
  }

  // Separating-axis test of two oriented boxes (rotation, centre, half extents; the 15 axes of
  // Gottschalk et al.'s OBBTree): true when no axis separates them. MuJoCo 2.2 has one
  // (mj_collideOBB, its mid-phase) but does not export it.
  static bool BoxesOverlap(const Eigen::Matrix3d& Ra, const Eigen::Vector3d& ca, const Eigen::Vector3d& ea,
                           const Eigen::Matrix3d& Rb, const Eigen::Vector3d& cb, const Eigen::Vector3d& eb) {
    const Eigen::Matrix3d R = Ra.transpose() * Rb;         // b's axes in a's frame
    const Eigen::Vector3d t = Ra.transpose() * (cb - ca);  // b's centre in a's frame
    const Eigen::Matrix3d A = R.cwiseAbs().array() + 1e-9;  // (+ eps: near-parallel edges)
    for (int i = 0; i < 3; ++i) {
      if (std::abs(t[i]) > ea[i] + A.row(i).dot(eb)) return false;
    }
    for (int j = 0; j < 3; ++j) {
      if (std::abs(t.dot(R.col(j))) > A.col(j).dot(ea) + eb[j]) return false;
    }
    for (int i = 0; i < 3; ++i) {
      const int i1 = (i + 1) % 3, i2 = (i + 2) % 3;
      for (int j = 0; j < 3; ++j) {
        const int j1 = (j + 1) % 3, j2 = (j + 2) % 3;
        const double ra = ea[i1] * A(i2, j) + ea[i2] * A(i1, j);
        const double rb = eb[j1] * A(i, j2) + eb[j2] * A(i, j1);
        if (std::abs(t[i2] * R(i1, j) - t[i1] * R(i2, j)) > ra + rb) return false;
      }
    }
    return true;
  }
  bool Near(const FreeBody& fb, const std::vector<int>& others) const {
    for (int g : fb.geoms) {
      for (int h : others) {
        if (Near(g, h)) return true;
      }
    }
    return false;
  }

  void Wake(FreeBody& fb) {
    if (!fb.asleep) return;
    for (size_t i = 0; i < fb.geoms.size(); ++i) {
      m->geom_contype[fb.geoms[i]] = fb.contype[i];
      m->geom_conaffinity[fb.geoms[i]] = fb.conaffinity[i];
    }
    fb.asleep = false;
    --asleep_count;
    fb.window_start = d->time;
    fb.window_pose = Qpos(fb);
  }
  void WakeAll() {
    for (FreeBody& fb : free_bodies) {
      Wake(fb);
      fb.window_start = d->time;
      fb.window_pose = Qpos(fb);
    }
  }

  bool NearAwakeBody(const FreeBody& fb, const std::vector<char>& counts) const {
    for (size_t j = 0; j < free_bodies.size(); ++j) {
      if (counts[j] && &free_bodies[j] != &fb && Near(fb, free_bodies[j].geoms)) return true;
    }
    return false;
  }

  // Wakes the sleepers that a robot geom or an awake body came near (poses of the last forward).
  void WakeNearMovers() {
    if (sleep.window_s <= 0.0) return;
    for (size_t j = 0; j < free_bodies.size(); ++j) awake[j] = !free_bodies[j].asleep;
    for (FreeBody& fb : free_bodies) {
      if (fb.asleep && (Near(fb, robot_geoms) || NearAwakeBody(fb, awake))) Wake(fb);
    }
  }

  // After each step: hold the sleepers, wake those a mover came near, put to sleep those at rest
  // with no mover near.
  void UpdateSleep() {
    if (sleep.window_s <= 0.0) return;
    for (FreeBody& fb : free_bodies) {
      if (!fb.asleep) continue;
      std::copy(fb.pinned.begin(), fb.pinned.end(), d->qpos + fb.qpos_adr);
      std::fill(d->qvel + fb.dof_adr, d->qvel + fb.dof_adr + 6, 0.0);
    }
    WakeNearMovers();
    // Rest: moved less than the tolerance since the window began, for the whole window.
    for (size_t j = 0; j < free_bodies.size(); ++j) {
      FreeBody& fb = free_bodies[j];
      eligible[j] = 0;
      if (fb.asleep) continue;
      const std::array<double, 7> q = Qpos(fb);
      if (Moved(q, fb.window_pose) > sleep.tolerance_m) {
        fb.window_start = d->time;
        fb.window_pose = q;
        continue;
      }
      eligible[j] = d->time - fb.window_start >= sleep.window_s && !Near(fb, robot_geoms);
    }
    // Bodies near an awake body that stays awake stay awake too (until nothing changes).
    for (bool changed = true; changed;) {
      changed = false;
      for (size_t j = 0; j < free_bodies.size(); ++j) staying[j] = !free_bodies[j].asleep && !eligible[j];
      for (size_t j = 0; j < free_bodies.size(); ++j) {
        if (eligible[j] && NearAwakeBody(free_bodies[j], staying)) {
          eligible[j] = 0;
          changed = true;
        }
      }
    }
    for (size_t j = 0; j < free_bodies.size(); ++j) {
      if (!eligible[j]) continue;
      FreeBody& fb = free_bodies[j];
      for (int g : fb.geoms) {
        m->geom_contype[g] = 0;
        m->geom_conaffinity[g] = 0;
      }
      fb.asleep = true;
      ++asleep_count;
      fb.pinned = Qpos(fb);
      std::fill(d->qvel + fb.dof_adr, d->qvel + fb.dof_adr + 6, 0.0);
    }
  }

  ~Impl() {
    if (d) mj_deleteData(d);
    if (m) mj_deleteModel(m);
  }

  // `t_before`: the time before the step (MuJoCo resets the state, time included, when it
  // finds the step unstable).
  void CheckWarnings(double t_before) {
    if (!status.ok) return;
    // An overflow of the contact or constraint room drops contacts: objects would pass through
    // each other unnoticed (PhysicsSpec::max_contacts, max_constraint_rows).
    static constexpr int kFatal[] = {mjWARN_BADQPOS, mjWARN_BADQVEL, mjWARN_BADQACC,
                                     mjWARN_BADCTRL, mjWARN_CONTACTFULL, mjWARN_CNSTRFULL};
    for (int w : kFatal) {
      if (d->warning[w].number > 0) {
        status.ok = false;
        status.message = Cat("MuJoCo reported ", mju_warningText(w, d->warning[w].lastinfo),
                             " stepping from t = ", t_before, " s",
                             w == mjWARN_CONTACTFULL   ? " (raise physics.max_contacts in the scene file)"
                             : w == mjWARN_CNSTRFULL ? " (raise physics.max_constraint_rows in the scene file)"
                                                     : "");
        return;
      }
    }
  }
};

World::World(const std::string& mjcf, std::string_view source) : impl_(std::make_unique<Impl>()) {
  InstallMujocoHandlers();
  // mjVFS holds 2000 file names of 1000 chars: keep it off the stack.
  auto vfs = std::make_unique<mjVFS>();
  mj_defaultVFS(vfs.get());
  const char* kName = "scene.xml";
  if (mj_makeEmptyFileVFS(vfs.get(), kName, static_cast<int>(mjcf.size())) != 0) {
    ThrowInvalid("World: could not stage '", source, "' in MuJoCo's virtual file system");
  }
  const int index = mj_findFileVFS(vfs.get(), kName);
  std::memcpy(vfs->filedata[index], mjcf.data(), mjcf.size());
  char error[1024] = {0};
  impl_->m = mj_loadXML(kName, vfs.get(), error, sizeof(error));
  mj_deleteVFS(vfs.get());
  if (!impl_->m) ThrowInvalid("World: MuJoCo cannot load '", source, "': ", error);
  impl_->d = mj_makeData(impl_->m);
  impl_->SetUpSleeping();
  impl_->SetUpNoslip();
  const mjModel* m = impl_->m;
  for (int a = 0; a < m->nu; ++a) {
    if (m->actuator_trntype[a] != mjTRN_JOINT) {
      ThrowInvalid("World: actuator ", a, " of '", source, "' does not drive a joint");
    }
    const int j = m->actuator_trnid[2 * a];
    impl_->joints.emplace_back(mj_id2name(m, mjOBJ_JOINT, j));
    impl_->qpos_adr.push_back(m->jnt_qposadr[j]);
    impl_->dof_adr.push_back(m->jnt_dofadr[j]);
  }
  if (m->nkey > 0) {
    ResetToKeyframe(mj_id2name(m, mjOBJ_KEY, 0));
  } else {
    mj_forward(m, impl_->d);
  }
}

World::~World() = default;
World::World(World&&) noexcept = default;
World& World::operator=(World&&) noexcept = default;

void World::ResetToKeyframe(std::string_view key) {
  const int id = mj_name2id(impl_->m, mjOBJ_KEY, std::string(key).c_str());
  if (id < 0) ThrowInvalid("World::ResetToKeyframe: unknown keyframe '", key, "'");
  mj_resetDataKeyframe(impl_->m, impl_->d, id);
  impl_->WakeAll();
  mj_forward(impl_->m, impl_->d);
  impl_->status = SimStatus{};
}

SimStatus World::Step(int steps) {
  const auto start = std::chrono::steady_clock::now();
  int taken = 0;
  for (; taken < steps && impl_->status.ok; ++taken) {
    const double t_before = impl_->d->time;
    if (impl_->noslip_on_demand) {
      impl_->m->opt.noslip_iterations = impl_->NeedsNoslip() ? impl_->noslip_iterations : 0;
    }
    impl_->stats.noslip_steps += impl_->m->opt.noslip_iterations > 0;
    mj_step(impl_->m, impl_->d);
    impl_->stats.contacts += impl_->d->ncon;
    impl_->stats.constraint_rows += impl_->d->nefc;
    impl_->stats.solver_iterations += impl_->d->solver_iter;
    impl_->CheckWarnings(t_before);
    impl_->UpdateSleep();
    impl_->stats.asleep += impl_->asleep_count;
  }
  impl_->stats.steps += taken;
  impl_->stats.wall_s += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return impl_->status;
}

SimStatus World::Advance(double seconds) {
  const int steps = static_cast<int>(std::ceil(seconds / impl_->m->opt.timestep - 1e-9));
  return Step(std::max(0, steps));
}

bool World::SettleFreeBodies(double max_time, double speed_tol, double hold) {
  // Judged by displacement over a window, not instantaneous speed: contacts of small convex parts
  // vibrate at a few mm/s without the body going anywhere.
  auto free_poses = [&] {
    std::vector<std::array<double, 7>> poses;
    for (const auto& fb : impl_->free_bodies) poses.push_back(impl_->Qpos(fb));
    return poses;
  };
  const double t_end = impl_->d->time + max_time;
  std::vector<std::array<double, 7>> before = free_poses();
  while (impl_->d->time < t_end && impl_->status.ok) {
    Advance(hold);
    const std::vector<std::array<double, 7>> after = free_poses();
    double moved = 0.0;
    for (size_t i = 0; i < after.size(); ++i) moved = std::max(moved, Impl::Moved(after[i], before[i]));
    if (moved < speed_tol * hold) return true;
    before = after;
  }
  return false;
}

double World::time() const { return impl_->d->time; }
double World::timestep() const { return impl_->m->opt.timestep; }
SimStatus World::status() const { return impl_->status; }
const PhysicsStats& World::physics_stats() const { return impl_->stats; }
const SleepSettings& World::sleep_settings() const { return impl_->sleep; }

bool World::IsAsleep(std::string_view body) const {
  const int id = mj_name2id(impl_->m, mjOBJ_BODY, std::string(body).c_str());
  if (id < 0) ThrowInvalid("World::IsAsleep: unknown body '", body, "'");
  for (const auto& fb : impl_->free_bodies) {
    if (fb.body == id) return fb.asleep;
  }
  ThrowInvalid("World::IsAsleep: body '", body, "' has no free joint");
}
const std::vector<std::string>& World::actuated_joints() const { return impl_->joints; }

Eigen::VectorXd World::JointPositions() const {
  Eigen::VectorXd q(impl_->joints.size());
  for (size_t i = 0; i < impl_->joints.size(); ++i) q[i] = impl_->d->qpos[impl_->qpos_adr[i]];
  return q;
}

Eigen::VectorXd World::JointVelocities() const {
  Eigen::VectorXd v(impl_->joints.size());
  for (size_t i = 0; i < impl_->joints.size(); ++i) v[i] = impl_->d->qvel[impl_->dof_adr[i]];
  return v;
}

Eigen::VectorXd World::JointTargets() const {
  return Eigen::Map<const Eigen::VectorXd>(impl_->d->ctrl, impl_->m->nu);
}

void World::SetJointTargets(const Eigen::VectorXd& q_target) {
  if (q_target.size() != impl_->m->nu) {
    ThrowInvalid("World::SetJointTargets: got ", q_target.size(), " targets, the robot has ",
                 impl_->m->nu, " actuated joints");
  }
  if (!q_target.allFinite()) {
    ThrowInvalid("World::SetJointTargets: non-finite target ", q_target.transpose());
  }
  for (int a = 0; a < impl_->m->nu; ++a) {
    double v = q_target[a];
    if (impl_->m->actuator_ctrllimited[a]) {
      v = std::clamp(v, impl_->m->actuator_ctrlrange[2 * a], impl_->m->actuator_ctrlrange[2 * a + 1]);
    }
    impl_->d->ctrl[a] = v;
  }
}

void World::TeleportJoints(const Eigen::VectorXd& q) {
  SetJointTargets(q);
  for (size_t i = 0; i < impl_->joints.size(); ++i) {
    impl_->d->qpos[impl_->qpos_adr[i]] = impl_->d->ctrl[i];
    impl_->d->qvel[impl_->dof_adr[i]] = 0.0;
  }
  mj_forward(impl_->m, impl_->d);
  impl_->WakeNearMovers();
}

void World::TeleportFreeBody(std::string_view body, const Eigen::Isometry3d& X_WB) {
  const mjModel* m = impl_->m;
  const int id = mj_name2id(m, mjOBJ_BODY, std::string(body).c_str());
  if (id < 0) ThrowInvalid("World::TeleportFreeBody: unknown body '", body, "'");
  const int jnt = m->body_jntadr[id];
  if (m->body_jntnum[id] != 1 || m->jnt_type[jnt] != mjJNT_FREE) {
    ThrowInvalid("World::TeleportFreeBody: body '", body, "' has no free joint");
  }
  if (!X_WB.matrix().allFinite()) ThrowInvalid("World::TeleportFreeBody: the pose of '", body, "' is not finite");
  double* qpos = impl_->d->qpos + m->jnt_qposadr[jnt];
  const Eigen::Quaterniond q(X_WB.linear());
  for (int i = 0; i < 3; ++i) qpos[i] = X_WB.translation()[i];
  qpos[3] = q.w();
  qpos[4] = q.x();
  qpos[5] = q.y();
  qpos[6] = q.z();
  for (int i = 0; i < 6; ++i) impl_->d->qvel[m->jnt_dofadr[jnt] + i] = 0.0;
  for (auto& fb : impl_->free_bodies) {
    if (fb.body == id) impl_->Wake(fb);
  }
  mj_forward(impl_->m, impl_->d);
  impl_->WakeNearMovers();
}

GroundTruth World::ground_truth() const {
  GroundTruth truth;
  truth.time = impl_->d->time;
  const mjModel* m = impl_->m;
  for (int b = 1; b < m->nbody; ++b) {
    const char* name = mj_id2name(m, mjOBJ_BODY, b);
    if (!name) continue;
    truth.X_WB[name] = PoseFrom(impl_->d->xpos + 3 * b, impl_->d->xquat + 4 * b);
  }
  return truth;
}

int World::num_contacts() const { return impl_->d->ncon; }

std::vector<std::string> World::ContactingBodies(std::string_view body) const {
  const mjModel* m = impl_->m;
  const int id = mj_name2id(m, mjOBJ_BODY, std::string(body).c_str());
  if (id < 0) ThrowInvalid("World::ContactingBodies: unknown body '", body, "'");
  std::vector<std::string> out;
  for (int c = 0; c < impl_->d->ncon; ++c) {
    const mjContact& con = impl_->d->contact[c];
    const int b1 = m->geom_bodyid[con.geom1];
    const int b2 = m->geom_bodyid[con.geom2];
    int other = -1;
    if (b1 == id) other = b2;
    if (b2 == id) other = b1;
    if (other < 0) continue;
    const char* name = mj_id2name(m, mjOBJ_BODY, other);
    std::string s = name ? name : "world";
    if (std::find(out.begin(), out.end(), s) == out.end()) out.push_back(s);
  }
  return out;
}

const mjModel_* World::mj_model() const { return impl_->m; }
mjData_* World::mj_data() { return impl_->d; }

}  // namespace toolbench::sim
