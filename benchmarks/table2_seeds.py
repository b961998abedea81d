"""Table 2 over distillation seeds: is language above primitive, or is it the seed?

Reads tables written by ``zsrm eval-multitask`` for the same rollouts distilled with different
``--seed`` and, per policy, spread and split, gives each seed's mean, the mean over seeds and
its standard error across seeds (the spread a user rerunning ``zsrm distill`` would see), and
per seed the test-task gaps language - primitive and primitive - none with the two standard
errors added (the issue's bar).

    python benchmarks/table2_seeds.py results/side/multitask/table2_seed0.json results/multitask/table2_seed1.json \\
        results/multitask/table2_seed2.json results/multitask/table2_seed3.json \\
        --out results/side/multitask/table2_seeds.json

``--language T1 T2 ...`` (one table per table above, each from the same rollouts and distillation
seed) puts each table's language row in place of the table's own: a language policy distilled
or scored apart (``zsrm distill --centre-text``, ``zsrm eval-multitask --text-span``) against the
primitive and unconditioned policies of its seed.
"""
from __future__ import annotations

import argparse

from zsrm.common.files import read_json, write_json
from zsrm.evaluation.multitask import POLICY_NAMES, SPLITS, SPREADS
from zsrm.rl.evaluate import mean_se

GAPS = (("language", "primitive"), ("primitive", "none"))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("tables", nargs="+", help="table2.json files, one per distillation seed")
    parser.add_argument("--language", nargs="+", metavar="TABLE",
                        help="tables whose language rows stand in for the tables' own, one per table")
    parser.add_argument("--out", default="results/side/multitask/table2_seeds.json")
    args = parser.parse_args()

    tables = [read_json(path, "a table of zsrm eval-multitask") for path in args.tables]
    seeds = [t["meta"].get("distill_seed") for t in tables]  # None: a table from before it was recorded
    out: dict = {"tables": args.tables, "distill_seeds": seeds,
                 "oracle_task_policies": [t["oracle_task_policies"]["mean"] for t in tables]}
    if args.language:
        if len(args.language) != len(args.tables):
            parser.error(f"--language takes one table per table: {len(args.tables)}, not {len(args.language)}")
        out["language_tables"], out["language_text"] = args.language, []
        for path, table in zip(args.language, tables):
            other = read_json(path, "a table of zsrm eval-multitask")
            recorded = {other["meta"].get("distill_seed"), table["meta"].get("distill_seed")} - {None}
            if other["oracle_task_policies"] != table["oracle_task_policies"] or len(recorded) > 1:
                parser.error(f"{path} is not from the same rollouts and distillation seed as the table it stands in for")
            table["language"] = other["language"]
            out["language_text"].append(other.get("language_text", "raw"))
    for name in POLICY_NAMES:
        having = [t for t in tables if name in t]
        if len(having) < 2:
            continue
        for spread in SPREADS:
            for split in SPLITS:
                means = [t[name][spread][split]["mean"] for t in having]
                mean, se = mean_se(means)
                out.setdefault(name, {}).setdefault(spread, {})[split] = {
                    "per_seed": means, "mean": mean, "se_over_seeds": se, "seeds": len(means)}
    for high, low in GAPS:
        for spread in SPREADS:
            rows = []
            for path, t in zip(args.tables, tables):
                if high in t and low in t:
                    a, b = t[high][spread]["test"], t[low][spread]["test"]
                    rows.append({"table": path, "gap": a["mean"] - b["mean"], "bar": a["se"] + b["se"],
                                 "holds": a["mean"] - b["mean"] > a["se"] + b["se"]})
            mean, se = mean_se([r["gap"] for r in rows])
            holds_in = f"{sum(r['holds'] for r in rows)} of {len(rows)}"
            out.setdefault("test_gaps", {}).setdefault(f"{high}-{low}", {})[spread] = {
                "per_table": rows, "mean": mean, "se_over_seeds": se if len(rows) > 1 else None, "holds_in": holds_in}
            print(f"test {high} - {low} ({spread}): " + ", ".join(f"{r['gap']:+.1f}" for r in rows)
                  + f"; mean {mean:+.2f}, holds in {holds_in}")
    write_json(args.out, out)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
