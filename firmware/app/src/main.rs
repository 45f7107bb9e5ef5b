//! Joint-excitation firmware: one application (`app`) on two thin hardware
//! layers (`board`), chosen by cargo feature:
//! - `nucleo-g474re`: STM32G474RE on embassy-stm32 (TIM2 tick, LPUART1 or FDCAN1, encoder, ADC, DAC);
//! - `mps2-an386`: QEMU's Cortex-M4 board (SysTick tick, CMSDK UART0, the core's simulated joint).
//!
//! It only builds for `thumbv7em-none-eabihf` (`cargo fw`, `cargo fw-qemu`);
//! on the host the package compiles to a `main` that says so, which keeps
//! `cargo clippy --workspace --all-targets` working.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
mod app;
#[cfg(target_os = "none")]
mod board;
#[cfg(target_os = "none")]
mod cost;

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!(
        "jointid-fw is firmware for thumbv7em-none-eabihf: build it with `cargo fw` (NUCLEO-G474RE) \
         or `cargo fw-qemu` (emulated mps2-an386); see firmware/app/README.md"
    );
    std::process::exit(2);
}
