#!/usr/bin/env bash
# Packs bench_segment_ranks with every library it loads, its loader included, and the mapper
# inputs given, into build/device/ (ignored by git), for a machine without the build's
# libraries: there, run it as
#   cd build/device && ./lib/ld-linux-x86-64.so.2 --library-path lib ./bench_segment_ranks \
#       INPUT.bin --segments 4 --ranks 4,1 --threads 4 --runs 2
# Mapper inputs come from `build/bench/mappers/bench_mapper_input DATABASE OUT.bin`.
#   bench/mappers/pack_segment_ranks.sh [INPUT.bin ...]
set -euo pipefail
cd "$(dirname "$0")/../.."
binary=build/bench/mappers/bench_segment_ranks
[ -x "$binary" ] || { echo "build $binary first (scripts/build)" >&2; exit 2; }
rm -rf build/device
mkdir -p build/device/lib
cp "$binary" build/device/
for lib in $(ldd "$binary" | awk '/=>/ {print $3} /ld-linux/ {print $1}'); do
  cp -L "$lib" build/device/lib/
done
for input in "$@"; do cp "$input" build/device/; done
du -sh build/device
