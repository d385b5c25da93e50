#!/usr/bin/python3
"""Converts LPIPS weights to the file d2gs reads (`d2gs eval --lpips-weights FILE`, docs/formats.md).

Inputs (PyTorch checkpoints, which d2gs cannot fetch for you):
  --trunk  the torchvision ImageNet trunk: vgg16-397923af.pth (torchvision.models.vgg16) or
           alexnet-owt-7be5be79.pth (torchvision.models.alexnet); only its `features.*` tensors are kept.
  --lin    the LPIPS v0.1 linear layers: weights/v0.1/vgg.pth or alex.pth of the LPIPS repository
           (keys linK.model.1.weight, K = 0..4).
Output: a safetensors file holding `features.N.weight`, `features.N.bias` (torchvision names and
shapes) and `linK.weight` [1, C, 1, 1], all float32, with metadata format=d2gs-lpips, net, version.

  /usr/bin/python3 tools/convert_lpips_weights.py --trunk vgg16-397923af.pth --lin vgg.pth -o lpips_vgg.safetensors

Needs PyTorch only to unpickle the checkpoints (Debian: python3-torch); writing safetensors needs
nothing but the standard library and NumPy.
"""
import argparse
import json
import pathlib
import struct
import sys

import numpy as np


def write_safetensors(path, tensors, metadata=None, dtype="F32"):
    """Writes {name: numpy array} as safetensors (names sorted, data packed in that order)."""
    np_dtype = {"F32": "<f4", "F16": "<f2", "F64": "<f8"}[dtype]
    header = {}
    if metadata:
        header["__metadata__"] = {str(k): str(v) for k, v in metadata.items()}
    blobs, offset = [], 0
    for name in sorted(tensors):
        data = np.ascontiguousarray(np.asarray(tensors[name]).astype(np_dtype)).tobytes()
        header[name] = {"dtype": dtype, "shape": list(np.asarray(tensors[name]).shape),
                        "data_offsets": [offset, offset + len(data)]}
        blobs.append(data)
        offset += len(data)
    text = json.dumps(header, separators=(",", ":")).encode()
    text += b" " * ((8 - (8 + len(text)) % 8) % 8)
    path = pathlib.Path(path)
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as f:
        f.write(struct.pack("<Q", len(text)))
        f.write(text)
        for b in blobs:
            f.write(b)
    tmp.replace(path)


def convert(trunk_state, lin_state, net=None):
    """Returns ({name: float32 array}, net) from a torchvision state dict and an LPIPS linear state dict."""
    out = {}
    for k, v in trunk_state.items():
        if k.startswith("features."):
            out[k] = v.detach().cpu().numpy().astype(np.float32)
    if "features.0.weight" not in out:
        raise SystemExit("trunk checkpoint has no features.0.weight: not a torchvision vgg16/alexnet state dict")
    kernel = out["features.0.weight"].shape[-1]
    detected = {3: "vgg16", 11: "alexnet"}.get(kernel)
    if detected is None:
        raise SystemExit(f"features.0.weight has {kernel}x{kernel} kernels: neither vgg16 nor alexnet")
    if net and net != detected:
        raise SystemExit(f"--net {net} but the trunk checkpoint is {detected}")
    for k in range(5):
        key = f"lin{k}.model.1.weight"
        if key not in lin_state:
            raise SystemExit(f"LPIPS checkpoint has no {key}: not an LPIPS v0.1 linear-layer file")
        out[f"lin{k}.weight"] = lin_state[key].detach().cpu().numpy().astype(np.float32)
    return out, detected


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--trunk", required=True, help="torchvision checkpoint (vgg16-*.pth or alexnet-*.pth)")
    ap.add_argument("--lin", required=True, help="LPIPS v0.1 linear weights (vgg.pth or alex.pth)")
    ap.add_argument("--net", choices=["vgg16", "alexnet"], help="expected trunk (default: detected)")
    ap.add_argument("-o", "--output", required=True, help="output .safetensors file")
    args = ap.parse_args(argv)
    import torch  # only to unpickle the checkpoints
    trunk = torch.load(args.trunk, map_location="cpu")
    lin = torch.load(args.lin, map_location="cpu")
    tensors, net = convert(trunk, lin, args.net)
    write_safetensors(args.output, tensors, {"format": "d2gs-lpips", "net": net, "version": "0.1",
                                             "trunk": pathlib.Path(args.trunk).name,
                                             "lin": pathlib.Path(args.lin).name})
    print(f"wrote {args.output}: {net}, {len(tensors)} tensors")


if __name__ == "__main__":
    sys.exit(main())
