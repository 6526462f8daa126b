#!/usr/bin/env bash
# Soak: continuous play (a simulated ball every GAP s) against the mock KR C4
# at 4 ms, with an optional CPU hog, sampling RSS. Not part of CI.
#
# MODE=demo (default): `topspin demo` in one process (simulated tracker ->
#   daemon threads -> mock KR C4), every stroke judged against the truth:
#   hit rate, late answers, latency. Its RSS includes the harness's record of
#   the whole TCP path (~120 bytes a cycle), so it grows by design.
# MODE=run: three processes, `topspin run` (the daemon as deployed),
#   `topspin mock-krc`, `topspin sim --to`; RSS is the daemon's alone, late
#   answers are the mock's count. REALTIME=false turns SCHED_FIFO off.
#
#   tools/soak.sh                 # 600 s, demo, hog on
#   MODE=run tools/soak.sh
#   DURATION=60 HOG=0 tools/soak.sh
#   TOPSPIN=/path/to/topspin OUT=/tmp/soak tools/soak.sh
#
# Writes OUT/rss.csv (t_s,rss_kib) and OUT/demo.json (demo) or OUT/mock.txt,
# OUT/daemon.log (run); prints the figures.
set -euo pipefail
DURATION=${DURATION:-600}   # seconds of play
GAP=${GAP:-1.5}             # launch-to-launch gap, s
HOG=${HOG:-1}               # 1: a niced busy loop runs beside the daemon
SEED=${SEED:-1}
MODE=${MODE:-demo}
REALTIME=${REALTIME:-true}
OUT=${OUT:-$(mktemp -d /tmp/topspin-soak.XXXXXX)}
TOPSPIN=${TOPSPIN:-}
if [[ -z "$TOPSPIN" ]]; then
    cargo build --release --quiet
    TOPSPIN=target/release/topspin
fi
mkdir -p "$OUT"
BALLS=$(awk -v d="$DURATION" -v g="$GAP" 'BEGIN { n = int(d / g); print (n < 1 ? 1 : n) }')

hog_pid=""
cleanup() { [[ -n "$hog_pid" ]] && kill "$hog_pid" 2>/dev/null || true; }
trap cleanup EXIT
if [[ "$HOG" == 1 ]]; then
    # A busy loop at the lowest priority: it competes for the CPU the daemon
    # does not pin, without starving the rest of a shared machine.
    nice -n 19 bash -c 'while :; do :; done' &
    hog_pid=$!
fi

echo "soak: $BALLS balls every ${GAP} s (~${DURATION} s), mode=$MODE, hog=$HOG, out=$OUT" >&2

sample_rss() { # pid -> appends to rss.csv while it lives
    local pid=$1 start
    start=$(date +%s)
    echo "t_s,rss_kib" >"$OUT/rss.csv"
    while kill -0 "$pid" 2>/dev/null; do
        rss=$(awk '/^VmRSS:/ { print $2 }' "/proc/$pid/status" 2>/dev/null || true)
        [[ -n "$rss" ]] && echo "$(($(date +%s) - start)),$rss" >>"$OUT/rss.csv"
        sleep 5
    done
}
rss_summary() {
    python3 - "$OUT" <<'PY'
import csv, sys
rows = list(csv.DictReader(open(f"{sys.argv[1]}/rss.csv")))
if rows:
    warm = next((r for r in rows if int(r["t_s"]) >= 10), rows[0])
    print(f"RSS kib: first {rows[0]['rss_kib']} (t={rows[0]['t_s']} s), after warm-up {warm['rss_kib']} (t={warm['t_s']} s), "
          f"last {rows[-1]['rss_kib']} (t={rows[-1]['t_s']} s), max {max(int(r['rss_kib']) for r in rows)}")
PY
}

if [[ "$MODE" == run ]]; then
    ports=$(python3 -c 'import socket
s=[socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(2)]
[x.bind(("127.0.0.1", 0)) for x in s]
print(" ".join(str(x.getsockname()[1]) for x in s))')
    read -r tracker rsi <<<"$ports"
    TOPSPIN_NETWORK__TRACKER_BIND="127.0.0.1:$tracker" TOPSPIN_NETWORK__RSI_BIND="127.0.0.1:$rsi" \
        TOPSPIN_THREADS__REALTIME="$REALTIME" "$TOPSPIN" run >/dev/null 2>"$OUT/daemon.log" &
    daemon_pid=$!
    sample_rss "$daemon_pid" &
    sleep 1
    cycles=$(awk -v d="$DURATION" 'BEGIN { print int((d + 5) / 0.004) }')
    "$TOPSPIN" mock-krc --bind 127.0.0.1:0 --to "127.0.0.1:$rsi" --cycles "$cycles" --late-limit 1000000000 \
        >"$OUT/mock.txt" 2>/dev/null &
    mock_pid=$!
    "$TOPSPIN" sim --balls "$BALLS" --gap "$GAP" --seed "$SEED" --to "127.0.0.1:$tracker" >/dev/null 2>&1
    wait "$mock_pid"
    kill -TERM "$daemon_pid"
    wait "$daemon_pid"
    rc=$?
    sleep 1
    echo "mock KR C4: $(cat "$OUT/mock.txt")"
    grep -o 'stopped: .*' "$OUT/daemon.log" | tail -n 1 | cut -c1-2000
    grep -i 'warn' "$OUT/daemon.log" | grep -v 'controller counted late' | head -n 5
    rss_summary
    exit $rc
fi
"$TOPSPIN" demo --balls "$BALLS" --gap "$GAP" --seed "$SEED" --late-limit "${LATE_LIMIT:-1000000000}" --json >"$OUT/demo.json" &
demo_pid=$!
echo "t_s,rss_kib" >"$OUT/rss.csv"
start=$(date +%s)
while kill -0 "$demo_pid" 2>/dev/null; do
    rss=$(awk '/^VmRSS:/ { print $2 }' "/proc/$demo_pid/status" 2>/dev/null || true)
    [[ -n "$rss" ]] && echo "$(( $(date +%s) - start )),$rss" >>"$OUT/rss.csv"
    sleep 5
done
wait "$demo_pid"
rc=$?
python3 - "$OUT" <<'PY'
import csv, json, sys
out = sys.argv[1]
d = json.load(open(f"{out}/demo.json"))
rows = [r for r in csv.DictReader(open(f"{out}/rss.csv"))]
# RSS after warm-up (first sample >= 10 s) vs the last sample.
warm = next((r for r in rows if int(r["t_s"]) >= 10), rows[0]) if rows else None
print(f"balls {d['balls']}, reachable {d['reachable']}, hits {d['hits']} (hit rate {d['hit_rate']:.3f})")
print(f"RSI cycles {d['rsi_cycles']}, late answers {d['late_rsi_answers']}, answers after the cycle {d['answers_after_cycle']}")
lat = d["latency_us"]["rsi_answer"]
print(f"RSI answer latency us p50 {lat['p50']} p99 {lat['p99']} p99.9 {lat['p999']} max {lat['max']}")
print(f"plans late {d['plans_late']}, rejected {d['plans_rejected']}, ended home {d['ended_home']}, warnings {d['warnings']}")
if rows:
    print(f"RSS kib: first {rows[0]['rss_kib']} (t={rows[0]['t_s']} s), after warm-up {warm['rss_kib']} (t={warm['t_s']} s), "
          f"last {rows[-1]['rss_kib']} (t={rows[-1]['t_s']} s), max {max(int(r['rss_kib']) for r in rows)}")
PY
exit $rc
