#!/usr/bin/env bash
# Time the SciPy peer and `pantowatch-tools bench` on the same example traces, plus the
# bench's own records (a 30 s slider and an input-driven axis, `pantowatch-tools bench
# records`), and print a markdown table (bench/compare.py) against truth.json.
#
#   bench/run.sh [--no-build] [--repeat N]
#
# PANTOWATCH_EXAMPLES: directory of the example traces and truth.json
#   (default ../shared/data/examples, relative to the repo root).
# Outputs are kept in bench/out/ (peer.jsonl, rust.jsonl, table.md).
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"

BUILD=1
REPEAT=1
while [ $# -gt 0 ]; do
    case "$1" in
        --no-build) BUILD=0 ;;
        --repeat) REPEAT="${2:?--repeat needs a number}"; shift ;;
        -h|--help) sed -n '2,10p' "$0"; exit 0 ;;
        *) echo "run.sh: unknown argument $1" >&2; exit 2 ;;
    esac
    shift
done

EX="${PANTOWATCH_EXAMPLES:-../shared/data/examples}"
[ -d "$EX" ] || { echo "run.sh: example directory $EX not found (set PANTOWATCH_EXAMPLES)" >&2; exit 1; }
[ -f "$EX/truth.json" ] || { echo "run.sh: $EX/truth.json not found" >&2; exit 1; }

shopt -s nullglob
FILES=("$EX"/*_baseline.json "$EX/J5_viscous_x2.5.json" "$EX/J3_dry_x1.8.json")
shopt -u nullglob
for f in "${FILES[@]}"; do
    [ -f "$f" ] || { echo "run.sh: missing example $f" >&2; exit 1; }
done
[ "${#FILES[@]}" -gt 2 ] || { echo "run.sh: no *_baseline.json in $EX" >&2; exit 1; }

python3 -c 'import numpy, scipy' 2>/dev/null || {
    echo "run.sh: numpy/scipy missing: pip install -r bench/requirements.txt" >&2; exit 1; }

if [ "$BUILD" = 1 ]; then
    cargo build --release -p pantowatch-tools
fi
BIN="${CARGO_TARGET_DIR:-$ROOT/target}/release/pantowatch-tools"
[ -x "$BIN" ] || { echo "run.sh: $BIN not found (build it, or drop --no-build)" >&2; exit 1; }
if ! "$BIN" bench --help >/dev/null 2>&1; then
    echo "run.sh: $BIN has no working 'bench' subcommand" >&2
    echo "        (expected: pantowatch-tools bench --json FILE... -> one JSON line per file)" >&2
    exit 1
fi

OUT="$ROOT/bench/out"
mkdir -p "$OUT"

# The records beyond the examples (issue 38): written with their truth merged into the examples'.
mapfile -t RECORDS < <(PANTOWATCH_EXAMPLES="$EX" "$BIN" bench records "$OUT/records")
[ "${#RECORDS[@]}" -gt 0 ] || { echo "run.sh: '$BIN bench records' wrote nothing" >&2; exit 1; }
FILES+=("${RECORDS[@]}")
TRUTH="$OUT/records/truth.json"

# Single-threaded BLAS for the peer: the fit is one process on one core.
echo "== SciPy peer (${#FILES[@]} files, repeat $REPEAT)" >&2
OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 \
    python3 bench/scipy_peer.py "${FILES[@]}" --repeat "$REPEAT" > "$OUT/peer.jsonl"

echo "== pantowatch-tools bench" >&2
if ! "$BIN" bench --json "${FILES[@]}" > "$OUT/rust.jsonl"; then
    echo "run.sh: '$BIN bench --json' failed" >&2
    exit 1
fi
if ! grep -q '^{' "$OUT/rust.jsonl"; then
    echo "run.sh: '$BIN bench --json' printed no JSON lines (see $OUT/rust.jsonl)" >&2
    exit 1
fi

python3 bench/compare.py --truth "$TRUTH" --peer "$OUT/peer.jsonl" \
    --rust "$OUT/rust.jsonl" | tee "$OUT/table.md"
