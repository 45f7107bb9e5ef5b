//! FDCAN1 link of the NUCLEO-G474RE (feature `can`): the same COBS wire
//! frames as on the UART, cut by the core's CAN-FD `Fragmenter` (one header
//! byte with a rolling counter, up to 63 wire bytes per CAN frame) and sent
//! with bit-rate switching: 1 Mbit/s arbitration, 5 Mbit/s data, kernel clock
//! PLL1_Q = 85 MHz, standard id [`CAN_ID`]. The host reassembles with the
//! core's `Reassembler`. Needs an external transceiver on PA11 (RX) / PA12 (TX).

use embassy_stm32::can::frame::FdFrame;
use embassy_stm32::can::{self, Can, CanConfigurator, OperatingMode};
use embassy_stm32::peripherals::{FDCAN1, PA11, PA12};
use embassy_stm32::{bind_interrupts, Peri};
use embedded_can::StandardId;
use jointid_core::transport::can::Fragmenter;
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
    fragmenter: Fragmenter,
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
        let id = StandardId::new(CAN_ID).unwrap_or(StandardId::ZERO);
        Self {
            can: cfg.start(OperatingMode::NormalOperationMode),
            fragmenter: Fragmenter::fd(id),
            errors: 0,
        }
    }
}

impl FrameSink for FdCanLink {
    fn send_frame(&mut self, frame: &[u8]) -> Result<(), TxError> {
        let can = &mut self.can;
        // write_fd waits for a free transmit buffer; it never fails
        let sent = self.fragmenter.fragment(frame, |f: FdFrame| {
            embassy_futures::block_on(can.write_fd(&f));
            Ok::<(), ()>(())
        });
        sent.map(|_| ()).inspect_err(|_| self.errors += 1)
    }

    fn tx_errors(&self) -> u32 {
        self.errors
    }
}
