#!/usr/bin/env bash
# Fuzzes the upload parsers (fuzz/: targets trace_json and trace_csv) for a fixed time each and
# exits non-zero on any crash. Installs cargo-fuzz if missing. Not part of .ci/run (too slow).
#
#   scripts/fuzz.sh [SECONDS]     seconds per target, default 60
#
# Environment: FUZZ_SANITIZER (none|address, default none: the code under test is safe Rust, and
# on a shared 2-core machine executions matter more than ASan's checks of dependencies' unsafe
# code), CARGO_TARGET_DIR (honoured by cargo-fuzz). The working corpus grows in
# fuzz/corpus/<target> (not committed); crashes land in fuzz/artifacts/<target>/.
set -euo pipefail

secs="${1:-60}"
case "$secs" in '' | *[!0-9]*) echo "usage: $0 [SECONDS]" >&2; exit 2 ;; esac
root="$(cd "$(dirname "$0")/.." && pwd)"
sanitizer="${FUZZ_SANITIZER:-none}"
# cargo-fuzz passes nightly-only flags (-Zsanitizer, -Cpasses=sancov-module); the toolchain here is
# stable, and RUSTC_BOOTSTRAP=1 lets it accept them.
export RUSTC_BOOTSTRAP=1

if ! cargo fuzz --version >/dev/null 2>&1; then
    echo "installing cargo-fuzz" >&2
    cargo install cargo-fuzz --locked
fi

cd "$root/fuzz"
cargo fuzz build -s "$sanitizer" -O

status=0
summary=""
for target in trace_json trace_csv; do
    corpus="$root/fuzz/corpus/$target"
    artifacts="$root/fuzz/artifacts/$target"
    mkdir -p "$corpus" "$artifacts"
    before=$(find "$artifacts" -type f | wc -l)
    log="$(mktemp)"
    set +e
    # Seeds: the example traces (fuzz/seeds, see make_seeds.py) and the malformed-upload corpus.
    cargo fuzz run -s "$sanitizer" -O "$target" "$corpus" "$root/fuzz/seeds/$target" "$root/tests/corpus" -- \
        -max_total_time="$secs" -max_len=65536 -timeout=10 -rss_limit_mb=2048 \
        -print_final_stats=1 -artifact_prefix="$artifacts/" >"$log" 2>&1
    rc=$?
    set -e
    grep -E '^(#[0-9]+[[:space:]]+(INITED|DONE)|==|SUMMARY|.*panicked)' "$log" || true
    after=$(find "$artifacts" -type f | wc -l)
    crashes=$((after - before))
    execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1 || true)
    cov=$(grep -oE 'cov: [0-9]+ ft: [0-9]+ corp: [0-9]+/[0-9a-zA-Z]+' "$log" | tail -1 || true)
    line="$target: ${secs}s, execs ${execs:-?}, ${cov:-no coverage line}, crashes $crashes, exit $rc"
    summary="$summary$line"$'\n'
    if [ "$rc" -ne 0 ] || [ "$crashes" -ne 0 ]; then
        status=1
        tail -40 "$log" >&2
    fi
    rm -f "$log"
done
printf '\n%s' "$summary"
if [ "$status" -ne 0 ]; then
    echo "fuzz: CRASH (inputs in fuzz/artifacts/)" >&2
fi
exit "$status"
