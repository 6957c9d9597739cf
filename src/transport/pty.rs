//! A pseudo-terminal pair created in-process, the bridge holding the master side.
//!
//! The EyeBot side (a host build of a control program, qemu, `probe`, a test) opens the slave
//! device, usually through the stable symlink. The bridge also keeps its own handle on the
//! slave open, so the pair survives the EyeBot side opening and closing it any number of
//! times: without it the master would read EIO after the last close and the pty would die.

use std::io;
use std::os::fd::{AsFd, AsRawFd, OwnedFd};
use std::path::{Path, PathBuf};
use std::pin::Pin;
use std::task::{Context, Poll, ready};

use nix::fcntl::{FcntlArg, OFlag, fcntl};
use nix::sys::termios::{self, SetArg};
use tokio::io::unix::AsyncFd;
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};

use super::symlink::{LinkError, OwnedLink};

/// Why a pty could not be set up.
#[derive(Debug, thiserror::Error)]
pub enum PtyError {
    #[error("cannot create a pseudo-terminal: {0}")]
    Open(#[source] nix::Error),
    #[error("cannot configure the pseudo-terminal {path}: {source}")]
    Configure {
        path: PathBuf,
        #[source]
        source: nix::Error,
    },
    #[error(transparent)]
    Link(#[from] LinkError),
    #[error("cannot register the pseudo-terminal with the runtime: {0}")]
    Register(#[source] io::Error),
}

/// The master side of a pty pair, readable and writable from tokio.
#[derive(Debug)]
pub struct PtyMaster {
    master: AsyncFd<OwnedFd>,
    /// Keeps the slave open so the EyeBot side may close and reopen it.
    _slave: OwnedFd,
    slave_path: PathBuf,
    link: Option<OwnedLink>,
}

impl PtyMaster {
    /// Opens a pair in raw mode (no echo, no line discipline), optionally with a stable
    /// symlink at `link` pointing at the slave. Must be called inside a tokio runtime.
    pub fn open(link: Option<&Path>) -> Result<Self, PtyError> {
        let pair = nix::pty::openpty(None, None).map_err(PtyError::Open)?;
        let slave_path = nix::unistd::ttyname(&pair.slave).map_err(PtyError::Open)?;
        let configure = |source| PtyError::Configure {
            path: slave_path.clone(),
            source,
        };
        let mut attrs = termios::tcgetattr(&pair.slave).map_err(configure)?;
        termios::cfmakeraw(&mut attrs);
        termios::tcsetattr(&pair.slave, SetArg::TCSANOW, &attrs).map_err(configure)?;
        let flags = fcntl(pair.master.as_fd(), FcntlArg::F_GETFL).map_err(configure)?;
        fcntl(
            pair.master.as_fd(),
            FcntlArg::F_SETFL(OFlag::from_bits_truncate(flags) | OFlag::O_NONBLOCK),
        )
        .map_err(configure)?;
        let link = link
            .map(|l| OwnedLink::create(l, &slave_path))
            .transpose()?;
        // SAFETY: `OwnedFd` is a valid open descriptor that stays open, and its `as_raw_fd`
        // returns the same descriptor, for as long as the `AsyncFd` owns it.
        let master =
            unsafe { AsyncFd::register(pair.master) }.map_err(|e| PtyError::Register(e.into()))?;
        Ok(Self {
            master,
            _slave: pair.slave,
            slave_path,
            link,
        })
    }

    /// The slave device (`/dev/pts/N`).
    pub fn slave_path(&self) -> &Path {
        &self.slave_path
    }

    /// The stable symlink, if one was requested.
    pub fn link_path(&self) -> Option<&Path> {
        self.link.as_ref().map(OwnedLink::path)
    }

    /// The path a client should open: the symlink if there is one, else the slave device.
    pub fn client_path(&self) -> &Path {
        self.link_path().unwrap_or(&self.slave_path)
    }

    /// Handles for taking the last input at shutdown ([`PtyDrain`]), on duplicates of the
    /// pair's descriptors.
    pub fn drain_handle(&self) -> io::Result<PtyDrain> {
        Ok(PtyDrain {
            master: self.master.get_ref().try_clone()?,
            slave: self._slave.try_clone()?,
        })
    }
}

/// Takes what the EyeBot side wrote before the bridge closes the pair.
///
/// [`hold_input`](Self::hold_input) suspends the slave's output (`tcflow(TCOOFF)`): the
/// EyeBot side's writes then wait, or fail with EAGAIN, instead of being accepted. After it,
/// reading the master until it would block ([`read_now`](Self::read_now)) takes every byte
/// the kernel accepted: none is left in the pty when it closes.
#[derive(Debug)]
pub struct PtyDrain {
    master: OwnedFd,
    slave: OwnedFd,
}

impl PtyDrain {
    /// Stops the slave side's writes from being accepted from now on.
    pub fn hold_input(&self) -> io::Result<()> {
        termios::tcflow(&self.slave, termios::FlowArg::TCOOFF).map_err(nix_to_io)
    }

    /// One non-blocking read of the master: `Ok(0)` at end of file, `WouldBlock` when
    /// nothing is buffered (the kernel pushes pending input to the reader before saying so).
    pub fn read_now(&self, buf: &mut [u8]) -> io::Result<usize> {
        nix::unistd::read(&self.master, buf).map_err(nix_to_io)
    }
}

fn nix_to_io(e: nix::Error) -> io::Error {
    io::Error::from_raw_os_error(e as i32)
}

impl AsyncRead for PtyMaster {
    fn poll_read(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        loop {
            let mut guard = ready!(self.master.poll_read_ready(cx))?;
            let unfilled = buf.initialize_unfilled();
            match guard.try_io(|fd| nix::unistd::read(fd.get_ref(), unfilled).map_err(nix_to_io)) {
                Ok(Ok(n)) => {
                    buf.advance(n);
                    return Poll::Ready(Ok(()));
                }
                Ok(Err(e)) => return Poll::Ready(Err(e)),
                Err(_would_block) => continue,
            }
        }
    }
}

impl AsyncWrite for PtyMaster {
    fn poll_write(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        loop {
            let mut guard = ready!(self.master.poll_write_ready(cx))?;
            match guard.try_io(|fd| nix::unistd::write(fd.get_ref(), buf).map_err(nix_to_io)) {
                Ok(result) => return Poll::Ready(result),
                Err(_would_block) => continue,
            }
        }
    }

    fn poll_flush(self: Pin<&mut Self>, _cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Poll::Ready(Ok(()))
    }

    fn poll_shutdown(self: Pin<&mut Self>, _cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Poll::Ready(Ok(()))
    }
}

impl AsRawFd for PtyMaster {
    fn as_raw_fd(&self) -> std::os::fd::RawFd {
        self.master.get_ref().as_raw_fd()
    }
}

#[cfg(test)]
mod tests {
    use std::io::{Read, Write};

    use tokio::io::{AsyncReadExt, AsyncWriteExt};

    use super::*;

    #[tokio::test]
    async fn bytes_cross_both_ways_and_survive_client_reopen() {
        let mut pty = PtyMaster::open(None).unwrap();
        for round in 0..3u8 {
            // A client opens the slave, talks, and closes it again.
            let mut client = std::fs::OpenOptions::new()
                .read(true)
                .write(true)
                .open(pty.slave_path())
                .unwrap();
            client.write_all(&[0xA5, round, b'$', 0x00]).unwrap();
            let mut got = [0u8; 4];
            pty.read_exact(&mut got).await.unwrap();
            assert_eq!(
                got,
                [0xA5, round, b'$', 0x00],
                "raw mode passes every byte unchanged"
            );

            pty.write_all(b"$SDDBT,,f,1.2,M,,F*00\r\n").await.unwrap();
            let mut back = [0u8; 23];
            client.read_exact(&mut back).unwrap();
            assert_eq!(&back, b"$SDDBT,,f,1.2,M,,F*00\r\n");
            drop(client);
        }
    }
}
