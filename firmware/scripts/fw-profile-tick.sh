#!/usr/bin/env bash
# Exact instruction split of single ticks of the QEMU replay (firmware/README.md, "Cost"):
# for each tick K, profile runs of K and K + 1 ticks (PARAGYRO_PROFILE_TICKS) under the
# histogram plugin; their difference is tick K alone (0-based), split as fw-profile.sh does.
# Usage: firmware/scripts/fw-profile-tick.sh K [K ...]
set -euo pipefail
cd "$(dirname "$0")/../.."
OUT="${FW_PROFILE_DIR:-target/fw-profile}"
NM="${LLVM_NM:-llvm-nm-14}"
mkdir -p "$OUT"
gcc -shared -fPIC -O2 -o "$OUT/libinsnprof.so" firmware/tools/insnprof.c
run() {
  local n="$1"
  [ -f "$OUT/prof-t$n.txt" ] && return 0
  PARAGYRO_PROFILE_TICKS="$n" CARGO_TARGET_DIR="$OUT/build" \
    cargo build -q -p paragyro-firmware --target thumbv7em-none-eabihf --release
  cp "$OUT/build/thumbv7em-none-eabihf/release/paragyro-firmware" "$OUT/fw-t$n.elf"
  "$NM" -S -C --defined-only "$OUT/fw-t$n.elf" > "$OUT/nm-t$n.txt"
  timeout 300 qemu-system-arm -cpu cortex-m4 -machine netduinoplus2 -nographic \
    -monitor none -serial none -semihosting-config enable=on,target=native \
    -plugin "$OUT/libinsnprof.so,out=$OUT/prof-t$n.txt" -d plugin \
    -kernel "$OUT/fw-t$n.elf" 2>"$OUT/qemu-t$n.log" | defmt-print -e "$OUT/fw-t$n.elf" > "$OUT/defmt-t$n.log"
}
rm -f "$OUT"/prof-t*.txt
for k in "$@"; do
  run "$k"
  run "$((k + 1))"
  d="$OUT/tick-$k"
  mkdir -p "$d"
  cp "$OUT/nm-t$k.txt" "$d/nm-0.txt"; cp "$OUT/prof-t$k.txt" "$d/prof-0.txt"
  cp "$OUT/nm-t$((k + 1)).txt" "$d/nm-1.txt"; cp "$OUT/prof-t$((k + 1)).txt" "$d/prof-1.txt"
  echo "== tick $k"
  python3 firmware/scripts/fw-profile.py 1 "$d"
done
