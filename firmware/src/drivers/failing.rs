//! A tiny [`SpiDevice`] that fails on command, for the drivers' error paths.
//!
//! `embedded-hal-mock` cannot inject bus errors, so the error paths of the drivers are
//! exercised with this device instead (STYLE.md habit 6). It is also a stand-in for an
//! absent chip: while it does not fail, every byte it "reads" is the `fill` byte, which is
//! what a floating-high (`0xFF`) or stuck-low (`0x00`) MISO line delivers.
//!
//! It lives in the library (not behind `cfg(test)`) so that integration tests and the
//! host simulation can use it; it is `no_std`, allocation-free and cannot panic.

use embedded_hal::spi::{self, ErrorKind, ErrorType, Operation, SpiDevice};

/// The error a [`FailingSpi`] returns once it has been told to fail.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FailingSpiError;

impl spi::Error for FailingSpiError {
    fn kind(&self) -> ErrorKind {
        ErrorKind::Other
    }
}

/// An [`SpiDevice`] whose transactions succeed for a while and then fail.
///
/// * [`FailingSpi::always_failing`]: every transaction returns [`FailingSpiError`].
/// * [`FailingSpi::responding`]: never fails; every byte read is `fill`.
/// * [`FailingSpi::failing_after`]: the first `n` transactions succeed (reading `fill`),
///   every later one fails.
///
/// [`FailingSpi::fail_now`] switches a device to failing at any time.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FailingSpi {
    fill: u8,
    /// Index of the first transaction that fails (`None`: never fail).
    fail_from: Option<u32>,
    transactions: u32,
}

impl FailingSpi {
    /// A device on which every transaction fails.
    pub const fn always_failing() -> Self {
        Self {
            fill: 0xFF,
            fail_from: Some(0),
            transactions: 0,
        }
    }

    /// A device that never fails and reads `fill` for every byte (`0xFF`: MISO floating
    /// high, as with an absent chip behind a pull-up; `0x00`: MISO stuck low).
    pub const fn responding(fill: u8) -> Self {
        Self {
            fill,
            fail_from: None,
            transactions: 0,
        }
    }

    /// A device whose first `ok_transactions` transactions succeed (reading `fill`) and
    /// whose later transactions all fail.
    pub const fn failing_after(ok_transactions: u32, fill: u8) -> Self {
        Self {
            fill,
            fail_from: Some(ok_transactions),
            transactions: 0,
        }
    }

    /// From now on every transaction fails.
    pub fn fail_now(&mut self) {
        self.fail_from = Some(self.transactions);
    }

    /// Number of transactions attempted so far (failed ones included).
    pub const fn transactions(&self) -> u32 {
        self.transactions
    }
}

impl ErrorType for FailingSpi {
    type Error = FailingSpiError;
}

impl SpiDevice<u8> for FailingSpi {
    fn transaction(&mut self, operations: &mut [Operation<'_, u8>]) -> Result<(), Self::Error> {
        let index = self.transactions;
        self.transactions = self.transactions.saturating_add(1);
        if self.fail_from.is_some_and(|first| index >= first) {
            return Err(FailingSpiError);
        }
        for op in operations.iter_mut() {
            match op {
                Operation::Read(buf) | Operation::TransferInPlace(buf) => buf.fill(self.fill),
                Operation::Transfer(read, _) => read.fill(self.fill),
                Operation::Write(_) | Operation::DelayNs(_) => {}
            }
        }
        Ok(())
    }
}
