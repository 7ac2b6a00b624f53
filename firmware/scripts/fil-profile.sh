#!/usr/bin/env bash
# Split per stage of the firmware's tick in the loop (firmware/README.md, "Firmware in the
# loop"): runs a loop session (default drift-retune) with the `fil` image, whose plugin also
# writes the counted instructions by address (target/fil/.../tickhist.txt: the ticks only,
# the fake chips excluded, exact), maps them to functions with llvm-nm and groups them as
# fw-profile.sh does.
# Usage: firmware/scripts/fil-profile.sh [SCENARIO [TICK]]   (TICK: that tick alone)
set -euo pipefail
cd "$(dirname "$0")/../.."
SC="${1:-drift-retune}"
TICK="${2:-}"
OUT="${FIL_PROFILE_DIR:-target/fil-profile}"
NM="${LLVM_NM:-llvm-nm-14}"
mkdir -p "$OUT"
PARAGYRO_FIL_HIST_TICK="$TICK" cargo run -q --release -p paragyro-fil -- "$SC" --out "$OUT" \
  > "$OUT/summary.out"
ELF=target/fil/paragyro-firmware-fil.elf
"$NM" -S -C --defined-only "$ELF" > "$OUT/nm-fil.txt"
if [ -n "$TICK" ]; then TICKS=1; else TICKS=$(wc -l < "$OUT/tickcount.txt"); fi
python3 firmware/scripts/fw-profile.py --loop "$TICKS" "$OUT"
