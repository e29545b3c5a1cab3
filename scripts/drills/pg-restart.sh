#!/usr/bin/env bash
# Drill: PostgreSQL restarted under load, against the real `pantowatch serve` process.
#
# A private throw-away cluster (initdb in a temp dir, a free port; run as `postgres` when this
# runs as root) — the shared server on 5432 is never touched. Three upload loops run (upload,
# 100 ms pause, again); PostgreSQL is stopped (`pg_ctl stop -m fast`) for OUTAGE_S seconds and started again.
# Printed: every answer's status and time during the outage, the recovery time, and whether
# every upload answered 202 is stored. Exit status 0 only if all checks hold. The cluster, the
# service and the temp dir are removed on exit, also on failure (trap).
#
# Usage: scripts/drills/pg-restart.sh [path/to/pantowatch]     (default: target/debug/pantowatch)
# Env:   OUTAGE_S (5), PG_BIN (newest /usr/lib/postgresql/*/bin)
set -euo pipefail

BIN=${1:-${CARGO_TARGET_DIR:-target}/debug/pantowatch}
OUTAGE_S=${OUTAGE_S:-5}
PG_BIN=${PG_BIN:-$(ls -d /usr/lib/postgresql/*/bin | sort -V | tail -1)}
HERE=$(cd "$(dirname "$0")/../.." && pwd)
DOC="$HERE/../shared/data/examples/J1_baseline.json"
[ -x "$BIN" ] || { echo "drill: $BIN not found (cargo build -p pantowatch)" >&2; exit 2; }
[ -x "$PG_BIN/initdb" ] || { echo "drill: no initdb in $PG_BIN (set PG_BIN)" >&2; exit 2; }

WORK=$(mktemp -d /tmp/pw-pg-drill.XXXXXX)
chmod 755 "$WORK"
PGDATA="$WORK/data"
PORT=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')
pg() { if [ "$(id -u)" = 0 ]; then runuser -u postgres -- "$PG_BIN/$1" "${@:2}"; else "$PG_BIN/$1" "${@:2}"; fi; }
[ "$(id -u)" = 0 ] && chown postgres:postgres "$WORK"
SERVE_PID=""
cleanup() {
    [ -n "$SERVE_PID" ] && kill "$SERVE_PID" 2>/dev/null && wait "$SERVE_PID" 2>/dev/null || true
    pg pg_ctl -D "$PGDATA" -m immediate -w stop >/dev/null 2>&1 || true
    rm -rf "$WORK"
}
trap cleanup EXIT

now() { date +%s.%N; }
pg initdb -D "$PGDATA" -U postgres -A trust -N -E UTF8 >/dev/null
pg_start() { pg pg_ctl -D "$PGDATA" -l "$WORK/pg.log" -w -t 60 \
    -o "-p $PORT -k $WORK -c listen_addresses=127.0.0.1" start >/dev/null; }
pg_start
URL="postgres://postgres@127.0.0.1:$PORT/postgres"
KEY=$(PANTOWATCH__DATABASE__URL=$URL "$BIN" keys create --role writer --label drill 2>/dev/null)
[ -n "$KEY" ] || { echo "drill: could not create a key" >&2; exit 1; }
PANTOWATCH__DATABASE__URL=$URL PANTOWATCH__WORKER__LEASE_SECS=5 PANTOWATCH__LOG__FILTER=warn \
    "$BIN" serve --listen 127.0.0.1:0 --workers 1 2>"$WORK/serve.log" &
SERVE_PID=$!
for _ in $(seq 300); do grep -q 'serving on' "$WORK/serve.log" && break; sleep 0.1; done
ADDR=$(grep -o 'http://[0-9.:]*' "$WORK/serve.log" | head -1)
[ -n "$ADDR" ] || { cat "$WORK/serve.log"; exit 1; }

# One upload: prints "<id> <status> <seconds> <start epoch>".
jq -c '.trace_id = "@ID@"' "$DOC" >"$WORK/template.json"
upload() {
    local id=$1 t0 out
    t0=$(now)
    out=$(sed "s/@ID@/$id/" "$WORK/template.json" | curl -s -o /dev/null -m 30 \
        -w '%{http_code} %{time_total}' -H "Authorization: Bearer $KEY" \
        -H 'Content-Type: application/json' --data-binary @- "$ADDR/v1/traces" || echo "000 0")
    echo "$id $out $t0"
}
LOG="$WORK/shots.txt"
LOAD_PIDS=()
for k in 1 2 3; do   # three concurrent upload loops
    ( n=0; while [ ! -f "$WORK/stop-load" ]; do upload "drill-$k-$n" >>"$LOG"; n=$((n + 1)); sleep 0.1; done ) &
    LOAD_PIDS+=($!)
done

sleep 2
T_STOP=$(now); pg pg_ctl -D "$PGDATA" -m fast -w stop >/dev/null; T_DOWN=$(now)
sleep "$OUTAGE_S"
T_RESTART=$(now); pg_start; T_UP=$(now)
sleep 4
touch "$WORK/stop-load"; wait "${LOAD_PIDS[@]}"

echo "== PostgreSQL restart drill: $(date -u +%FT%TZ), $(nproc) cores, outage ${OUTAGE_S} s"
awk -v d="$T_DOWN" -v r="$T_RESTART" -v up="$T_UP" -v s="$T_STOP" '
  { n++; st[$2]++ }
  $4 >= d && $4 + $3 <= r { o++; if ($2 == 503) o503++; if ($3 > omax) omax = $3 }
  $4 >= r && $2 == 202 && (first == "" || $4 + $3 < first) { first = $4 + $3 }
  END {
    printf "stop took %.2f s, down %.2f s, start took %.2f s\n", d - s, r - d, up - r
    printf "%d uploads:", n; for (k in st) printf " %d x %s", st[k], k; printf "\n"
    printf "during the outage: %d requests, %d answered 503, slowest %.3f s\n", o, o503, omax
    printf "first 202 %.2f s after PostgreSQL was up\n", first - up
    if (o == 0 || o503 != o || omax >= 2) exit 1
  }' "$LOG" || { echo "drill: FAILED outage checks"; exit 1; }
bad=$(awk '$2 != 202 && $2 != 503' "$LOG" | wc -l)
missing=0
for id in $(awk '$2 == 202 { print $1 }' "$LOG"); do
    code=$(curl -s -o /dev/null -w '%{http_code}' -H "Authorization: Bearer $KEY" "$ADDR/v1/traces/$id")
    [ "$code" = 200 ] || { echo "lost: $id ($code)"; missing=$((missing + 1)); }
done
# The in-process worker recovers too: every accepted trace gets its fit (60 s at most).
unfitted=-1
for _ in $(seq 60); do
    unfitted=0
    for id in $(awk '$2 == 202 { print $1 }' "$LOG"); do
        code=$(curl -s -o /dev/null -w '%{http_code}' -H "Authorization: Bearer $KEY" "$ADDR/v1/traces/$id/fit")
        [ "$code" = 200 ] || unfitted=$((unfitted + 1))
    done
    [ "$unfitted" = 0 ] && break
    sleep 1
done
echo "answers other than 202/503: $bad; accepted uploads missing afterwards: $missing; without a fit: $unfitted"
[ "$bad" = 0 ] && [ "$missing" = 0 ] && [ "$unfitted" = 0 ] || { echo "drill: FAILED"; exit 1; }
echo "drill: OK"
