#!/usr/bin/python3
"""Writes the golden PLY fixtures of tests/model/fixtures with an independent writer (numpy + a header
written by hand, as plyfile writes it for the original 3DGS code). tests/model/test_ply.cpp builds the
same models from the same formula and checks that d2gs reads these files to those values and writes
those models to exactly these bytes.

Usage: /usr/bin/python3 tools/make_ply_fixture.py [OUT_DIR]   (default: tests/model/fixtures)

Values: attribute `a` of Gaussian `i`, flattened per-Gaussian index `m` (memory layout of d2gs: means,
sh_dc, sh_rest N x K x 3 coefficient-major with RGB innermost, opacity, log-scales, quaternions):
    v(i, a, m) = ((i + 1) * 1000 + a * 100 + m) / 16, negated when (i + a + m) is odd
with a few special values overriding it (see SPECIALS), all exactly representable in float32.
"""
import os
import sys

import numpy as np

ATTR_MEANS, ATTR_DC, ATTR_REST, ATTR_OPACITY, ATTR_SCALE, ATTR_ROT = range(6)
F32_MAX = float(np.finfo(np.float32).max)
# (gaussian, attribute, memory index) -> value
SPECIALS = {
    (0, ATTR_MEANS, 0): -0.0,
    (0, ATTR_MEANS, 1): 2.0 ** -149,  # smallest positive denormal
    (0, ATTR_MEANS, 2): F32_MAX,
    (1, ATTR_DC, 2): -(2.0 ** -130),  # a negative denormal
    (1, ATTR_OPACITY, 0): -F32_MAX,
}


def value(i, a, m):
    if (i, a, m) in SPECIALS:
        return SPECIALS[(i, a, m)]
    v = ((i + 1) * 1000 + a * 100 + m) / 16.0
    return -v if (i + a + m) % 2 else v


def attribute(n, a, width):
    return np.array([[value(i, a, m) for m in range(width)] for i in range(n)], dtype=np.float32)


def gaussians_ply(n, degree):
    k = (degree + 1) ** 2 - 1
    means = attribute(n, ATTR_MEANS, 3)
    dc = attribute(n, ATTR_DC, 3)
    rest = attribute(n, ATTR_REST, 3 * k).reshape(n, k, 3)  # memory layout N x K x 3
    opacity = attribute(n, ATTR_OPACITY, 1)
    scale = attribute(n, ATTR_SCALE, 3)
    rot = attribute(n, ATTR_ROT, 4)
    # File layout, as the 3DGS code's save_ply: f_rest grouped by channel (transpose to N x 3 x K).
    rest_file = rest.transpose(0, 2, 1).reshape(n, 3 * k)
    names = (["x", "y", "z", "nx", "ny", "nz"] + [f"f_dc_{j}" for j in range(3)] +
             [f"f_rest_{j}" for j in range(3 * k)] + ["opacity"] + [f"scale_{j}" for j in range(3)] +
             [f"rot_{j}" for j in range(4)])
    table = np.concatenate([means, np.zeros((n, 3), np.float32), dc, rest_file, opacity, scale, rot], axis=1)
    assert table.shape[1] == len(names)
    header = "ply\nformat binary_little_endian 1.0\n" + f"element vertex {n}\n"
    header += "".join(f"property float {name}\n" for name in names) + "end_header\n"
    return header.encode("ascii") + table.astype("<f4").tobytes()


def points_ply(n):
    dtype = [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("nx", "<f4"), ("ny", "<f4"), ("nz", "<f4"),
             ("red", "u1"), ("green", "u1"), ("blue", "u1")]
    rows = np.zeros(n, dtype=dtype)
    for i in range(n):
        rows[i]["x"], rows[i]["y"], rows[i]["z"] = (value(i, ATTR_MEANS, m) for m in range(3))
        rows[i]["red"], rows[i]["green"], rows[i]["blue"] = ((i * 70 + c * 30) % 256 for c in range(3))
    header = "ply\nformat binary_little_endian 1.0\n" + f"element vertex {n}\n"
    header += "".join(f"property {'float' if t == '<f4' else 'uchar'} {name}\n" for name, t in dtype)
    header += "end_header\n"
    return header.encode("ascii") + rows.tobytes()


def main():
    out = sys.argv[1] if len(sys.argv) > 1 else os.path.join(os.path.dirname(__file__), "..", "tests", "model", "fixtures")
    os.makedirs(out, exist_ok=True)
    files = {
        "gaussians_sh0.ply": gaussians_ply(2, 0),
        "gaussians_sh1.ply": gaussians_ply(3, 1),
        "gaussians_sh3.ply": gaussians_ply(2, 3),
        "points.ply": points_ply(4),
    }
    for name, data in files.items():
        with open(os.path.join(out, name), "wb") as f:
            f.write(data)
        print(f"{name}: {len(data)} bytes")


if __name__ == "__main__":
    main()
