"""Images of the realism gauge: the mean 8-bit luma of the scored frames, contact sheets of the objects a detector
missed, and the plot of recall by distance beside the fog's transmittance.

Luma is OpenCV's grey conversion of the 8-bit sRGB image (ITU-R BT.601 weights, 0.299 R + 0.587 G + 0.114 B, on
the encoded values), the same measure as the render's black-frame check. A contact sheet is a grid of crops, one
per missed object (its tallest box, the box drawn, a margin of a quarter of the box around it), each captioned
with its image group, box height and distance; at most ``limit`` crops, tallest first.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import cv2
import numpy as np

from evaluation.inputs import GroundTruth
from evaluation.validate import InputError

TILE_PX = 112
CAPTION_PX = 16
COLUMNS = 8
BOX_BGR = (60, 220, 60)
GREY = 114


def read_image(images: Path, attrs: dict[str, Any], source: str) -> np.ndarray:
    """(H, W, 3) uint8 BGR image of ``attrs["file_name"]`` under ``images``."""
    name = attrs.get("file_name")
    if not isinstance(name, str):
        raise InputError(f"{source}: an image has no file_name (needed to read its pixels)")
    image = cv2.imread(str(images / name), cv2.IMREAD_COLOR)
    if image is None:
        raise FileNotFoundError(f"{images / name}: image of {source} (images[].file_name) not found")
    return image


def mean_luma(gt: GroundTruth, images: Path, image_group: np.ndarray, names: list[str]) -> dict[str, Any]:
    """Mean 8-bit luma of every image and its mean per image group: ``{group: {"mean": x, "images": n}}``, with
    ``all`` first."""
    luma = np.array([cv2.cvtColor(read_image(images, a, gt.source), cv2.COLOR_BGR2GRAY).mean()
                     for a in gt.image_attrs])
    out = {"all": {"mean": float(luma.mean()) if len(luma) else None, "images": len(luma)}}
    for i, name in enumerate(names):
        sel = image_group == i
        out[name] = {"mean": float(luma[sel].mean()) if sel.any() else None, "images": int(sel.sum())}
    return out


def _tile(image: np.ndarray, box: np.ndarray, caption: str) -> np.ndarray:
    x, y, w, h = box
    margin = 0.25 * max(w, h)
    h_img, w_img = image.shape[:2]
    x0, y0 = int(max(0, np.floor(x - margin))), int(max(0, np.floor(y - margin)))
    x1, y1 = int(min(w_img, np.ceil(x + w + margin))), int(min(h_img, np.ceil(y + h + margin)))
    crop = image[y0:y1, x0:x1].copy()
    cv2.rectangle(crop, (round(x - x0), round(y - y0)), (round(x + w - x0) - 1, round(y + h - y0) - 1), BOX_BGR, 1)
    scale = TILE_PX / max(crop.shape[:2])
    crop = cv2.resize(crop, (max(1, round(crop.shape[1] * scale)), max(1, round(crop.shape[0] * scale))),
                      interpolation=cv2.INTER_AREA if scale < 1 else cv2.INTER_LINEAR)
    tile = np.full((TILE_PX + CAPTION_PX, TILE_PX, 3), GREY, np.uint8)
    oy, ox = (TILE_PX - crop.shape[0]) // 2, (TILE_PX - crop.shape[1]) // 2
    tile[oy:oy + crop.shape[0], ox:ox + crop.shape[1]] = crop
    tile[TILE_PX:] = 0
    cv2.putText(tile, caption, (2, TILE_PX + CAPTION_PX - 4), cv2.FONT_HERSHEY_SIMPLEX, 0.33, (255, 255, 255), 1,
                cv2.LINE_AA)
    return tile


def contact_sheet(gt: GroundTruth, images: Path, annotations: np.ndarray, group_by: str,
                  limit: int = 64) -> np.ndarray | None:
    """(H, W, 3) uint8 BGR grid of the crops of ``annotations`` (indices, in order; the first ``limit``), or None
    when there is none."""
    picked = annotations[:limit]
    if not len(picked):
        return None
    tiles = []
    for i in picked:
        attrs = gt.image_attrs[gt.image_index[i]]
        distance = f" {gt.distance_m[i]:.0f}m" if gt.distance_valid[i] else ""
        caption = f"{attrs.get(group_by, '')} {gt.bbox[i, 3]:.0f}px{distance}"
        tiles.append(_tile(read_image(images, attrs, gt.source), gt.bbox[i], caption))
    columns = min(COLUMNS, len(tiles))
    tiles += [np.zeros_like(tiles[0])] * (-len(tiles) % columns)
    rows = [np.concatenate(tiles[r:r + columns], axis=1) for r in range(0, len(tiles), columns)]
    return np.concatenate(rows, axis=0)


def write_png(path: Path, image: np.ndarray) -> None:
    if not cv2.imwrite(str(path), image):
        raise OSError(f"{path}: could not write the PNG")


def distance_plot(path: Path, metrics: dict[str, Any], class_group: str = "vehicles") -> None:
    """Recall by distance of ``class_group`` per image group, and each visibility's transmittance, as a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [r for r in metrics["distance"]["rows"] if r["class_group"] == class_group and r["group"] != "all"]
    fig, ax = plt.subplots(figsize=(7, 4.2), dpi=100)
    for value in dict.fromkeys(r["group"] for r in rows):
        mine = [r for r in rows if r["group"] == value and r["recall"] is not None]
        centre = [r["lo_m"] if r["hi_m"] is None else (r["lo_m"] + r["hi_m"]) / 2 for r in mine]
        ax.plot(centre, [r["recall"] for r in mine], marker="o", lw=2.5 if value == "fog" else 1.2, label=value)
    edges = metrics["distance"]["edges_m"]
    d = np.linspace(0.0, edges[-1] * 1.25, 200)
    for value, visibility in metrics["distance"]["visibility_m"].items():
        ax.plot(d, np.exp(-3.912 * d / visibility), ls="--", color="grey" if value != "fog" else "black",
                label=f"T(d), {value}: V = {visibility:g} m")
    ax.set_xlabel("distance to the camera (m)")
    ax.set_ylabel(f"recall of {class_group} / transmittance")
    ax.set_ylim(0, 1.02)
    ax.set_title(f"{class_group}: recall by distance (score >= {metrics['score_threshold']:g}, IoU 0.5, every size)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(path, metadata={"Software": None})
    plt.close(fig)
