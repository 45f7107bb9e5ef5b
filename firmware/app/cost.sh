#!/usr/bin/env bash
# Measures the firmware's work per 2 kHz tick on the emulated Cortex-M4
# (QEMU mps2-an386, -icount shift=3,align=off,sleep=off: one SysTick count at
# 25 MHz is 40 ns of virtual time = 40 / 2^3 = 5 instructions). The firmware
# times its tick handler and every idle-loop poll with SysTick and prints one
# `jointid-cost key=value ...` line on semihosting stderr at the end of its run;
# this script builds it, runs it, and prints that line as a table.
set -euo pipefail
cd "$(dirname "$0")/../.."
cargo fw-qemu --quiet
elf="${CARGO_TARGET_DIR:-target}/thumbv7em-none-eabihf/firmware/jointid-fw"
line=$(timeout 300 qemu-system-arm -machine mps2-an386 -cpu cortex-m4 -nographic -monitor none \
    -icount shift=3,align=off,sleep=off -semihosting-config enable=on,target=native \
    -serial null -kernel "$elf" 2>&1 >/dev/null | grep '^jointid-cost ')
echo "firmware work per 2 kHz tick, emulated Cortex-M4, whole run (instructions; ticks = count):"
for kv in ${line#jointid-cost }; do
    printf '  %-20s %8s\n' "${kv%%=*}" "${kv#*=}"
done
