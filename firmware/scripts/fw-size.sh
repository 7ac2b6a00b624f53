#!/usr/bin/env bash
# Flash and static RAM of a firmware ELF (firmware/README.md, "Cost"):
# flash = .vector_table + .text + .rodata + .data (its load image), static RAM = .data + .bss
# + .uninit (the stack comes on top: the qemu board prints its measured high-water mark).
set -euo pipefail
ELF="$1"; LABEL="${2:-$1}"
"${LLVM_SIZE:-llvm-size-14}" -A "$ELF" | awk -v label="$LABEL" '
  $1 == ".vector_table" || $1 == ".text" || $1 == ".rodata" { flash += $2 }
  $1 == ".data" { flash += $2; ram += $2 }
  $1 == ".bss" || $1 == ".uninit" { ram += $2 }
  $1 == ".rodata" { rodata = $2 }
  END { printf "%s: flash %d B (%.1f KiB; .rodata %d B), static RAM %d B (%.1f KiB)\n", label, flash, flash / 1024, rodata, ram, ram / 1024 }'
