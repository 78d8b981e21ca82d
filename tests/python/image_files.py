"""Readers of the files `stereoctl snapshot` writes, in numpy only: grayscale PNG (8 and
16 bit, non-interlaced) and PFM."""

import struct
import zlib
from pathlib import Path

import numpy as np


def _unfilter(raw: bytes, height: int, stride: int, bpp: int) -> np.ndarray:
    out = np.zeros((height, stride), dtype=np.uint8)
    previous = np.zeros(stride, dtype=np.int32)
    pos = 0
    for y in range(height):
        kind = raw[pos]
        line = np.frombuffer(raw, dtype=np.uint8, count=stride, offset=pos + 1).astype(np.int32)
        pos += 1 + stride
        if kind == 0:
            row = line
        elif kind == 2:
            row = (line + previous) & 0xFF
        elif kind in (1, 3, 4):
            row = line.copy()
            for x in range(stride):
                a = int(row[x - bpp]) if x >= bpp else 0
                b = int(previous[x])
                if kind == 1:
                    predictor = a
                elif kind == 3:
                    predictor = (a + b) >> 1
                else:
                    c = int(previous[x - bpp]) if x >= bpp else 0
                    p = a + b - c
                    pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                    predictor = a if pa <= pb and pa <= pc else (b if pb <= pc else c)
                row[x] = (row[x] + predictor) & 0xFF
        else:
            raise ValueError(f"PNG filter type {kind}")
        out[y] = row
        previous = row
    return out


def read_png_gray(path: Path) -> np.ndarray:
    return read_png(path, colour_ok=False)


def read_png(path: Path, colour_ok: bool = True) -> np.ndarray:
    """A non-interlaced grey (H x W, 8 or 16 bit) or, with colour_ok, 8-bit RGB PNG
    (H x W x 3, red first)."""
    data = Path(path).read_bytes()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise ValueError(f"{path}: not a PNG")
    pos = 8
    idat = b""
    width = height = depth = colour = interlace = None
    while pos < len(data):
        length, kind = struct.unpack(">I4s", data[pos:pos + 8])
        body = data[pos + 8:pos + 8 + length]
        pos += 12 + length
        if kind == b"IHDR":
            width, height, depth, colour, _, _, interlace = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat += body
        elif kind == b"IEND":
            break
    if colour_ok and colour == 2 and depth == 8 and interlace == 0:
        rows = _unfilter(zlib.decompress(idat), height, width * 3, 3)
        return rows.reshape(height, width, 3)
    if colour != 0 or interlace != 0 or depth not in (8, 16):
        raise ValueError(f"{path}: only non-interlaced 8/16-bit grayscale PNG is read here")
    bpp = depth // 8
    rows = _unfilter(zlib.decompress(idat), height, width * bpp, bpp)
    if depth == 8:
        return rows.reshape(height, width)
    return rows.view(">u2").reshape(height, width).astype(np.uint16)


def read_pfm(path: Path) -> np.ndarray:
    data = Path(path).read_bytes()
    fields = []
    pos = 0
    while len(fields) < 4:  # "Pf", width, height, scale, separated by whitespace
        while data[pos:pos + 1].isspace():
            pos += 1
        start = pos
        while not data[pos:pos + 1].isspace():
            pos += 1
        fields.append(data[start:pos].decode())
    pos += 1  # the single whitespace after the scale
    if fields[0] != "Pf":
        raise ValueError(f"{path}: only grayscale PFM is read here")
    width, height, scale = int(fields[1]), int(fields[2]), float(fields[3])
    dtype = "<f4" if scale < 0 else ">f4"
    image = np.frombuffer(data, dtype=dtype, count=width * height, offset=pos)
    # PFM rows run bottom to top.
    return image.reshape(height, width)[::-1].astype(np.float32)
