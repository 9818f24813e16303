//! The serial link to the chip: QEMU's USART1 socket.

use std::io::{Read, Write};
use std::net::Shutdown;
use std::os::unix::net::UnixStream;
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{self, Receiver};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};

/// A connection to the chip's link UART. A reader thread drains the socket
/// continuously into a channel: QEMU's USART transmit blocks the whole
/// emulator while the socket's buffer is full, so a host that wrote
/// without reading would deadlock with QEMU (the chip would stop echoing,
/// the host's write would stop draining).
pub struct McuLink {
    stream: UnixStream,
    rx: Receiver<Vec<u8>>,
    reader: Option<JoinHandle<()>>,
    sent: u64,
    received: Arc<AtomicU64>,
}

impl McuLink {
    /// Connect to the chip's socket, retrying until `timeout`.
    pub fn connect(socket: &Path, timeout: Duration) -> Result<McuLink> {
        let t0 = Instant::now();
        // A chip being started has not made its socket yet: wait for it (up
        // to `timeout`). A socket that is there but refuses is a chip that
        // is gone (a stale socket): said after a second, not after the
        // whole timeout; a path that is not a socket, at once.
        const REFUSED_FOR: Duration = Duration::from_secs(1);
        let mut refused_since: Option<Instant> = None;
        let stream = loop {
            use std::os::unix::fs::FileTypeExt;
            match std::fs::metadata(socket) {
                Ok(m) if !m.file_type().is_socket() => anyhow::bail!(
                    "{} is not a socket (--mcu-socket names the chip's link socket)",
                    socket.display()
                ),
                _ => {}
            }
            match UnixStream::connect(socket) {
                Ok(s) => break s,
                Err(e) if e.kind() == std::io::ErrorKind::ConnectionRefused => {
                    let since = *refused_since.get_or_insert_with(Instant::now);
                    if since.elapsed() >= REFUSED_FOR {
                        anyhow::bail!(
                            "nothing listens on {} (a socket left by a chip that is gone?): {e}",
                            socket.display()
                        );
                    }
                }
                Err(e) if t0.elapsed() >= timeout => {
                    return Err(e).with_context(|| {
                        format!(
                            "no chip made {} within {timeout:?} (is it running?)",
                            socket.display()
                        )
                    })
                }
                Err(_) => {}
            }
            std::thread::sleep(Duration::from_millis(5));
        };
        let mut reading = stream.try_clone().context("cloning the link socket")?;
        let received = Arc::new(AtomicU64::new(0));
        let count = Arc::clone(&received);
        let (tx, rx) = mpsc::channel();
        let reader = std::thread::Builder::new()
            .name("mcu-link-reader".into())
            .spawn(move || {
                let mut buf = [0u8; 4096];
                loop {
                    match reading.read(&mut buf) {
                        Ok(0) | Err(_) => break,
                        Ok(n) => {
                            count.fetch_add(n as u64, Ordering::Relaxed);
                            if tx.send(buf.get(..n).unwrap_or(&[]).to_vec()).is_err() {
                                break;
                            }
                        }
                    }
                }
            })
            .context("starting the link reader thread")?;
        Ok(McuLink {
            stream,
            rx,
            reader: Some(reader),
            sent: 0,
            received,
        })
    }

    /// Send `bytes` (blocks while the socket is full: the chip reads one
    /// byte at a time as its receive register frees).
    pub fn send(&mut self, bytes: &[u8]) -> Result<()> {
        self.stream
            .write_all(bytes)
            .context("writing to the chip")?;
        self.sent += bytes.len() as u64;
        Ok(())
    }

    /// The next chunk received, waiting at most `timeout`; `None` on
    /// timeout or when the chip closed the link.
    pub fn recv(&self, timeout: Duration) -> Option<Vec<u8>> {
        self.rx.recv_timeout(timeout).ok()
    }

    /// The next chunk received, if one is waiting.
    pub fn try_recv(&self) -> Option<Vec<u8>> {
        self.rx.try_recv().ok()
    }

    /// Bytes written but not yet read by QEMU (the socket's send queue,
    /// `TIOCOUTQ`): the link's backlog, what a new frame waits behind.
    pub fn backlog(&self) -> usize {
        use std::os::fd::AsRawFd;
        let mut n: libc::c_int = 0;
        // SAFETY: TIOCOUTQ writes one int through a valid pointer.
        let ok = unsafe { libc::ioctl(self.stream.as_raw_fd(), libc::TIOCOUTQ, &mut n) } == 0;
        if ok {
            usize::try_from(n).unwrap_or(0)
        } else {
            0
        }
    }

    /// Bytes sent so far.
    pub fn bytes_sent(&self) -> u64 {
        self.sent
    }

    /// Bytes the reader thread has received so far (including chunks not
    /// yet taken with [`McuLink::recv`]).
    pub fn bytes_received(&self) -> u64 {
        self.received.load(Ordering::Relaxed)
    }
}

impl Drop for McuLink {
    fn drop(&mut self) {
        let _ = self.stream.shutdown(Shutdown::Both);
        if let Some(t) = self.reader.take() {
            let _ = t.join();
        }
    }
}
