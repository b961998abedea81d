"""Grad-CAM images per second for three phrases: batched head-only gradients vs one full
backward per phrase, in one run.

* batched (:meth:`GradCAM.heatmaps`): the image trunk runs once per image without autograd;
  the three phrases' gradients at the Grad-CAM layer come from one backward pass through the
  head only (the activations repeated once per phrase);
* simple (:meth:`GradCAM.reference_heatmaps`): per phrase, a full forward with autograd and a
  full backward pass through the whole network, parameters included: plain Grad-CAM.

The model is open_clip RN50 with random weights (no pretrained weights can be had here; the
speed does not depend on the weights). Both ways run on the same images, alternating round by
round so that load from other processes hits both alike, and must give the same heat maps.

    .venv/bin/python benchmarks/gradcam_speed.py --out results/gradcam_speed.json
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("HF_HUB_OFFLINE", "1")

import numpy as np
import torch

from zsrm.grounding.gradcam import GradCAM
from zsrm.vlm import load_vlm

PHRASES = ["red block", "yellow block", "blue block"]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--model", default="open_clip:RN50:none")
    parser.add_argument("--images", type=int, default=6)
    parser.add_argument("--rounds", type=int, default=2, help="timed rounds of each way (after one warm-up)")
    parser.add_argument("--threads", type=int, default=1, help="torch threads (the machine is shared)")
    parser.add_argument("--out", default="results/gradcam_speed.json")
    args = parser.parse_args(argv)
    torch.manual_seed(0)
    torch.set_num_threads(args.threads)

    vlm = load_vlm(args.model)
    rng = np.random.default_rng(0)
    images = rng.integers(0, 256, (args.images, 64, 64, 3), dtype=np.uint8)
    cam = GradCAM(vlm, contrast=PHRASES, batch_size=args.images)

    # Warm-up, and the two must agree.
    fast, _ = cam.heatmaps(images, PHRASES)
    ref, _ = cam.reference_heatmaps(images, PHRASES)
    scale = float(ref.abs().max())
    max_diff = float((fast - ref).abs().max())
    if max_diff > 1e-4 * max(scale, 1.0):
        print(f"heat maps differ by {max_diff:.3g} (max {scale:.3g})", file=sys.stderr)
        return 1

    times = {"batched": [], "full_backward": []}
    for _ in range(args.rounds):
        for name, fn in (("batched", cam.heatmaps), ("full_backward", cam.reference_heatmaps)):
            start = time.perf_counter()
            fn(images, PHRASES)
            times[name].append(time.perf_counter() - start)
    ips = {k: args.images / float(np.median(v)) for k, v in times.items()}
    result = {
        "images_per_s_batched": ips["batched"],
        "images_per_s_full_backward": ips["full_backward"],
        "ratio": ips["batched"] / ips["full_backward"],
        "meta": {
            "command": "python benchmarks/gradcam_speed.py " + " ".join(argv if argv is not None else sys.argv[1:]),
            "model": args.model,
            "phrases": PHRASES,
            "images": args.images,
            "input_px": list(vlm.preprocess(images[:1]).shape[-2:]),
            "rounds": args.rounds,
            "seconds": times,
            "max_abs_map_difference": max_diff,
            "max_abs_map": scale,
            "torch_threads": args.threads,
            "torch": torch.__version__,
            "cpu": platform.processor() or platform.machine(),
        },
    }
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=2) + "\n")
    print(f"batched {ips['batched']:.2f} img/s, full backward per phrase {ips['full_backward']:.2f} img/s, "
          f"ratio {result['ratio']:.2f}; wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
