#!/usr/bin/env bash
# Runs every cargo-fuzz (libFuzzer) target of fuzz/ for a fixed budget and
# reports executions and crashes per target. Not part of `cargo test`.
#
# Install once (from crates.io):
#   cargo install cargo-fuzz --locked
# It needs a nightly compiler (-Z sanitizer flags): with a nightly toolchain
# installed this script uses `cargo +nightly fuzz`; without one it sets
# RUSTC_BOOTSTRAP=1 on the stable toolchain.
#
#   tools/fuzz.sh                      # 60 s per target, all targets
#   FUZZ_SECONDS=600 tools/fuzz.sh     # longer
#   tools/fuzz.sh observation rsi_rob  # some targets
#
# New inputs go to fuzz/corpus/TARGET (ignored by git); the committed seeds
# are fuzz/seeds/TARGET. A crash leaves fuzz/artifacts/TARGET/crash-*;
# reproduce it with `cargo +nightly fuzz run TARGET fuzz/artifacts/TARGET/crash-…`
# and turn it into a unit test beside the parser. Exit status 1 on any crash.
set -uo pipefail
cd "$(dirname "$0")/.."
SECONDS_PER_TARGET=${FUZZ_SECONDS:-60}
TARGETS=("$@")
if [[ ${#TARGETS[@]} -eq 0 ]]; then
    TARGETS=(observation crop rsi_rob rsi_sen config calib fit_csv)
fi
if rustup toolchain list 2>/dev/null | grep -q '^nightly'; then
    FUZZ=(cargo +nightly fuzz)
else
    export RUSTC_BOOTSTRAP=1
    FUZZ=(cargo fuzz)
fi
# Crop datagrams are up to 27 684 bytes, the rest far smaller.
max_len() { case "$1" in crop) echo 28000 ;; config | calib | fit_csv) echo 8192 ;; *) echo 2048 ;; esac; }

"${FUZZ[@]}" build || exit 2
status=0
printf '%-12s %12s %10s %8s\n' target executions exec/s crashes
for t in "${TARGETS[@]}"; do
    mkdir -p "fuzz/corpus/$t" "fuzz/artifacts/$t"
    before=$(find "fuzz/artifacts/$t" -type f | wc -l)
    log="fuzz/artifacts/$t.log"
    "${FUZZ[@]}" run "$t" "fuzz/corpus/$t" "fuzz/seeds/$t" -- \
        -max_total_time="$SECONDS_PER_TARGET" -max_len="$(max_len "$t")" -print_final_stats=1 >"$log" 2>&1
    execs=$(awk '/stat::number_of_executed_units/ { print $2 }' "$log" | tail -n 1)
    rate=$(awk '/stat::average_exec_per_sec/ { print $2 }' "$log" | tail -n 1)
    crashes=$(( $(find "fuzz/artifacts/$t" -type f | wc -l) - before ))
    printf '%-12s %12s %10s %8s\n' "$t" "${execs:-?}" "${rate:-?}" "$crashes"
    if [[ "$crashes" -ne 0 || -z "$execs" ]]; then
        status=1
        tail -n 30 "$log" >&2
    fi
done
exit $status
