#!/usr/bin/python3
"""Reference for d2gs's PIL-compatible resize (src/d2gs/core/resize_pil.cpp): real scene images resized by
Pillow's `Image.resize(size)` with its default filter, exactly as the original 3DGS loader
(`PILtoTorch(image.resize(resolution))`) does. Writes tests/core/fixtures/pil_resize_*.png (8-bit RGB, the
resized image or a crop of it) and pil_resize.json (sizes, crops, Pillow version, per-image byte sums).

Run from the repository root: /usr/bin/python3 tools/make_pil_resize_fixture.py
"""
import json
import pathlib

import numpy as np
import PIL
from PIL import Image

ROOT = pathlib.Path(__file__).resolve().parent.parent
DATA = ROOT.parent / "shared" / "data"
OUT = ROOT / "tests" / "core" / "fixtures"

# name, source (relative to ../shared/data), factor (target = round(size / factor), Python's round),
# crop of the result stored (x, y, w, h) or None for the whole image.
CASES = [
    ("fern_r8_from_images4", "nerf_llff_data/fern/images_4/image000.png", 2, (200, 100, 128, 128)),
    ("fern_x8_from_images4", "nerf_llff_data/fern/images_4/image000.png", 8, None),
    ("room_x4_jpeg", "llff_nex_reprocessed/room/images/img001.JPG", 4, None),
]


def main():
    OUT.mkdir(parents=True, exist_ok=True)
    manifest = {"pillow": PIL.__version__, "cases": []}
    for name, src, factor, crop in CASES:
        im = Image.open(DATA / src).convert("RGB")
        w, h = im.size
        size = (round(w / factor), round(h / factor))
        out = np.asarray(im.resize(size))  # the loader's call: default filter (bicubic since Pillow 7)
        stored = out if crop is None else out[crop[1]:crop[1] + crop[3], crop[0]:crop[0] + crop[2]]
        Image.fromarray(stored).save(OUT / f"pil_resize_{name}.png")
        manifest["cases"].append({"name": name, "source": src, "width": size[0], "height": size[1],
                                  "crop": crop, "byte_sum": int(out.astype(np.int64).sum())})
    (OUT / "pil_resize.json").write_text(json.dumps(manifest, indent=2) + "\n")


if __name__ == "__main__":
    main()
