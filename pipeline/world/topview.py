"""Top-down picture of a static world, coloured by semantic class (for humans checking the geometry)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pipeline.core.classes import SemanticClass

CLASS_COLOURS = {
    SemanticClass.TERRAIN: "#6b8f4e", SemanticClass.ROAD: "#3b3b3f", SemanticClass.SIDEWALK: "#b5b0a8",
    SemanticClass.KERB: "#d8d5cf", SemanticClass.CROSSING: "#55555a", SemanticClass.LANE_MARKING: "#f4f4ee",
    SemanticClass.BUILDING: "#b0653f", SemanticClass.VEGETATION: "#1f5a1a", SemanticClass.POLE: "#2050d0",
    SemanticClass.BARRIER: "#e0c040", SemanticClass.TRAFFIC_LIGHT: "#e02020",
}


def plot_top_view(world, path: Path, *, extent: tuple[float, float, float, float] | None = None,
                  size_in: float = 12.0) -> None:
    """Draw every triangle seen from above (higher surfaces over lower ones) into a PNG at ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection

    from pipeline.world.materials import material_index

    paint = material_index("lane_paint")
    polys, colours, heights = [], [], []
    for mesh in world.meshes:
        tri = mesh.vertices[mesh.triangles]
        polys.append(tri[:, :, :2])
        colour = np.full(len(tri), CLASS_COLOURS.get(mesh.semantic, "#ff00ff"), dtype=object)
        colour[mesh.material == paint] = "#f4f4ee"  # zebra stripes are CROSSING but painted
        colours.append(colour)
        heights.append(tri[:, :, 2].max(axis=1))
    polys, heights, colours = np.concatenate(polys), np.concatenate(heights), np.concatenate(colours)
    order = np.argsort(heights, kind="stable")
    fig, ax = plt.subplots(figsize=(size_in, size_in))
    ax.add_collection(PolyCollection(polys[order], facecolors=colours[order], edgecolors="none"))
    x0, y0, x1, y1 = extent if extent is not None else world.ground_bounds
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    if len(world.street_lights):
        ax.plot(world.street_lights[:, 0], world.street_lights[:, 1], "o", ms=2, color="yellow")
    ax.set_title(f"static world: {world.num_triangles} triangles")
    fig.savefig(path, dpi=100, bbox_inches="tight")
    plt.close(fig)
