"""Labeler F1 per relation for each ``--locate`` method on a development split: tabletop
images collected with another seed than results/grounding.json's (seed 0), so that choices
made on it are not tuned on the evaluation images. Prints, writes nothing but the data.

    OMP_NUM_THREADS=1 python benchmarks/grounding_dev.py --out data/grounding_dev --seed 7
"""
import argparse
import os

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("HF_HUB_OFFLINE", "1")

from zsrm.data.collect import CollectConfig, collect  # noqa: E402
from zsrm.evaluation.grounding_quality import evaluate_grounding  # noqa: E402
from zsrm.grounding.annotate import LabelConfig, label_dataset  # noqa: E402
from zsrm.grounding.gradcam import LOCATE  # noqa: E402
from zsrm.tasks.relations import RELATIONS  # noqa: E402


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="data/grounding_dev")
    parser.add_argument("--images", type=int, default=600)
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--locate", nargs="+", default=list(LOCATE), choices=LOCATE)
    args = parser.parse_args(argv)
    if args.seed == 0:
        parser.error("seed 0 is the evaluation split of results/grounding.json")
    collect(CollectConfig(images=args.images, seed=args.seed), args.out, progress=False)  # resumes
    print(f"{'locate':14s} {'px error f/l/t':16s} " + " ".join(f"{r[:11]:>11s}" for r in RELATIONS))
    for how in args.locate:
        labels = f"labels_{how}"
        label_dataset(args.out, LabelConfig(locate=how), out=labels, progress=False)
        report = evaluate_grounding(args.out, labels)
        err = "/".join(f"{report['median_px_error'][c]:.2f}" for c in ("front", "left", "tilted"))
        print(f"{how:14s} {err:16s} " + " ".join(f"{report['f1'][r] or 0:11.3f}" for r in RELATIONS))


if __name__ == "__main__":
    main()
