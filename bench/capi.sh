#!/usr/bin/env bash
# Query throughput and an integration frame through the C API against the
# Rust API, in the same run: the same wall (60 000 points), the same 20
# frames, and the same batches of 1, 1 000 and 1 000 000 random points
# (distances and gradients), on all cores.
#
#   bash bench/capi.sh
#
# Builds libedtmap_c and the Rust side (crates/capi/examples/query_bench.rs)
# in the release profile (honours CARGO_TARGET_DIR and CARGO_PROFILE_*),
# compiles bench/capi_bench.c with gcc -O2 against the shared library, runs
# both, and prints per batch the ns per point and per call of each and the
# C/Rust ratio (the goal: within 1.10 for 1 000 points or more).
#
# Needs: cargo, gcc, python3. Exit status 1 when a run fails.
set -euo pipefail
cd "$(dirname "$0")/.."
target="${CARGO_TARGET_DIR:-target}"
cargo build --release --locked -p edtmap-capi --lib --example query_bench >&2
out=bench/out/capi
mkdir -p "$out"
gcc -O2 -std=c11 -I include bench/capi_bench.c -L "$target/release" -ledtmap_c -Wl,-rpath,"$(cd "$target/release" && pwd)" -o "$out/capi_bench"
echo "capi.sh at commit $(git rev-parse --short HEAD), $(date -u '+%Y-%m-%d %H:%M UTC'), nproc $(nproc), load $(cut -d' ' -f1-3 /proc/loadavg)"
# Interleaved, twice each, the faster run kept: the machine is shared.
for i in 1 2; do
    "$target/release/examples/query_bench" >"$out/rust_$i.txt"
    "$out/capi_bench" >"$out/c_$i.txt"
done
python3 - "$out" <<'PY'
import sys
out = sys.argv[1]
best = {}
for side in ("rust", "c"):
    for i in (1, 2):
        for line in open(f"{out}/{side}_{i}.txt"):
            who, what, batch, per_point, per_call = line.split()
            key = (who, what, int(batch))
            if key not in best or float(per_call) < best[key][1]:
                best[key] = (float(per_point), float(per_call))
print()
print("| measurement | points per call | Rust ns/point | C ns/point | Rust ns/call | C ns/call | C / Rust |")
print("|---|---|---|---|---|---|---|")
for what, batch in [("integrate", 60000), ("query", 1), ("query", 1000), ("query", 1000000)]:
    r, c = best[("rust", what, batch)], best[("c", what, batch)]
    print(f"| {what} | {batch:,} | {r[0]:.2f} | {c[0]:.2f} | {r[1]:,.0f} | {c[1]:,.0f} | {c[1] / r[1]:.2f} |")
PY
