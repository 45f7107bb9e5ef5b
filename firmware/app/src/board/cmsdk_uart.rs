//! Transmitter of the Arm CMSDK APB UART (mps2 boards), as a blocking
//! `embedded_io::Write` that polls TXFULL. Registers: DATA +0x00,
//! STATE +0x04 (bit 0 TXFULL), CTRL +0x08 (bit 0 TX enable), BAUDDIV +0x10.

use core::convert::Infallible;
use core::ptr::{read_volatile, write_volatile};

/// one CMSDK UART, transmit side
pub struct CmsdkUartTx {
    base: usize,
}

impl CmsdkUartTx {
    /// Enables the transmitter at `base` with baud divider `bauddiv` (QEMU
    /// ignores the UART unless `bauddiv >= 16`; it does not pace bytes).
    ///
    /// # Safety
    /// `base` is a CMSDK UART that nothing else drives.
    pub unsafe fn new(base: usize, bauddiv: u32) -> Self {
        // SAFETY: the caller guarantees exclusive access to the UART at `base`.
        unsafe {
            write_volatile((base + 0x10) as *mut u32, bauddiv);
            write_volatile((base + 0x08) as *mut u32, 1);
        }
        Self { base }
    }
}

impl embedded_io::ErrorType for CmsdkUartTx {
    type Error = Infallible;
}

impl embedded_io::Write for CmsdkUartTx {
    fn write(&mut self, buf: &[u8]) -> Result<usize, Infallible> {
        for &b in buf {
            // SAFETY: STATE and DATA of the UART this value owns.
            unsafe {
                while read_volatile((self.base + 0x04) as *const u32) & 1 != 0 {}
                write_volatile(self.base as *mut u32, u32::from(b));
            }
        }
        Ok(buf.len())
    }

    fn flush(&mut self) -> Result<(), Infallible> {
        Ok(())
    }
}
