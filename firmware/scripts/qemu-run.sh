#!/usr/bin/env bash
# Cargo runner for thumbv7em-none-eabihf: boots the ELF in QEMU's netduinoplus2
# (STM32F405, the same MCU and memory map as the real board), decodes the defmt stream
# from semihosting with defmt-print, and exits with the firmware's verdict
# (semihosting exit: 0 pass, 1 fail/panic/HardFault; 124 on a hang).
set -euo pipefail
ELF="$1"; shift
QEMU_ICOUNT="${QEMU_ICOUNT:-shift=0}"
DEFMT_PRINT="${DEFMT_PRINT:-defmt-print}"
timeout "${QEMU_TIMEOUT:-120}" qemu-system-arm \
  -cpu cortex-m4 -machine netduinoplus2 -nographic -monitor none -serial none \
  -icount "$QEMU_ICOUNT" \
  -semihosting-config enable=on,target=native \
  -kernel "$ELF" "$@" \
  | "$DEFMT_PRINT" -e "$ELF"
