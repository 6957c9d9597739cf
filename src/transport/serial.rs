//! A real serial device (an RS232 port, a USB adapter, or one end of a `socat` pty pair),
//! opened with the configured baud, data bits, parity, stop bits and flow control.

use std::path::{Path, PathBuf};

use tokio_serial::{SerialPortBuilderExt, SerialStream};

use super::{FlowControl, LineSettings, Parity};

/// Why a serial device could not be opened.
#[derive(Debug, thiserror::Error)]
#[error("serial device {path} ({line}): {source}")]
pub struct SerialError {
    pub path: PathBuf,
    pub line: LineSettings,
    #[source]
    pub source: tokio_serial::Error,
}

fn builder(path: &Path, line: &LineSettings) -> tokio_serial::SerialPortBuilder {
    let data_bits = match line.data_bits {
        5 => tokio_serial::DataBits::Five,
        6 => tokio_serial::DataBits::Six,
        7 => tokio_serial::DataBits::Seven,
        _ => tokio_serial::DataBits::Eight,
    };
    let parity = match line.parity {
        Parity::None => tokio_serial::Parity::None,
        Parity::Odd => tokio_serial::Parity::Odd,
        Parity::Even => tokio_serial::Parity::Even,
    };
    let stop_bits = if line.stop_bits == 2 {
        tokio_serial::StopBits::Two
    } else {
        tokio_serial::StopBits::One
    };
    let flow = match line.flow_control {
        FlowControl::None => tokio_serial::FlowControl::None,
        FlowControl::Hardware => tokio_serial::FlowControl::Hardware,
        FlowControl::Software => tokio_serial::FlowControl::Software,
    };
    tokio_serial::new(path.to_string_lossy(), line.baud)
        .data_bits(data_bits)
        .parity(parity)
        .stop_bits(stop_bits)
        .flow_control(flow)
}

/// Opens `path` with `line` applied through termios. Must be called inside a tokio runtime.
pub fn open(path: &Path, line: &LineSettings) -> Result<SerialStream, SerialError> {
    builder(path, line)
        .open_native_async()
        .map_err(|source| SerialError {
            path: path.to_path_buf(),
            line: *line,
            source,
        })
}

#[cfg(test)]
mod tests {
    use nix::sys::termios::{self, ControlFlags};

    use super::*;
    use crate::transport::pty::PtyMaster;

    /// The settings reach the device's termios: a pty's slave stands in for a UART here.
    /// Linux ptys force CS8 and clear PARENB in `pty_set_termios`, so only the baud rate and
    /// the stop bits are observable on one; parity and data bits are mapped by the same code.
    #[tokio::test]
    async fn line_settings_are_applied_to_the_device() {
        let pty = PtyMaster::open(None).unwrap();
        let line: LineSettings = "9600 8N2".parse().unwrap();
        let port = open(pty.slave_path(), &line).unwrap();
        // The speed is set through termios2 (BOTHER); serialport reads it back from the device.
        assert_eq!(tokio_serial::SerialPort::baud_rate(&port).unwrap(), 9600);
        assert_eq!(
            tokio_serial::SerialPort::stop_bits(&port).unwrap(),
            tokio_serial::StopBits::Two
        );
        use std::os::fd::{AsRawFd, BorrowedFd};
        // SAFETY: the descriptor belongs to `port`, which outlives this borrow.
        let fd = unsafe { BorrowedFd::borrow_raw(port.as_raw_fd()) };
        let flags = termios::tcgetattr(fd).unwrap().control_flags;
        assert!(flags.contains(ControlFlags::CSTOPB | ControlFlags::CREAD | ControlFlags::CLOCAL));
    }

    #[tokio::test]
    async fn a_missing_device_names_its_path() {
        let err = open(
            Path::new("/dev/does-not-exist-eyebot"),
            &LineSettings::n81(4800),
        )
        .unwrap_err();
        assert!(
            err.to_string().contains("/dev/does-not-exist-eyebot"),
            "{err}"
        );
    }
}
