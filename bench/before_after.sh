#!/usr/bin/env bash
# Before and after in one run: per file in turn the SciPy peer, then `BEFORE bench --json` and
# `AFTER bench --json` (median of --repeat 5), so that each trio runs under the same load on a
# shared machine; then bench/compare.py's table for each.
#
#   bench/before_after.sh BEFORE_BIN AFTER_BIN [OUT_DIR]
#
# Files: the shared examples of bench/run.sh and the records AFTER writes (`bench records`).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
BEFORE="${1:?before binary}"; AFTER="${2:?after binary}"; OUT="${3:-$ROOT/bench/out/before-after}"
EX="${PANTOWATCH_EXAMPLES:-../shared/data/examples}"
rm -rf "$OUT"; mkdir -p "$OUT"
mapfile -t RECORDS < <(PANTOWATCH_EXAMPLES="$EX" "$AFTER" bench records "$OUT/records")
FILES=("$EX"/*_baseline.json "$EX/J5_viscous_x2.5.json" "$EX/J3_dry_x1.8.json" "${RECORDS[@]}")
for f in "${FILES[@]}"; do
    uptime >> "$OUT/load.txt"
    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 \
        python3 bench/scipy_peer.py "$f" --repeat 1 >> "$OUT/peer.jsonl"
    "$BEFORE" bench --json --repeat 5 "$f" >> "$OUT/rust-before.jsonl"
    "$AFTER" bench --json --repeat 5 "$f" >> "$OUT/rust-after.jsonl"
done
uptime >> "$OUT/load.txt"
for v in before after; do
    python3 bench/compare.py --truth "$OUT/records/truth.json" --peer "$OUT/peer.jsonl" \
        --rust "$OUT/rust-$v.jsonl" > "$OUT/table-$v.md"
done
cat "$OUT/table-before.md" "$OUT/table-after.md"
