#!/usr/bin/env python3
"""Writes the small mesh and sidecar fixtures of tests/toollib (run from this folder).

A cube of side 0.1 m (corner at the origin) in every supported format, plus one malformed
file per defect the readers and validators must report. The files are committed; this script
documents how they were made.
"""
import json
import os
import struct

S = 0.1
# Corner i has x = bit 0, y = bit 1, z = bit 2.
VERTS = [((i & 1) * S, ((i >> 1) & 1) * S, ((i >> 2) & 1) * S) for i in range(8)]
# Quads, counter-clockwise seen from outside.
QUADS = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
TRIS = [t for q in QUADS for t in ((q[0], q[1], q[2]), (q[0], q[2], q[3]))]


def normal(t, verts=VERTS):
    a, b, c = (verts[i] for i in t)
    u = [b[k] - a[k] for k in range(3)]
    v = [c[k] - a[k] for k in range(3)]
    n = [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]]
    length = sum(x * x for x in n) ** 0.5
    return [x / length for x in n]


def stl_ascii(path, tris, verts=VERTS):
    with open(path, "w") as f:
        f.write("solid cube\n")
        for t in tris:
            f.write("  facet normal %g %g %g\n    outer loop\n" % tuple(normal(t, verts)))
            for i in t:
                f.write("      vertex %.9g %.9g %.9g\n" % verts[i])
            f.write("    endloop\n  endfacet\n")
        f.write("endsolid cube\n")


def stl_binary(path, tris, verts=VERTS, header=b"binary cube fixture"):
    data = header.ljust(80, b" ") + struct.pack("<I", len(tris))
    for t in tris:
        data += struct.pack("<3f", *normal(t, verts))
        for i in t:
            data += struct.pack("<3f", *verts[i])
        data += struct.pack("<H", 0)
    with open(path, "wb") as f:
        f.write(data)
    return data


def obj(path, faces, verts=VERTS, extra=""):
    with open(path, "w") as f:
        f.write("# cube, 0.1 m\nmtllib cube.mtl\no cube\n")
        for v in verts:
            f.write("v %.9g %.9g %.9g\n" % v)
        f.write("vt 0 0\nvn 0 0 1\ns off\n")
        f.write(extra)
        for q in faces:
            f.write("f " + " ".join(q) + "\n")


def main():
    os.makedirs("bad", exist_ok=True)
    os.makedirs("sidecars", exist_ok=True)
    stl_ascii("cube_ascii.stl", TRIS)
    binary = stl_binary("cube_binary.stl", TRIS)
    # OBJ: quads (fan-triangulated by the reader), all reference forms, negative indices.
    forms = []
    for n, q in enumerate(QUADS):
        if n == 0:
            forms.append([str(i + 1) for i in q])
        elif n == 1:
            forms.append(["%d/1" % (i + 1) for i in q])
        elif n == 2:
            forms.append(["%d//1" % (i + 1) for i in q])
        elif n == 3:
            forms.append(["%d/1/1" % (i + 1) for i in q])
        else:
            forms.append([str(i - 8) for i in q])  # relative: -8 is the first vertex
    obj("cube.obj", forms)
    # PLY ascii: triangles, float coordinates, uchar/int lists.
    with open("cube_ascii.ply", "w") as f:
        f.write("ply\nformat ascii 1.0\ncomment cube, 0.1 m\nelement vertex 8\n"
                "property float x\nproperty float y\nproperty float z\n"
                "element face %d\nproperty list uchar int vertex_indices\nend_header\n" % len(TRIS))
        for v in VERTS:
            f.write("%.9g %.9g %.9g\n" % v)
        for t in TRIS:
            f.write("3 %d %d %d\n" % t)
    # PLY binary: double coordinates plus an extra property, quads with int/uint lists, and an
    # extra element that must be skipped.
    header = ("ply\nformat binary_little_endian 1.0\ncomment cube, 0.1 m\nelement vertex 8\n"
              "property double x\nproperty double y\nproperty double z\nproperty uchar red\n"
              "element face 6\nproperty list int uint vertex_indices\nproperty float quality\n"
              "element edge 1\nproperty int vertex1\nproperty int vertex2\nend_header\n")
    body = b"".join(struct.pack("<3dB", *v, 200) for v in VERTS)
    body += b"".join(struct.pack("<i4If", 4, *q, 1.0) for q in QUADS)
    body += struct.pack("<2i", 0, 1)
    with open("cube_binary.ply", "wb") as f:
        f.write(header.encode() + body)

    # Malformed files.
    with open("bad/truncated.stl", "wb") as f:
        f.write(binary[:84 + 50 * 5 + 20])
    open("bad/empty.stl", "wb").close()
    obj("bad/index_out_of_range.obj", [[str(i + 1) for i in q] for q in QUADS[:5]] + [["2", "4", "8", "9"]])
    with open("bad/nan_vertex.ply", "w") as f:
        f.write("ply\nformat ascii 1.0\nelement vertex 8\n"
                "property float x\nproperty float y\nproperty float z\n"
                "element face %d\nproperty list uchar int vertex_indices\nend_header\n" % len(TRIS))
        for n, v in enumerate(VERTS):
            f.write("nan %.9g %.9g\n" % v[1:] if n == 5 else "%.9g %.9g %.9g\n" % v)
        for t in TRIS:
            f.write("3 %d %d %d\n" % t)
    obj("bad/open_box.obj", [[str(i + 1) for i in q] for q in QUADS[:5]])  # no +x face
    obj("bad/inverted.obj", [[str(i + 1) for i in reversed(q)] for q in QUADS])
    stl_binary("bad/cube_mm.stl", TRIS, [tuple(1000 * c for c in v) for v in VERTS])

    # Sidecars (meshes relative to the sidecar's folder).
    good = {
        "name": "user_cube", "family": "custom", "mesh": "../cube_binary.stl", "mass": 0.2,
        "handle": {"center": [0.05, 0.05, 0.05], "axis": [0, 0, 1], "length": 0.1, "radius": 0.05},
        "effector": {"center": [0.05, 0.05, 0.09], "axis": [1, 0, 0], "length": 0.1, "radius": 0.05},
        "symmetries": ["rot_z_90"], "params": {"side": 0.1},
    }
    with open("sidecars/user_cube.json", "w") as f:
        json.dump(good, f, indent=2)
    missing = dict(good)
    del missing["mass"]
    with open("sidecars/missing_mass.json", "w") as f:
        json.dump(missing, f, indent=2)
    unknown = dict(good, family="spoon")
    with open("sidecars/unknown_family.json", "w") as f:
        json.dump(unknown, f, indent=2)
    bad_axis = dict(good, handle=dict(good["handle"], axis="up"))
    with open("sidecars/bad_axis_type.json", "w") as f:
        json.dump(bad_axis, f, indent=2)
    mm = dict(good, mesh="../bad/cube_mm.stl")
    with open("sidecars/mm_mesh.json", "w") as f:
        json.dump(mm, f, indent=2)


if __name__ == "__main__":
    main()
