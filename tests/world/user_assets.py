"""Small mesh files the user-mesh tests write themselves: a box-shaped body with a glass cabin on its front half.

The model, in our axes (x forward, y left, z up), metres: a body box x in [0, 4], y in [-0.9, 0.9], z in [0.2, 1]
(material "body") and a cabin box x in [2, 3.5], y in [-0.7, 0.7], z in [1, 1.5] (material "glass"). Normalised
to the unit box: x -> (x - 2) / 4, y -> y / 1.8, z -> (z - 0.2) / 1.3 - 0.5, so the cabin spans unit x [0, 0.375],
|y| <= 0.7 / 1.8, z [0.5 - 0.5 / 1.3, 0.5]. Files in other axes hold the same model turned by their convention.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

BODY = ((0.0, -0.9, 0.2), (4.0, 0.9, 1.0))
CABIN = ((2.0, -0.7, 1.0), (3.5, 0.7, 1.5))
UNIT_CABIN_LO = np.array([0.0, -0.7 / 1.8, 0.5 - 0.5 / 1.3])
UNIT_CABIN_HI = np.array([0.375, 0.7 / 1.8, 0.5])

# Outward faces of a box with corners ordered (x, y, z) in {lo, hi}^3, index = 4 i + 2 j + k.
BOX_FACES = np.array([
    [0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
    [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3],
])


def box_vertices(lo, hi) -> np.ndarray:
    """(8, 3) corners of the axis-aligned box from ``lo`` to ``hi``."""
    return np.array([[(lo, hi)[i][0], (lo, hi)[j][1], (lo, hi)[k][2]] for i in (0, 1) for j in (0, 1) for k in (0, 1)])


def to_file_axes(points: np.ndarray, forward: str, up: str) -> np.ndarray:
    """Our (x forward, y left, z up) points in a file whose forward and up are the named axes (each "+x", ...)."""
    axes = {"x": 0, "y": 1, "z": 2}
    out = np.zeros_like(points)
    f, u = np.eye(3)[axes[forward[1]]] * (1 if forward[0] == "+" else -1), \
        np.eye(3)[axes[up[1]]] * (1 if up[0] == "+" else -1)
    left = np.cross(u, f)
    out += points[:, :1] * f + points[:, 1:2] * left + points[:, 2:3] * u
    return out


def write_obj(folder: Path, name: str = "wedge", forward: str = "+x", up: str = "+z",
              extra_lines: str = "") -> Path:
    """``name``.obj with ``name``.mtl: the body ("body") and the cabin ("glass"), in the given axes."""
    (folder / f"{name}.mtl").write_text("newmtl body\nKd 0.8 0.1 0.1\nnewmtl glass\nKd 0.1 0.1 0.1\n")
    lines = [f"mtllib {name}.mtl", "o car"]
    for part, (lo, hi), material in ((0, BODY, "body"), (1, CABIN, "glass")):
        for v in to_file_axes(box_vertices(lo, hi), forward, up):
            lines.append("v {:.6f} {:.6f} {:.6f}".format(*v))
        lines.append(f"usemtl {material}")
        lines += ["f {} {} {}".format(*(f + 1 + 8 * part)) for f in BOX_FACES]
    path = folder / f"{name}.obj"
    path.write_text("\n".join(lines) + "\n" + extra_lines)
    return path


def write_glb(folder: Path, name: str = "wedge") -> Path:
    """``name``.glb in glTF's axes (y up, +z forward), written by trimesh's exporter: two nodes, the body and the
    cabin, the cabin's vertices about its own centre and placed by its node's translation."""
    import trimesh

    scene = trimesh.Scene()
    for node, (lo, hi), material in (("body", BODY, "body"), ("cabin", CABIN, "glass")):
        centre = 0.5 * (np.array(lo) + np.array(hi))
        local = to_file_axes(box_vertices(lo, hi) - centre, "+z", "+y")
        mesh = trimesh.Trimesh(local, BOX_FACES, process=False)
        mesh.visual = trimesh.visual.TextureVisuals(material=trimesh.visual.material.PBRMaterial(name=material))
        move = np.eye(4)
        move[:3, 3] = to_file_axes(centre[None], "+z", "+y")[0]
        scene.add_geometry(mesh, node_name=node, geom_name=node, transform=move)
    path = folder / f"{name}.glb"
    path.write_bytes(scene.export(file_type="glb"))
    return path
