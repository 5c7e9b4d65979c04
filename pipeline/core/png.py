"""Lossless PNG writing: one fixed row filter (numpy) and zlib's deflate (the standard library's), level 1.

The render stage writes four PNGs per camera frame. Any PNG reader decodes them (the tests read them back with
OpenCV and Pillow); ``bench/bench_png.py`` times this writer against OpenCV's.

Same image, same bytes: zlib's deflate is a function of its input, level and zlib version. ISA-L's deflate, which
wrote these files before (about 5 times faster), is not: on one 160 x 120 instance image it wrote two different
streams (both decoding to the same rows) in a Ray worker and in the local process of the same machine
(tests/stages/test_ray_executor.py, on a fresh clone, 2026-11-27), which breaks "same config and seed, same bytes".

PNG in brief (ISO/IEC 15948): the signature, an IHDR chunk (size, bit depth, colour type), IDAT chunks holding one
zlib stream of the filtered rows (each row prefixed by its filter type), and IEND. 16-bit samples are big-endian.
Filters act on bytes, on the raw values of the previous pixel (Sub) or row (Up), modulo 256.
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import numpy as np

SIGNATURE = b"\x89PNG\r\n\x1a\n"
FILTERS = {"none": 0, "sub": 1, "up": 2}  # PNG filter types 0-2; Average and Paeth cost more than they save here
COLOUR_TYPES = {1: 0, 2: 4, 3: 2, 4: 6}  # channels -> PNG colour type: grey, grey+alpha, RGB, RGBA
LEVEL = 1  # zlib's fastest level that compresses
# zlib's strategies: "default" finds repeated strings (label and depth images: long runs) and codes what is left;
# "huffman" only codes bytes by their frequency. A camera's image is sensor noise at every pixel: its filtered rows
# hold almost no repeats worth the search, and their codes alone come out smaller (the rendered frames: 11-19 %) in
# about 0.6 of the time (docs/performance.md).
STRATEGIES = {"default": zlib.Z_DEFAULT_STRATEGY, "huffman": zlib.Z_HUFFMAN_ONLY}


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(data, zlib.crc32(kind)))


def filter_rows(image: np.ndarray, row_filter: str = "none") -> np.ndarray:
    """(H, 1 + row bytes) uint8: ``image``'s rows as PNG stores them before compression, each led by its filter
    type (``row_filter``: none, sub or up)."""
    h = image.shape[0]
    channels = image.shape[2] if image.ndim == 3 else 1
    data = np.ascontiguousarray(image, image.dtype.newbyteorder(">")).view(np.uint8).reshape(h, -1)
    bpp = channels * image.dtype.itemsize  # bytes per pixel: Sub's distance
    out = np.empty((h, data.shape[1] + 1), np.uint8)
    out[:, 0] = FILTERS[row_filter]
    if row_filter == "none":
        out[:, 1:] = data
    elif row_filter == "sub":
        out[:, 1:1 + bpp] = data[:, :bpp]
        np.subtract(data[:, bpp:], data[:, :-bpp], out=out[:, 1 + bpp:])  # uint8 arithmetic: modulo 256
    else:
        out[0, 1:] = data[0]
        np.subtract(data[1:], data[:-1], out=out[1:, 1:])
    return out


def encode_png(image: np.ndarray, row_filter: str = "none", *, name: str = "image", strategy: str = "default"
               ) -> bytes:
    """The PNG file of ``image``: (H, W) or (H, W, C) uint8 or uint16, C = 1 (grey), 2 (grey + alpha), 3 (RGB, in
    that order) or 4 (RGBA); deflated with zlib's ``strategy`` (:data:`STRATEGIES`). ``name`` names the image in
    errors."""
    image = np.asarray(image)
    if image.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"{name}: PNG samples must be uint8 or uint16, got {image.dtype}")
    channels = image.shape[2] if image.ndim == 3 else 1
    if image.ndim not in (2, 3) or channels not in COLOUR_TYPES or 0 in image.shape[:2]:
        raise ValueError(f"{name}: a PNG image is (H, W) or (H, W, C) with H, W > 0 and C in 1-4, "
                         f"got shape {image.shape}")
    if row_filter not in FILTERS:
        raise ValueError(f"{name}: row filter must be one of {sorted(FILTERS)}, got {row_filter!r}")
    if strategy not in STRATEGIES:
        raise ValueError(f"{name}: zlib strategy must be one of {sorted(STRATEGIES)}, got {strategy!r}")
    h, w = image.shape[:2]
    header = struct.pack(">IIBBBBB", w, h, 8 * image.dtype.itemsize, COLOUR_TYPES[channels], 0, 0, 0)
    deflate = zlib.compressobj(LEVEL, zlib.DEFLATED, zlib.MAX_WBITS, 8, STRATEGIES[strategy])
    data = deflate.compress(filter_rows(image, row_filter).data) + deflate.flush()
    return SIGNATURE + _chunk(b"IHDR", header) + _chunk(b"IDAT", data) + _chunk(b"IEND", b"")


def write_png(path: Path, image: np.ndarray, row_filter: str = "none", strategy: str = "default") -> None:
    """Write ``image`` (see :func:`encode_png`) to ``path``."""
    Path(path).write_bytes(encode_png(image, row_filter, name=str(path), strategy=strategy))


def check_png(data: bytes, source: str, *, width: int | None = None, height: int | None = None) -> None:
    """Raise ValueError naming ``source`` unless ``data`` is a whole PNG: the signature, then chunks each with a
    matching CRC (a flipped or missing byte fails), IHDR first, IEND last, and the size ``width`` x ``height``
    when given. Reads no pixel: a fraction of the cost of decoding."""
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise ValueError(f"{source}: not a PNG image (no PNG signature)")
    at, first = 8, True
    while True:
        if at + 8 > len(data):
            raise ValueError(f"{source}: truncated PNG (ends at byte {len(data)} without its IEND chunk)")
        length, kind = struct.unpack(">I4s", data[at: at + 8])
        end = at + 12 + length
        if end > len(data):
            raise ValueError(f"{source}: truncated PNG (its {kind.decode('latin-1')} chunk ends past byte {len(data)})")
        (crc,) = struct.unpack(">I", data[end - 4: end])
        if zlib.crc32(data[at + 4: end - 4]) != crc:
            raise ValueError(f"{source}: damaged PNG (CRC mismatch in its {kind.decode('latin-1')} chunk at byte {at})")
        if first:
            if kind != b"IHDR":
                raise ValueError(f"{source}: damaged PNG (first chunk {kind!r}, not IHDR)")
            w, h = struct.unpack(">II", data[at + 8: at + 16])
            if (width is not None and w != width) or (height is not None and h != height):
                raise ValueError(f"{source}: PNG of {w}x{h} pixels, expected {width}x{height}")
            first = False
        if kind == b"IEND":
            return
        at = end


def with_text(data: bytes, keyword: str, text: str) -> bytes:
    """The PNG ``data`` with a tEXt chunk (``keyword``, ``text``; Latin-1) right after its IHDR."""
    check_png(data, "the PNG being marked")
    after_ihdr = 8 + 12 + struct.unpack(">I", data[8:12])[0]
    chunk = _chunk(b"tEXt", keyword.encode("latin-1") + b"\0" + text.encode("latin-1"))
    return data[:after_ihdr] + chunk + data[after_ihdr:]


def png_text(path: Path) -> dict[str, str]:
    """The tEXt chunks before the image data of the PNG file ``path`` (keyword -> text); {} for a file that is not
    a PNG or is damaged there. Reads only the chunk headers up to the first IDAT."""
    out: dict[str, str] = {}
    with Path(path).open("rb") as fh:
        if fh.read(8) != SIGNATURE:
            return out
        while True:
            head = fh.read(8)
            if len(head) < 8:
                return out
            length, kind = struct.unpack(">I4s", head)
            if kind in (b"IDAT", b"IEND"):
                return out
            body = fh.read(length)
            fh.read(4)  # CRC
            if kind == b"tEXt" and b"\0" in body:
                key, _, value = body.partition(b"\0")
                out[key.decode("latin-1")] = value.decode("latin-1")
