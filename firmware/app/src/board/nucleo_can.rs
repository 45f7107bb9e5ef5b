//! FDCAN1 link of the NUCLEO-G474RE (feature `can`): the same COBS frame
//! stream as the UART, cut into CAN-FD frames of up to 64 bytes with bit-rate
//! switching (1 Mbit/s arbitration, 5 Mbit/s data, kernel clock PLL1_Q = 85 MHz),
//! standard id [`CAN_ID`]. A short last piece is padded with 0x00 to the next
//! FD length; the host's decoder skips those as idle fill between frames.
//! Needs an external transceiver on PA11 (RX) / PA12 (TX).

use embassy_stm32::can::frame::{FdFrame, Header};
use embassy_stm32::can::{self, Can, CanConfigurator, OperatingMode};
use embassy_stm32::peripherals::{FDCAN1, PA11, PA12};
use embassy_stm32::{bind_interrupts, Peri};
use embedded_can::{Id, StandardId};
use jointid_core::transport::{FrameSink, TxError};

/// standard CAN id of the stream's frames
pub const CAN_ID: u16 = 0x101;

bind_interrupts!(struct Irqs {
    FDCAN1_IT0 => can::IT0InterruptHandler<FDCAN1>;
    FDCAN1_IT1 => can::IT1InterruptHandler<FDCAN1>;
});

/// the stream over FDCAN1
pub struct FdCanLink {
    can: Can<'static>,
    errors: u32,
}

impl FdCanLink {
    /// FDCAN1 at 1 Mbit/s nominal, 5 Mbit/s data phase, normal mode
    pub fn new(
        fdcan: Peri<'static, FDCAN1>,
        rx: Peri<'static, PA11>,
        tx: Peri<'static, PA12>,
    ) -> Self {
        let mut cfg = CanConfigurator::new(fdcan, rx, tx, Irqs);
        cfg.set_bitrate(1_000_000);
        cfg.set_fd_data_bitrate(5_000_000, true);
        Self {
            can: cfg.start(OperatingMode::NormalOperationMode),
            errors: 0,
        }
    }
}

/// smallest CAN-FD payload length that holds `n` bytes
fn fd_len(n: usize) -> usize {
    match n {
        0..=8 => n,
        9..=12 => 12,
        13..=16 => 16,
        17..=20 => 20,
        21..=24 => 24,
        25..=32 => 32,
        33..=48 => 48,
        _ => 64,
    }
}

impl FrameSink for FdCanLink {
    fn send_frame(&mut self, frame: &[u8]) -> Result<(), TxError> {
        let id = Id::Standard(StandardId::new(CAN_ID).ok_or(TxError::Fragment)?);
        for piece in frame.chunks(64) {
            let mut data = [0u8; 64];
            data[..piece.len()].copy_from_slice(piece);
            let len = fd_len(piece.len());
            let Ok(fd) = FdFrame::new(Header::new_fd(id, len as u8, false, true), &data[..len])
            else {
                self.errors += 1;
                return Err(TxError::Fragment);
            };
            // waits for a free transmit buffer; a frame it displaces is not ours to lose
            let _ = embassy_futures::block_on(self.can.write_fd(&fd));
        }
        Ok(())
    }

    fn tx_errors(&self) -> u32 {
        self.errors
    }
}
