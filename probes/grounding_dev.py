"""Labeler F1 per relation for each ``--locate`` method on a development split: tabletop
images collected with another seed than results/grounding.json's (seed 0), so that choices
made on it are not tuned on the evaluation images. Prints, writes nothing but the data.

    OMP_NUM_THREADS=1 python probes/grounding_dev.py --out data/grounding_dev --seed 7

With ``--min-visible``, the silhouette refinement's one choice (zsrm.grounding.silhouette's
MIN_VISIBLE: how much of a block must show for its own colour's region to be kept), chosen on
data with the box (``--p-box``), labelled with ``--vlm`` and the box's ``--box-vlm``:

    OMP_NUM_THREADS=1 python probes/grounding_dev.py --out data/grounding_dev_box --p-box 0.3 \
        --vlm runs/vlm-box --box-vlm runs/vlm-box-full --locate fine --min-visible 0.5 0.65 0.8
"""
import argparse
import os

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("HF_HUB_OFFLINE", "1")

from zsrm.data.collect import CollectConfig, collect  # noqa: E402
from zsrm.evaluation.grounding_quality import evaluate_grounding  # noqa: E402
from zsrm.grounding import silhouette  # noqa: E402
from zsrm.grounding.annotate import LabelConfig, label_dataset  # noqa: E402
from zsrm.grounding.gradcam import LOCATE  # noqa: E402
from zsrm.tasks.relations import RELATIONS  # noqa: E402


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="data/grounding_dev")
    parser.add_argument("--images", type=int, default=600)
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--locate", nargs="+", default=list(LOCATE), choices=LOCATE)
    parser.add_argument("--p-box", type=float, default=0.0, help="share of scenes with the box")
    parser.add_argument("--vlm", default="scene")
    parser.add_argument("--box-vlm", default=None)
    parser.add_argument("--min-visible", nargs="+", type=float, default=[silhouette.MIN_VISIBLE])
    args = parser.parse_args(argv)
    if args.seed == 0:
        parser.error("seed 0 is the evaluation split of results/grounding.json")
    cfg = CollectConfig(images=args.images, seed=args.seed, scenes=("tabletop",), p_box=args.p_box)
    collect(cfg, args.out, progress=False)  # resumes
    print(f"{'locate':14s} {'visible':>7s} {'px error f/l/t':16s} " + " ".join(f"{r[:11]:>11s}" for r in RELATIONS))
    for how in args.locate:
        for visible in args.min_visible:
            silhouette.MIN_VISIBLE = visible
            labels = f"labels_{how}_{visible}"
            label_dataset(args.out, LabelConfig(vlm=args.vlm, box_vlm=args.box_vlm, locate=how), out=labels,
                          progress=False)
            report = evaluate_grounding(args.out, labels)
            err = "/".join(f"{report['median_px_error'][c]:.2f}" for c in ("front", "left", "tilted"))
            print(f"{how:14s} {visible:7.2f} {err:16s} " + " ".join(f"{report['f1'][r] or 0:11.3f}" for r in RELATIONS))


if __name__ == "__main__":
    main()
