//! Output over semihosting: the images' result lines ([`Console`]) and the
//! `log` records ([`init_logger`]).

use core::fmt::Write;

use cortex_m_semihosting::hio;

/// Bytes a [`Console`] buffers before it writes (a full buffer is written
/// even without a newline).
const LINE: usize = 200;

/// Semihosting stdout, buffered per line: one host call per line instead of
/// one per `write!` fragment, which keeps printing cheap under QEMU. Call
/// [`Console::flush`] before exiting to write a last unterminated line.
pub struct Console {
    host: Option<hio::HostStream>,
    buf: [u8; LINE],
    len: usize,
}

impl Console {
    /// The host's stdout; without a debugger attached the output is
    /// dropped (the run itself goes on).
    pub fn new() -> Self {
        Self {
            host: hio::hstdout().ok(),
            buf: [0; LINE],
            len: 0,
        }
    }

    /// Write what is buffered.
    pub fn flush(&mut self) {
        if let (Some(h), Some(bytes)) = (self.host.as_mut(), self.buf.get(..self.len)) {
            let _ = h.write_all(bytes);
        }
        self.len = 0;
    }
}

impl Default for Console {
    fn default() -> Self {
        Self::new()
    }
}

impl Write for Console {
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        for &b in s.as_bytes() {
            if let Some(slot) = self.buf.get_mut(self.len) {
                *slot = b;
                self.len += 1;
            }
            if b == b'\n' || self.len == self.buf.len() {
                self.flush();
            }
        }
        Ok(())
    }
}

/// `log` records as `log <level> <message>` lines on the semihosting
/// console; the QEMU tests skip them when they parse the result lines.
struct SemihostingLogger;

impl log::Log for SemihostingLogger {
    fn enabled(&self, _: &log::Metadata) -> bool {
        true
    }

    fn log(&self, record: &log::Record) {
        if let Ok(mut h) = hio::hstdout() {
            let _ = writeln!(h, "log {} {}", record.level(), record.args());
        }
    }

    fn flush(&self) {}
}

static LOGGER: SemihostingLogger = SemihostingLogger;

/// Route the `log` macros (the swap's accept/reject records, the control
/// step's warnings) to the semihosting console, at level `Info`. A second
/// call changes nothing.
pub fn init_logger() {
    if log::set_logger(&LOGGER).is_ok() {
        log::set_max_level(log::LevelFilter::Info);
    }
}
