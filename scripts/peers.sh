#!/usr/bin/env bash
# Runs the peer registration tools (../shared/peers/register_pair.py: Open3D ICP/GICP/FPFH+RANSAC,
# small_gicp, KISS-ICP, GenZ-ICP) on a folder of exported bench pairs, twice per pair: from no
# initial guess (identity) and from the seeded guess 0.2 m / 5° off the truth. Then aggregates.
#
#   cargo run --release -p sdem-cli --example export_bench_pairs -- --out /tmp/pairs --count 50 --seed 1 --localize
#   scripts/peers.sh /tmp/pairs docs/peers
#
# PAIRS holds pair_NNN/{query.ply,reference.ply,truth.txt,guess.txt} (and optionally sdem.jsonl).
# Source = query, target = reference: the truth is T_target_source = reference_from_query.
# Writes OUT/raw/pair_NNN.{noguess,guess}.jsonl (register_pair.py's lines as printed),
# OUT/raw.jsonl (all lines, with "pair" and "guess" added) and OUT/table.md.
#
# Environment: PEERS_DIR (default: ../shared/peers beside the repository), PEERS_VENV
# (default /tmp/peers-venv; created with the peers' requirements when missing), REPEAT (timed
# runs per method, median reported; default 5), METHODS (comma-separated subset; default all),
# LIMIT (only the first N pairs; default all), THRESHOLD_M (success: translation error below
# this; default 0.02).
set -euo pipefail

if [[ $# -lt 2 ]]; then
    sed -n '2,20p' "$0" | sed 's/^# \{0,1\}//'
    exit 2
fi
PAIRS=$(cd "$1" && pwd)
mkdir -p "$2"
OUT=$(cd "$2" && pwd)
REPO=$(cd "$(dirname "$0")/.." && pwd)
PEERS_DIR=${PEERS_DIR:-$REPO/../shared/peers}
PEERS_VENV=${PEERS_VENV:-/tmp/peers-venv}
REPEAT=${REPEAT:-5}
METHODS=${METHODS:-}
LIMIT=${LIMIT:-0}
THRESHOLD_M=${THRESHOLD_M:-0.02}
PY=$PEERS_VENV/bin/python

if [[ ! -x $PY ]] || ! "$PY" -c 'import open3d, small_gicp' 2>/dev/null; then
    echo "peers.sh: setting up $PEERS_VENV (about 3 minutes)" >&2
    python3 -m venv "$PEERS_VENV"
    "$PEERS_VENV/bin/pip" install -q -r "$PEERS_DIR/requirements.txt"
    if ! "$PY" -c 'import open3d' 2>/dev/null; then
        echo "peers.sh: Open3D does not import; it needs libusb: apt-get install -y libusb-1.0-0" >&2
        exit 1
    fi
fi

extra=(--repeat "$REPEAT")
[[ -n $METHODS ]] && extra+=(--methods "$METHODS")
mkdir -p "$OUT/raw"
n=0
start=$(date +%s)
for dir in "$PAIRS"/pair_*/; do
    [[ $LIMIT -gt 0 && $n -ge $LIMIT ]] && break
    name=$(basename "$dir")
    for mode in noguess guess; do
        init=()
        [[ $mode == guess ]] && init=(--init "$dir/guess.txt")
        "$PY" "$PEERS_DIR/register_pair.py" "$dir/query.ply" "$dir/reference.ply" \
            --truth "$dir/truth.txt" "${init[@]}" "${extra[@]}" \
            >"$OUT/raw/$name.$mode.jsonl" 2>"$OUT/raw/$name.$mode.log"
    done
    n=$((n + 1))
    echo "peers.sh: $name done ($n pairs, $(($(date +%s) - start)) s)" >&2
done

sdem=()
[[ -f $PAIRS/sdem.jsonl ]] && sdem=(--sdem "$PAIRS/sdem.jsonl")
"$PY" "$REPO/scripts/peers_table.py" "$OUT/raw" --threshold-m "$THRESHOLD_M" \
    --raw-out "$OUT/raw.jsonl" "${sdem[@]}" >"$OUT/table.md"
cat "$OUT/table.md"
echo "peers.sh: $n pairs in $(($(date +%s) - start)) s; wrote $OUT/raw.jsonl and $OUT/table.md" >&2
