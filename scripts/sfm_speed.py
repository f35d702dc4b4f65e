#!/usr/bin/env python3
"""Structure from motion speed and accuracy: Frond's matcher against COLMAP's exhaustive
matcher, measured in the same run on the same photos (issue 24's targets).

  python3 scripts/sfm_speed.py synthetic [--seeds 8 9 10] [--preset broadleaf] [--work DIR]
      36 photos at 800x600 per seed (frond synth --no-points). For each matcher: SfM seconds,
      photos -> plant seconds (frond reconstruct PHOTOS; the baseline runs the route Frond
      took before: COLMAP exhaustive matching, undistortion, densify, reconstruct), registered
      views, RMS of the camera centres after a similarity alignment to the truth, leaf recall.
  python3 scripts/sfm_speed.py arabidopsis [--work DIR]
      The 60 real photos in ../shared/data/romi_arabidopsis: SfM seconds, registered photos,
      mean reprojection error, for both matchers (OPENCV camera, as scripts/arabidopsis.sh).
  python3 scripts/sfm_speed.py scaling [--views 25 50 100 200] [--baseline-up-to 50]
      Frond's SfM time against the number of photos of one synthetic orbit (COLMAP exhaustive
      too, up to --baseline-up-to photos).

Prints a Markdown table and writes WORK/<mode>.json. Needs a release build (built here) and
COLMAP (scripts/setup.sh). Single runs on a 2-core machine take minutes per seed; the
exhaustive baseline dominates.
"""

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FROND = os.path.join(ROOT, "target", "release", "frond")


def run(args, **kwargs):
    started = time.monotonic()
    result = subprocess.run(args, capture_output=True, text=True, **kwargs)
    seconds = time.monotonic() - started
    if result.returncode != 0:
        sys.stderr.write(result.stdout + result.stderr)
        raise SystemExit(f"failed: {' '.join(args)}")
    return result.stdout + result.stderr, seconds


def sfm_json(folder):
    with open(os.path.join(folder, "sfm.json")) as f:
        return json.load(f)["report"]


def evaluate(dataset, out, model):
    text, _ = run([FROND, "eval", "--gt", dataset, "--pred", out, "--pred-model", model, "--json"])
    report = json.loads(text[text.index("{"):])
    return {
        "camera_rms_mm": report["alignment"]["rms_camera_residual"] * 1e3,
        "leaf_recall": report["leaves"]["recall"],
        "leaf_precision": report["leaves"]["precision"],
    }


def synthetic(args):
    rows = []
    for seed in args.seeds:
        dataset = os.path.join(args.work, f"{args.preset}_{seed}")
        if not os.path.isdir(os.path.join(dataset, "images")):
            run([FROND, "synth", "--preset", args.preset, "--seed", str(seed), "--views", "36",
                 "--size", "800x600", "--no-points", "--out", dataset])
        photos = os.path.join(dataset, "images")
        # Frond's route: reconstruct straight from the photos.
        out = os.path.join(args.work, f"frond_{args.preset}_{seed}")
        shutil.rmtree(out, ignore_errors=True)
        _, total = run([FROND, "reconstruct", photos, "--out", out])
        sfm = sfm_json(os.path.join(out, "sfm"))
        row = {"seed": seed, "matcher": "frond", "photos_to_plant_s": total,
               "sfm_s": sum(sfm["timings"].values()), "registered": sfm["registered"],
               "keyframes": sfm.get("keyframes") or "all",
               "pairs": sfm["pairs_matched"], "reprojection_px": sfm["mean_reprojection_error_px"]}
        row.update(evaluate(dataset, out, os.path.join(out, "sfm", "sparse", "0")))
        rows.append(row)
        # The baseline: COLMAP exhaustive matching, its undistorted workspace, densify.
        base = os.path.join(args.work, f"colmap_{args.preset}_{seed}")
        shutil.rmtree(base, ignore_errors=True)
        _, sfm_s = run([FROND, "sfm", photos, "--out", os.path.join(base, "sfm"),
                        "--matcher", "exhaustive"])
        _, dense_s = run([FROND, "densify", os.path.join(base, "sfm", "dense"),
                          "--out", os.path.join(base, "dense")])
        _, rec_s = run([FROND, "reconstruct", os.path.join(base, "dense"),
                        "--out", os.path.join(base, "out")])
        sfm = sfm_json(os.path.join(base, "sfm"))
        row = {"seed": seed, "matcher": "colmap exhaustive",
               "photos_to_plant_s": sfm_s + dense_s + rec_s, "sfm_s": sfm_s,
               "registered": sfm["registered"], "pairs": 36 * 35 // 2,
               "reprojection_px": sfm["mean_reprojection_error_px"]}
        row.update(evaluate(dataset, os.path.join(base, "out"),
                            os.path.join(base, "sfm", "sparse", "0")))
        rows.append(row)
        print_rows(rows[-2:], header=(len(rows) == 2))
    return rows


def arabidopsis(args):
    photos = os.path.join(ROOT, "..", "shared", "data", "romi_arabidopsis", "images")
    rows = []
    for matcher in ["auto", "exhaustive"]:
        out = os.path.join(args.work, f"arabidopsis_{matcher}")
        shutil.rmtree(out, ignore_errors=True)
        _, seconds = run([FROND, "sfm", photos, "--out", out, "--matcher", matcher,
                          "--camera-model", "OPENCV", "--no-undistort"])
        sfm = sfm_json(out)
        rows.append({"seed": "arabidopsis", "matcher": "frond" if matcher == "auto" else
                     "colmap exhaustive", "sfm_s": seconds, "registered": sfm["registered"],
                     "keyframes": sfm.get("keyframes") or "all",
                     "pairs": sfm["pairs_matched"] or 60 * 59 // 2,
                     "reprojection_px": sfm["mean_reprojection_error_px"]})
        print_rows(rows[-1:], header=(len(rows) == 1))
    return rows


def scaling(args):
    rows = []
    for views in args.views:
        dataset = os.path.join(args.work, f"orbit_{views}")
        if not os.path.isdir(os.path.join(dataset, "images")):
            run([FROND, "synth", "--seed", "21", "--views", str(views), "--size", "800x600",
                 "--no-points", "--out", dataset])
        matchers = ["auto"] + (["exhaustive"] if views <= args.baseline_up_to else [])
        for matcher in matchers:
            out = os.path.join(args.work, f"orbit_{views}_{matcher}")
            shutil.rmtree(out, ignore_errors=True)
            _, seconds = run([FROND, "sfm", os.path.join(dataset, "images"), "--out", out,
                              "--matcher", matcher, "--no-undistort"])
            sfm = sfm_json(out)
            text, _ = run([FROND, "eval", "--gt", dataset, "--dense", out, "--json"])
            alignment = json.loads(text[text.index("{"):])["alignment"]
            rows.append({"seed": f"{views} views", "matcher": "frond" if matcher == "auto"
                         else "colmap exhaustive", "sfm_s": seconds,
                         "registered": sfm["registered"],
                         "keyframes": sfm.get("keyframes") or "all",
                         "camera_rms_mm": alignment["rms_camera_residual"] * 1e3,
                         "pairs": sfm["pairs_matched"] or views * (views - 1) // 2,
                         "reprojection_px": sfm["mean_reprojection_error_px"],
                         "timings": sfm["timings"]})
            print_rows(rows[-1:], header=(len(rows) == 1))
    return rows


COLUMNS = [("seed", "plant", "{}"), ("matcher", "matcher", "{}"), ("pairs", "pairs", "{}"),
           ("sfm_s", "SfM s", "{:.1f}"), ("photos_to_plant_s", "photos→plant s", "{:.1f}"),
           ("registered", "registered", "{}"), ("keyframes", "keyframes", "{}"),
           ("camera_rms_mm", "camera RMS mm", "{:.2f}"),
           ("reprojection_px", "reproj. px", "{:.3f}"), ("leaf_recall", "leaf recall", "{:.3f}")]


def print_rows(rows, header):
    if header:
        print("| " + " | ".join(title for _, title, _ in COLUMNS) + " |")
        print("|" + "---|" * len(COLUMNS))
    for row in rows:
        cells = [fmt.format(row[key]) if key in row else "–" for key, _, fmt in COLUMNS]
        print("| " + " | ".join(cells) + " |", flush=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("mode", choices=["synthetic", "arabidopsis", "scaling"])
    parser.add_argument("--work", default=os.path.join(ROOT, "target", "sfm_speed"))
    parser.add_argument("--seeds", type=int, nargs="+", default=[8, 9, 10])
    parser.add_argument("--preset", default="broadleaf")
    parser.add_argument("--views", type=int, nargs="+", default=[25, 50, 100, 200])
    parser.add_argument("--baseline-up-to", type=int, default=50)
    args = parser.parse_args()
    os.makedirs(args.work, exist_ok=True)
    subprocess.run(["cargo", "build", "--release", "--quiet", "--bin", "frond"], cwd=ROOT,
                   check=True)
    rows = {"synthetic": synthetic, "arabidopsis": arabidopsis, "scaling": scaling}[args.mode](args)
    with open(os.path.join(args.work, f"{args.mode}.json"), "w") as f:
        json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
