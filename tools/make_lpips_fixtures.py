#!/usr/bin/python3
"""Independent LPIPS reference for tests/eval (method.md §6), computed with PyTorch (Debian python3-torch
and python3-torchvision; this script only, never the tests or the program).

The networks are torchvision's own modules: `torchvision.models.vgg16().features` and
`torchvision.models.alexnet().features` at full width, `torchvision.models.vgg.make_layers` for the
width-reduced VGG16 and an nn.Sequential checked layer by layer against torchvision's AlexNet for the
width-reduced AlexNet. The LPIPS head follows the LPIPS package: ScalingLayer, the five slices,
normalize_tensor (eps 1e-10), squared difference, 1×1 conv without bias, spatial mean, sum. Everything is
evaluated in float64.

Writes tests/eval/fixtures/lpips/:
  vgg16_w8.safetensors   VGG16 with every width / 8 (8, 16, 32, 64, 64), seeded weights, stored as F16,
                         written through tools/convert_lpips_weights.py from torch .pth checkpoints
  alexnet_w8.safetensors AlexNet with every width / 8 (8, 24, 48, 32, 32), seeded weights, F32, same path
  img_64x48_{a,b}.npy, img_41x35_{a,b}.npy   image pairs, H×W×3 float32 in [0, 1]
  expected.json          LPIPS (total and per tap) for every net × pair × input range, including the
                         full-width nets whose weights come from hash_weights() below (C++ rebuilds them
                         from the same formula, so nothing large is committed)

Run: /usr/bin/python3 tools/make_lpips_fixtures.py
"""
import json
import pathlib
import sys
import tempfile

import numpy as np
import torch
import torch.nn as nn
import torchvision

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import convert_lpips_weights as conv  # noqa: E402

OUT = pathlib.Path(__file__).resolve().parent.parent / "tests" / "eval" / "fixtures" / "lpips"
SHIFT = torch.tensor([-.030, -.088, -.188], dtype=torch.float64).view(1, 3, 1, 1)
SCALE = torch.tensor([.458, .448, .450], dtype=torch.float64).view(1, 3, 1, 1)
M64 = (1 << 64) - 1


def hash_uniform(stream, count):
    """count values in [-1, 1) from a SplitMix64-style hash of (stream, index); exact in float32.
    Mirrored by hash_uniform() in tests/eval/test_lpips.cpp."""
    n = np.arange(count, dtype=np.uint64)
    with np.errstate(over="ignore"):
        x = (n + np.uint64(1)) * np.uint64(0x9E3779B97F4A7C15) + np.uint64(stream) * np.uint64(0xBF58476D1CE4E5B9)
        x ^= x >> np.uint64(31)
        x *= np.uint64(0x94D049BB133111EB)
        x ^= x >> np.uint64(29)
    return (x >> np.uint64(40)).astype(np.float64) / float(1 << 24) * 2.0 - 1.0


def hash_weights(features, lin_channels):
    """The closed-form weights: conv weight u·sqrt(6/fan_in) with stream 2i, bias 0.05·u with stream
    2i+1 (i = torchvision feature index), linK weight 0.05·(u + 1) with stream 1000 + K; each value
    rounded to float32."""
    out = {}
    for i, m in enumerate(features):
        if isinstance(m, nn.Conv2d):
            w = m.weight.shape
            fan_in = w[1] * w[2] * w[3]
            out[f"features.{i}.weight"] = (hash_uniform(2 * i, int(np.prod(w))) * np.sqrt(6.0 / fan_in)).astype(np.float32).reshape(w)
            out[f"features.{i}.bias"] = (0.05 * hash_uniform(2 * i + 1, w[0])).astype(np.float32)
    for k, c in enumerate(lin_channels):
        out[f"lin{k}.weight"] = (0.05 * (hash_uniform(1000 + k, c) + 1.0)).astype(np.float32).reshape(1, c, 1, 1)
    return out


def seeded_weights(features, lin_channels, rng):
    """He-normal conv weights, small biases, non-negative linear weights (as trained LPIPS ones)."""
    trunk, lin = {}, {}
    for i, m in enumerate(features):
        if isinstance(m, nn.Conv2d):
            w = m.weight.shape
            fan_in = w[1] * w[2] * w[3]
            trunk[f"features.{i}.weight"] = torch.tensor(rng.normal(0, np.sqrt(2.0 / fan_in), w), dtype=torch.float32)
            trunk[f"features.{i}.bias"] = torch.tensor(rng.normal(0, 0.05, w[0]), dtype=torch.float32)
    for k, c in enumerate(lin_channels):
        lin[f"lin{k}.model.1.weight"] = torch.tensor(rng.uniform(0, 0.2, (1, c, 1, 1)), dtype=torch.float32)
    return trunk, lin


def reduced_alexnet(widths):
    c1, c2, c3, c4, c5 = widths
    seq = nn.Sequential(
        nn.Conv2d(3, c1, 11, 4, 2), nn.ReLU(inplace=True), nn.MaxPool2d(3, 2),
        nn.Conv2d(c1, c2, 5, padding=2), nn.ReLU(inplace=True), nn.MaxPool2d(3, 2),
        nn.Conv2d(c2, c3, 3, padding=1), nn.ReLU(inplace=True),
        nn.Conv2d(c3, c4, 3, padding=1), nn.ReLU(inplace=True),
        nn.Conv2d(c4, c5, 3, padding=1), nn.ReLU(inplace=True), nn.MaxPool2d(3, 2))
    ref = torchvision.models.alexnet().features
    assert len(seq) == len(ref)
    for a, b in zip(seq, ref):  # same layers as torchvision's, only narrower
        assert type(a) is type(b)
        if isinstance(a, nn.Conv2d):
            assert (a.kernel_size, a.stride, a.padding) == (b.kernel_size, b.stride, b.padding)
        if isinstance(a, nn.MaxPool2d):
            assert (a.kernel_size, a.stride) == (b.kernel_size, b.stride)
    return seq


# LPIPS slices of torchvision's `features` (pretrained_networks.py of the LPIPS package).
SLICES = {"vgg16": [(0, 4), (4, 9), (9, 16), (16, 23), (23, 30)],
          "alexnet": [(0, 2), (2, 5), (5, 8), (8, 10), (10, 12)]}


def tap_channels(features, net):
    out = []
    for _, end in SLICES[net]:
        convs = [m for m in list(features)[:end] if isinstance(m, nn.Conv2d)]
        out.append(convs[-1].out_channels)
    return out


def load_into(features, tensors):
    sd = {k[len("features."):]: torch.tensor(np.asarray(v, dtype=np.float32)) for k, v in tensors.items() if k.startswith("features.")}
    features.load_state_dict(sd)
    return features.double().eval()


def lpips(features, lin, net, img0, img1, symmetric):
    """img: H×W×3 float array in [0, 1]. Returns (total, per-tap list)."""
    def prep(img):
        x = torch.tensor(np.asarray(img, dtype=np.float64)).permute(2, 0, 1).unsqueeze(0)
        if symmetric:
            x = 2 * x - 1
        return (x - SHIFT) / SCALE

    def taps(x):
        out = []
        for a, b in SLICES[net]:
            for m in list(features)[a:b]:
                x = m(x)
            out.append(x)
        return out

    def normalize_tensor(f, eps=1e-10):
        return f / (torch.sqrt(torch.sum(f ** 2, dim=1, keepdim=True)) + eps)

    with torch.no_grad():
        t0, t1 = taps(prep(img0)), taps(prep(img1))
        per = []
        for k in range(5):
            d = (normalize_tensor(t0[k]) - normalize_tensor(t1[k])) ** 2
            w = torch.tensor(np.asarray(lin[f"lin{k}.weight"], dtype=np.float64)).view(1, -1, 1, 1)
            per.append(float(nn.functional.conv2d(d, w).mean(dim=(2, 3)).item()))
    return float(sum(per)), per


def make_images(rng, h, w):
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    a = np.stack([0.5 + 0.4 * np.sin(x / 5.0 + c) * np.cos(y / 7.0 - c) for c in range(3)], axis=-1)
    a += rng.normal(0, 0.05, a.shape)
    b = a + 0.15 * np.sin((x + 2 * y)[..., None] / 3.0 + np.arange(3)) + rng.normal(0, 0.08, a.shape)
    return np.clip(a, 0, 1).astype(np.float32), np.clip(b, 0, 1).astype(np.float32)


def main():
    OUT.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(20260407)
    pairs = {}
    for name, (h, w) in {"64x48": (48, 64), "41x35": (35, 41)}.items():
        a, b = make_images(rng, h, w)
        np.save(OUT / f"img_{name}_a.npy", a)
        np.save(OUT / f"img_{name}_b.npy", b)
        pairs[name] = (a, b)

    nets = {}
    # Width-reduced nets with seeded weights, through the converter (torch .pth checkpoints in, safetensors out).
    cfg = [8, 8, "M", 16, 16, "M", 32, 32, 32, "M", 64, 64, 64, "M", 64, 64, 64, "M"]
    reduced = {"vgg16_w8": ("vgg16", torchvision.models.vgg.make_layers(cfg), "F16"),
               "alexnet_w8": ("alexnet", reduced_alexnet([8, 24, 48, 32, 32]), "F32")}
    with tempfile.TemporaryDirectory() as tmp:
        for key, (net, features, dtype) in reduced.items():
            trunk, lin = seeded_weights(features, tap_channels(features, net), rng)
            torch.save(trunk, f"{tmp}/{key}_trunk.pth")
            torch.save(lin, f"{tmp}/{key}_lin.pth")
            tensors, detected = conv.convert(torch.load(f"{tmp}/{key}_trunk.pth"), torch.load(f"{tmp}/{key}_lin.pth"), net)
            assert detected == net
            if dtype == "F16":  # the reference uses exactly the values the file holds
                tensors = {k: v.astype(np.float16).astype(np.float32) for k, v in tensors.items()}
            conv.write_safetensors(OUT / f"{key}.safetensors", tensors,
                                   {"format": "d2gs-lpips", "net": net, "version": "0.1", "note": "test fixture, seeded weights"},
                                   dtype)
            nets[key] = (net, load_into(features, tensors), tensors)
    # Full-width torchvision nets with closed-form weights (not committed; rebuilt by the C++ test).
    for key, net, features in [("vgg16_hash", "vgg16", torchvision.models.vgg16().features),
                               ("alexnet_hash", "alexnet", torchvision.models.alexnet().features)]:
        tensors = hash_weights(features, tap_channels(features, net))
        nets[key] = (net, load_into(features, tensors), tensors)

    expected = {"generator": "tools/make_lpips_fixtures.py", "torch": torch.__version__,
                "torchvision": torchvision.__version__, "cases": []}
    for key, (net, features, tensors) in nets.items():
        for pname, (a, b) in pairs.items():
            for rname, symmetric in [("unit", False), ("symmetric", True)]:
                total, per = lpips(features, tensors, net, a, b, symmetric)
                expected["cases"].append({"net": key, "trunk": net, "pair": pname, "range": rname,
                                          "lpips": total, "per_tap": per})
                print(f"{key:13s} {pname} {rname:9s} {total:.8f}")
        same, _ = lpips(features, tensors, net, pairs["64x48"][0], pairs["64x48"][0], False)
        assert same == 0.0, same
    (OUT / "expected.json").write_text(json.dumps(expected, indent=1) + "\n")
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
