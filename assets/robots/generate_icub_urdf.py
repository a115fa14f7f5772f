#!/usr/bin/env python3
"""Generate the iCub upper-body URDF (icub_upper_body.urdf) and its sidecar (icub_upper_body.json).

Python 3 standard library only.  Run from anywhere:

    python3 assets/robots/generate_icub_urdf.py            # writes both files next to this script
    python3 assets/robots/generate_icub_urdf.py --print    # also prints the zero-pose frames and gain table

Every number below is re-typed from shared/facts/icub.md (section given in each comment); the
kinematics follow iKin's standard DH convention exactly:

    T_i = Rz(q_i + offset_i) . Tz(d_i) . Tx(a_i) . Rx(alpha_i),   chain = H0 . T_0 ... T_n

URDF mapping (so that the URDF joint angle IS the encoder reading q_i, in radians):
  * every revolute joint of torso, arm and neck has axis (0 0 1) = the DH z axis of that link;
  * the child link of DH joint i has the frame  F_i . Rz(offset_i + q_i)  (F_i = DH frame i);
  * hence the URDF origin of joint i is  Tz(d_{i-1}) Tx(a_{i-1}) Rx(alpha_{i-1}) . Rz(offset_i),
    and the origin of the first joint is  H0 . Rz(offset_0).
  * Exception (branching, icub.md section 3): the chest link is DH frame 2 rotated by Rz(q_yaw)
    only; the torso-yaw offset and the rest of DH link 2 differ between the arm branch and the
    head branch, so each branch's first joint origin starts with its own  Rz(offset_2) Tz Tx Rx.
"""

import json
import math
import os
import random
import sys

PI = math.pi
HERE = os.path.dirname(os.path.abspath(__file__))
URDF_NAME = "icub_upper_body.urdf"
SIDECAR_NAME = "icub_upper_body.json"

# ----------------------------------------------------------------------------------------------
# 1. DH tables (icub.md sections 1-4), v2 rows: arm "right_v2", eye "left_v2".
#    Row: (joint name, a [m], d [m], alpha [rad], offset [deg], min [deg], max [deg])
#    min/max = iKin defaults (icub.md section 5, left column).
# ----------------------------------------------------------------------------------------------

# icub.md section 1: H0 for all chains of kinematic versions < 3.0 (rows).
H0 = [[0.0, -1.0, 0.0, 0.0],
      [0.0, 0.0, -1.0, 0.0],
      [1.0, 0.0, 0.0, 0.0],
      [0.0, 0.0, 0.0, 1.0]]

# Torso links 0-1 (shared by arm and head chains, icub.md sections 2-4). Chain order is
# pitch, roll, yaw (the robot's torso part is ordered yaw, roll, pitch).
TORSO_DH = [
    ("torso_pitch", 0.032, 0.0, +PI / 2, 0.0, -22.0, 84.0),
    ("torso_roll", 0.0, -0.0055, +PI / 2, -90.0, -39.0, 39.0),
]
TORSO_YAW_LIMITS_DEG = (-59.0, 59.0)

# DH link 2 (torso yaw): the arm and the head chains end this link at different points.
ARM_LINK2 = ("torso_yaw", -0.0233647, -0.1433, +PI / 2, -105.0)   # icub.md section 3 (arm v1/v2)
HEAD_LINK2 = ("torso_yaw", 0.0, -0.2233, -PI / 2, -90.0)           # icub.md section 4 (eye v2)

# Right arm, chain links 3-9 (icub.md section 3, "right_v2": d7 = -0.1413, d9 = 0.02598).
ARM_R_V2_DH = [
    ("r_shoulder_pitch", 0.0, -0.10774, +PI / 2, -90.0, -95.5, 5.0),
    ("r_shoulder_roll", 0.0, 0.0, -PI / 2, -90.0, 0.0, 160.8),
    ("r_shoulder_yaw", -0.015, -0.15228, -PI / 2, -105.0, -37.0, 100.0),
    ("r_elbow", 0.015, 0.0, +PI / 2, 0.0, 5.5, 106.0),
    ("r_wrist_prosup", 0.0, -0.1413, +PI / 2, -90.0, -50.0, 50.0),
    ("r_wrist_pitch", 0.0, 0.0, +PI / 2, 90.0, -65.0, 10.0),
    ("r_wrist_yaw", 0.0625, 0.02598, 0.0, 180.0, -25.0, 25.0),
]

# Head / left eye, chain links 3-7 (icub.md section 4, "left_v2"). Links 6-7 (eyes) are kept at
# zero in the URDF: they only place the fixed l_eye / r_eye frames (right eye: link 6 d = +0.034).
EYE_L_V2_DH = [
    ("neck_pitch", 0.0095, 0.0, +PI / 2, 90.0, -40.0, 30.0),
    ("neck_roll", 0.0, 0.0, -PI / 2, -90.0, -70.0, 60.0),
    ("neck_yaw", -0.0509, 0.08205, -PI / 2, 90.0, -55.0, 55.0),
    ("eyes_tilt", 0.0, -0.034, -PI / 2, 0.0, -35.0, 15.0),
    ("l_eye_pan", 0.0, 0.0, +PI / 2, -90.0, -50.0, 50.0),
]
RIGHT_EYE_LINK6_D = +0.034

# icub.md section 10 / thesis Alg. 7: helmet RGB-D depth origin in the LEFT-EYE frame at eyes = 0,
# pure translation (camera axes parallel to the eye frame = OpenCV optical frame).
# p_eye = p_cam + t  ->  camera origin in the eye frame is t.
CAMERA_IN_LEFT_EYE = (0.034 - 0.0175, -0.11564, 0.02673)

# ----------------------------------------------------------------------------------------------
# 2. Small 4x4 / 3x3 matrix toolkit (lists of lists).
# ----------------------------------------------------------------------------------------------


def mmul(A, B):
    return [[sum(A[i][k] * B[k][j] for k in range(len(B))) for j in range(len(B[0]))]
            for i in range(len(A))]


def eye4():
    return [[1.0 if i == j else 0.0 for j in range(4)] for i in range(4)]


def trans(x, y, z):
    T = eye4()
    T[0][3], T[1][3], T[2][3] = x, y, z
    return T


def rotx(t):
    c, s = math.cos(t), math.sin(t)
    return [[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]]


def roty(t):
    c, s = math.cos(t), math.sin(t)
    return [[c, 0, s, 0], [0, 1, 0, 0], [-s, 0, c, 0], [0, 0, 0, 1.0]]


def rotz(t):
    c, s = math.cos(t), math.sin(t)
    return [[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]]


def chain(*Ts):
    out = eye4()
    for T in Ts:
        out = mmul(out, T)
    return out


def dh_fixed(a, d, alpha):
    """Fixed part of a DH link: Tz(d) Tx(a) Rx(alpha)."""
    return chain(trans(0, 0, d), trans(a, 0, 0), rotx(alpha))


def dh_link(q, a, d, alpha, offset):
    """Full iKin link transform; q and offset in radians."""
    return chain(rotz(q + offset), dh_fixed(a, d, alpha))


def inv(T):
    R = [[T[j][i] for j in range(3)] for i in range(3)]
    p = [-sum(R[i][k] * T[k][3] for k in range(3)) for i in range(3)]
    return [R[0] + [p[0]], R[1] + [p[1]], R[2] + [p[2]], [0, 0, 0, 1.0]]


def rot_of(T):
    return [row[:3] for row in T[:3]]


def pos_of(T):
    return [T[0][3], T[1][3], T[2][3]]


def from_rp(R, p):
    return [list(R[0]) + [p[0]], list(R[1]) + [p[1]], list(R[2]) + [p[2]], [0, 0, 0, 1.0]]


def rpy_from_R(R):
    """(roll, pitch, yaw) with R = Rz(yaw) Ry(pitch) Rx(roll) (URDF convention)."""
    cp = math.hypot(R[0][0], R[1][0])
    pitch = math.atan2(-R[2][0], cp)
    if cp > 1e-9:
        roll = math.atan2(R[2][1], R[2][2])
        yaw = math.atan2(R[1][0], R[0][0])
    else:  # gimbal lock: pitch = +-90 deg, put everything into yaw
        roll = 0.0
        yaw = math.atan2(-R[0][1], R[1][1])
    return roll, pitch, yaw


def R_from_rpy(r, p, y):
    return rot_of(chain(rotz(y), roty(p), rotx(r)))


def vsub(a, b):
    return [a[i] - b[i] for i in range(3)]


def vadd(a, b):
    return [a[i] + b[i] for i in range(3)]


def vscale(a, s):
    return [x * s for x in a]


def vdot(a, b):
    return sum(a[i] * b[i] for i in range(3))


def vcross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def vnorm(a):
    return math.sqrt(vdot(a, a))


def vunit(a):
    n = vnorm(a)
    return [x / n for x in a]


def mat3_mul(A, B):
    return [[sum(A[i][k] * B[k][j] for k in range(3)) for j in range(3)] for i in range(3)]


def mat3_T(A):
    return [[A[j][i] for j in range(3)] for i in range(3)]


def mat3_vec(A, v):
    return [sum(A[i][k] * v[k] for k in range(3)) for i in range(3)]


def axis_angle_R(axis, angle):
    x, y, z = vunit(axis)
    c, s = math.cos(angle), math.sin(angle)
    C = 1 - c
    return [[c + x * x * C, x * y * C - z * s, x * z * C + y * s],
            [y * x * C + z * s, c + y * y * C, y * z * C - x * s],
            [z * x * C - y * s, z * y * C + x * s, c + z * z * C]]


def frame_z_along(u):
    """Rotation whose z column is the unit vector u (x, y columns chosen deterministically)."""
    z = vunit(u)
    helper = [1.0, 0.0, 0.0] if abs(z[0]) < 0.9 else [0.0, 1.0, 0.0]
    x = vunit(vcross(helper, z))
    y = vcross(z, x)
    return [[x[0], y[0], z[0]], [x[1], y[1], z[1]], [x[2], y[2], z[2]]]


def jacobi_eig3(A, sweeps=60):
    """Eigen-decomposition of a symmetric 3x3 matrix: returns (values, V) with A = V diag V^T."""
    A = [row[:] for row in A]
    V = [[1.0 if i == j else 0.0 for j in range(3)] for i in range(3)]
    for _ in range(sweeps):
        off = abs(A[0][1]) + abs(A[0][2]) + abs(A[1][2])
        if off < 1e-22:
            break
        for p, q in ((0, 1), (0, 2), (1, 2)):
            if abs(A[p][q]) < 1e-30:
                continue
            theta = (A[q][q] - A[p][p]) / (2 * A[p][q])
            t = (1.0 if theta >= 0 else -1.0) / (abs(theta) + math.sqrt(theta * theta + 1))
            c = 1 / math.sqrt(t * t + 1)
            s = t * c
            for k in range(3):  # A <- A J
                akp, akq = A[k][p], A[k][q]
                A[k][p] = c * akp - s * akq
                A[k][q] = s * akp + c * akq
            for k in range(3):  # A <- J^T A
                apk, aqk = A[p][k], A[q][k]
                A[p][k] = c * apk - s * aqk
                A[q][k] = s * apk + c * aqk
            for k in range(3):
                vkp, vkq = V[k][p], V[k][q]
                V[k][p] = c * vkp - s * vkq
                V[k][q] = s * vkp + c * vkq
    vals = [A[0][0], A[1][1], A[2][2]]
    det = (V[0][0] * (V[1][1] * V[2][2] - V[1][2] * V[2][1])
           - V[0][1] * (V[1][0] * V[2][2] - V[1][2] * V[2][0])
           + V[0][2] * (V[1][0] * V[2][1] - V[1][1] * V[2][0]))
    if det < 0:
        for k in range(3):
            V[k][2] = -V[k][2]
    return vals, V


# ----------------------------------------------------------------------------------------------
# 3. Model containers.
# ----------------------------------------------------------------------------------------------

MATERIALS = {
    # name: rgba
    "icub_white": (0.92, 0.92, 0.90, 1.0),     # plastic covers
    "icub_grey": (0.62, 0.63, 0.66, 1.0),      # palm, fingers, inner structure
    "icub_black": (0.10, 0.10, 0.11, 1.0),     # joints, neck, waist
    "helmet_black": (0.03, 0.03, 0.03, 1.0),   # helmet and camera mount
    "camera_grey": (0.22, 0.23, 0.26, 1.0),    # RealSense case
    "eye_white": (0.97, 0.97, 0.97, 1.0),
    "pupil_black": (0.0, 0.0, 0.0, 1.0),
}


class Link:
    def __init__(self, name, mass=0.0):
        self.name = name
        self.mass = mass
        self.geoms = []          # dicts: kind, size, T (in link frame), material, name, collide
        self.inertial = None     # (T_com_principal, [ixx, iyy, izz])


class Joint:
    def __init__(self, name, jtype, parent, child, T, axis=(0.0, 0.0, 1.0),
                 lower=None, upper=None, effort=None, velocity=None, damping=None):
        self.name, self.type, self.parent, self.child = name, jtype, parent, child
        self.T, self.axis = T, list(axis)
        self.lower, self.upper, self.effort, self.velocity = lower, upper, effort, velocity
        self.damping = damping


class Robot:
    def __init__(self):
        self.links = {}
        self.link_order = []
        self.joints = []

    def add_link(self, name, mass):
        link = Link(name, mass)
        self.links[name] = link
        self.link_order.append(name)
        return link

    def add_joint(self, joint):
        self.joints.append(joint)
        return joint

    def joint(self, name):
        return next(j for j in self.joints if j.name == name)

    def movable(self):
        return [j for j in self.joints if j.type == "revolute"]

    def fk(self, q=None):
        """World (root) pose of every link; q: {joint name: rad}."""
        q = q or {}
        X = {"root_link": eye4()}
        for j in self.joints:  # joints are added parent-first
            T = mmul(X[j.parent], j.T)
            if j.type == "revolute":
                R = axis_angle_R(j.axis, q.get(j.name, 0.0))
                T = mmul(T, from_rp(R, [0, 0, 0]))
            X[j.child] = T
        return X

    def subtree(self, link_name):
        out = [link_name]
        for j in self.joints:
            if j.parent in out and j.child not in out:
                out.append(j.child)
        return out


# ----------------------------------------------------------------------------------------------
# 4. Kinematic tree.
# ----------------------------------------------------------------------------------------------

R2D = 180.0 / PI
D2R = PI / 180.0

# Effort [Nm] and velocity [rad/s] per joint (brief: shoulder ~40, elbow 20, wrist 5, torso 40-80,
# neck 10, fingers 1-2 Nm; 2-3 rad/s, fingers faster).
EFFORT_VEL = {
    "torso_pitch": (80.0, 2.0), "torso_roll": (60.0, 2.0), "torso_yaw": (40.0, 2.0),
    "r_shoulder_pitch": (40.0, 2.5), "r_shoulder_roll": (40.0, 2.5), "r_shoulder_yaw": (30.0, 2.5),
    "r_elbow": (20.0, 2.5), "r_wrist_prosup": (5.0, 3.0), "r_wrist_pitch": (5.0, 3.0),
    "r_wrist_yaw": (5.0, 3.0),
    "neck_pitch": (10.0, 3.0), "neck_roll": (10.0, 3.0), "neck_yaw": (10.0, 3.0),
}
FINGER_EFFORT, FINGER_VEL = 1.5, 6.0
THUMB_OPPOSE_EFFORT = 2.0


def build_kinematics(robot):
    """Links/joints of torso, right arm, head; returns nothing (fills robot)."""
    mk = robot.add_link
    J = robot.add_joint

    def rev(name, parent, child, T, lo_deg, hi_deg):
        eff, vel = EFFORT_VEL[name]
        return J(Joint(name, "revolute", parent, child, T, (0, 0, 1),
                       lo_deg * D2R, hi_deg * D2R, eff, vel))

    mk("root_link", 5.091)
    # --- torso (chain links 0, 1, 2) ---
    name, a0, d0, al0, off0, lo, hi = TORSO_DH[0]
    mk("torso_1", 0.6714)
    rev("torso_pitch", "root_link", "torso_1", mmul(H0, rotz(off0 * D2R)), lo, hi)
    name, a1, d1, al1, off1, lo, hi = TORSO_DH[1]
    mk("torso_2", 0.4257)
    rev("torso_roll", "torso_1", "torso_2", mmul(dh_fixed(a0, d0, al0), rotz(off1 * D2R)), lo, hi)
    mk("chest", 7.638)
    # chest = DH frame 2 . Rz(q_yaw): the yaw offset lives in each branch (icub.md section 3).
    rev("torso_yaw", "torso_2", "chest", dh_fixed(a1, d1, al1), *TORSO_YAW_LIMITS_DEG)

    # --- right arm (chain links 3..9) ---
    arm_links = ["r_shoulder_1", "r_shoulder_2", "r_shoulder_3", "r_elbow_1", "r_forearm",
                 "r_wrist_1", "r_hand"]
    arm_masses = [0.1149, 0.2382, 0.3591, 0.2679, 0.6347, 0.0363, 0.2483]  # icub.md section 8
    _, a2, d2, al2, off2 = ARM_LINK2
    prev_fixed = mmul(rotz(off2 * D2R), dh_fixed(a2, d2, al2))
    parent = "chest"
    for (name, a, d, al, off, lo, hi), child, m in zip(ARM_R_V2_DH, arm_links, arm_masses):
        mk(child, m)
        rev(name, parent, child, mmul(prev_fixed, rotz(off * D2R)), lo, hi)
        if child == "r_shoulder_3":
            # fixed upper-arm cover (as in the iCub URDF: r_shoulder_3 -> r_upper_arm, fixed)
            mk("r_upper_arm", 0.7451)
            J(Joint("r_upper_arm_fixed_joint", "fixed", "r_shoulder_3", "r_upper_arm", eye4()))
        prev_fixed = dh_fixed(a, d, al)
        parent = child
    # palm end-effector frame (iKin EE, icub.md section 7): after the fixed part of link 9
    mk("r_hand_dh_frame", 0.001)
    J(Joint("r_hand_dh_frame_fixed_joint", "fixed", "r_hand", "r_hand_dh_frame", prev_fixed))

    # --- head (chain links 3..5) ---
    _, a2, d2, al2, off2 = HEAD_LINK2
    prev_fixed = mmul(rotz(off2 * D2R), dh_fixed(a2, d2, al2))
    parent = "chest"
    for (name, a, d, al, off, lo, hi), child, m in zip(EYE_L_V2_DH[:3], ["neck_1", "neck_2", "head"],
                                                      [0.1258, 0.1771, 1.507]):
        mk(child, m)
        rev(name, parent, child, mmul(prev_fixed, rotz(off * D2R)), lo, hi)
        prev_fixed = dh_fixed(a, d, al)
        parent = child
    # prev_fixed = head link -> DH frame 6 (head centre, between the eyes)
    head_to_f6 = prev_fixed
    _, a6, d6, al6, off6, _, _ = EYE_L_V2_DH[3]
    _, a7, d7, al7, off7, _, _ = EYE_L_V2_DH[4]
    f6_to_leye = mmul(dh_link(0.0, a6, d6, al6, off6 * D2R), dh_link(0.0, a7, d7, al7, off7 * D2R))
    f6_to_reye = mmul(dh_link(0.0, a6, RIGHT_EYE_LINK6_D, al6, off6 * D2R),
                      dh_link(0.0, a7, d7, al7, off7 * D2R))
    head_to_leye = mmul(head_to_f6, f6_to_leye)
    mk("l_eye", 0.01)
    J(Joint("l_eye_fixed_joint", "fixed", "head", "l_eye", head_to_leye))
    mk("r_eye", 0.01)
    J(Joint("r_eye_fixed_joint", "fixed", "head", "r_eye", mmul(head_to_f6, f6_to_reye)))
    # helmet (black cap + camera mount, mass assumed) as its own fixed link so that every link
    # has a single colour (MuJoCo's URDF import paints collision geoms with the link's last
    # visual material)
    mk("helmet", 0.12)
    J(Joint("helmet_fixed_joint", "fixed", "head", "helmet", eye4()))
    # helmet camera: left-eye frame (eyes at zero) translated by the thesis offset, same axes
    mk("helmet_camera", 0.072)  # D435 mass
    J(Joint("helmet_camera_fixed_joint", "fixed", "head", "helmet_camera",
            mmul(head_to_leye, trans(*CAMERA_IN_LEFT_EYE))))
    return head_to_f6


# ----------------------------------------------------------------------------------------------
# 5. Right hand (fingers).  Hand geometry is written in the palm frame r_hand_dh_frame (P):
#    x_P toward the fingertips, y_P from thumb side toward the little finger, z_P out of the palm.
#    r_hand's own frame is parallel to P (DH link 9 has alpha = 0), origin at the wrist centre.
# ----------------------------------------------------------------------------------------------

PALM_IN_RHAND = (0.0625, 0.0, 0.02598)          # = (a9, 0, d9), icub.md section 3
PALM_BOX_CENTER_P = (-0.0195, 0.0, 0.002)        # palm box 0.069 x 0.065 x 0.022 (icub.md s. 8)
PALM_BOX_SIZE = (0.069, 0.065, 0.022)            # -> x in [-0.054, 0.015], z in [-0.009, 0.013]
# heel of the palm (thenar/hypothenar pad) toward the wrist: cradles the handle on its -x side
PALM_HEEL_CENTER_P = (-0.037, 0.0, 0.017)
PALM_HEEL_SIZE = (0.026, 0.065, 0.008)            # x in [-0.050, -0.024], z in [0.013, 0.021]
GRASP_CYL_CENTER_P = (0.0, 0.0, 0.030)           # handle axis centre (TA convention, icub.md s. 8)
GRASP_CYL_AXIS_P = (0.0, 1.0, 0.0)               # handle axis along y_P
GRASP_CYL_RADIUS, GRASP_CYL_LENGTH = 0.016, 0.080  # thesis handle template

FINGER_FLEX_AXIS = (0.0, -1.0, 0.0)   # rotation about -y_P: +x_P (finger) turns toward +z_P
# (name, base in P, proximal length, distal length (middle + tip phalanx), radius)
# Lengths from icub.md section 7 (URDF phalanges: proximal; middle + 0.0168 tip).
FINGERS = [
    ("index", (0.015, -0.024, 0.0055), 0.0259, 0.0220 + 0.0168, 0.0075),
    ("middle", (0.015, -0.008, 0.0055), 0.0258, 0.0240 + 0.0168, 0.0075),
    ("ring", (0.015, 0.008, 0.0055), 0.0259, 0.0220 + 0.0168, 0.0075),
    ("little", (0.012, 0.024, 0.0055), 0.0219, 0.0190 + 0.0168, 0.0065),
]
FINGER_LIMITS_DEG = (0.0, 90.0)
# Thumb: base on the palm's thumb (-y) side, between the wrist and the handle; at q = 0 it lies
# in the palm plane pointing along -y_P (tilted THUMB_SPLAY_DEG toward +x_P): open hand.
# r_thumb_oppose turns it about -x_P: at 90 deg it stands along +z_P on the wrist side of the
# handle, at the 110 deg limit it leans 20 deg over the palm (+y_P) so that it presses the handle
# near the index/middle fingers rather than at the handle's end.  Proximal/distal flex about the
# thumb's own +z (~ +y_P once opposed), curling it over the handle toward +x_P, against the
# fingers that curl over it from the +x_P side.  Close in two steps: hand_preshape (oppose),
# then hand_closed (see README.md).
THUMB_BASE_P = (-0.027, -0.030, 0.0055)
THUMB_SPLAY_DEG = 0.0
THUMB_L1, THUMB_L2, THUMB_R = 0.026, 0.022 + 0.0168, 0.008
THUMB_OPPOSE_AXIS = (-1.0, 0.0, 0.0)
THUMB_FLEX_AXIS = (0.0, 0.0, 1.0)
THUMB_OPPOSE_LIMITS_DEG = (0.0, 110.0)
THUMB_FLEX_LIMITS_DEG = (0.0, 90.0)
PHALANX_MASS = 0.015
THUMB_METACARPAL_MASS = 0.012


def build_hand(robot):
    J = robot.add_joint
    off = PALM_IN_RHAND

    def in_rhand(p):
        return trans(p[0] + off[0], p[1] + off[1], p[2] + off[2])

    def flex(name, parent, child, T, axis, lo, hi, effort=FINGER_EFFORT):
        robot.add_link(child, PHALANX_MASS)
        J(Joint(name, "revolute", parent, child, T, axis, lo * D2R, hi * D2R, effort, FINGER_VEL))

    hand = {}
    for name, base, l1, l2, r in FINGERS:
        prox, dist = "r_%s_proximal_phalanx" % name, "r_%s_distal_phalanx" % name
        flex("r_%s_proximal" % name, "r_hand", prox, in_rhand(base), FINGER_FLEX_AXIS,
             *FINGER_LIMITS_DEG)
        flex("r_%s_distal" % name, prox, dist, trans(l1, 0, 0), FINGER_FLEX_AXIS, *FINGER_LIMITS_DEG)
        hand[name] = (base, l1, l2, r)
    # thumb
    sp = THUMB_SPLAY_DEG * D2R
    d0 = [math.sin(sp), -math.cos(sp), 0.0]
    robot.add_link("r_thumb_metacarpal", THUMB_METACARPAL_MASS)
    J(Joint("r_thumb_oppose", "revolute", "r_hand", "r_thumb_metacarpal", in_rhand(THUMB_BASE_P),
            THUMB_OPPOSE_AXIS, THUMB_OPPOSE_LIMITS_DEG[0] * D2R, THUMB_OPPOSE_LIMITS_DEG[1] * D2R,
            THUMB_OPPOSE_EFFORT, FINGER_VEL))
    flex("r_thumb_proximal", "r_thumb_metacarpal", "r_thumb_proximal_phalanx", eye4(),
         THUMB_FLEX_AXIS, *THUMB_FLEX_LIMITS_DEG)
    flex("r_thumb_distal", "r_thumb_proximal_phalanx", "r_thumb_distal_phalanx",
         trans(*vscale(d0, THUMB_L1)), THUMB_FLEX_AXIS, *THUMB_FLEX_LIMITS_DEG)
    hand["thumb"] = (THUMB_BASE_P, THUMB_L1, THUMB_L2, THUMB_R, d0)
    return hand


# ----------------------------------------------------------------------------------------------
# 6. Geometry (primitives only).  Body-part primitives are written in ROOT coordinates at the
#    zero pose and converted to link coordinates; hand parts are written in the palm frame P.
# ----------------------------------------------------------------------------------------------


class GeomBuilder:
    def __init__(self, robot):
        self.robot = robot
        self.X0 = robot.fk({})            # zero-pose link frames in root
        self.count = {}

    def _add(self, link, kind, size, T_root, material, collide=True, mass_weight=None, tag=None):
        T_link = mmul(inv(self.X0[link]), T_root)
        n = self.count.get(link, 0)
        self.count[link] = n + 1
        g = {"kind": kind, "size": size, "T": T_link, "material": material, "collide": collide,
             "name": "%s_%s%d" % (link, tag or kind, n), "mass_weight": mass_weight}
        self.robot.links[link].geoms.append(g)
        return g

    # --- primitives in root coordinates (zero pose) ---
    def box(self, link, center, size, material, R=None, collide=True):
        R = R or [[1, 0, 0], [0, 1, 0], [0, 0, 1]]
        return self._add(link, "box", tuple(size), from_rp(R, center), material, collide)

    def sphere(self, link, center, r, material, collide=True, mass=True):
        g = self._add(link, "sphere", (r,), trans(*center), material, collide)
        if not mass:
            g["mass_weight"] = 0.0
        return g

    def cylinder(self, link, p1, p2, r, material, collide=True):
        u = vsub(p2, p1)
        c = vscale(vadd(p1, p2), 0.5)
        return self._add(link, "cylinder", (r, vnorm(u)), from_rp(frame_z_along(u), c),
                         material, collide)

    def capsule(self, link, p1, p2, r, material, collide=True):
        """Cylinder + two end spheres (separate elements); inertia uses the capsule as one body."""
        cyl = self.cylinder(link, p1, p2, r, material, collide)
        cyl["capsule"] = True
        s1 = self.sphere(link, p1, r, material, collide, mass=False)
        s2 = self.sphere(link, p2, r, material, collide, mass=False)
        return cyl

    # --- helpers for hand coordinates ---
    def palm_to_root(self, p):
        X = self.X0["r_hand_dh_frame"]
        return vadd(pos_of(X), mat3_vec(rot_of(X), p))

    def palm_R(self):
        return rot_of(self.X0["r_hand_dh_frame"])


def build_geometry(robot, hand):
    G = GeomBuilder(robot)
    X0 = G.X0
    P = lambda link: pos_of(X0[link])  # noqa: E731

    # -- root_link: pelvis block (legs are not modelled) --
    G.box("root_link", (0.0, 0.0, -0.045), (0.10, 0.15, 0.09), "icub_white")
    # -- torso_1: hip/pitch-joint housing, cylinder along the torso-pitch axis (root y) --
    G.cylinder("torso_1", (0.0, -0.055, 0.0), (0.0, 0.055, 0.0), 0.035, "icub_black")
    # -- torso_2: waist, vertical cylinder between pitch and chest --
    G.cylinder("torso_2", (0.0, 0.0, 0.035), (0.0, 0.0, 0.075), 0.045, "icub_black")
    # -- chest: main box + shoulder-height upper block + neck base --
    G.box("chest", (-0.002, 0.0, 0.160), (0.110, 0.150, 0.160), "icub_white")
    # -- right shoulder: pitch housing along the (15 deg tilted) shoulder-pitch axis --
    sh = P("r_shoulder_2")                        # shoulder centre (DH frames 4 = 5)
    z3 = rot_of(X0["r_shoulder_1"])               # shoulder-pitch axis = z of r_shoulder_1
    axis3 = [z3[0][2], z3[1][2], z3[2][2]]        # points from the shoulder toward the chest
    G.cylinder("r_shoulder_1", vadd(sh, vscale(axis3, 0.047)), vadd(sh, vscale(axis3, 0.031)),
               0.031, "icub_black")
    G.sphere("r_shoulder_2", sh, 0.031, "icub_black")
    # upper arm: shoulder_3 carries the top of it, r_upper_arm the cover down to the elbow
    elbow = P("r_forearm")                        # DH frame 7: elbow point on the forearm axis
    G.cylinder("r_shoulder_3", vadd(sh, (0, 0, -0.030)), vadd(sh, (0, 0, -0.060)), 0.028,
               "icub_black")
    G.capsule("r_upper_arm", vadd(sh, (0, 0, -0.060)), vadd(elbow, (0, 0, 0.040)), 0.026,
              "icub_white")
    # elbow joint: cylinder along the elbow axis (z of r_elbow_1) through DH frame 6
    z6 = rot_of(X0["r_elbow_1"])
    axis6 = [z6[0][2], z6[1][2], z6[2][2]]
    e6 = P("r_elbow_1")
    G.cylinder("r_elbow_1", vadd(e6, vscale(axis6, -0.024)), vadd(e6, vscale(axis6, 0.024)),
               0.024, "icub_black")
    # forearm (r 0.020, icub.md section 8) from just below the elbow to the wrist
    wrist = P("r_wrist_1")
    G.capsule("r_forearm", vadd(elbow, (0, 0, -0.012)), vadd(wrist, (0, 0, 0.030)), 0.020,
              "icub_white")
    G.sphere("r_wrist_1", wrist, 0.016, "icub_black")

    # -- right hand: palm box in P, fingers as capsules in P --
    RP = G.palm_R()
    G.box("r_hand", G.palm_to_root(PALM_BOX_CENTER_P), PALM_BOX_SIZE, "icub_grey", R=RP)
    G.box("r_hand", G.palm_to_root(PALM_HEEL_CENTER_P), PALM_HEEL_SIZE, "icub_grey", R=RP)
    for name, (base, l1, l2, r) in ((k, v) for k, v in hand.items() if k != "thumb"):
        b = list(base)
        j = vadd(b, (l1, 0, 0))
        t = vadd(j, (l2, 0, 0))
        G.capsule("r_%s_proximal_phalanx" % name, G.palm_to_root(b), G.palm_to_root(j), r,
                  "icub_grey")
        G.capsule("r_%s_distal_phalanx" % name, G.palm_to_root(j), G.palm_to_root(t), r * 0.95,
                  "icub_white")
    base, l1, l2, r, d0 = hand["thumb"]
    j = vadd(list(base), vscale(d0, l1))
    t = vadd(j, vscale(d0, l2))
    G.sphere("r_thumb_metacarpal", G.palm_to_root(base), 0.0095, "icub_grey")
    G.capsule("r_thumb_proximal_phalanx", G.palm_to_root(base), G.palm_to_root(j), r, "icub_grey")
    G.capsule("r_thumb_distal_phalanx", G.palm_to_root(j), G.palm_to_root(t), r * 0.95,
              "icub_white")

    # -- neck and head --
    n1 = P("neck_1")                   # neck-pitch axis point (axis = z of neck_1, along root y)
    G.cylinder("neck_1", vadd(n1, (0, -0.022, 0)), vadd(n1, (0, 0.022, 0)), 0.018, "icub_black")
    n2 = P("neck_2")
    hc = P("head")                     # neck-yaw joint point
    G.cylinder("neck_2", vadd(n2, (0, 0, 0.010)), (hc[0], hc[1], hc[2] - 0.020), 0.022,
               "icub_black")
    eyec = vscale(vadd(P("l_eye"), P("r_eye")), 0.5)        # head centre (DH frame 6)
    skull = (eyec[0] + 0.068, 0.0, eyec[2] + 0.008)
    G.sphere("head", skull, 0.075, "icub_white")
    # helmet: black cap on the skull and a mount under the camera
    G.cylinder("helmet", (skull[0], 0, skull[2] + 0.045), (skull[0], 0, skull[2] + 0.077), 0.074,
               "helmet_black")
    cam = P("helmet_camera")
    G.box("helmet", (cam[0] + 0.030, 0.0, (cam[2] - 0.0125 + skull[2] + 0.077) / 2),
          (0.050, 0.050, cam[2] - 0.0125 - (skull[2] + 0.077)), "helmet_black")
    # eyes: eyeballs r 0.0125 (white) with pupils (visual only) along the optical axis (+z_eye)
    for eye in ("l_eye", "r_eye"):
        pe = P(eye)
        Re = rot_of(X0[eye])
        zc = [Re[0][2], Re[1][2], Re[2][2]]
        G.sphere(eye, vadd(pe, vscale(zc, 0.0095)), 0.0045, "pupil_black", collide=False,
                 mass=False)
        G.sphere(eye, pe, 0.0125, "eye_white")
    # helmet camera: RealSense case 90 x 25 x 25 mm; the depth origin is 17.5 mm from the case
    # centre toward -x_cam and 4.2 mm behind the front glass (icub.md section 10, RSx).  The
    # 4.7 mm in front of the optical origin is left out so the camera never renders its own case.
    Rc = rot_of(X0["helmet_camera"])
    c_cam = [0.0175, 0.0, -0.0005 - 0.0203 / 2]
    G.box("helmet_camera", vadd(cam, mat3_vec(Rc, c_cam)), (0.090, 0.025, 0.0203), "camera_grey",
          R=Rc)
    return G


def add_left_arm(robot, home):
    """Left arm, fixed on the chest in the given posture of the right arm (`home`): every right-arm link (shoulder to
    fingertips) mirrored through the sagittal plane (root y -> -y) and renamed r_* -> l_*.
    A reflection of a box/cylinder/sphere pose (p, R) is the same primitive at (M p, M R M)."""
    Xh = robot.fk(home)
    Xchest = Xh["chest"]  # torso at 0 in `home`: the zero-pose chest frame
    M = [[1, 0, 0], [0, -1, 0], [0, 0, 1]]

    def mirror(T):
        return from_rp(mat3_mul(mat3_mul(M, rot_of(T)), M), mat3_vec(M, pos_of(T)))

    for ln in robot.subtree("r_shoulder_1"):
        src = robot.links[ln]
        if not src.geoms:
            continue  # r_hand_dh_frame
        name = "l_" + ln[2:]
        link = robot.add_link(name, src.mass)
        T_link_root = mirror(Xh[ln])
        robot.add_joint(Joint(name + "_fixed_joint", "fixed", "chest", name,
                              mmul(inv(Xchest), T_link_root)))
        for g in src.geoms:
            ng = dict(g)
            ng["T"] = mmul(inv(T_link_root), mirror(mmul(Xh[ln], g["T"])))
            ng["name"] = "l_" + g["name"][2:]
            link.geoms.append(ng)


# ----------------------------------------------------------------------------------------------
# 7. Inertia from the primitives: mass of each link spread over its primitives by volume
#    (capsule = cylinder + two hemispheres counted once), parallel-axis composition, then
#    principal axes (diagonal inertia at the centre of mass).
# ----------------------------------------------------------------------------------------------


def prim_volume_inertia(g):
    """(volume, [Ixx, Iyy, Izz] per unit mass) in the primitive's own frame."""
    k, s = g["kind"], g["size"]
    if k == "box":
        a, b, c = s
        return a * b * c, [(b * b + c * c) / 12, (a * a + c * c) / 12, (a * a + b * b) / 12]
    if k == "sphere":
        r = s[0]
        return 4.0 / 3.0 * PI * r ** 3, [0.4 * r * r] * 3
    if k == "cylinder" and g.get("capsule"):
        r, h = s
        vc, vh = PI * r * r * h, 4.0 / 3.0 * PI * r ** 3
        v = vc + vh
        mc, mh = vc / v, vh / v  # unit total mass
        izz = mc * r * r / 2 + mh * 0.4 * r * r
        ixx = (mc * (h * h / 12 + r * r / 4)
               + mh * (0.4 * r * r + h * h / 4 + 3.0 * h * r / 8))
        return v, [ixx, ixx, izz]
    if k == "cylinder":
        r, h = s
        return PI * r * r * h, [(3 * r * r + h * h) / 12] * 2 + [r * r / 2]
    raise ValueError(k)


def compute_inertials(robot):
    for link in robot.links.values():
        prims = [g for g in link.geoms if g.get("mass_weight") != 0.0 and g["collide"]]
        if not prims:  # pure frames: a tiny sphere of radius 5 mm
            r = 0.005
            i = 0.4 * link.mass * r * r
            link.inertial = (eye4(), [i, i, i])
            continue
        vols = [prim_volume_inertia(g) for g in prims]
        vtot = sum(v for v, _ in vols)
        masses = [link.mass * v / vtot for v, _ in vols]
        com = [0.0, 0.0, 0.0]
        for g, m in zip(prims, masses):
            com = vadd(com, vscale(pos_of(g["T"]), m / link.mass))
        I = [[0.0] * 3 for _ in range(3)]
        for g, m, (v, iu) in zip(prims, masses, vols):
            R = rot_of(g["T"])
            Ic = mat3_mul(mat3_mul(R, [[iu[0] * m, 0, 0], [0, iu[1] * m, 0], [0, 0, iu[2] * m]]),
                          mat3_T(R))
            d = vsub(pos_of(g["T"]), com)
            dd = vdot(d, d)
            for a in range(3):
                for b in range(3):
                    I[a][b] += Ic[a][b] + m * ((dd if a == b else 0.0) - d[a] * d[b])
        vals, V = jacobi_eig3(I)
        link.inertial = (from_rp(V, com), vals)


# ----------------------------------------------------------------------------------------------
# 8. Gains (sidecar) and damping (URDF): sampled over the joint ranges with the model itself.
# ----------------------------------------------------------------------------------------------

GRAVITY = 9.81
SAG_RAD = 1.0 * D2R            # kp so that the worst-case gravity torque sags < 1 deg
DT = 0.002                     # MuJoCo step the gains are designed for
OMEGA_DT_MAX = 0.25            # keep sqrt(kp / I_min) * dt below this (explicit kp term)
ZETA = 1.0                     # damping ratio at the largest reflected inertia (over-damped else)
KP_FLOOR = {"torso": 300.0, "r_shoulder": 300.0, "r_elbow": 150.0, "r_wrist": 20.0,
            "neck": 30.0}
ARMATURE_BASE = {"torso": 0.05, "r_shoulder": 0.03, "r_elbow": 0.02, "r_wrist": 0.005,
                 "neck": 0.01}
FINGER_KP, THUMB_OPPOSE_KP, FINGER_ARMATURE = 2.0, 2.0, 1.0e-4


def nice_up(x):
    """Round up to 1, 1.2, 1.5, 2, 2.5, 3, 4, 5, 6, 8 x 10^k."""
    if x <= 0:
        return 0.0
    e = math.floor(math.log10(x))
    for m in (1, 1.2, 1.5, 2, 2.5, 3, 4, 5, 6, 8, 10):
        if m * 10 ** e >= x * (1 - 1e-12):
            return float("%.6g" % (m * 10 ** e))
    return 10.0 ** (e + 1)


def link_world_inertia(robot, X, ln):
    link = robot.links[ln]
    Tc, vals = link.inertial
    Tw = mmul(X[ln], Tc)
    R = rot_of(Tw)
    I = mat3_mul(mat3_mul(R, [[vals[0], 0, 0], [0, vals[1], 0], [0, 0, vals[2]]]), mat3_T(R))
    return pos_of(Tw), I


def joint_loads(robot, q):
    """Per movable joint: (reflected inertia about the axis [kg m^2], gravity torque [Nm])."""
    X = robot.fk(q)
    out = {}
    parent_X = {}
    for j in robot.joints:
        parent_X[j.name] = mmul(X[j.parent], j.T)
    cache = {ln: link_world_inertia(robot, X, ln) for ln in robot.links}
    for j in robot.movable():
        Tj = parent_X[j.name]
        a = mat3_vec(rot_of(Tj), j.axis)
        pj = pos_of(Tj)
        Ieff, tau = 0.0, 0.0
        for ln in robot.subtree(j.child):
            m = robot.links[ln].mass
            c, Iw = cache[ln]
            r = vsub(c, pj)
            ar = vcross(a, r)
            Ieff += m * vdot(ar, ar) + vdot(a, mat3_vec(Iw, a))
            tau += vdot(a, vcross(r, [0.0, 0.0, -GRAVITY * m]))
        out[j.name] = (Ieff, abs(tau))
    return out


def group_of(jname):
    for g in ("torso", "r_shoulder", "r_elbow", "r_wrist", "neck"):
        if jname.startswith(g):
            return g
    return "finger"


def design_gains(robot, samples=1500, seed=7):
    rng = random.Random(seed)
    mov = robot.movable()
    stats = {j.name: [float("inf"), 0.0, 0.0] for j in mov}   # I_min, I_max, tau_max
    for k in range(samples):
        if k == 0:
            q = {}
        else:
            q = {j.name: rng.uniform(j.lower, j.upper) for j in mov}
        for name, (I, tau) in joint_loads(robot, q).items():
            s = stats[name]
            s[0], s[1], s[2] = min(s[0], I), max(s[1], I), max(s[2], tau)
    gains = {}
    for j in mov:
        I_min, I_max, tau = stats[j.name]
        g = group_of(j.name)
        if g == "finger":
            kp = THUMB_OPPOSE_KP if j.name == "r_thumb_oppose" else FINGER_KP
            arm = FINGER_ARMATURE
        else:
            kp = nice_up(max(KP_FLOOR[g], tau / SAG_RAD))
            arm = ARMATURE_BASE[g]
        # stability of the explicit stiffness term at dt
        w_lim = OMEGA_DT_MAX / DT
        arm = max(arm, kp / (w_lim * w_lim) - I_min)
        arm = float("%.2g" % nice_up(arm))
        damping = 2.0 * ZETA * math.sqrt(kp * (I_max + arm))
        damping = float("%.3g" % damping)
        gains[j.name] = {"kp": kp, "armature": arm, "damping": damping,
                         "I_min": I_min, "I_max": I_max, "tau_g_max": tau,
                         "sag_deg": tau / kp * R2D,
                         "omega_dt": math.sqrt(kp / (I_min + arm)) * DT,
                         "zeta_min": damping / (2 * math.sqrt(kp * (I_max + arm))),
                         "zeta_max": damping / (2 * math.sqrt(kp * (I_min + arm)))}
        j.damping = damping
    return gains


# ----------------------------------------------------------------------------------------------
# 9. Poses and sidecar.
# ----------------------------------------------------------------------------------------------

# icub.md section 9: Gazebo start pose, right arm (deg); torso and neck 0; hand open.
HOME_ARM_DEG = [-29.8, 29.8, 0.0, 45.0, 0.0, 0.0, 0.0]
# Fixed left arm: upper arm raised forward and out, elbow fully bent, hand beside the head. Its
# lowest point stays 10 cm above the table for torso pitch <= 40, |roll| <= 20, |yaw| <= 30 deg;
# raised only to the side ([0, 80, 0, 90]) its fingers reached 5 cm below the table top there, and
# touched the table in the looks and ball grasps, holding the torso back.
LEFT_ARM_PARK_DEG = [-60.0, 120.0, -30.0, 106.0, 0.0, 0.0, 0.0]
HAND_GROUPS = {
    "thumb": ["r_thumb_oppose", "r_thumb_proximal", "r_thumb_distal"],
    "index": ["r_index_proximal", "r_index_distal"],
    "middle": ["r_middle_proximal", "r_middle_distal"],
    "ring_little": ["r_ring_proximal", "r_ring_distal", "r_little_proximal", "r_little_distal"],
}


# Closing targets [deg]: about 30 deg past the contact angles that check_icub_fk.py found for
# the 32 mm handle (fingers touch at ~55-60 deg, the opposed thumb at ~5-10 deg), just inside the
# 90 deg joint limits, so that the position actuators still squeeze the library's thinnest
# handles (22 mm: the fingers touch later). With 20 deg (and FINGER_KP 1) handles under 30 mm
# pivoted 12-70 deg in the hand when lifted off the rack (toolbench bench --protocol pull-gt,
# lift_pivot_deg).
HAND_CLOSED_DEG = {
    "r_thumb_oppose": None, "r_thumb_proximal": 45.0, "r_thumb_distal": 55.0,
    "r_index_proximal": 89.0, "r_index_distal": 89.0, "r_middle_proximal": 89.0,
    "r_middle_distal": 89.0, "r_ring_proximal": 89.0, "r_ring_distal": 89.0,
    "r_little_proximal": 89.0, "r_little_distal": 89.0,
}


def home_deg(robot):
    h = {j.name: 0.0 for j in robot.movable()}
    for (name, *_), v in zip(ARM_R_V2_DH, HOME_ARM_DEG):
        h[name] = v
    return h


def build_sidecar(robot, gains):
    HAND_CLOSED_DEG["r_thumb_oppose"] = THUMB_OPPOSE_LIMITS_DEG[1]
    hand_joints = [n for g in HAND_GROUPS.values() for n in g]
    return {
        "urdf": URDF_NAME,
        "root_link": "root_link",
        "palm_frame": "r_hand_dh_frame",
        "camera_frame": "helmet_camera",
        "camera": {"fovy_deg": 58, "width": 640, "height": 480},
        "grasp": {
            "frame": "r_hand_dh_frame",
            "handle_axis_center": list(GRASP_CYL_CENTER_P),
            "handle_axis": list(GRASP_CYL_AXIS_P),
            "handle_radius": GRASP_CYL_RADIUS,
            "handle_length": GRASP_CYL_LENGTH,
        },
        "actuators": {j.name: {"kp": gains[j.name]["kp"], "armature": gains[j.name]["armature"],
                               "damping": gains[j.name]["damping"]}
                      for j in robot.movable()},
        "hand_groups": HAND_GROUPS,
        "hand_open": {n: 0.0 for n in hand_joints},
        "hand_preshape": {n: (HAND_CLOSED_DEG[n] * D2R if n == "r_thumb_oppose" else 0.0)
                          for n in hand_joints},
        "hand_closed": {n: HAND_CLOSED_DEG[n] * D2R for n in hand_joints},
        "home_deg": home_deg(robot),
        "notes": ("actuators[*].damping repeats the URDF <dynamics damping> (N m s/rad) for "
                  "reference; kp in N m/rad, armature in kg m^2. Generated by "
                  "generate_icub_urdf.py; do not edit by hand."),
    }


# ----------------------------------------------------------------------------------------------
# 10. URDF writer.
# ----------------------------------------------------------------------------------------------


def fmt(v):
    if abs(v) < 5e-13:
        v = 0.0
    s = "%.12g" % v
    return "0" if s in ("-0", "0") else s


def fmt3(v):
    return " ".join(fmt(x) for x in v)


def origin_xml(T):
    return '<origin xyz="%s" rpy="%s"/>' % (fmt3(pos_of(T)), fmt3(rpy_from_R(rot_of(T))))


def geom_xml(g):
    k, s = g["kind"], g["size"]
    if k == "box":
        return '<box size="%s"/>' % fmt3(s)
    if k == "sphere":
        return '<sphere radius="%s"/>' % fmt(s[0])
    return '<cylinder radius="%s" length="%s"/>' % (fmt(s[0]), fmt(s[1]))


def write_urdf(robot, path):
    L = []
    w = L.append
    w('<?xml version="1.0"?>')
    w("<!-- GENERATED by generate_icub_urdf.py - do not edit by hand.")
    w("     iCub upper body (torso, right arm v2 + hand, neck, helmet RGB-D camera), iKin DH v2.")
    w("     Frames: root_link = iKin root (x backward, y to the robot's right, z up).")
    w("     Numbers: shared/facts/icub.md sections 1-10. See README.md in this folder. -->")
    w('<robot name="icub_upper_body">')
    w("  <!-- MuJoCo URDF extension: keep fixed frames (r_hand_dh_frame, helmet_camera, eyes) -->")
    w('  <mujoco><compiler fusestatic="false"/></mujoco>')
    for m, rgba in MATERIALS.items():
        w('  <material name="%s"><color rgba="%s"/></material>' % (m, " ".join("%g" % c for c in rgba)))
    for ln in robot.link_order:
        link = robot.links[ln]
        w('  <link name="%s">' % ln)
        Tc, vals = link.inertial
        w("    <inertial>")
        w("      " + origin_xml(Tc))
        w('      <mass value="%s"/>' % fmt(link.mass))
        w('      <inertia ixx="%s" ixy="0" ixz="0" iyy="%s" iyz="0" izz="%s"/>'
          % (fmt(vals[0]), fmt(vals[1]), fmt(vals[2])))
        w("    </inertial>")
        mats = {g["material"] for g in link.geoms if g["collide"]}
        assert len(mats) <= 1, (ln, mats)  # one colour per link (see helmet note)
        # visual-only geoms first: MuJoCo colours collision geoms with the LAST visual material
        for g in sorted(link.geoms, key=lambda g: g["collide"]):
            w('    <visual name="%s">' % g["name"])
            w("      " + origin_xml(g["T"]))
            w("      <geometry>%s</geometry>" % geom_xml(g))
            w('      <material name="%s"/>' % g["material"])
            w("    </visual>")
        for g in link.geoms:
            if not g["collide"]:
                continue
            w('    <collision name="%s">' % g["name"])
            w("      " + origin_xml(g["T"]))
            w("      <geometry>%s</geometry>" % geom_xml(g))
            w("    </collision>")
        w("  </link>")
    for j in robot.joints:
        w('  <joint name="%s" type="%s">' % (j.name, j.type))
        w('    <parent link="%s"/>' % j.parent)
        w('    <child link="%s"/>' % j.child)
        w("    " + origin_xml(j.T))
        if j.type == "revolute":
            w('    <axis xyz="%s"/>' % fmt3(j.axis))
            w('    <limit lower="%s" upper="%s" effort="%s" velocity="%s"/>'
              % (fmt(j.lower), fmt(j.upper), fmt(j.effort), fmt(j.velocity)))
            w('    <dynamics damping="%s" friction="0"/>' % fmt(j.damping))
        w("  </joint>")
    w("</robot>")
    with open(path, "w") as f:
        f.write("\n".join(L) + "\n")


# ----------------------------------------------------------------------------------------------


def build():
    robot = Robot()
    build_kinematics(robot)
    hand = build_hand(robot)
    build_geometry(robot, hand)
    # The left arm is raised, elbow bent (ours: the robot only uses its right arm).
    # In the home pose its hand would reach over the table, which it then hits when the torso
    # pitches forward to reach the rack or the ball.
    park = {k: v * D2R for k, v in home_deg(robot).items()}
    for (name, *_), v in zip(ARM_R_V2_DH, LEFT_ARM_PARK_DEG):
        park[name] = v * D2R
    add_left_arm(robot, park)
    compute_inertials(robot)
    gains = design_gains(robot)
    return robot, gains


def main(argv):
    robot, gains = build()
    write_urdf(robot, os.path.join(HERE, URDF_NAME))
    with open(os.path.join(HERE, SIDECAR_NAME), "w") as f:
        json.dump(build_sidecar(robot, gains), f, indent=2)
        f.write("\n")
    print("wrote %s and %s (%d links, %d joints, %d movable)"
          % (URDF_NAME, SIDECAR_NAME, len(robot.links), len(robot.joints), len(robot.movable())))
    if "--print" in argv:
        X0 = robot.fk({})
        print("\nzero-pose link origins in root_link:")
        for ln in robot.link_order:
            print("  %-28s %s" % (ln, " ".join("%+.4f" % v for v in pos_of(X0[ln]))))
        print("\n%-18s %8s %8s %9s %9s %8s %7s %7s %6s %6s" % (
            "joint", "kp", "armat", "I_min", "I_max", "tau_g", "sag_deg", "w*dt", "z_min", "z_max"))
        for j in robot.movable():
            g = gains[j.name]
            print("%-18s %8.4g %8.2g %9.3g %9.3g %8.3g %7.3f %7.3f %6.2f %6.2f  damping %.3g" % (
                j.name, g["kp"], g["armature"], g["I_min"], g["I_max"], g["tau_g_max"],
                g["sag_deg"], g["omega_dt"], g["zeta_min"], g["zeta_max"], g["damping"]))
        total = sum(l.mass for l in robot.links.values())
        print("\ntotal mass %.3f kg" % total)


if __name__ == "__main__":
    main(sys.argv)
