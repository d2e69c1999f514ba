"""Summary tables of a ``benchmarks/results.sh`` run, from the JSON files it wrote.

The ``posedrift eval`` commands print each run's Table 1; the tables that compare runs
(per clip, per view, drift, the spread over point samples) and the targets of the
tracker's issue need the JSON. This script reads ``OUT/*.json`` and prints those
tables as Markdown, so that every figure of ``docs/RESULTS.md`` comes from a command.
Runs missing from ``OUT`` are left out of the tables (with a note on standard error).

Usage::

    python benchmarks/results_summary.py OUT > OUT/summary.md
"""

from __future__ import annotations

import argparse
import json
import sys
from functools import cache
from pathlib import Path

from posedrift.skeleton import ANGLE_NAMES

# (file stem, row label) of the single runs whose clips and views are tabulated.
SINGLE_RUNS = (
    ("table1_dev", "development clips"),
    ("table1_heldout", "held-out clips"),
    ("unseen_007", "the rest of subject 007"),
    ("table1_noise", "with noise"),
    ("table1_room", "with noise, in a room"),
    ("near", "too near (1.6 m)"),
    ("close", "Table 1's eight clips at 2.0 m"),
    ("tilt", "camera 2.2 m high, 24 degrees down"),
    ("body_1.95", "held out, 1.95 m, girth 0.9"),
    ("body_1.55", "held out, 1.55 m, girth 1.15"),
    ("utd", "UTD-MHAD, 27 first trials (Kinect convention)"),
    ("utd_trial2", "UTD-MHAD, 108 second trials (Kinect convention)"),
    ("smooth_dev", "development clips, smoothed offline (--smooth 0.1)"),
    ("smooth_heldout", "held-out clips, smoothed offline"),
    ("smooth_utd", "UTD-MHAD, 27 first trials, smoothed offline"),
    ("live_dev", "development clips, smoothed with two frames' latency (--smooth-lag 0.067)"),
    ("live_utd", "UTD-MHAD, 27 first trials, smoothed with two frames' latency"),
)
REPEAT_RUNS = (
    ("repeats_dev", "development clips"),
    ("repeats_heldout", "held-out clips"),
    ("repeats_noise", "with noise"),
    ("repeats_room", "with noise, in a room"),
    ("repeats_tall", "held out, 1.95 m, girth 0.9"),
    ("repeats_near", "too near (1.6 m)"),
    ("repeats_close", "Table 1's eight clips at 2.0 m"),
    ("repeats_drift", "built-in motion"),
    ("repeats_utd1", "UTD-MHAD, 27 first trials"),
    ("repeats_utd2", "UTD-MHAD, 108 second trials"),
    ("smooth_repeats_dev", "development clips, smoothed offline"),
    ("smooth_repeats_drift", "built-in motion, smoothed offline"),
    ("live_repeats_dev", "development clips, smoothed with two frames' latency"),
)
MAX_CLIP_COLUMNS = 9  # wider runs (the UTD-MHAD trials) get no per-clip table
PAPER_MEAN = 6.26  # the paper's Table 1, degrees


@cache
def load(out: Path, stem: str) -> dict | None:
    path = out / f"{stem}.json"
    if not path.is_file():
        print(f"note: {path} is missing; its rows are left out", file=sys.stderr)
        return None
    return json.loads(path.read_text())


def fmt(value: float | None, digits: int = 2) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def table(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" + "---:|" * (len(header) - 1)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines)


def per_clip(report: dict) -> str:
    """Each method's mean angle error per sequence; the tracker's also over the angles seen."""
    names = report["sequences"]
    rows = []
    for method, row in report["methods"].items():
        cells = [fmt(row["per_sequence"][n]["angle_error_mean_deg"]) for n in names]
        rows.append([method, *cells, fmt(row["angle_error_deg"]["mean"])])
        if method == "cpd" and "seen" in row:
            per = [row["per_sequence"][n] for n in names]
            cells = [
                f"{fmt(p.get('seen_angle_error_mean_deg'))} ({100 * p['seen_angle_share']:.0f}%)"
                if p.get("seen_angle_share") is not None
                else "-"
                for p in per
            ]
            seen = row["seen"]
            total = f"{fmt(seen['angle_error_deg']['mean'])} ({100 * seen['angle_share']:.0f}%)"
            rows.append(["cpd, angles seen (share)", *cells, total])
    return table(["method", *names, "all"], rows)


def per_view(report: dict) -> str:
    """Mean angle error per view, the angles in view and seen, and the median facing yaw."""
    rows = []
    for method, row in report["methods"].items():
        views = row["by_view"]
        cells = []
        for view in ("front", "side", "back"):
            v = views[view]
            own, ref = v["facing_yaw_median_deg"], v["reference_facing_yaw_median_deg"]
            cells.append(
                f"{fmt(v['angle_error_mean_deg'])} ({v['frames']} fr., yaw "
                f"{fmt(own, 0)}/{fmt(ref, 0)})"
                if v["frames"]
                else "-"
            )
        inside = row["in_view"]
        cells.append(
            f"{fmt(inside['angle_error_mean_deg'])} ({100 * inside['angle_share']:.1f}%) / "
            f"{fmt(inside['out_of_view_angle_error_mean_deg'])}"
        )
        seen = row.get("seen")
        cells.append(
            "-"
            if seen is None
            else f"{fmt(seen['angle_error_deg']['mean'])} ({100 * seen['angle_share']:.1f}%) / "
            f"{fmt(seen['hidden_angle_error_mean_deg'])}"
        )
        rows.append([method, *cells])
    header = ["method", "front", "side", "back", "angles in view (share) / out of view"]
    return table(header + ["angles seen (share) / hidden"], rows)


def per_angle_seen(report: dict) -> str | None:
    """Each method's angle errors over the angles whose joints the frames show."""
    rows = []
    for method, row in report["methods"].items():
        if "seen" not in row:
            continue
        seen = row["seen"]
        errors = seen["angle_error_deg"]
        cells = [fmt(errors[a]) for a in ANGLE_NAMES] + [fmt(errors["mean"])]
        rows.append([method, *cells, f"{100 * seen['angle_share']:.1f}%"])
    if not rows:
        return None
    header = ["method", *(a.replace("_", " ") for a in ANGLE_NAMES), "mean", "seen"]
    return table(header, rows)


def drift(report: dict, methods: tuple[str, ...] | None = None) -> str:
    """First and last 100 frames of each sequence (the drift target), per method."""
    names = report["sequences"]
    rows = []
    for method, row in report["methods"].items():
        if methods is not None and method not in methods:
            continue
        cells, firsts, lasts = [], [], []
        for n in names:
            seq = row["per_sequence"][n]
            first, last = seq.get("first_100_deg"), seq.get("last_100_deg")
            cells.append(f"{fmt(first)} / {fmt(last)}")
            if first is not None and last is not None:
                firsts.append(first)
                lasts.append(last)
        ratio = sum(lasts) / sum(firsts) if firsts else None
        rows.append([method, *cells, f"{fmt(ratio)}x"])
    return table(["method", *names, "last / first"], rows)


def spread(reports: list[tuple[str, dict]]) -> str:
    """The tracker against ICP-style tracking over seeds 0-4."""
    rows = []
    for label, report in reports:
        cpd, icp = report["methods"]["cpd"], report["methods"]["icp"]
        runs_cpd = cpd["repeats"]["angle_error_mean_deg"]
        runs_icp = icp["repeats"]["angle_error_mean_deg"]
        lower = sum(a < b for a, b in zip(runs_cpd, runs_icp, strict=True))
        rows.append(
            [
                f"{label} ({report['frames']})",
                f"{fmt(cpd['angle_error_deg']['mean'])} ± {fmt(cpd['repeats']['sd_deg'])}",
                f"{fmt(icp['angle_error_deg']['mean'])} ± {fmt(icp['repeats']['sd_deg'])}",
                f"{lower} of {len(runs_cpd)}",
                f"{fmt(cpd['map_10cm'], 3)} / {fmt(icp['map_10cm'], 3)}",
            ]
        )
    header = ["run (frames)", "cpd", "icp", "seeds where cpd is lower", "mAP@10cm cpd / icp"]
    return table(header, rows)


def targets(out: Path) -> str:
    """The tracker's accuracy targets (issue: the tracker) as measured in this run."""
    rows = []
    for stem, label in (
        ("table1_dev", "development clips"),
        ("table1_heldout", "held out"),
        ("smooth_dev", "development clips, smoothed offline"),
        ("smooth_heldout", "held out, smoothed offline"),
        ("live_dev", "development clips, smoothed with two frames' latency"),
    ):
        report = load(out, stem)
        if report is None:
            continue
        cpd = report["methods"]["cpd"]["angle_error_deg"]
        worst = max(ANGLE_NAMES, key=lambda a: cpd[a])
        met = cpd["mean"] <= PAPER_MEAN and cpd[worst] <= 8.0
        rows.append(
            [
                f"{label}: mean <= {PAPER_MEAN}, no angle above 8",
                f"{fmt(cpd['mean'])}; largest {worst.replace('_', ' ')} {fmt(cpd[worst])}",
                "yes" if met else "no",
            ]
        )
        seen = report["methods"]["cpd"].get("seen")
        if seen is not None:  # not a target: what the frames show, for comparison
            errors = seen["angle_error_deg"]
            worst = max(ANGLE_NAMES, key=lambda a: errors[a])
            rows.append(
                [
                    f"{label}, over the angles the frames show ({100 * seen['angle_share']:.1f}%)",
                    f"{fmt(errors['mean'])}; largest {worst.replace('_', ' ')} "
                    f"{fmt(errors[worst])}",
                    "-",
                ]
            )
    for stem, note in (("repeats_drift", ""), ("smooth_repeats_drift", ", smoothed offline")):
        report = load(out, stem)
        if report is None:
            continue
        seq = report["methods"]["cpd"]["per_sequence"]["builtin"]
        ratio = seq["last_100_deg"] / seq["first_100_deg"]
        rows.append(
            [
                f"no drift: last 100 frames <= 1.2x the first 100 (built-in motion, 5 seeds{note})",
                f"{fmt(seq['first_100_deg'])} -> {fmt(seq['last_100_deg'])} ({ratio:.2f}x)",
                "yes" if ratio <= 1.2 else "no",
            ]
        )
    report = load(out, "utd")
    if report is not None:
        cpd = report["methods"]["cpd"]
        rows.append(
            [
                "UTD-MHAD mAP@10cm >= 0.80, every sequence to its end",
                f"{fmt(cpd['map_10cm'], 3)}; failed frames {cpd['failed_frames']}",
                "yes" if cpd["map_10cm"] >= 0.80 else "no",
            ]
        )
    return table(["target", "measured", "met?"], rows)


def seen_overview(out: Path) -> str | None:
    """Per run: the share of the angles the frames show and the errors over them."""
    rows = []
    for stem, label in SINGLE_RUNS:
        report = load(out, stem)
        if report is None or "seen" not in report["methods"].get("cpd", {}):
            continue
        seen = report["methods"]["cpd"]["seen"]
        errors = seen["angle_error_deg"]
        cells = [
            label,
            f"{100 * seen['angle_share']:.1f}%",
            f"{fmt(errors['mean'])} ({fmt(errors['left_elbow'])} / {fmt(errors['right_elbow'])})",
            fmt(seen["hidden_angle_error_mean_deg"]),
        ]
        for method in ("icp", "shotton", "pda"):
            row = report["methods"].get(method)
            cells.append("-" if row is None else fmt(row["seen"]["angle_error_deg"]["mean"]))
        rows.append(cells)
    if not rows:
        return None
    header = ["run", "seen", "cpd (elbows L / R)", "cpd, hidden", "icp", "shotton", "pda"]
    return table(header, rows)


LABEL_FOLDERS = (
    ("h1", "007_01, 1.58 m, girth 1.15, noise"),
    ("h2", "007_05, 1.92 m, girth 0.88"),
    ("h3", "007_10, 1.70 m, noise, 3.2 m away"),
    ("h4", "131_03, 1.65 m, camera 0.8 m high"),
)


def labels(out: Path) -> str | None:
    """Pixel accuracy of the forest and the part net on the held-out label folders."""
    rows, weighted = [], {"forest": 0.0, "net": 0.0}
    frames = 0
    for folder, what in LABEL_FOLDERS:
        forest, net = load(out, f"labels_{folder}_forest"), load(out, f"labels_{folder}_net")
        if forest is None or net is None:
            continue
        hands = [
            f"{r['per_part']['right_hand']:.2f} / {r['per_part']['left_hand']:.2f}"
            for r in (forest, net)
        ]
        rows.append(
            [
                f"{folder} ({what})",
                str(forest["frames"]),
                fmt(forest["pixel_accuracy"], 3),
                fmt(net["pixel_accuracy"], 3),
                *hands,
                f"{forest['ms_per_frame']:.1f} / {net['ms_per_frame']:.1f}",
            ]
        )
        frames += forest["frames"]
        for name, report in (("forest", forest), ("net", net)):
            weighted[name] += report["frames"] * report["pixel_accuracy"]
    if not rows:
        return None
    rows.append(
        ["weighted by frames", str(frames)]
        + [fmt(weighted[k] / frames, 3) for k in weighted]
        + ["", "", ""]
    )
    header = [
        "folder",
        "frames",
        "forest",
        "net",
        "hands, forest (right / left)",
        "hands, net",
        "ms per frame, forest / net",
    ]
    return table(header, rows)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path, help="the folder results.sh wrote")
    args = parser.parse_args(argv)
    out: Path = args.out
    sections = [f"# Summary of {out}\n", "## Targets\n", targets(out)]
    for stem, label in SINGLE_RUNS:
        report = load(out, stem)
        if report is None:
            continue
        sections += [f"\n## {label} (`{stem}.json`)\n"]
        if len(report["sequences"]) <= MAX_CLIP_COLUMNS:
            sections += [per_clip(report), ""]
        sections += [per_view(report)]
        seen = per_angle_seen(report)
        if seen is not None:
            sections += ["", "Over the angles whose joints the frames show:", "", seen]
    for stem in ("drift", "there_and_back", "repeats_drift", "smooth_repeats_drift"):
        report = load(out, stem)
        if report is not None:
            sections += [f"\n## Drift, first / last 100 frames (`{stem}.json`)\n"]
            sections += [drift(report)]
    seen = seen_overview(out)
    if seen is not None:
        sections += ["\n## Over the angles the frames show (`seen`)\n", seen]
    pixels = labels(out)
    if pixels is not None:
        sections += ["\n## Pixel accuracy of the labels (`eval labels`)\n", pixels]
    reports = [(label, r) for stem, label in REPEAT_RUNS if (r := load(out, stem)) is not None]
    if reports:
        sections += ["\n## Over five point samples (seeds 0-4)\n", spread(reports)]
    print("\n".join(sections))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
