#!/usr/bin/env python3
"""Aggregates the peers' per-pair JSON lines (written by scripts/peers.sh) into a markdown table.

    peers_table.py RAW_DIR [--sdem PAIRS/sdem.jsonl] [--threshold-m 0.02] [--raw-out raw.jsonl]

RAW_DIR holds pair_NNN.noguess.jsonl and pair_NNN.guess.jsonl: register_pair.py's output for
each pair from the identity and from the seeded guess (0.2 m / 5° off the truth). Per method and
mode the table gives the median time_ms, the median and 95th-percentile translation and rotation
errors and the success rate (translation error below --threshold-m). A method
that raised an error on a pair counts as a failure there (no time, infinite error). With --sdem,
sdem's lines (from `export_bench_pairs --localize`) join the table as one more row: sdem takes
no position guess, only the gyro/compass attitude reading (compass off by up to 10°).

Standard library only. Prints the table on stdout.
"""
import argparse
import glob
import json
import math
import os
import re
import statistics


def percentile(values, q):
    """Linear between order statistics (numpy's default); inf counts as the worst."""
    v = sorted(values)
    if not v:
        return math.nan
    pos = q * (len(v) - 1)
    lo, hi = math.floor(pos), math.ceil(pos)
    if lo == hi or v[lo] == v[hi]:
        return v[lo]
    return v[lo] + (v[hi] - v[lo]) * (pos - lo)


def load(raw_dir):
    """Records with 'pair' (int) and 'guess' (bool) added, in pair order."""
    records = []
    for path in sorted(glob.glob(os.path.join(raw_dir, "pair_*.*.jsonl"))):
        m = re.match(r"pair_(\d+)\.(noguess|guess)\.jsonl$", os.path.basename(path))
        if not m:
            continue
        with open(path) as f:
            for line in f:
                if line.strip():
                    rec = json.loads(line)
                    rec["pair"], rec["guess"] = int(m.group(1)), m.group(2) == "guess"
                    records.append(rec)
    return records


def load_sdem(path):
    records = []
    with open(path) as f:
        for line in f:
            if line.strip():
                rec = json.loads(line)
                rec["method"], rec["guess"] = "sdem", False
                records.append(rec)
    return records


def summary(recs, threshold):
    times = [r["time_ms"] for r in recs if "time_ms" in r and "error" not in r]
    trans = [r.get("trans_err_m", math.inf) if "error" not in r else math.inf for r in recs]
    rot = [r.get("rot_err_deg", math.inf) if "error" not in r else math.inf for r in recs]
    return {
        "n": len(recs),
        "time_ms": statistics.median(times) if times else math.nan,
        "trans_med": percentile(trans, 0.5),
        "trans_p95": percentile(trans, 0.95),
        "rot_med": percentile(rot, 0.5),
        "rot_p95": percentile(rot, 0.95),
        "success": sum(t < threshold for t in trans) / len(recs) if recs else math.nan,
        "failed": sum(1 for r in recs if "error" in r),
    }


def fmt_len(m):
    if math.isinf(m):
        return "fail"
    if math.isnan(m):
        return "–"
    return f"{100 * m:.2f} cm" if m < 1 else f"{m:.2f} m"


def fmt(s):
    if s is None:
        return ["–"] * 6
    rot = ["fail" if math.isinf(d) else f"{d:.2f}°" for d in (s["rot_med"], s["rot_p95"])]
    ms = "–" if math.isnan(s["time_ms"]) else f"{s['time_ms']:.0f}"
    return [ms, fmt_len(s["trans_med"]), fmt_len(s["trans_p95"]), *rot, f"{100 * s['success']:.0f} %"]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("raw_dir")
    ap.add_argument("--sdem", help="sdem.jsonl from export_bench_pairs --localize")
    ap.add_argument("--threshold-m", type=float, default=0.02, help="success: translation error below (m)")
    ap.add_argument("--raw-out", help="write every record (pair and guess added) here, one JSON a line")
    a = ap.parse_args()

    records = load(a.raw_dir)
    if a.sdem:
        records += load_sdem(a.sdem)
    if a.raw_out:
        with open(a.raw_out, "w") as f:
            for r in records:
                f.write(json.dumps(r) + "\n")

    methods = list(dict.fromkeys(r["method"] for r in records))
    pairs = len({r["pair"] for r in records})
    cols = ["time ms", "trans. err. median", "trans. p95", "rot. err. median", "rot. p95", f"success (< {100 * a.threshold_m:g} cm)"]
    print(f"{pairs} pairs; median over pairs; success = translation error below {100 * a.threshold_m:g} cm.\n")
    print("| method | " + " | ".join(f"no guess: {c}" if i == 0 else c for i, c in enumerate(cols))
          + " | " + " | ".join(f"guess 0.2 m / 5°: {c}" if i == 0 else c for i, c in enumerate(cols)) + " |")
    print("|---|" + "---:|" * (2 * len(cols)))
    for m in methods:
        row = []
        for guess in (False, True):
            recs = [r for r in records if r["method"] == m and r["guess"] == guess]
            row += fmt(summary(recs, a.threshold_m) if recs else None)
        label = "**sdem** (compass ±10°, no position guess)" if m == "sdem" else m
        print(f"| {label} | " + " | ".join(row) + " |")
    failed = [(m, g, summary([r for r in records if r["method"] == m and r["guess"] == g], a.threshold_m)["failed"])
              for m in methods for g in (False, True)]
    notes = [f"{m} ({'guess' if g else 'no guess'}): {k} raised an error" for m, g, k in failed if k]
    if notes:
        print("\nErrors (counted as failures): " + "; ".join(notes) + ".")


if __name__ == "__main__":
    main()
