#!/usr/bin/env bash
# The C and C++ API end to end, as a C++ user gets it: builds libedtmap_c
# through its CMake project, installs it into a temporary prefix, builds the
# tests and the planner example against the installed package from a clean
# build directory (find_package), runs them, runs the C test under valgrind
# (no leaks, no invalid accesses), runs the C and C++ tests once more built
# with AddressSanitizer and UBSan, and compiles the C test once more through
# pkg-config.
#
#   bash tests/capi/run.sh [--profile dev|release]   (default: dev)
#
# Needs cmake, gcc, g++, pkg-config and valgrind (Debian: apt-get install
# cmake g++ pkg-config valgrind). Exit status 1 on any failure.
set -euo pipefail
cd "$(dirname "$0")/../.."
root=$(pwd)
profile=dev
while [ $# -gt 0 ]; do
    case "$1" in
        --profile) profile=$2; shift 2 ;;
        *) echo "usage: bash tests/capi/run.sh [--profile dev|release]" >&2; exit 2 ;;
    esac
done
for tool in cmake gcc g++ pkg-config valgrind; do
    command -v "$tool" >/dev/null || { echo "tests/capi/run.sh: $tool is missing (Debian: apt-get install cmake g++ pkg-config valgrind)" >&2; exit 1; }
done
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
prefix="$work/prefix"

# 1. Build and install the package (the README's commands).
cmake -S crates/capi -B "$work/build-lib" -DEDTMAP_CARGO_PROFILE="$profile" >/dev/null
cmake --build "$work/build-lib"
cmake --install "$work/build-lib" --prefix "$prefix" >/dev/null
ls "$prefix"/lib*/libedtmap_c.* "$prefix/include/edtmap.h" "$prefix/include/edtmap.hpp" >/dev/null

# 2. The Rust Mapper's answers for the bit-for-bit comparison.
cargo run -q --locked -p edtmap-capi --example wall_reference -- "$work/wall.bin"

# 3. Tests and example against the installed package, from a clean build dir.
cmake -S tests/capi -B "$work/build-tests" -DCMAKE_PREFIX_PATH="$prefix" -DCMAKE_BUILD_TYPE=Debug >/dev/null
cmake --build "$work/build-tests" -j 2
"$work/build-tests/test_edtmap_c" "$work/wall.bin" "$work"
"$work/build-tests/test_edtmap_c_static" "$work/wall.bin" "$work"
"$work/build-tests/test_edtmap_cpp" "$work/wall.bin" "$work"

# 4. The C test under valgrind: no invalid access, no definite leak.
valgrind -q --error-exitcode=1 --leak-check=full --show-leak-kinds=definite --errors-for-leak-kinds=definite \
    "$work/build-tests/test_edtmap_c" "$work/wall.bin" "$work"

# 5. The C (shared and static) and C++ tests built with AddressSanitizer
# and UBSan: no invalid access or undefined behaviour on the C side, no
# leak (the library's allocations go through ASan's malloc too).
cmake -S tests/capi -B "$work/build-asan" -DCMAKE_PREFIX_PATH="$prefix" -DCMAKE_BUILD_TYPE=Debug -DEDTMAP_TEST_SANITIZERS=ON >/dev/null
cmake --build "$work/build-asan" -j 2 --target test_edtmap_c test_edtmap_c_static test_edtmap_cpp
for t in test_edtmap_c test_edtmap_c_static test_edtmap_cpp; do
    ASAN_OPTIONS=detect_leaks=1:halt_on_error=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
        "$work/build-asan/$t" "$work/wall.bin" "$work"
done

# 6. pkg-config, as a Makefile would use it.
PKG_CONFIG_PATH="$(ls -d "$prefix"/lib*/pkgconfig | head -n 1)" \
    bash -c 'gcc -std=c11 -Wall -Werror -I tests/capi tests/capi/test_edtmap.c $(pkg-config --cflags --libs edtmap) -lpthread -lm -Wl,-rpath,$(pkg-config --variable=libdir edtmap) -o "$0"' "$work/test_pc"
"$work/test_pc" "$work/wall.bin" "$work"

# 7. The example on a map the CLI saves.
edtmap_bin="${CARGO_TARGET_DIR:-$root/target}/debug/edtmap"
[ -x "$edtmap_bin" ] || cargo build -q --locked -p edtmap-cli
"$edtmap_bin" run --scene uav_pillars --frames 20 --out "$work/run" --save "$work/map.edtmap" >/dev/null
"$work/build-tests/example/planner" "$work/map.edtmap"
echo "tests/capi/run.sh: all passed"
