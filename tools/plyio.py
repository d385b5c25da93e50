"""Reading the vertex element of a PLY file into a numpy structured array, for the analysis scripts in tools/.

Binary little-endian (what `d2gs` writes, and 3DGS's point_cloud.ply) and ASCII (COLMAP's fused.ply exports)
are read; the vertex element must come first and have scalar properties only. Errors exit with one line
naming the file.
"""
import sys

import numpy as np

TYPES = {"float": "<f4", "float32": "<f4", "double": "<f8", "float64": "<f8", "uchar": "u1", "uint8": "u1",
         "char": "i1", "int8": "i1", "ushort": "<u2", "uint16": "<u2", "short": "<i2", "int16": "<i2",
         "int": "<i4", "int32": "<i4", "uint": "<u4", "uint32": "<u4"}


def read_ply(path):
    """The vertex element of PLY file `path` as a structured array (one field per property)."""
    with open(path, "rb") as f:
        header = []
        while True:
            line = f.readline()
            if not line:
                sys.exit(f"{path}: no end_header")
            line = line.decode("ascii", "replace").strip()
            header.append(line)
            if line == "end_header":
                break
        formats = [h for h in header if h.startswith("format ")]
        ascii_format = formats == ["format ascii 1.0"]
        if not ascii_format and formats != ["format binary_little_endian 1.0"]:
            sys.exit(f"{path}: not an ASCII or binary little-endian PLY")
        count = None
        fields = []
        for line in header:
            words = line.split()
            if words[:2] == ["element", "vertex"]:
                if fields or count is not None:
                    sys.exit(f"{path}: more than one vertex element")
                count = int(words[2])
            elif words and words[0] == "element":
                if count is None:
                    sys.exit(f"{path}: the vertex element is not the first element")
                break
            elif words and words[0] == "property" and count is not None:
                if words[1] == "list" or words[1] not in TYPES:
                    sys.exit(f"{path}: unsupported property '{line}'")
                fields.append((words[2], TYPES[words[1]]))
        if count is None:
            sys.exit(f"{path}: no vertex element")
        dtype = np.dtype(fields)
        if ascii_format:
            rows = np.loadtxt(f, max_rows=count, ndmin=2)
            if rows.shape != (count, len(fields)):
                sys.exit(f"{path}: {rows.shape[0]} vertex rows of {rows.shape[1]} values, expected {count} of {len(fields)}")
            data = np.empty(count, dtype=dtype)
            for i, (name, _) in enumerate(fields):
                data[name] = rows[:, i]
            return data
        raw = f.read(count * dtype.itemsize)
        if len(raw) < count * dtype.itemsize:
            sys.exit(f"{path}: truncated ({len(raw)} bytes of vertex data, expected {count * dtype.itemsize})")
        return np.frombuffer(raw, dtype=dtype, count=count)


def read_xyz(path):
    """The vertex positions of PLY file `path` as an N×3 float64 array."""
    a = read_ply(path)
    return np.stack([a["x"], a["y"], a["z"]], 1).astype(np.float64)
