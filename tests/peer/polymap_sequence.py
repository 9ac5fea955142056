"""polymap's sequence format (README "The sequence format") read by the test peers in plain
Python (no numpy, no PIL), sharing no code with polymap."""

import struct
import zlib


def read_poses(seq):
    """(stamp ns, position, quaternion xyzw) per frame, stamps read exactly from the text."""
    out = []
    for line in (seq / "poses.txt").read_text().splitlines():
        if not line.strip() or line.startswith("#"):
            continue
        f = line.split()
        sec, _, frac = f[0].partition(".")
        stamp = int(sec) * 1_000_000_000 + int((frac + "000000000")[:9])
        out.append((stamp, [float(v) for v in f[1:4]], [float(v) for v in f[4:8]]))
    return out


def read_png16(path):
    """(width, height, big-endian 16-bit samples) of a 16-bit grayscale PNG."""
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n", path
    pos, idat, width, height = 8, b"", 0, 0
    while pos < len(data):
        n, kind = struct.unpack(">I4s", data[pos:pos + 8])
        body = data[pos + 8:pos + 8 + n]
        if kind == b"IHDR":
            width, height, depth, colour, _, _, interlace = struct.unpack(">IIBBBBB", body)
            assert (depth, colour, interlace) == (16, 0, 0), (path, depth, colour, interlace)
        elif kind == b"IDAT":
            idat += body
        pos += 12 + n
    raw, bpp, stride = zlib.decompress(idat), 2, width * 2
    out, prev = bytearray(), bytearray(stride)
    for y in range(height):
        f, line = raw[y * (stride + 1)], bytearray(raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)])
        for i in range(stride):
            a = line[i - bpp] if i >= bpp else 0
            b = prev[i]
            c = prev[i - bpp] if i >= bpp else 0
            if f == 1:
                line[i] = (line[i] + a) & 0xFF
            elif f == 2:
                line[i] = (line[i] + b) & 0xFF
            elif f == 3:
                line[i] = (line[i] + (a + b) // 2) & 0xFF
            elif f == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                line[i] = (line[i] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 0xFF
        out += line
        prev = line
    return width, height, bytes(out)


def camera_toml(seq):
    return {k.strip(): float(v) for k, v in (l.split("=") for l in (seq / "camera.toml").read_text().splitlines() if "=" in l)}


