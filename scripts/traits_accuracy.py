#!/usr/bin/env python3
"""Trait accuracy on synthetic plants: the truth's traits (computed by Frond's trait code from
the true meshes and branches) against a reconstruction's, leaf by leaf and branch by branch.

Usage: scripts/traits_accuracy.py [--seeds 11,12,13] [--preset broadleaf] [--modes semi,photos]
       [--out target/traits_accuracy]
  semi:   `frond synth` with semi-dense points -> `frond reconstruct` (the dataset's COLMAP
          project, no alignment needed)
  photos: `frond synth --no-points` -> `frond reconstruct PHOTOS` (COLMAP + densify; the
          prediction is aligned to the truth by its camera centres)
Writes OUT/<mode>_<preset>_<seed>/{dataset,run,traits_eval.json}, OUT/summary.json and prints a
Markdown table. Needs target/release/frond (cargo build --release --bin frond).
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FROND = os.path.join(ROOT, "target/release/frond")


def run(args, log):
    with open(log, "a") as f:
        f.write("$ " + " ".join(args) + "\n")
        f.flush()
        subprocess.run(args, check=True, stdout=f, stderr=subprocess.STDOUT)


def one(mode, preset, seed, out):
    base = os.path.join(out, f"{mode}_{preset}_{seed}")
    dataset, recon = os.path.join(base, "dataset"), os.path.join(base, "run")
    os.makedirs(base, exist_ok=True)
    log = os.path.join(base, "log.txt")
    synth = [FROND, "synth", "--preset", preset, "--seed", str(seed), "--out", dataset]
    if mode == "photos":
        synth.append("--no-points")
    if not os.path.isdir(dataset):
        run(synth, log)
    started = time.time()
    if not os.path.isfile(os.path.join(recon, "traits.json")):
        source = os.path.join(dataset, "images") if mode == "photos" else dataset
        run(["/usr/bin/time", "-f", "peak_kb %M", FROND, "reconstruct", source, "--out", recon], log)
    seconds = time.time() - started
    evaluate = [FROND, "eval", "--gt", dataset, "--pred", recon, "--traits", "--json"]
    if mode == "photos":
        evaluate += ["--pred-model", os.path.join(recon, "dense", "sparse")]
    result = subprocess.run(evaluate, check=True, capture_output=True, text=True)
    accuracy = json.loads(result.stdout)
    with open(os.path.join(base, "traits_eval.json"), "w") as f:
        json.dump(accuracy, f, indent=2)
    peak = None
    for line in open(log):
        if line.startswith("peak_kb"):
            peak = int(line.split()[1])
    return accuracy, seconds, peak


def median(values):
    return statistics.median(values) if values else float("nan")


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--seeds", default="11,12,13")
    parser.add_argument("--preset", default="broadleaf")
    parser.add_argument("--modes", default="semi,photos")
    parser.add_argument("--out", default=os.path.join(ROOT, "target/traits_accuracy"))
    args = parser.parse_args()
    seeds = [int(s) for s in args.seeds.split(",")]
    rows, summary = [], []
    for mode in args.modes.split(","):
        pooled = {"area": [], "length": [], "inclination": [], "branch": [], "insertion": []}
        for seed in seeds:
            accuracy, seconds, peak = one(mode, args.preset, seed, args.out)
            leaves = accuracy["leaves"]
            area = [l["area_relative_error"] for l in leaves]
            length = [l["length_relative_error"] for l in leaves]
            inclination = [l["inclination_error_deg"] for l in leaves]
            branch = [b["length_relative_error"] for b in accuracy["branches"]]
            insertion = [b["insertion_height_error"] for b in accuracy["branches"]
                         if b.get("insertion_height_error") is not None]
            for key, values in zip(pooled, [area, length, inclination, branch, insertion]):
                pooled[key] += values
            record = {
                "mode": mode, "preset": args.preset, "seed": seed,
                "leaves": f"{len(leaves)}/{accuracy['gt_leaves']}",
                "branches": f"{len(branch)}/{accuracy['gt_branches']}",
                "area": median(area), "length": median(length),
                "inclination": median(inclination), "branch_length": median(branch),
                "insertion_mm": 1000 * median(insertion), "seconds": seconds, "peak_kb": peak,
            }
            summary.append(record)
            rows.append(record)
            print(json.dumps(record), file=sys.stderr)
        rows.append({
            "mode": mode, "preset": args.preset, "seed": "all",
            "leaves": str(len(pooled["area"])), "branches": str(len(pooled["branch"])),
            "area": median(pooled["area"]), "length": median(pooled["length"]),
            "inclination": median(pooled["inclination"]),
            "branch_length": median(pooled["branch"]),
            "insertion_mm": 1000 * median(pooled["insertion"]), "seconds": None, "peak_kb": None,
        })
    with open(os.path.join(args.out, "summary.json"), "w") as f:
        json.dump(rows, f, indent=2)
    print("| input | seed | leaves compared | leaf area | leaf length | leaf inclination | branches matched | branch length | branch insertion height |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['mode']} | {r['seed']} | {r['leaves']} | {100 * r['area']:.1f} % | "
              f"{100 * r['length']:.1f} % | {r['inclination']:.1f}° | {r['branches']} | "
              f"{100 * r['branch_length']:.1f} % | {r['insertion_mm']:.1f} mm |")


if __name__ == "__main__":
    main()
