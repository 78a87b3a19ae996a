#!/usr/bin/env bash
# Checks bench/dynamicedt.sh and its harness on tiny grids against a
# brute-force EDT in plain Python (no numpy), and checks that malformed
# changes files are refused with exit status 2 and the offending line.
#
#   bench/dynamicedt/check_tiny.sh
#
# Cases:
#   tiny       by hand: 20x20x10 box, max_distance_vox 4.5; frame 0 sets
#              three voxels (one in a corner of the box), frame 1 clears one
#              and sets another on the box floor.
#   rand-*     seeded random sequences (40 frames of sets and clears) on the
#              same box with an integer cutoff (3: distances exactly 3 must
#              stay finite), a cutoff past the box diagonal (a full EDT), and
#              a sequence that ends with every obstacle cleared (all +inf).
# Each final field must equal min(distance to the nearest obstacle centre,
# +inf beyond max_distance_vox) within 1e-5 voxels.
#
# Prints one line per case and "check_tiny: all passed"; exits 1 otherwise.
set -euo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT

cat >"$TMP/tiny.changes" <<'EOF'
edtmap-changes 1
# hand-made: see check_tiny.sh
voxel_size_m 0.2
max_distance_vox 4.5
box -10 -10 0 20 20 10
frames 2

frame 0 set 3 clear 0
3 4 5
10 10 2
19 19 9
frame 1 set 1 clear 1
15 5 0
10 10 2
EOF

# Seeded random sequences: NAME SEED MAX_DISTANCE_VOX CLEAR_ALL_AT_END
python3 - "$TMP" <<'EOF'
import random, sys

def generate(path, seed, max_dist, clear_all):
    rng = random.Random(seed)
    n = (20, 20, 10)
    occupied = set()
    frames = []
    for k in range(40):
        clear = rng.sample(sorted(occupied), min(len(occupied), rng.randint(0, 4)))
        if rng.random() < 0.3:  # clearing a free voxel is a no-op
            clear.append(tuple(rng.randrange(m) for m in n))
        sets = [tuple(rng.randrange(m) for m in n) for _ in range(rng.randint(0, 6))]
        occupied.difference_update(clear)
        occupied.update(sets)
        frames.append((k, sets, clear))
    if clear_all:
        frames.append((40, [], sorted(occupied)))
    with open(path, "w") as f:
        f.write(f"edtmap-changes 1\nvoxel_size_m 0.1\nmax_distance_vox {max_dist}\n")
        f.write(f"box 0 0 0 {n[0]} {n[1]} {n[2]}\nframes {len(frames)}\n")
        for k, sets, clear in frames:
            f.write(f"frame {k} set {len(sets)} clear {len(clear)}\n")
            for v in sets + clear:
                f.write("%d %d %d\n" % v)

tmp = sys.argv[1]
generate(f"{tmp}/rand-int-cutoff.changes", 1, 3, False)
generate(f"{tmp}/rand-full.changes", 2, 40, False)
generate(f"{tmp}/rand-cleared.changes", 3, 6.5, True)
EOF

status=0
for case in tiny rand-int-cutoff rand-full rand-cleared; do
    "$ROOT/bench/dynamicedt.sh" --repeat 2 --out "$TMP/$case" "$TMP/$case.changes" >"$TMP/$case.json"
    python3 - "$TMP/$case" <<'EOF' || status=1
import math, struct, sys

prefix = sys.argv[1]
lines = [l.split() for l in open(prefix + ".changes") if l.strip() and not l.lstrip().startswith("#")]
max_dist = float(lines[2][1])
nx, ny, nz = map(int, lines[3][4:7])
occupied, i, frames = set(), 5, 0
while i < len(lines):
    s, c = int(lines[i][3]), int(lines[i][5])
    sets = [tuple(map(int, l)) for l in lines[i + 1:i + 1 + s]]
    clears = [tuple(map(int, l)) for l in lines[i + 1 + s:i + 1 + s + c]]
    occupied.difference_update(clears)
    occupied.update(sets)
    i += 1 + s + c
    frames += 1

data = open(prefix + ".final.f32", "rb").read()
assert len(data) == 4 * nx * ny * nz, f"{len(data)} bytes, expected {4 * nx * ny * nz}"
got = struct.unpack(f"<{nx * ny * nz}f", data)
worst, bad = 0.0, []
for z in range(nz):
    for y in range(ny):
        for x in range(nx):
            sq = min(((x - a) ** 2 + (y - b) ** 2 + (z - c) ** 2 for a, b, c in occupied), default=None)
            want = math.sqrt(sq) if sq is not None and math.sqrt(sq) <= max_dist else math.inf
            g = got[x + nx * (y + ny * z)]
            if math.isinf(want) or math.isinf(g):
                ok = want == g
            else:
                worst = max(worst, abs(g - want))
                ok = abs(g - want) <= 1e-5
            if not ok:
                bad.append(((x, y, z), g, want))

rows = open(prefix + ".times.csv").read().split("\n")
assert rows[0] == "frame,set,clear,update_ms" and len([r for r in rows[1:] if r]) == frames, "times.csv"
name = prefix.rsplit("/", 1)[-1]
if bad:
    print(f"FAIL {name}: {len(bad)} voxels differ, e.g. (voxel, got, want) {bad[:5]}")
    sys.exit(1)
print(f"ok   {name}: {nx}x{ny}x{nz}, {frames} frames, {len(occupied)} obstacles, cutoff {max_dist}, "
      f"max |error| {worst:.2e}")
EOF
done

# Malformed files: exit status 2 and a message naming file:line.
BIN="$ROOT/bench/out/replay_dynamicedt"
refuse() { # refuse NAME EXPECTED_LINE: the harness must refuse $TMP/NAME.changes
    local name=$1 line=$2 rc=0
    "$BIN" "$TMP/$name.changes" "$TMP/$name" 2>"$TMP/$name.err" >/dev/null || rc=$?
    if [[ $rc -eq 2 ]] && grep -q "$name.changes:$line: " "$TMP/$name.err"; then
        echo "ok   $name refused: $(cat "$TMP/$name.err")"
    else
        echo "FAIL $name: exit $rc, stderr: $(cat "$TMP/$name.err")"
        status=1
    fi
}
head -n 13 "$TMP/tiny.changes" >"$TMP/truncated.changes"               # drops the last clear line
sed '1s/.*/edtmap-changes 2/' "$TMP/tiny.changes" >"$TMP/version.changes"
sed '1s/.*/octomap-changes 1/' "$TMP/tiny.changes" >"$TMP/magic.changes"
sed '10s/.*/10 20 2/' "$TMP/tiny.changes" >"$TMP/outside.changes"        # y = 20 in a 20-wide box
{ cat "$TMP/tiny.changes"; echo "frame 2 set 0 clear 0"; } >"$TMP/extra.changes"
refuse truncated 14
refuse version 1
refuse magic 1
refuse outside 10
refuse extra 15

[[ $status -eq 0 ]] && echo "check_tiny: all passed" || echo "check_tiny: FAILED"
exit $status
