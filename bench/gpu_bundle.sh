#!/usr/bin/env bash
# Prepares `bash bench/gpu.sh --device` for a machine with a GPU and no
# network (the device tool's H200, say): builds here what it needs and packs
# it into .device/, which git ignores (this script adds it to
# .git/info/exclude) and the device call carries.
#
#   bash bench/gpu_bundle.sh
#
# What it puts in .device/:
#   bundle.tar.xz   bin/edtmap (release, stripped), tests/* (the GPU test
#                   executables: edtmap-gpu's unit, conformance and resident
#                   tests; edtmap's gpu_pipeline, gpu_integrate and
#                   gpu_projection; release, stripped) and data/ (a copy of
#                   the shared recordings 3dmatch-seq01 and velodyne-pair,
#                   from $EDTMAP_DATA or ../shared/data)
#   gl/*.deb        the Vulkan loader (libvulkan1) for amd64, in case the
#                   machine has none; gpu.sh --device unpacks it only then
# Then, on the device (the tool's `run`, carry [".device"]):
#   bash bench/gpu.sh --device
# It prints the tables and copies them to $OUT/gpu.md when OUT is set.
#
# Needs: cargo, xz, apt-get (for the loader; skipped with a note if it
# fails). The bundle is about 25 MB; the device tool carries at most 64 MiB.
set -euo pipefail
cd "$(dirname "$0")/.."
root=$(pwd)
data="${EDTMAP_DATA:-$root/../shared/data}"
[ -d "$data/3dmatch-seq01" ] && [ -d "$data/velodyne-pair" ] || { echo "gpu_bundle: the shared recordings are not in $data (set EDTMAP_DATA)" >&2; exit 1; }
grep -qx '/.device/' .git/info/exclude 2>/dev/null || echo '/.device/' >>.git/info/exclude
rm -rf .device && mkdir -p .device/gl
stage=$(mktemp -d)
trap 'rm -rf "$stage"' EXIT
mkdir -p "$stage/bin" "$stage/tests" "$stage/data"

cargo build --release --locked -p edtmap-cli >&2
cp target/release/edtmap "$stage/bin/"
# The test executables, from cargo's own list of what it built.
# (Two calls: `--test` narrows every package it is given with.)
{
    cargo test --release --locked --no-run --message-format=json -p edtmap-gpu
    cargo test --release --locked --no-run --message-format=json -p edtmap --test gpu_pipeline --test gpu_integrate --test gpu_projection
} 2>/dev/null |
    python3 -c '
import json, sys
for line in sys.stdin:
    m = json.loads(line)
    if m.get("reason") == "compiler-artifact" and m.get("executable") and m["profile"]["test"]:
        print(m["target"]["name"], m["executable"])
' | while read -r name exe; do cp "$exe" "$stage/tests/$name"; done
[ -n "$(ls "$stage/tests")" ] || { echo "gpu_bundle: no test executable was built" >&2; exit 1; }
strip "$stage/bin/edtmap" "$stage/tests/"* 2>/dev/null || true
cp -r "$data/3dmatch-seq01" "$data/velodyne-pair" "$stage/data/"
chmod -R u+w "$stage/data"
tar -C "$stage" -cJf .device/bundle.tar.xz bin tests data

# The Vulkan loader, as the device tool's README describes (amd64 lists).
if (o='-oAPT::Architecture=amd64 -oAPT::Architectures=amd64 -oDir::State::Lists=/tmp/amd64'
    mkdir -p /tmp/amd64/partial && apt-get $o update -qq && cd .device/gl && apt-get $o download libvulkan1) >/dev/null 2>&1; then
    :
else
    echo "gpu_bundle: could not download libvulkan1; the device must have a Vulkan loader" >&2
fi
ls -l .device/bundle.tar.xz .device/gl
du -sh .device
