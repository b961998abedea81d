"""The labelled exploration data the full reward model (results/reward_eval.json) trains on.

Same as ``zsrm collect`` + ``zsrm label`` with the settings the label command does not expose:

* both scenes (tabletop blocks and pushing pucks: push_close is a puck task), 16,000 images,
  a quarter of the episodes starting with two objects side by side and some stacked
  (``CollectConfig.p_side``/``p_stack``): random actions alone rarely bring two pucks together;
* Grad-CAM cell centres on the ``grid``; the tilted camera is read on the table in metres
  through its calibration (the pixel-to-table homography in the data manifest);
* two labeler calibrations against Grad-CAM's localisation error (the oracle keeps Table 1's
  thresholds): "on top of"/"below" height offset eps_y 12 cm (9 cm in Table 1: two stacked
  blocks read 1.7 block widths apart vertically) and "close to" 12 cm (10 cm in Table 1:
  Grad-CAM pushes two touching objects apart, so at 10 cm only 45% of touching puck pairs were
  labelled close, at 12 cm 89%). ``zsrm eval-grounding`` measures the same localisation error.

Both stages resume after a kill (their shards are listed in a manifest).

    .venv/bin/python benchmarks/reward_data.py --out data/zsrm/explore
"""
from __future__ import annotations

import argparse
import os
import sys
from dataclasses import asdict

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("HF_HUB_OFFLINE", "1")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="data/zsrm/explore")
    p.add_argument("--images", type=int, default=16000)
    p.add_argument("--shard-size", type=int, default=250)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--labels", default="labels", help="labels folder inside OUT")
    p.add_argument("--eps-y", type=float, default=0.12, help="on top of / below: largest height offset (m)")
    p.add_argument("--close", type=float, default=0.12, help="close to: largest centre distance (m)")
    args = p.parse_args(argv)

    from zsrm.data.collect import CollectConfig, collect
    from zsrm.grounding.annotate import LabelConfig, label_dataset
    from zsrm.tasks.relations import WORLD_THRESHOLDS

    collect(CollectConfig(images=args.images, shard_size=args.shard_size, seed=args.seed,
                          scenes=("tabletop", "pushing")), args.out)
    cfg = LabelConfig(cell_centres="grid", thresholds={**asdict(WORLD_THRESHOLDS), "eps_y": args.eps_y,
                                                                "close": args.close})
    folder = label_dataset(args.out, cfg, out=args.labels)
    print(f"labelled data in {args.out} (labels: {folder})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
