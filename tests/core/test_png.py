"""The PNG writer: files that independent readers (OpenCV, Pillow) decode to the same samples, and the filters'
bytes in closed form."""

from __future__ import annotations

import struct
import zlib

import cv2
import numpy as np
import pytest
from PIL import Image

from pipeline.core.png import encode_png, filter_rows, write_png


def _images(rng: np.random.Generator) -> list[np.ndarray]:
    smooth = np.cumsum(rng.integers(0, 3, (37, 53)), axis=1).astype(np.uint16) * 97  # carries across bytes
    return [
        rng.integers(0, 256, (37, 53, 3), dtype=np.uint8),  # RGB
        rng.integers(0, 256, (37, 53, 4), dtype=np.uint8),  # RGBA
        rng.integers(0, 256, (37, 53), dtype=np.uint8),  # grey
        rng.integers(0, 65536, (37, 53), dtype=np.uint16),  # 16-bit grey (instance ids, depth)
        smooth,
        rng.integers(0, 65536, (5, 7, 3), dtype=np.uint16),  # 16-bit RGB
        np.zeros((1, 1), np.uint8),
    ]


@pytest.mark.parametrize("strategy", ["default", "huffman"])
@pytest.mark.parametrize("row_filter", ["none", "sub", "up"])
def test_opencv_and_pillow_read_back_the_samples(tmp_path, row_filter, strategy):
    for k, image in enumerate(_images(np.random.default_rng(3))):
        path = tmp_path / f"{k}.png"
        write_png(path, image, row_filter, strategy)
        back = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        if image.ndim == 3:  # OpenCV returns BGR(A)
            back = back[..., [2, 1, 0, 3][:image.shape[2]]]
        assert back.dtype == image.dtype and np.array_equal(back, image), (k, row_filter)
        with Image.open(path) as pil:
            pil.load()
            if image.dtype == np.uint8:  # Pillow's 16-bit modes are single-channel; 8-bit ones cover every layout
                assert np.array_equal(np.asarray(pil), image), (k, row_filter)
            elif image.ndim == 2:
                assert np.array_equal(np.asarray(pil).astype(np.uint16), image), (k, row_filter)


def test_filters_in_closed_form():
    image = np.array([[[10, 200], [250, 5], [0, 255]], [[9, 201], [3, 3], [128, 0]]], np.uint8)  # (2, 3, 2) grey+alpha
    none = filter_rows(image, "none")
    assert none.tolist() == [[0, 10, 200, 250, 5, 0, 255], [0, 9, 201, 3, 3, 128, 0]]
    sub = filter_rows(image, "sub")  # each byte minus the same byte of the pixel to its left, modulo 256
    assert sub.tolist() == [[1, 10, 200, 240, 61, 6, 250], [1, 9, 201, 250, 58, 125, 253]]
    up = filter_rows(image, "up")  # each byte minus the byte above it
    assert up.tolist() == [[2, 10, 200, 250, 5, 0, 255], [2, 255, 1, 9, 254, 128, 1]]
    wide = filter_rows(np.array([[0x0102, 0x0304]], np.uint16), "sub")  # big-endian bytes, 2 bytes per pixel
    assert wide.tolist() == [[1, 0x01, 0x02, 0x02, 0x02]]


def test_file_structure():
    data = encode_png(np.full((2, 3, 3), 7, np.uint8), "up")
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    pos, chunks = 8, []
    while pos < len(data):
        (length,) = struct.unpack(">I", data[pos:pos + 4])
        kind, body = data[pos + 4:pos + 8], data[pos + 8:pos + 8 + length]
        (crc,) = struct.unpack(">I", data[pos + 8 + length:pos + 12 + length])
        assert crc == zlib.crc32(kind + body)
        chunks.append((kind, body))
        pos += 12 + length
    assert [k for k, _ in chunks] == [b"IHDR", b"IDAT", b"IEND"]
    assert struct.unpack(">IIBBBBB", chunks[0][1]) == (3, 2, 8, 2, 0, 0, 0)
    assert zlib.decompress(chunks[1][1]) == bytes([2] + [7] * 9 + [2] + [0] * 9)


def test_same_image_same_bytes():
    image = np.random.default_rng(5).integers(0, 256, (60, 80, 3), dtype=np.uint8)
    assert encode_png(image, "up") == encode_png(image.copy(), "up")
    assert encode_png(image, "up", strategy="huffman") == encode_png(image.copy(), "up", strategy="huffman")


def test_strategies_are_zlibs():
    """The default strategy is zlib's level-1 deflate of the filtered rows; "huffman" codes the same rows without
    looking for repeats: on a noisy image (a camera's) a smaller stream, on one of long runs (a label image) larger."""
    rng = np.random.default_rng(6)
    noisy = np.clip(rng.normal(128, 12, (60, 80, 3)), 0, 255).astype(np.uint8)
    runs = np.repeat(rng.integers(0, 5, (60, 8), dtype=np.uint8), 10, axis=1)

    def idat(data: bytes) -> bytes:
        (length,) = struct.unpack(">I", data[33:37])  # the chunk after the signature (8) and IHDR (25)
        assert data[37:41] == b"IDAT"
        return data[41:41 + length]

    for image in (noisy, runs):
        rows = filter_rows(image, "up").tobytes()
        assert idat(encode_png(image, "up")) == zlib.compress(rows, 1)
        assert zlib.decompress(idat(encode_png(image, "up", strategy="huffman"))) == rows
    assert len(encode_png(noisy, "up", strategy="huffman")) < len(encode_png(noisy, "up"))
    assert len(encode_png(runs, "none", strategy="huffman")) > len(encode_png(runs, "none"))


@pytest.mark.parametrize("image, row_filter, message", [
    (np.zeros((4, 4), np.float32), "none", "uint8 or uint16"),
    (np.zeros((4, 4, 5), np.uint8), "none", r"got shape \(4, 4, 5\)"),
    (np.zeros((0, 4), np.uint8), "none", r"got shape \(0, 4\)"),
    (np.zeros(4, np.uint8), "none", r"got shape \(4,\)"),
    (np.zeros((4, 4), np.uint8), "paeth", "row filter must be one of"),
])
def test_bad_input_is_named(tmp_path, image, row_filter, message):
    path = tmp_path / "bad.png"
    with pytest.raises(ValueError, match=message) as err:
        write_png(path, image, row_filter)
    assert str(path) in str(err.value)
    assert not path.exists()
    with pytest.raises(ValueError, match="zlib strategy must be one of") as err:
        write_png(path, np.zeros((4, 4), np.uint8), "none", "rle")
    assert str(path) in str(err.value) and not path.exists()
