#!/usr/bin/env bash
# Exact instruction profile of the firmware's tick in QEMU (firmware/README.md, "Cost").
# Builds the qemu board twice in profile mode (PARAGYRO_PROFILE_TICKS=N and =0: set-up only),
# runs both under the per-address histogram plugin firmware/tools/insnprof.c, maps the
# addresses to functions with llvm-nm and prints, per tick, the instructions of each group
# of functions (N-tick run minus 0-tick run, divided by N): exact, no sampling.
# Usage: firmware/scripts/fw-profile.sh [N]   (default 5001, the whole replay table)
set -euo pipefail
cd "$(dirname "$0")/../.."
N="${1:-5001}"
OUT="${FW_PROFILE_DIR:-target/fw-profile}"
NM="${LLVM_NM:-llvm-nm-14}"
mkdir -p "$OUT"
gcc -shared -fPIC -O2 -o "$OUT/libinsnprof.so" firmware/tools/insnprof.c
for n in 0 "$N"; do
  PARAGYRO_PROFILE_TICKS="$n" CARGO_TARGET_DIR="$OUT/build" \
    cargo build -q -p paragyro-firmware --target thumbv7em-none-eabihf --release
  cp "$OUT/build/thumbv7em-none-eabihf/release/paragyro-firmware" "$OUT/fw-$n.elf"
  "$NM" -S -C --defined-only "$OUT/fw-$n.elf" > "$OUT/nm-$n.txt"
  timeout 300 qemu-system-arm -cpu cortex-m4 -machine netduinoplus2 -nographic \
    -monitor none -serial none -semihosting-config enable=on,target=native \
    -plugin "$OUT/libinsnprof.so,out=$OUT/prof-$n.txt" -d plugin \
    -kernel "$OUT/fw-$n.elf" 2>"$OUT/qemu-$n.log" | defmt-print -e "$OUT/fw-$n.elf" > "$OUT/defmt-$n.log"
done
python3 firmware/scripts/fw-profile.py "$N" "$OUT"
