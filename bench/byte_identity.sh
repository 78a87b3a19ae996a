#!/usr/bin/env bash
# Checks that a refactor left the maps byte-identical: builds revision BASE
# (default: the build before the backends became a trait) and the working
# tree, saves the map of `edtmap demo`, of every built-in scene (both
# integration modes) and of the two shared recordings with each, and
# compares the files byte for byte.
#
#   bash bench/byte_identity.sh [BASE] [--backend cpu|gpu]
#
# The builds are release builds without LTO (quick to build, quick to run),
# kept under target/byte-identity/ between runs. Exits 1 on any difference.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/.." && pwd)"
base=153a9e9
backend=cpu
while [ $# -gt 0 ]; do
    case "$1" in
        --backend) backend="$2"; shift 2 ;;
        -h|--help) sed -n '2,11p' "$0"; exit 0 ;;
        *) base="$1"; shift ;;
    esac
done
shared="$root/../shared/data"
[ -d "$shared" ] || { echo "byte_identity: $shared is missing (the shared recordings sit beside the checkout)" >&2; exit 1; }
work="$root/target/byte-identity"
mkdir -p "$work"
export CARGO_PROFILE_RELEASE_LTO=false CARGO_PROFILE_RELEASE_CODEGEN_UNITS=16

build() { # build SRC_DIR TARGET_DIR
    (cd "$1" && CARGO_TARGET_DIR="$2" cargo build --release -q -p edtmap-cli)
}

rev="$(git -C "$root" rev-parse --verify "$base^{commit}")"
tree="$work/base-$rev"
if [ ! -x "$work/target-base-$rev/release/edtmap" ]; then
    rm -rf "$tree"
    git -C "$root" worktree add --detach -f "$tree" "$rev" >/dev/null
    build "$tree" "$work/target-base-$rev"
    git -C "$root" worktree remove --force "$tree"
fi
build "$root" "$work/target-new"
old_bin="$work/target-base-$rev/release/edtmap"
new_bin="$work/target-new/release/edtmap"

cases=(
    "demo|demo"
    "uav_pillars|run --scene uav_pillars"
    "ugv_corridor|run --scene ugv_corridor"
    "room|run --scene room"
    "planar|run --scene planar"
    "room_exact|run --scene room --integration exact"
    "planar_exact|run --scene planar --integration exact --connectivity 6"
    "3dmatch|run --config $root/configs/3dmatch.toml --dataset $shared/3dmatch-seq01"
    "velodyne|run --config $root/configs/velodyne.toml --dataset $shared/velodyne-pair"
)
fail=0
for c in "${cases[@]}"; do
    name="${c%%|*}"
    args="${c#*|}"
    for side in old new; do
        bin="${side}_bin"
        out="$work/out/$name/$side"
        rm -rf "$out"
        mkdir -p "$out"
        if [ "$args" = demo ]; then
            (cd "$out" && "${!bin}" demo --backend "$backend" >/dev/null)
            mv "$out/edtmap-out/map.edtmap" "$out/map.edtmap"
        else
            # shellcheck disable=SC2086
            (cd "$out" && "${!bin}" $args --backend "$backend" --out "$out/run" --save "$out/map.edtmap" >/dev/null)
        fi
    done
    if cmp -s "$work/out/$name/old/map.edtmap" "$work/out/$name/new/map.edtmap"; then
        echo "same      $name ($(stat -c %s "$work/out/$name/new/map.edtmap") bytes)"
    else
        echo "DIFFERENT $name"
        fail=1
    fi
done
[ "$fail" = 0 ] && echo "byte_identity: every map equals $base's" || echo "byte_identity: maps differ from $base's" >&2
exit "$fail"
