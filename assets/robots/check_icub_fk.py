#!/usr/bin/env python3
"""Validate icub_upper_body.urdf (+ sidecar) against the published numbers of shared/facts/icub.md.

Python 3 standard library only.  Usage:

    python3 assets/robots/check_icub_fk.py [path/to/icub_upper_body.urdf]

The URDF is parsed with xml.etree; forward kinematics composes each joint's <origin> (xyz, and
rpy with R = Rz(y) Ry(p) Rx(r)) and the rotation by the joint angle about its <axis>.  Nothing
of the generator is used for the FK test vectors: they are typed in below from icub.md.  The
random-configuration cross-check against the iKin DH product imports the DH tables of
generate_icub_urdf.py (the reviewable copy of icub.md sections 2-4).

Exit code 0 when every check passes; each failing check prints "FAIL".
"""

import json
import math
import os
import random
import sys
import xml.etree.ElementTree as ET

HERE = os.path.dirname(os.path.abspath(__file__))
D2R = math.pi / 180.0
POS_TOL = 1e-4          # m, for values published with 4 decimals
POS_TOL_3DEC = 6e-4     # m, for values published with 3 decimals (rounding alone is 5e-4)
AXIS_TOL = 0.01         # per component

FAILS = []
PASSES = []


def report(ok, label, detail):
    print("%-4s %-58s %s" % ("ok" if ok else "FAIL", label, detail))
    (PASSES if ok else FAILS).append(label)


# ---------------------------------------------------------------------------------- math ----

def mmul(A, B):
    return [[sum(A[i][k] * B[k][j] for k in range(4)) for j in range(4)] for i in range(4)]


def eye4():
    return [[1.0 if i == j else 0.0 for j in range(4)] for i in range(4)]


def rot_axis(axis, t):
    n = math.sqrt(sum(a * a for a in axis))
    x, y, z = (a / n for a in axis)
    c, s, C = math.cos(t), math.sin(t), 1 - math.cos(t)
    return [[c + x * x * C, x * y * C - z * s, x * z * C + y * s, 0],
            [y * x * C + z * s, c + y * y * C, y * z * C - x * s, 0],
            [z * x * C - y * s, z * y * C + x * s, c + z * z * C, 0],
            [0, 0, 0, 1.0]]


def origin_T(xyz, rpy):
    r, p, y = rpy
    T = mmul(mmul(rot_axis((0, 0, 1), y), rot_axis((0, 1, 0), p)), rot_axis((1, 0, 0), r))
    T[0][3], T[1][3], T[2][3] = xyz
    return T


def inv(T):
    R = [[T[j][i] for j in range(3)] for i in range(3)]
    p = [-sum(R[i][k] * T[k][3] for k in range(3)) for i in range(3)]
    return [R[0] + [p[0]], R[1] + [p[1]], R[2] + [p[2]], [0, 0, 0, 1.0]]


def pos(T):
    return [T[0][3], T[1][3], T[2][3]]


def col(T, k):
    return [T[0][k], T[1][k], T[2][k]]


def apply(T, p):
    return [sum(T[i][k] * p[k] for k in range(3)) + T[i][3] for i in range(3)]


def sub(a, b):
    return [a[i] - b[i] for i in range(3)]


def add(a, b):
    return [a[i] + b[i] for i in range(3)]


def scale(a, s):
    return [x * s for x in a]


def dot(a, b):
    return sum(a[i] * b[i] for i in range(3))


def norm(a):
    return math.sqrt(dot(a, a))


def maxabs(a, b):
    return max(abs(a[i] - b[i]) for i in range(3))


def seg_seg_dist(p1, q1, p2, q2):
    """Minimum distance between segments p1q1 and p2q2 (Ericson, Real-Time Collision Detection)."""
    d1, d2, r = sub(q1, p1), sub(q2, p2), sub(p1, p2)
    a, e, f = dot(d1, d1), dot(d2, d2), dot(d2, r)
    eps = 1e-15
    if a <= eps and e <= eps:
        return norm(r)
    if a <= eps:
        s, t = 0.0, min(max(f / e, 0.0), 1.0)
    else:
        c = dot(d1, r)
        if e <= eps:
            t, s = 0.0, min(max(-c / a, 0.0), 1.0)
        else:
            b = dot(d1, d2)
            den = a * e - b * b
            s = min(max((b * f - c * e) / den, 0.0), 1.0) if den > eps else 0.0
            t = (b * s + f) / e
            if t < 0.0:
                t, s = 0.0, min(max(-c / a, 0.0), 1.0)
            elif t > 1.0:
                t, s = 1.0, min(max((b - c) / a, 0.0), 1.0)
    c1, c2 = add(p1, scale(d1, s)), add(p2, scale(d2, t))
    return norm(sub(c1, c2))


# ------------------------------------------------------------------------------ the URDF ----

class Urdf:
    def __init__(self, path):
        root = ET.parse(path).getroot()
        self.links = {}
        for l in root.findall("link"):
            self.links[l.get("name")] = l
        self.joints = {}
        self.children = {}
        self.parent_joint = {}
        for j in root.findall("joint"):
            o = j.find("origin")
            xyz = [float(v) for v in (o.get("xyz") or "0 0 0").split()] if o is not None else [0] * 3
            rpy = [float(v) for v in (o.get("rpy") or "0 0 0").split()] if o is not None else [0] * 3
            ax = j.find("axis")
            axis = [float(v) for v in ax.get("xyz").split()] if ax is not None else [1.0, 0, 0]
            lim = j.find("limit")
            dyn = j.find("dynamics")
            info = {"name": j.get("name"), "type": j.get("type"),
                    "parent": j.find("parent").get("link"), "child": j.find("child").get("link"),
                    "T": origin_T(xyz, rpy), "axis": axis,
                    "lower": float(lim.get("lower")) if lim is not None else None,
                    "upper": float(lim.get("upper")) if lim is not None else None,
                    "effort": float(lim.get("effort")) if lim is not None else None,
                    "velocity": float(lim.get("velocity")) if lim is not None else None,
                    "damping": float(dyn.get("damping")) if dyn is not None else None,
                    "friction": float(dyn.get("friction", "0")) if dyn is not None else None}
            self.joints[info["name"]] = info
            self.children.setdefault(info["parent"], []).append(info)
            self.parent_joint[info["child"]] = info
        roots = [l for l in self.links if l not in self.parent_joint]
        assert len(roots) == 1, roots
        self.root = roots[0]

    def movable(self):
        return [j for j in self.joints.values() if j["type"] in ("revolute", "continuous")]

    def fk(self, q):
        X = {self.root: eye4()}
        stack = [self.root]
        while stack:
            ln = stack.pop()
            for j in self.children.get(ln, []):
                T = mmul(X[ln], j["T"])
                if j["type"] in ("revolute", "continuous"):
                    T = mmul(T, rot_axis(j["axis"], q.get(j["name"], 0.0)))
                X[j["child"]] = T
                stack.append(j["child"])
        return X

    def collision_prims(self, link):
        out = []
        for c in self.links[link].findall("collision"):
            o = c.find("origin")
            xyz = [float(v) for v in o.get("xyz").split()]
            rpy = [float(v) for v in o.get("rpy").split()]
            g = c.find("geometry")[0]
            out.append((g.tag, g.attrib, origin_T(xyz, rpy)))
        return out


def deg(d):
    return {k: v * D2R for k, v in d.items()}


TORSO = ("torso_pitch", "torso_roll", "torso_yaw")   # CHAIN order (robot order is yaw, roll, pitch)
ARM = ("r_shoulder_pitch", "r_shoulder_roll", "r_shoulder_yaw", "r_elbow", "r_wrist_prosup",
       "r_wrist_pitch", "r_wrist_yaw")
NECK = ("neck_pitch", "neck_roll", "neck_yaw")


def cfg(torso=(0, 0, 0), arm=(0,) * 7, neck=(0, 0, 0)):
    q = {}
    q.update(zip(TORSO, torso))
    q.update(zip(ARM, arm))
    q.update(zip(NECK, neck))
    return deg(q)


# ------------------------------------------------------------------------ test vectors ------

def check_arm(u):
    print("\n== right arm v2, palm frame r_hand_dh_frame (icub.md sections 3, 7, 9, 11) ==")
    vectors = [
        ("s11 arm_r_v2 torso(10,0,30) arm(-30,30,0,45,0,0,0)",
         cfg((10, 0, 30), (-30, 30, 0, 45, 0, 0, 0)),
         (-0.1651, 0.3246, -0.0028), (-0.661, 0.715, -0.228), (-0.606, -0.688, -0.400), POS_TOL),
        ("s11 arm_r_v2 torso 0 arm(-60,20,10,80,-30,-10,5)",
         cfg((0, 0, 0), (-60, 20, 10, 80, -30, -10, 5)),
         (-0.2909, 0.1094, 0.2700), (-0.727, 0.104, 0.678), (0.203, -0.911, 0.358), POS_TOL),
        # icub.md s9 lists the Gazebo start as (-29.8, 29.8, 0, 45) deg, but its derived palm pose
        # (and the axes, identical to the s11 arm_r_v1 row) are those of exactly (-30, 30, 0, 45).
        ("s9 Gazebo start palm (v2 DH) at (-30,30,0,45,0,0,0)",
         cfg((0, 0, 0), (-30, 30, 0, 45, 0, 0, 0)),
         (-0.304, 0.202, 0.026), (-0.955, 0.274, -0.110), (-0.233, -0.929, -0.289), POS_TOL_3DEC),
        ("s7 zero pose: x_hand=-z, z_hand=-y (root)", cfg(),
         (-0.0108, 0.0841, -0.1808), (0, 0, -1), (0, -1, 0), POS_TOL),
    ]
    for label, q, p, x, z, ptol in vectors:
        T = u.fk(q)["r_hand_dh_frame"]
        ep, ex, ez = maxabs(pos(T), p), maxabs(col(T, 0), x), maxabs(col(T, 2), z)
        report(ep < ptol and ex < AXIS_TOL and ez < AXIS_TOL, label,
               "p=(%+.4f %+.4f %+.4f) |dp|max=%.1e |dx|=%.1e |dz|=%.1e"
               % (tuple(pos(T)) + (ep, ex, ez)))
    # y_hand at zero pose = root +x (section 7)
    T = u.fk(cfg())["r_hand_dh_frame"]
    report(maxabs(col(T, 1), (1, 0, 0)) < AXIS_TOL, "s7 zero pose: y_hand = +x (root)",
           "y=(%+.3f %+.3f %+.3f)" % tuple(col(T, 1)))
    print("\n-- section 3 DH frame origins at q = 0 (v2 arm) --")
    X = u.fk(cfg())
    frames = [("frame 3  r_shoulder_1 (after torso yaw)", "r_shoulder_1", (0.0171, 0.0060, 0.1753)),
              ("frame 4  r_shoulder_2 (shoulder centre)", "r_shoulder_2", (-0.0108, 0.1101, 0.1753)),
              ("frame 5  r_shoulder_3 (shoulder centre)", "r_shoulder_3", (-0.0108, 0.1101, 0.1753)),
              ("frame 6  r_elbow_1", "r_elbow_1", (-0.0258, 0.1101, 0.0230)),
              ("frame 7  r_forearm", "r_forearm", (-0.0108, 0.1101, 0.0230)),
              ("frame 8  r_wrist_1 (wrist centre)", "r_wrist_1", (-0.0108, 0.1101, -0.1183)),
              ("frame 9  r_hand (wrist centre)", "r_hand", (-0.0108, 0.1101, -0.1183)),
              ("frame 10 r_hand_dh_frame (palm)", "r_hand_dh_frame", (-0.0108, 0.0841, -0.1808))]
    for label, link, p in frames:
        e = maxabs(pos(X[link]), p)
        report(e < POS_TOL, label, "p=(%+.4f %+.4f %+.4f) err %.1e" % (tuple(pos(X[link])) + (e,)))


def check_head(u, gen):
    print("\n== head, eyes and helmet camera (icub.md sections 4, 10, 11) ==")
    X = u.fk(cfg())
    for label, link, p in [("s4 l_eye at q=0 (v2)", "l_eye", (-0.0564, -0.034, 0.3468)),
                           ("s4 r_eye at q=0 (v2)", "r_eye", (-0.0564, 0.034, 0.3468))]:
        T = X[link]
        e = maxabs(pos(T), p)
        ea = max(maxabs(col(T, 0), (0, 1, 0)), maxabs(col(T, 1), (0, 0, -1)),
                 maxabs(col(T, 2), (-1, 0, 0)))
        report(e < POS_TOL and ea < AXIS_TOL, label + ", optical axes x=+y y=-z z=-x",
               "p=(%+.4f %+.4f %+.4f) err %.1e axes %.1e" % (tuple(pos(T)) + (e, ea)))
    mid = scale(add(pos(X["l_eye"]), pos(X["r_eye"])), 0.5)
    e = maxabs(mid, (-0.0564, 0.0, 0.3468))
    report(e < POS_TOL, "s4 head centre (eye midpoint) at q=0", "err %.1e" % e)

    T = X["helmet_camera"]
    e = maxabs(pos(T), (-0.0831, -0.0175, 0.4625))
    ea = max(maxabs(col(T, 0), (0, 1, 0)), maxabs(col(T, 1), (0, 0, -1)),
             maxabs(col(T, 2), (-1, 0, 0)))
    report(e < POS_TOL and ea < AXIS_TOL, "s10 camera depth origin at q=0, OpenCV axes",
           "p=(%+.4f %+.4f %+.4f) err %.1e axes %.1e" % (tuple(pos(T)) + (e, ea)))

    # camera in the neck-yaw DH frame (frame 6 = head link . Tz(d5) Tx(a5) Rx(alpha5))
    _, a5, d5, al5, *_ = gen.EYE_L_V2_DH[2]
    F6 = mmul(X["head"], mmul(mmul(origin_T((0, 0, d5), (0, 0, 0)), origin_T((a5, 0, 0), (0, 0, 0))),
                             origin_T((0, 0, 0), (al5, 0, 0))))
    C6 = mmul(inv(F6), T)
    e = maxabs(pos(C6), (-0.0267, -0.1156, -0.0175))
    R6c = [[C6[i][k] for k in range(3)] for i in range(3)]
    pub = [[0, 0, -1], [0, 1, 0], [1, 0, 0]]
    e_rows = max(abs(R6c[i][k] - pub[i][k]) for i in range(3) for k in range(3))
    e_cols = max(abs(R6c[k][i] - pub[i][k]) for i in range(3) for k in range(3))
    report(e < POS_TOL and min(e_rows, e_cols) < 1e-9,
           "s10 camera in neck-yaw DH frame 6",
           "p=(%+.4f %+.4f %+.4f) err %.1e; published R matches %s"
           % (tuple(pos(C6)) + (e, "as rows of R_6c (camera axes in frame 6 = its columns)"
                                if e_rows < 1e-9 else "R_6c transposed")))

    q = cfg((10, 0, 30), neck=(-20, 0, -10))
    T = u.fk(q)["helmet_camera"]
    e, ez = maxabs(pos(T), (-0.2048, 0.0695, 0.3932)), maxabs(col(T, 2), (-0.645, 0.613, -0.456))
    report(e < POS_TOL and ez < AXIS_TOL, "s10 camera test torso(10,0,30) neck(-20,0,-10)",
           "p=(%+.4f %+.4f %+.4f) err %.1e, optical axis (%+.3f %+.3f %+.3f) err %.1e"
           % (tuple(pos(T)) + (e,) + tuple(col(T, 2)) + (ez,)))

    # eye_l_v2 (section 11): the URDF keeps the eyes fixed at zero, so the moving eye links 6-7
    # are appended to the URDF's head: F6 = l_eye(q_eyes=0) . (T6(0) T7(0))^-1.
    def dh(qr, a, d, al, off):
        return mmul(mmul(rot_axis((0, 0, 1), qr + off), origin_T((a, 0, d), (0, 0, 0))),
                    origin_T((0, 0, 0), (al, 0, 0)))
    _, a6, d6, al6, off6, *_ = gen.EYE_L_V2_DH[3]
    _, a7, d7, al7, off7, *_ = gen.EYE_L_V2_DH[4]
    tilt, version, vergence = -10.0, 5.0, 10.0
    pan = version + vergence / 2.0          # left pan = version + vergence/2 (section 4)
    q = cfg((0, 0, 20), neck=(-25, 5, 10))
    L0 = u.fk(q)["l_eye"]
    F6q = mmul(L0, inv(mmul(dh(0, a6, d6, al6, off6 * D2R), dh(0, a7, d7, al7, off7 * D2R))))
    E = mmul(F6q, mmul(dh(tilt * D2R, a6, d6, al6, off6 * D2R), dh(pan * D2R, a7, d7, al7, off7 * D2R)))
    e = maxabs(pos(E), (-0.0928, -0.0055, 0.3226))
    ex, ez = maxabs(col(E, 0), (0.362, 0.931, -0.053)), maxabs(col(E, 2), (-0.776, 0.269, -0.571))
    report(e < POS_TOL and ex < AXIS_TOL and ez < AXIS_TOL,
           "s11 eye_l_v2 (URDF head + DH eye links 6-7)",
           "p=(%+.4f %+.4f %+.4f) err %.1e |dx| %.1e |dz| %.1e" % (tuple(pos(E)) + (e, ex, ez)))


def check_signs(u):
    print("\n== section 6 sign conventions ==")
    z0 = col(u.fk(cfg())["helmet_camera"], 2)
    zy = col(u.fk(cfg((0, 0, 20)))["helmet_camera"], 2)
    report(zy[1] > z0[1] + 0.1, "torso_yaw + turns the trunk to the RIGHT", "optical axis y %+.3f" % zy[1])
    zn = col(u.fk(cfg(neck=(0, 0, 20)))["helmet_camera"], 2)
    report(zn[1] < -0.1, "neck_yaw + turns the head to the LEFT", "optical axis y %+.3f" % zn[1])
    zp = col(u.fk(cfg(neck=(20, 0, 0)))["helmet_camera"], 2)
    report(zp[2] > 0.1, "neck_pitch + looks up", "optical axis z %+.3f" % zp[2])
    e0 = pos(u.fk(cfg())["l_eye"])
    er = pos(u.fk(cfg((0, 20, 0)))["l_eye"])
    report(er[1] < e0[1] - 0.01, "torso_roll + leans to the LEFT", "eye y %+.3f" % er[1])
    h0 = pos(u.fk(cfg())["r_hand_dh_frame"])
    hp = pos(u.fk(cfg(arm=(-40, 0, 0, 0, 0, 0, 0)))["r_hand_dh_frame"])
    report(hp[0] < h0[0] - 0.05, "r_shoulder_pitch - lifts the arm forward", "palm x %+.3f" % hp[0])
    X = u.fk(cfg(arm=(0, 0, 0, 90, 0, 0, 0)))
    fa = sub(pos(X["r_wrist_1"]), pos(X["r_forearm"]))
    report(fa[0] < -0.13 and abs(fa[2]) < 0.01, "r_elbow 90 deg: forearm horizontal, forward",
           "forearm (%+.3f %+.3f %+.3f)" % tuple(fa))


def dh_chain_fk(gen, q, branch):
    """iKin product H0 . T_0 ... with the generator's v2 tables (q in rad, chain order)."""
    def dh(qr, a, d, al, off_deg):
        return mmul(mmul(rot_axis((0, 0, 1), qr + off_deg * D2R), origin_T((a, 0, d), (0, 0, 0))),
                    origin_T((0, 0, 0), (al, 0, 0)))
    rows = [r[:5] for r in gen.TORSO_DH]
    if branch == "arm":
        rows += [gen.ARM_LINK2] + [r[:5] for r in gen.ARM_R_V2_DH]
    else:
        rows += [gen.HEAD_LINK2] + [r[:5] for r in gen.EYE_L_V2_DH]
    T = [row[:] for row in gen.H0]
    for name, a, d, al, off in rows:
        T = mmul(T, dh(q.get(name, 0.0), a, d, al, off))
    return T


def check_random(u, gen, n=300):
    print("\n== URDF vs iKin DH product, %d random configurations within limits ==" % n)
    rng = random.Random(1)
    mov = [j for j in u.movable()]
    worst = {"palm": [0, 0], "l_eye": [0, 0], "camera": [0, 0]}
    cam_in_eye = origin_T(gen.CAMERA_IN_LEFT_EYE, (0, 0, 0))
    for _ in range(n):
        q = {j["name"]: rng.uniform(j["lower"], j["upper"]) for j in mov}
        X = u.fk(q)
        A = dh_chain_fk(gen, q, "arm")
        E = dh_chain_fk(gen, q, "eye")   # eye joints absent from q -> 0 (fixed eyes)
        for key, T, R in (("palm", X["r_hand_dh_frame"], A), ("l_eye", X["l_eye"], E),
                          ("camera", X["helmet_camera"], mmul(E, cam_in_eye))):
            ep = maxabs(pos(T), pos(R))
            ea = max(maxabs(col(T, k), col(R, k)) for k in range(3))
            worst[key] = [max(worst[key][0], ep), max(worst[key][1], ea)]
    for key, (ep, ea) in worst.items():
        report(ep < 1e-9 and ea < 1e-9, "random configs: %s pose = DH" % key,
               "max |dp| %.1e m, max |dR| %.1e" % (ep, ea))


# iKin default limits (icub.md section 5, left column), degrees
IKIN_LIMITS = {
    "torso_pitch": (-22, 84), "torso_roll": (-39, 39), "torso_yaw": (-59, 59),
    "r_shoulder_pitch": (-95.5, 5), "r_shoulder_roll": (0, 160.8), "r_shoulder_yaw": (-37, 100),
    "r_elbow": (5.5, 106), "r_wrist_prosup": (-50, 50), "r_wrist_pitch": (-65, 10),
    "r_wrist_yaw": (-25, 25), "neck_pitch": (-40, 30), "neck_roll": (-70, 60), "neck_yaw": (-55, 55),
}


def check_structure(u, sidecar):
    print("\n== structure, limits, dynamics, inertia, sidecar ==")
    names = {
        "torso_pitch": ("root_link", "torso_1"), "torso_roll": ("torso_1", "torso_2"),
        "torso_yaw": ("torso_2", "chest"), "r_shoulder_pitch": ("chest", "r_shoulder_1"),
        "r_shoulder_roll": ("r_shoulder_1", "r_shoulder_2"),
        "r_shoulder_yaw": ("r_shoulder_2", "r_shoulder_3"), "r_elbow": (None, "r_elbow_1"),
        "r_wrist_prosup": ("r_elbow_1", "r_forearm"), "r_wrist_pitch": ("r_forearm", "r_wrist_1"),
        "r_wrist_yaw": ("r_wrist_1", "r_hand"), "neck_pitch": ("chest", "neck_1"),
        "neck_roll": ("neck_1", "neck_2"), "neck_yaw": ("neck_2", "head"),
    }
    bad = [n for n, (p, c) in names.items()
           if n not in u.joints or u.joints[n]["child"] != c or (p and u.joints[n]["parent"] != p)]
    report(not bad, "iCub joint/link names and parent/child", "mismatch: %s" % bad if bad else "")
    for ln in ("r_hand_dh_frame", "helmet_camera", "l_eye", "r_eye"):
        report(ln in u.links and u.parent_joint[ln]["type"] == "fixed", "fixed frame link %s" % ln, "")
    report(u.root == "root_link", "root link is root_link", u.root)

    bad = []
    for n, (lo, hi) in IKIN_LIMITS.items():
        j = u.joints[n]
        if abs(j["lower"] - lo * D2R) > 1e-9 or abs(j["upper"] - hi * D2R) > 1e-9:
            bad.append(n)
        if maxabs(j["axis"], (0, 0, 1)) > 0:
            bad.append(n + " (axis)")
    report(not bad, "iKin default limits (s5) and DH z axis on torso/arm/neck", str(bad or ""))

    bad = [j["name"] for j in u.movable()
           if j["damping"] is None or j["damping"] <= 0 or j["friction"] != 0
           or not (j["effort"] > 0 and j["velocity"] > 0 and j["lower"] < j["upper"])]
    report(not bad, "every movable joint: damping>0, friction 0, effort/vel>0", str(bad or ""))
    hand = [j for j in u.movable() if j["name"] not in IKIN_LIMITS]
    report(len(hand) <= 12, "hand joints <= 12", "%d hand joints" % len(hand))

    bad = []
    for ln, l in u.links.items():
        i = l.find("inertial")
        if i is None:
            bad.append(ln + " (none)")
            continue
        m = float(i.find("mass").get("value"))
        a = {k: float(v) for k, v in i.find("inertia").attrib.items()}
        I = [[a["ixx"], a["ixy"], a["ixz"]], [a["ixy"], a["iyy"], a["iyz"]], [a["ixz"], a["iyz"], a["izz"]]]
        d1 = I[0][0]
        d2 = I[0][0] * I[1][1] - I[0][1] ** 2
        d3 = (I[0][0] * (I[1][1] * I[2][2] - I[1][2] ** 2) - I[0][1] * (I[0][1] * I[2][2] - I[1][2] * I[0][2])
              + I[0][2] * (I[0][1] * I[1][2] - I[1][1] * I[0][2]))
        tri = (a["ixx"] + a["iyy"] >= a["izz"] and a["iyy"] + a["izz"] >= a["ixx"]
               and a["ixx"] + a["izz"] >= a["iyy"])
        if not (m > 0 and d1 > 0 and d2 > 0 and d3 > 0 and tri):
            bad.append(ln)
    report(not bad, "every link: mass>0, inertia PD + triangle inequality", str(bad or ""))
    total = sum(float(l.find("inertial/mass").get("value")) for l in u.links.values())
    print("     total mass %.3f kg over %d links" % (total, len(u.links)))

    mov = {j["name"] for j in u.movable()}
    act = set(sidecar["actuators"])
    report(act == mov, "sidecar: one actuator per movable joint",
           "missing %s extra %s" % (sorted(mov - act), sorted(act - mov)) if act != mov else
           "%d actuators" % len(act))
    bad = [n for n, a in sidecar["actuators"].items()
           if not (a["kp"] > 0 and a["armature"] > 0 and abs(a["damping"] - u.joints[n]["damping"]) < 1e-12)]
    report(not bad, "sidecar: kp>0, armature>0, damping = URDF", str(bad or ""))
    groups = [n for g in sidecar["hand_groups"].values() for n in g]
    report(sorted(groups) == sorted(j["name"] for j in hand) and len(groups) == len(set(groups)),
           "sidecar: hand_groups cover every hand joint once", "")
    bad = [n for key in ("hand_open", "hand_closed") for n, v in sidecar[key].items()
           if not (u.joints[n]["lower"] - 1e-9 <= v <= u.joints[n]["upper"] + 1e-9)]
    report(not bad, "sidecar: hand_open / hand_closed within limits", str(bad or ""))
    home = sidecar["home_deg"]
    want = dict(zip(ARM, (-29.8, 29.8, 0, 45, 0, 0, 0)))
    ok = all(abs(home[n] - want.get(n, 0.0)) < 1e-9 for n in mov) and set(home) == mov
    ok = ok and all(u.joints[n]["lower"] <= home[n] * D2R <= u.joints[n]["upper"] for n in mov)
    report(ok, "sidecar: home = Gazebo start arm, rest 0, within limits", "")
    for k in ("urdf", "root_link", "palm_frame", "camera_frame"):
        print("     %s = %s" % (k, sidecar[k]))


# ------------------------------------------------------------------------------ the grasp ----

def capsule_segments(u, X_P, link):
    """Collision cylinders of `link` as (p, q, radius) segments in the palm frame P."""
    out = []
    Tl = mmul(inv(X_P), u.fk_cache[link])
    for tag, att, T in u.collision_prims(link):
        if tag != "cylinder":
            continue
        h, r = float(att["length"]), float(att["radius"])
        TT = mmul(Tl, T)
        out.append((apply(TT, (0, 0, -h / 2)), apply(TT, (0, 0, h / 2)), r))
    return out


def point_box_dist(p, T_box, size):
    local = apply(inv(T_box), p)
    d = [max(abs(local[i]) - size[i] / 2, 0.0) for i in range(3)]
    return norm(d)


def check_grasp(u, sidecar):
    gr = sidecar["grasp"]
    C, ax = gr["handle_axis_center"], gr["handle_axis"]
    R, Lh = gr["handle_radius"], gr["handle_length"]
    A1, A2 = add(C, scale(ax, -Lh / 2)), add(C, scale(ax, Lh / 2))
    print("\n== grasp: handle cylinder r=%.3f L=%.3f, axis %s through %s in %s ==" %
          (R, Lh, ax, C, gr["frame"]))
    groups = sidecar["hand_groups"]
    fingers = {"thumb": groups["thumb"], "index": groups["index"], "middle": groups["middle"],
               "ring": [n for n in groups["ring_little"] if "ring" in n],
               "little": [n for n in groups["ring_little"] if "little" in n]}

    def segs(q, name):
        X = u.fk(q)
        u.fk_cache = X
        XP = X["r_hand_dh_frame"]
        out = []
        for jn in fingers[name]:
            out.append(capsule_segments(u, XP, u.joints[jn]["child"]))
        return out   # per joint: list of segments of that joint's child link

    def clearance(seglist):
        return min(seg_seg_dist(p, q, A1, A2) - (R + r) for p, q, r in seglist)

    # (a) approach: open hand does not touch the handle; palm surface clearance
    q0 = {}
    X = u.fk(q0)
    u.fk_cache = X
    XP = X["r_hand_dh_frame"]
    worst = 1.0
    for jn in [n for g in groups.values() for n in g]:
        for s in capsule_segments(u, XP, u.joints[jn]["child"]):
            worst = min(worst, clearance([s]))
    Tpalm = mmul(inv(XP), X["r_hand"])
    palm_cl = 1.0
    for tag, att, T in u.collision_prims("r_hand"):
        if tag == "box":
            size = [float(v) for v in att["size"].split()]
            for k in range(201):
                p = add(A1, scale(sub(A2, A1), k / 200.0))
                palm_cl = min(palm_cl, point_box_dist(p, mmul(Tpalm, T), size) - R)
    report(worst > 0 and palm_cl >= 0 and palm_cl < 0.004,
           "open hand: handle touches nothing, sits on the palm",
           "finger clearance %.1f mm, palm-to-handle gap %.1f mm" % (worst * 1e3, palm_cl * 1e3))

    # (b) contact before the limits: close each finger with its joints moving together (the
    #     thumb in two stages, as the iCub pre-shapes it: oppose first, then proximal + distal);
    #     a joint stops when moving it further would push a phalanx distal to it into the handle.
    step = 0.25 * D2R
    staged = {}
    for name, joints in fingers.items():
        stages = [joints[:1], joints[1:]] if name == "thumb" else [joints]
        q, first_contact = {}, {}
        for stage in stages:
            blocked = {jn: False for jn in stage}
            for it in range(2000):
                moved = False
                for jn in stage:
                    if blocked[jn]:
                        continue
                    k = joints.index(jn)
                    trial = dict(q)
                    trial[jn] = min(q.get(jn, 0.0) + step, u.joints[jn]["upper"])
                    S = segs(trial, name)
                    if min(clearance(S[m]) for m in range(k, len(joints)) if S[m]) < 0:
                        blocked[jn] = True
                        first_contact[jn] = q.get(jn, 0.0)
                        continue
                    if trial[jn] >= u.joints[jn]["upper"]:
                        blocked[jn] = True
                    q = trial
                    moved = True
                if not moved:
                    break
        staged[name] = q
        S = segs(q, name)
        per = [clearance(s) if s else float("nan") for s in S]
        tip = S[-1][0][1]   # cylinders run from the joint (-z end) to the fingertip (+z end)
        # far side: the fingertip is above the handle axis (z_P > C_z) and over the handle in x
        over = (tip[2] > C[2] and abs(tip[0] - C[0]) < R + 0.01
                and abs(dot(sub(tip, C), ax)) <= Lh / 2)
        flexing = [jn for jn in joints if "oppose" not in jn]
        ok = all(jn in first_contact for jn in flexing) and over
        angles = " ".join("%s=%.1f" % (jn.split("_", 2)[2], q.get(jn, 0.0) / D2R) for jn in joints)
        report(ok, "close %-6s: contact before limits, tip over the handle" % name,
               "stop at [%s] deg; clearance %s mm; tip P=(%+.3f %+.3f %+.3f)"
               % (angles, "/".join("%.1f" % (c * 1e3) for c in per), tip[0], tip[1], tip[2]))

    # (c) the brief's plain test: flexing proximal + distal together toward their upper limits
    #     (thumb: at the oppose angle reached in (b)), some angle within the limits brings each
    #     phalanx within handle radius + phalanx radius of the handle axis.
    for name, joints in fingers.items():
        flexing = [jn for jn in joints if "oppose" not in jn]
        base_q = {jn: staged[name][jn] for jn in joints if "oppose" in jn}
        first = {}
        for k in range(0, 1001):
            s = k / 1000.0
            q = dict(base_q)
            q.update({jn: s * u.joints[jn]["upper"] for jn in flexing})
            S = segs(q, name)
            for m, jn in enumerate(joints):
                if jn in flexing and jn not in first and S[m] and clearance(S[m]) < 0:
                    first[jn] = s
        txt = " ".join("%s@%s" % (jn.split("_", 2)[2], "%.0f%%" % (100 * first[jn]) if jn in first
                                  else "never") for jn in flexing)
        report(all(jn in first for jn in flexing),
               "flex %-6s together: each phalanx reaches the handle" % name,
               "first contact at fraction of upper limit: " + txt
               + (" (oppose %.1f deg)" % (base_q[joints[0]] / D2R) if base_q else ""))


def check_generated(path, gen):
    """The committed URDF and sidecar are exactly what generate_icub_urdf.py emits."""
    import tempfile
    robot, gains = gen.build()
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "x.urdf")
        gen.write_urdf(robot, out)
        same_urdf = open(out).read() == open(path).read()
    side = json.dumps(gen.build_sidecar(robot, gains), indent=2) + "\n"
    with open(os.path.join(os.path.dirname(os.path.abspath(path)), gen.SIDECAR_NAME)) as f:
        same_side = f.read() == side
    report(same_urdf and same_side, "URDF + sidecar up to date with the generator",
           "" if same_urdf and same_side else "re-run generate_icub_urdf.py")


def main(argv):
    path = argv[1] if len(argv) > 1 else os.path.join(HERE, "icub_upper_body.urdf")
    sys.dont_write_bytecode = True  # keep assets/robots free of __pycache__
    sys.path.insert(0, HERE)
    import generate_icub_urdf as gen  # DH tables only (for the random cross-check)
    u = Urdf(path)
    with open(os.path.join(os.path.dirname(os.path.abspath(path)), "icub_upper_body.json")) as f:
        sidecar = json.load(f)
    print("URDF %s: %d links, %d joints (%d movable)" % (path, len(u.links), len(u.joints), len(u.movable())))
    check_generated(path, gen)
    check_arm(u)
    check_head(u, gen)
    check_signs(u)
    check_random(u, gen)
    check_structure(u, sidecar)
    check_grasp(u, sidecar)
    print("\n%d passed, %d failed" % (len(PASSES), len(FAILS)))
    if FAILS:
        print("FAILED checks (%d): %s" % (len(FAILS), ", ".join(FAILS)))
        return 1
    print("ALL CHECKS PASSED")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
