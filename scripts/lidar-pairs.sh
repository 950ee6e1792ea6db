#!/usr/bin/env bash
# sdem against small_gicp's GICP on pairs of real LiDAR frames (KITTI 00's first frames), in one
# run: for each pair, sdem (the grid and options derived from the scan, no guess, ±1 m, ±5°;
# `cargo run --release -p sdem-cli --example lidar_pairs`), then GICP from identity through
# ../shared/peers/register_pair.py, as shipped (voxel 5 cm, 25 cm correspondences) and tuned
# for a street (voxel 25 cm, 1 m correspondences). Times are medians of REPEAT runs each.
#
#   scripts/lidar-pairs.sh [OUT] [PAIRS...]      e.g. scripts/lidar-pairs.sh /tmp/lidar 0:1 5:6 10:11
#
# Errors are against KITTI's ground truth (whose first frames its README doubts by up to
# 0.18 m a frame) and, as "sdem vs GICP", between sdem's pose and tuned GICP's.
# Environment: KITTI (default ../shared/data/kitti-00-first16), PEERS_DIR (../shared/peers),
# PEERS_VENV (/tmp/peers-venv; see scripts/peers.sh), REPEAT (5).
set -euo pipefail

REPO=$(cd "$(dirname "$0")/.." && pwd)
OUT=${1:-/tmp/sdem-lidar-pairs}
shift || true
PAIRS=("$@")
[[ ${#PAIRS[@]} -eq 0 ]] && PAIRS=(0:1 5:6 10:11)
KITTI=${KITTI:-$REPO/../shared/data/kitti-00-first16}
PEERS_DIR=${PEERS_DIR:-$REPO/../shared/peers}
PY=${PEERS_VENV:-/tmp/peers-venv}/bin/python
REPEAT=${REPEAT:-5}
if [[ ! -d $KITTI ]]; then
    echo "lidar-pairs.sh: no KITTI frames at $KITTI (set KITTI)" >&2
    exit 1
fi
if [[ ! -x $PY ]] || ! "$PY" -c 'import small_gicp, numpy' 2>/dev/null; then
    echo "lidar-pairs.sh: no peers' Python at $PY; make it as scripts/peers.sh does" >&2
    exit 1
fi

mkdir -p "$OUT"
cd "$REPO"
cargo build --release -q -p sdem-cli --bin sdem --example lidar_pairs
target/release/sdem import "$KITTI" --out "$OUT/kitti" --force >/dev/null
# The frames as text for the peers, and each pair's true T_target_source (query into reference).
"$PY" - "$OUT" "${PAIRS[@]}" <<'PY'
import sys, numpy as np
out, pairs = sys.argv[1], [tuple(map(int, p.split(":"))) for p in sys.argv[2:]]
poses = [np.vstack([np.array(l.split(), float).reshape(3, 4), [0, 0, 0, 1]])
         for l in open(f"{out}/kitti/poses_truth.txt") if l.strip()]
for r, q in pairs:
    for i in (r, q):
        p = np.fromfile(f"{out}/kitti/scans/{i:06d}.bin", dtype=np.float32).reshape(-1, 4)[:, :3]
        np.savetxt(f"{out}/{i:06d}.xyz", p[np.isfinite(p).all(1)], fmt="%.4f")
    t = np.linalg.inv(poses[r]) @ poses[q]
    open(f"{out}/truth_{r}_{q}.txt", "w").write(" ".join(f"{v:.12g}" for v in t[:3].ravel()) + "\n")
PY

: >"$OUT/raw.jsonl"
for pair in "${PAIRS[@]}"; do
    r=${pair%:*}
    q=${pair#*:}
    sdem_line=$(target/release/examples/lidar_pairs "$OUT/kitti" "$pair" --repeat "$REPEAT" --json)
    echo "{\"method\":\"sdem\",\"line\":$sdem_line}" >>"$OUT/raw.jsonl"
    for setting in shipped tuned; do
        extra=()
        [[ $setting == tuned ]] && extra=(--voxel 0.25 --max-corr 1.0)
        "$PY" "$PEERS_DIR/register_pair.py" "$OUT/$(printf %06d "$q").xyz" \
            "$OUT/$(printf %06d "$r").xyz" --truth "$OUT/truth_${r}_${q}.txt" \
            --methods small_gicp_gicp --repeat "$REPEAT" "${extra[@]}" 2>/dev/null |
            sed "s/^/{\"method\":\"gicp_$setting\",\"pair\":[$r,$q],\"line\":/; s/\$/}/" >>"$OUT/raw.jsonl"
    done
done

"$PY" - "$OUT/raw.jsonl" <<'PY' | tee "$OUT/table.md"
import json, sys, numpy as np
rows = {}
for l in open(sys.argv[1]):
    d = json.loads(l)
    line = d["line"]
    pair = tuple(line["pair"]) if d["method"] == "sdem" else tuple(d["pair"])
    rows.setdefault(pair, {})[d["method"]] = line
print("| pair | sdem time | sdem error (truth) | GICP shipped: time | error | GICP tuned: time | error | sdem vs tuned GICP | GICP tuned / sdem time |")
print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
for pair, m in sorted(rows.items()):
    s, a, b = m["sdem"], m.get("gicp_shipped", {}), m.get("gicp_tuned", {})
    def err(x):
        return f"{100 * x.get('trans_err_m', x.get('error_m', float('nan'))):.1f} cm / {x.get('rot_err_deg', x.get('error_deg', float('nan'))):.2f}°"
    vs = "n/a"
    if "T" in b:
        ts, tg = np.array(s["T"]), np.array(b["T"])
        d = np.linalg.inv(tg) @ ts
        ang = np.degrees(np.arccos(np.clip((np.trace(d[:3, :3]) - 1) / 2, -1, 1)))
        vs = f"{100 * np.linalg.norm(ts[:3, 3] - tg[:3, 3]):.1f} cm / {ang:.2f}°"
    ratio = b.get("time_ms", float("nan")) / s["time_ms"]
    print(f"| {pair[0]}→{pair[1]} | {s['time_ms']:.0f} ms | {err(s)} | {a.get('time_ms', float('nan')):.0f} ms | {err(a)} "
          f"| {b.get('time_ms', float('nan')):.0f} ms | {err(b)} | {vs} | {ratio:.1f}× |")
PY
