#!/usr/bin/env bash
# Cargo runner for thumbv7em-none-eabihf: one target, two boards. It reads the
# ELF entry point (the reset handler, placed right after the vector table):
#   0x08xx_xxxx -> NUCLEO-G474RE, flashed and logged with probe-rs (defmt over RTT)
#   0x00xx_xxxx -> emulated mps2-an386, run in qemu-system-arm
# QEMU settings (see firmware/app/README.md):
#   -icount shift=3,align=off,sleep=off  deterministic; SysTick then counts instructions
#   semihosting on                        defmt log on stdout, exit status, cost line on stderr
#   UART0 -> $JOINTID_SERIAL (a QEMU chardev, default: file:<elf dir>/uart0.jcap)
# stdout is decoded with defmt-print when it is installed, otherwise saved
# next to the ELF as defmt.bin (decode later: defmt-print -e <elf> < defmt.bin).
set -euo pipefail
elf="$1"
shift
entry=$(od -An -tx4 -j24 -N4 "$elf" | tr -d ' \n')
case "$entry" in
08*)
    if ! command -v probe-rs >/dev/null; then
        echo "runner: probe-rs not found (cargo install probe-rs-tools --locked); $elf is built" >&2
        exit 2
    fi
    exec probe-rs run --chip STM32G474RETx "$elf" "$@"
    ;;
00*)
    dir=$(cd "$(dirname "$elf")" && pwd)
    serial=${JOINTID_SERIAL:-file:$dir/uart0.jcap}
    qemu=(timeout "${JOINTID_QEMU_TIMEOUT:-300}" qemu-system-arm
        -machine mps2-an386 -cpu cortex-m4 -nographic -monitor none
        -icount shift=3,align=off,sleep=off
        -semihosting-config enable=on,target=native
        -serial "$serial" -kernel "$elf")
    if command -v defmt-print >/dev/null; then
        "${qemu[@]}" | defmt-print -e "$elf"
        status=${PIPESTATUS[0]}
    else
        echo "runner: defmt-print not found; raw defmt log in $dir/defmt.bin" >&2
        status=0
        "${qemu[@]}" >"$dir/defmt.bin" || status=$?
    fi
    echo "runner: qemu exit status $status; UART0 -> $serial" >&2
    exit "$status"
    ;;
*)
    echo "runner: $elf: entry point 0x$entry is neither NUCLEO flash (0x08..) nor mps2-an386 (0x00..)" >&2
    exit 2
    ;;
esac
